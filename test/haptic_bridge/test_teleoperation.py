"""Teleoperation under delay: the emulated link, the passivity observer and controller, the teleop benchmark's
definitions, and the link on real nodes (behaviour, no timing thresholds)."""
import json
import subprocess
import sys

import numpy as np
import pytest

from haptic_bridge.parameters import PARAMETERS as BRIDGE
from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.passivity import (
    GENERATED_LIMIT_J,
    WINDOW_S,
    GenerationMonitor,
    PassivityObserver,
    max_generated_energy,
)
from haptic_bridge.tick import BridgeTick, passive_model_update_on
from liver_sim.base.emulated_link import LINK_PARAMETERS, EmulatedLink, LinkSettings
from liver_sim.base.local_model import LocalModel, penetration
from liver_sim.bench import teleop
from liver_sim.physics.parameters import PARAMETERS as PHYSICS

T = 0.001


# -- the emulated link
def test_a_delayed_message_is_released_at_its_arrival_plus_the_delay_and_not_before():
    link = EmulatedLink(LinkSettings(delay_s=0.1))
    link.send("a", 1.0)
    link.send("b", 1.001)
    assert link.receive(1.0999) == []
    assert link.receive(1.1) == [("a", pytest.approx(1.1))]
    assert link.waiting == 1 and link.receive(2.0) == [("b", pytest.approx(1.101))]


def test_jitter_spreads_the_delay_never_below_zero_and_never_reorders():
    link = EmulatedLink(LinkSettings(delay_s=0.01, jitter_s=0.02, seed=3))
    arrivals = np.arange(1000) * T
    for i, arrival in enumerate(arrivals):
        link.send(i, arrival)
    released = link.receive(10.0)
    order = [item for item, _ in released]
    release = np.array([when for _, when in released])
    assert order == list(range(1000))
    assert np.all(np.diff(release) >= 0.0) and np.all(release >= arrivals)
    delays = release - arrivals
    assert delays.max() > 0.02 and delays.min() < 0.01  # it does spread, both ways


def test_loss_is_the_asked_fraction_and_a_seed_repeats_it():
    def lost(seed):
        link = EmulatedLink(LinkSettings(delay_s=0.0, loss_fraction=0.05, seed=seed))
        kept = []
        for i in range(20000):
            link.send(i, i * T)
            kept += [item for item, _ in link.receive(i * T)]
        return link.lost, kept

    count, kept = lost(7)
    assert count == pytest.approx(1000, rel=0.15) and len(kept) == 20000 - count
    assert lost(7) == (count, kept) and lost(8)[1] != kept


def test_a_full_queue_drops_its_oldest_message_and_counts_it():
    link = EmulatedLink(LinkSettings(delay_s=1.0), capacity=3)
    for i in range(5):
        link.send(i, 0.0)
    assert link.counts() == {"link_sent": 5, "link_lost": 0, "link_overflowed": 2, "link_waiting": 3}
    assert [item for item, _ in link.receive(2.0)] == [2, 3, 4]


def test_zero_delay_jitter_and_loss_is_no_link_and_both_sides_declare_the_same_parameters():
    assert not LinkSettings().emulated and LinkSettings(jitter_s=0.001).emulated
    for table in (PHYSICS, BRIDGE):
        assert {name: table[name] for name in LINK_PARAMETERS} == LINK_PARAMETERS


# -- the passivity observer and controller
def test_the_observer_pairs_each_motion_with_the_command_in_effect_at_the_device():
    """The motion between two samples meets the newest command sent at or before the later stamp minus the
    measured latency: with no latency the command sent just before, with 2 ms of latency the one before that."""
    def energy(latency_s: float) -> float:
        observer = PassivityObserver(T)
        observer.commanded(0.9995, np.zeros(3))
        observer.sample(1.000, 1.000 + latency_s, (0.0, 0.0, 0.0))
        observer.commanded(1.0005, np.array([0.0, 0.0, 1.0]))
        observer.sample(1.001, 1.001 + latency_s, (0.0, 0.0, 0.001))  # moved 1 mm along +z
        return observer.energy_j

    assert energy(0.0) == pytest.approx(0.001)   # the 1 N command acted over that millimetre: 1 mJ to the hand
    assert energy(0.002) == pytest.approx(0.0)   # it had not reached the device yet: the zero acted


def test_the_observer_counts_each_sample_once_and_only_forward():
    observer = PassivityObserver(T)
    observer.commanded(0.0, np.array([1.0, 0.0, 0.0]))
    observer.sample(0.001, 0.001, (0.0, 0.0, 0.0))
    observer.sample(0.002, 0.002, (0.002, 0.0, 0.0))
    observer.sample(0.002, 0.003, (0.002, 0.0, 0.0))   # the same sample read again
    observer.sample(0.0015, 0.003, (0.9, 0.0, 0.0))    # an older one
    assert observer.energy_j == pytest.approx(0.002)
    observer.forget_motion()                           # stale: no motion counted across the hole
    observer.sample(0.010, 0.010, (1.0, 1.0, 1.0))
    assert observer.energy_j == pytest.approx(0.002)


def test_the_controller_damps_measured_motion_only_and_only_what_the_contact_gave_back():
    """α = (E − E(t0))/(T·|v|²), v the measured stylus velocity, at most the cap; a still stylus gets nothing."""
    def controlled(excess_j: float, velocity_m_s: float, cap: float = 20.0, control: bool = True):
        observer = PassivityObserver(T, control=control, max_damping_ns_per_m=cap)
        observer.sample(0.0, 0.0, (0.0, 0.0, 0.0))
        observer.sample(0.001, 0.001, (0.0, 0.0, velocity_m_s * 0.001))
        observer.energy_j = observer.episode_energy_j + excess_j
        return observer.damp(np.array([0.0, 0.0, 1.0])), observer.damping_ns_per_m

    force, alpha = controlled(0.0006, 1.0)  # 0.6 mJ given back beyond what was put in, moving at 1 m/s
    assert alpha == pytest.approx(0.6) and force == pytest.approx([0.0, 0.0, 0.4])
    assert controlled(0.0006, 0.0) == (pytest.approx([0.0, 0.0, 1.0]), 0.0), "a still stylus: no controller force"
    assert controlled(-0.001, 1.0) == (pytest.approx([0.0, 0.0, 1.0]), 0.0), "covered by what the hand put in"
    assert controlled(0.0006, 1.0, control=False) == (pytest.approx([0.0, 0.0, 1.0]), 0.0)
    force, alpha = controlled(0.0006, 1.0, cap=0.5)
    assert alpha == 0.5 and force == pytest.approx([0.0, 0.0, 0.5])


def test_passive_model_updates_are_on_by_default_exactly_when_a_link_is_emulated():
    p = BridgeParameters.defaults()
    assert not passive_model_update_on(p)
    assert passive_model_update_on(p.replace(link_delay_s=0.05))
    assert passive_model_update_on(p.replace(link_loss_fraction=0.1))
    assert not passive_model_update_on(p.replace(link_delay_s=0.05, passive_model_update="never"))
    assert passive_model_update_on(p.replace(passive_model_update="always"))


def _plane_tick(control: bool) -> BridgeTick:
    p = BridgeParameters.defaults().replace(passivity_control=control, soft_start_s=0.1,
                                            max_force_rate_n_per_s=100000.0)
    return BridgeTick(p)


def test_the_bridge_counts_the_energy_of_what_it_sent_in_the_device_frame():
    """A tip pressed into a fixed plane and drawn back along the same path: the observer's energy is the sum of
    the commands times the motion (samples without latency), and a plane that jumps outward while in contact (a
    model update) gives the hand energy, which the controller then takes back out."""
    plane = LocalModel("plane", True, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.0, 0.0, True, None)
    raised = LocalModel("plane", True, np.array([0.0, 0.0, 0.005]), np.array([0.0, 0.0, 1.0]),
                        np.array([0.0, 0.0, 0.005]), 0.0, 0.0, True, None)
    depths = np.concatenate([np.linspace(0.0, 0.01, 400), np.full(200, 0.01), np.linspace(0.01, 0.0, 400)])
    results = {}
    for control in (False, True):
        tick = _plane_tick(control)
        sent, positions = [], []
        for k, depth in enumerate(depths):
            tip = np.array([0.0, 0.0, 0.015 - depth])
            model = raised if 450 <= k else plane
            tick.sample(k * T, k * T, tip)
            sent.append(tick.step(k * T, tip, 0.0, (model, 1.0), 0.0))
            positions.append(tip)
        expected = sum(float(f @ (x1 - x0)) for f, x0, x1 in zip(sent, positions, positions[1:]))
        assert tick.passivity.energy_j == pytest.approx(expected)
        results[control] = tick.passivity
    assert results[False].energy_j > 0.0             # the raised plane pushed the hand out with more than it took
    assert results[True].energy_j < results[False].energy_j


def test_the_observer_takes_the_stylus_motion_through_the_device_map():
    """With a turned and scaled map the energy is the command (device frame) times the stylus's motion (device frame),
    and the sample places the tool tip through the map."""
    from liver_sim.base.geometry.device_map import DeviceMap

    device_map = DeviceMap([0.0, 0.0, np.sin(np.pi / 8), np.cos(np.pi / 8)], [0.1, 0.0, 0.0], 2.0)
    p = BridgeParameters.defaults()
    tick = BridgeTick(p.replace(stiffness_n_per_m=90.0), device_map)  # passive at this map's scale 2
    tips = [np.array([0.01, 0.02, 0.03]), np.array([0.012, 0.017, 0.034]), np.array([0.011, 0.02, 0.031])]
    forces = [np.array([0.3, -0.2, 0.5]), np.array([-0.1, 0.4, 0.2])]
    assert tick.sample(0.0, 0.0, device_map.liver_to_device(tips[0])) == pytest.approx(tips[0])  # placed by it
    for k, (force, tip) in enumerate(zip(forces, tips[1:])):
        tick.passivity.commanded(k * T + 0.0005, force)
        tick.sample((k + 1) * T, (k + 1) * T, device_map.liver_to_device(tip))
    expected = sum(float(f @ (device_map.liver_to_device(b) - device_map.liver_to_device(a)))
                   for f, a, b in zip(forces, tips, tips[1:]))
    assert tick.passivity.energy_j == pytest.approx(expected, rel=1e-12)


# -- the windowed passivity judgement, on synthetic traces
def _trace(*segments):
    """(energy J, episode energy J) of consecutive (samples, energy at the end, in contact) segments at 1 kHz,
    energy moving linearly within each."""
    energy, episode, e, e0 = [], [], 0.0, 0.0
    for samples, end, contact in segments:
        for value in np.linspace(e, end, samples + 1)[1:]:
            if not contact:
                e0 = value
            energy.append(value)
            episode.append(e0)
        e = end
    return np.array(energy), np.array(episode)


def _generated(*segments) -> float:
    energy, episode = _trace(*segments)
    return float(max_generated_energy(energy, episode, round(WINDOW_S / T)).max())


def test_a_passive_press_and_release_generates_nothing():
    # the hand puts 2 mJ into a contact, which gives back 1.5 mJ (the rest dissipated), then lets go
    assert _generated((200, 0.0, False), (300, -0.002, True), (300, -0.0005, True), (200, -0.0005, False)) <= 1e-12


def test_energy_put_in_early_does_not_hide_energy_generated_later():
    """The old judgement (the running total never above 1 mJ) called this passive: 5 mJ absorbed by a first contact
    hid the 1 mJ a second contact generated seconds later."""
    segments = ((100, 0.0, False), (400, -0.005, True), (100, -0.005, False), (2000, -0.005, False),
                (300, -0.005, True), (300, -0.004, True), (100, -0.004, False))
    energy, _ = _trace(*segments)
    assert energy.max() <= 0.001  # passive by the old, running-total judgement
    assert _generated(*segments) == pytest.approx(0.001)


def test_a_contact_generating_slowly_within_a_window_is_caught_and_outside_it_is_not_summed():
    # 0.3 mJ generated in each of two contacts 2 s apart: no window holds more than 0.3 mJ
    segments = ((100, 0.0, False), (200, 0.0003, True), (2000, 0.0003, False), (200, 0.0006, True))
    assert _generated(*segments) == pytest.approx(0.0003)
    assert GENERATED_LIMIT_J > 0.0003 and _generated((100, 0.0, False), (400, 0.0008, True)) > GENERATED_LIMIT_J


def test_the_monitor_folds_what_the_loop_recorded_into_the_largest_window():
    monitor = GenerationMonitor(T)
    energy, episode = _trace((100, 0.0, False), (400, -0.002, True), (100, -0.002, False), (300, -0.001, True))
    in_contact = np.r_[np.zeros(100, bool), np.ones(400, bool), np.zeros(100, bool), np.ones(300, bool)]
    for k, (e, contact) in enumerate(zip(energy, in_contact)):
        monitor.record(k * T, float(e), bool(contact))
        if k % 250 == 0:
            monitor.update()
    assert monitor.update() == pytest.approx(0.001) and monitor.at_s == pytest.approx(899 * T)


# -- the oscillation measure (stable), on synthetic traces
def _press_trace():
    times = np.arange(0.0, 12.0, T)
    taps = np.clip(np.sin(2 * np.pi * 0.4 * times), 0.0, None)[:, None] * np.array([0.0, 0.0, 0.5])
    return times, taps


@pytest.mark.parametrize("frequency_hz", [0.6, 1.25, 6.0, 40.0, 80.0])
def test_the_oscillation_measure_catches_an_oscillation_from_half_a_hertz_to_a_hundred(frequency_hz):
    times, taps = _press_trace()
    wobble = taps.copy()
    during = (times > 2.0) & (times < 9.0)
    wobble[during, 2] += 0.15 * np.sin(2 * np.pi * frequency_hz * times[during])
    assert teleop.oscillating_s((times, taps), (times, taps)) == 0.0
    assert teleop.oscillating_s((times, wobble), (times, taps)) >= teleop.OSCILLATION_SUSTAINED_S


def test_the_oscillation_measure_catches_a_force_turning_at_the_clamp():
    """A force stuck at its clamp whose direction swings: its norm never moves."""
    times = np.arange(0.0, 12.0, T)
    steady = np.tile([0.0, 0.0, 2.0], (len(times), 1))
    angle = 0.3 * np.sin(2 * np.pi * 3.0 * times)
    swinging = 2.0 * np.column_stack([np.sin(angle), np.zeros_like(angle), np.cos(angle)])
    assert np.allclose(np.linalg.norm(swinging, axis=1), 2.0)
    assert teleop.oscillating_s((times, swinging), (times, steady)) >= teleop.OSCILLATION_SUSTAINED_S


def test_the_teleop_targets_need_the_runs_to_have_had_jitter_and_loss():
    rows = [{"variant": "local_model", "delay_ms": d, "stable": True, "passive": True}
            for d in (0.0, 10.0, 50.0, 100.0)]
    key = "default_stable_and_passive_up_to_delay_ms"
    assert teleop.targets_met(rows, 10.0, 0.05)[key]
    assert not teleop.targets_met(rows, 0.0, 0.0)[key]
    assert not teleop.targets_met(rows[:-1], 10.0, 0.05)[key]
    assert not teleop.targets_met([{**rows[0], "passive": False}, *rows[1:]], 10.0, 0.05)[key]


# -- the command line refuses bad link options by name
@pytest.mark.parametrize("argv, named", [
    (["demo", "--link-delay", "-0.1"], "--link-delay"),
    (["demo", "--link-loss", "1.5"], "--link-loss"),
    (["demo", "--offline", "--link-delay", "0.05"], "--link-"),
    (["bench", "teleop", "--loss", "2"], "--loss"),
    (["bench", "teleop", "--delays", "-5"], "--delays")])
def test_bad_link_options_are_refused_by_name(argv, named, tmp_path):
    result = subprocess.run([sys.executable, "-m", "liver_sim.cli.main", *argv, "--out", str(tmp_path)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and named in result.stderr, result.stderr


# -- on real nodes
def test_the_link_delays_the_inputs_of_both_sides_and_the_stamps_show_it(ros_domain_id, tmp_path):
    """The demo over a 60 ms link: each side reports the link, and the delay its stamps measured is at least it
    (a released message is never older than its stamp plus the delay); the force is still felt and safe."""
    from liver_sim.studies.demo import run_demo

    summary = run_demo(tmp_path, duration_s=8.0, progress=lambda line: None, link=LinkSettings(0.06, 0.005, 0.02, 1),
                       check_domain=False)  # the test's domain is its own
    assert summary["link"] == {"delay_s": 0.06, "jitter_s": 0.005, "loss_fraction": 0.02, "seed": 1}
    for name in ("liver_physics: loop", "haptic_bridge: loop"):
        status = summary["diagnostics"][name]
        assert float(status["link_delay_s"]) == 0.06 and int(status["link_sent"]) > 100, name
        assert int(status["link_lost"]) > 0, name
        assert 0.06 - 0.005 <= float(status["link_delay_measured_s"]) < 1.0, name
    bridge = summary["diagnostics"]["haptic_bridge: loop"]
    assert np.isfinite(float(bridge["energy_to_hand_j"])) and bridge["passive_model_update"] == "True"  # a link
    device = summary["diagnostics"]["phantom_sim: loop"]
    assert np.isfinite(float(device["energy_to_hand_j"])) and float(device["energy_generated_max_j"]) >= 0.0
    assert 0.1 < summary["peak_haptic_force_n"] <= BRIDGE["max_force_n"].default + 1e-9


def test_teleop_bench_rows_carry_every_key_and_the_reference_matches_itself(ros_domain_id, tmp_path):
    # the reference and the variant the target is about: two closed loops of the bench's four a delay (the
    # direct-force rendering, local_model none, has its bridge tests)
    variants = ("local_model",)
    report = json.loads(json.dumps(teleop.run_teleop_bench((50.0,), 10.0, 0.05, out_dir=tmp_path, duration_s=5.0,
                                                           variants=variants, check_domain=False), default=float))
    assert report["machine"] and set(report["met"]) == {"default_stable_and_passive_up_to_delay_ms"}
    reference = report["references"]["local_model"]
    assert reference["force_error_rms_n"] == 0.0 and reference["oscillating_s"] == 0.0 and set(report["references"]) \
        == {"local_model"}
    assert [r["variant"] for r in report["rows"]] == list(variants)
    assert set(report["first_unstable_delay_ms"]) == {"local_model"}
    for row in report["rows"]:
        assert set(teleop.ROW_KEYS) <= set(row) and row["delay_ms"] == 50.0 and row["passive_model_update"]
        assert np.isfinite(row["energy_to_hand_j"]) and row["energy_generated_max_j"] >= 0.0
        assert np.isfinite(row["bridge_energy_to_hand_j"]) and row["bridge_energy_generated_max_j"] >= 0.0
        assert 0.0 < row["peak_force_n"] <= BRIDGE["max_force_n"].default + 1e-9
        assert row["force_error_rms_n"] > 0.0 and row["penetration_max_mm"] > 0.0
    assert {"stable", "passive", "energy_to_hand_j", "estimate_agrees", "references"} <= set(report["definitions"])
    for path in report["plots"]:
        assert open(path, "rb").read(8) == b"\x89PNG\r\n\x1a\n"


def test_over_a_delayed_link_the_bridge_renders_and_still_zeroes_when_the_physics_stops(rig_factory, ros_env):
    """A bridge whose local model comes over a 100 ms link with jitter and loss renders it as without the link;
    when the physics stops, the queued models run out and the watchdog takes the force to exactly zero, as it
    does when the physics dies without a link. The device never gets more than the clamp."""
    from bridge_rig import EXPECTED_INSIDE, INSIDE, QUARTER_TURN_X, assert_safe, local_model, start_bridge, stop

    rig = rig_factory(rotation_xyzw=QUARTER_TURN_X)
    rig.model, rig.tool = local_model("plane"), INSIDE
    # direct updates: a tool held still inside a surface that appears stores what the hand never put in, which a
    # passive model update (on over a link by default) rightly refuses to render; they have their own tests
    bridge = start_bridge(ros_env, link_delay_s=0.1, link_jitter_s=0.01, link_loss_fraction=0.05, link_seed=3,
                          passive_model_update="never")
    try:
        rig.wait_for_force(EXPECTED_INSIDE, bridge)
        rig.wait_until(lambda: int((rig.loop_status() or {}).get("link_lost", "0")) > 0, "a message lost", bridge)
        status = rig.loop_status()
        assert float(status["link_delay_s"]) == 0.1 and float(status["link_delay_measured_s"]) >= 0.09
        rig.model = None  # the physics stops
        rig.wait_for_stale_zero(bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def _pumped_energy(update: str) -> float:
    """A hand resting its stylus on a surface whose delayed model rises and falls 3 mm at 2 Hz (updates at 150 Hz):
    the largest energy generated in a window, by the simulated device's own measure."""
    from liver_sim.phantom.device import PhantomSim
    from liver_sim.tool.scripts import ScriptedTrajectory

    p = BridgeParameters.defaults()
    tick = BridgeTick(p.replace(passive_model_update=update, soft_start_s=0.1))
    rest = np.array([0.0, 0.0, 0.015 - 0.002])  # the hand holds the tip 2 mm into the mean surface
    device = PhantomSim(ScriptedTrajectory("rest", np.zeros(1), rest[np.newaxis]))
    monitor = GenerationMonitor(T)
    model = None
    for k in range(3000):
        now = k * T
        if k % 7 == 0:  # a physics frame
            height = 0.003 * np.sin(2 * np.pi * 2.0 * now)
            point = np.array([0.0, 0.0, height])
            model = LocalModel("plane", True, point, np.array([0.0, 0.0, 1.0]), point, 0.0, 0.0, True, 190.0)
        tick.sample(now, now, device.position.copy())  # the stylus sample of this tick, no latency
        command = tick.step(now, device.position.copy(), 0.0, (model, 1.0), 0.0)
        device.step(T, command)
        monitor.record(now, device.energy_to_hand_j, bool(device.force.any()))
    return monitor.update()


def test_a_passive_model_update_keeps_a_moving_surface_from_pumping_energy_into_the_hand():
    assert _pumped_energy("never") > GENERATED_LIMIT_J
    assert _pumped_energy("always") <= 0.1 * GENERATED_LIMIT_J


def test_a_passive_model_update_stores_no_more_than_the_hand_put_in():
    from haptic_bridge.rendering import PassiveModelUpdate, contact_potential

    tip = np.array([0.0, 0.0, 0.0])
    up = np.array([0.0, 0.0, 1.0])

    def plane(height):
        return LocalModel("plane", True, up * height, up, up * height, 0.0, 0.0, True, 100.0)

    def depth(model):
        return penetration(model, tip)[0]

    def admit(update, height, budget_j):
        return depth(update.admit(plane(height), depth, lambda m: 100.0, budget_j))

    update = PassiveModelUpdate(max_force_n=2.0)
    assert admit(update, 0.004, 0.0) == pytest.approx(0.0) and update.held_back  # first contact: up to touching
    assert admit(update, -0.001, 0.0) == 0.0 and not update.held_back            # away from the tool: at once
    update.shown = plane(0.002)                                                   # 2 mm deep, storing 0.2 mJ
    paid = contact_potential(0.003, 100.0, 2.0)                                   # the hand put in 0.45 mJ
    assert admit(update, 0.005, paid) == pytest.approx(0.003) and update.held_back  # 5 mm asked: 3 mm paid
    assert admit(update, 0.001, 0.0) == pytest.approx(0.001)                         # backing off: at once
    assert admit(update, 0.005, 1.0) == pytest.approx(0.005) and not update.held_back


def test_after_a_restart_in_contact_a_passive_update_builds_the_contact_again_from_touching():
    """A stall while the hand rests 5 mm deep: a soft start back to the full force would store energy the hand never
    put in. With passive updates the surface comes back touching the tool, and the force with the hand's push."""
    p = BridgeParameters.defaults()
    tick = BridgeTick(p.replace(passive_model_update="always", soft_start_s=0.1))
    plane = LocalModel("plane", True, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.0, 0.0, True, 190.0)
    depths = np.concatenate([np.linspace(-0.005, 0.005, 500), np.full(300, 0.005)])
    forces = []
    for k, depth in enumerate(depths):
        tip = np.array([0.0, 0.0, 0.015 - depth])
        tick.sample(k * T, k * T, tip)
        forces.append(float(np.linalg.norm(tick.step(k * T, tip, 0.0, (plane, 1.0), 0.0))))
        if k == 600:
            tick.restart()  # a stall of the loop, 5 mm deep
    assert forces[599] == pytest.approx(0.95, abs=0.02), "pressed in by the hand: the full force"
    assert max(forces[601:]) < 0.01, "after the restart: no force the hand did not build"
