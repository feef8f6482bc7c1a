"""Teleoperation under delay: the emulated link, the passivity observer and controller, the teleop benchmark's
definitions, and the link on real nodes (behaviour, no timing thresholds)."""
import json
import subprocess
import sys

import numpy as np
import pytest

from haptic_bridge.parameters import PARAMETERS as BRIDGE
from haptic_bridge.passivity import PassivityObserver
from haptic_bridge.tick import BridgeTick
from liver_sim.base.link import LINK_PARAMETERS, EmulatedLink, LinkSettings
from liver_sim.base.local_model import LocalModel
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
def test_the_observer_adds_the_held_force_times_the_next_motion():
    observer = PassivityObserver(T)
    observer.observe(np.zeros(3))
    observer.commanded(np.array([0.0, 0.0, 1.0]))
    observer.observe(np.array([0.0, 0.0, 0.001]))      # moved with the force: the device gave 1 mJ
    assert observer.energy_j == pytest.approx(0.001)
    observer.commanded(np.array([0.0, 0.0, 2.0]))
    observer.observe(np.array([0.0, 0.0, 0.0]))         # pushed back against it: the hand gave 2 mJ
    assert observer.energy_j == pytest.approx(-0.001) and observer.peak_energy_j == pytest.approx(0.001)
    observer.observe(None)                              # no stylus: no motion counted across the hole
    observer.observe(np.array([1.0, 1.0, 1.0]))
    assert observer.energy_j == pytest.approx(-0.001)


def test_the_controller_damps_only_a_force_that_would_give_back_more_than_was_put_in():
    """α = (F·Δx + E)·T/|Δx|², Δx the last tick's motion, at most the cap; nothing while the hand's energy covers it."""
    def after(control, energy_j, force_z, cap=20.0):
        observer = PassivityObserver(T, control=control, max_damping_ns_per_m=cap)
        observer.observe(np.zeros(3))
        observer.energy_j = energy_j
        observer.observe(np.array([0.0, 0.0, 0.001]))  # moving at 1 m/s along +z
        return observer.damp(np.array([0.0, 0.0, force_z])), observer.damping_ns_per_m

    assert after(False, 0.0, 1.0) == (pytest.approx([0.0, 0.0, 1.0]), 0.0)
    # 1 N along the motion would give 1 mJ; the hand has put in 0.4 mJ: 0.6 mJ too much, α = 0.6 N·s/m
    force, alpha = after(True, -0.0004, 1.0)
    assert alpha == pytest.approx(0.6) and force == pytest.approx([0.0, 0.0, 0.4])
    assert after(True, -0.002, 1.0) == (pytest.approx([0.0, 0.0, 1.0]), 0.0)   # covered by what the hand put in
    assert after(True, 0.0, -1.0) == (pytest.approx([0.0, 0.0, -1.0]), 0.0)    # a force against the motion
    force, alpha = after(True, 0.0, 1.0, cap=0.5)
    assert alpha == 0.5 and force == pytest.approx([0.0, 0.0, 0.5])


def _plane_tick(control: bool) -> BridgeTick:
    p = {name: spec.default for name, spec in BRIDGE.items()}
    p.update(passivity_control=control, soft_start_s=0.1, max_force_rate_n_per_s=100000.0)
    return BridgeTick(p)


def test_the_bridge_counts_the_energy_of_what_it_sent_in_the_device_frame():
    """A tip pressed into a fixed plane and drawn back along the same path: the observer's energy is the sum of
    the commands times the motion, and a plane that jumps outward while in contact (a model update) gives the
    hand energy, which the controller then takes back out."""
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
            sent.append(tick.step(k * T, tip, 0.0, (model, 1.0), 0.0))
            positions.append(tip)
        expected = sum(float(f @ (x1 - x0)) for f, x0, x1 in zip(sent, positions, positions[1:]))
        assert tick.passivity.energy_j == pytest.approx(expected)
        results[control] = tick.passivity
    assert results[False].energy_j > 0.0             # the raised plane pushed the hand out with more than it took
    assert results[True].energy_j < results[False].energy_j


def test_the_observer_takes_the_stylus_motion_through_the_device_map():
    """With a turned and scaled map the energy is the command (device frame) times the stylus's motion, Rᵀ·Δtip/s."""
    from liver_sim.base.geometry.device_map import DeviceMap

    device_map = DeviceMap([0.0, 0.0, np.sin(np.pi / 8), np.cos(np.pi / 8)], [0.1, 0.0, 0.0], 2.0)
    observer = PassivityObserver(T)
    observer.set_map(device_map.liver_to_device_motion)
    tips = [np.array([0.01, 0.02, 0.03]), np.array([0.012, 0.017, 0.034]), np.array([0.011, 0.02, 0.031])]
    forces = [np.array([0.3, -0.2, 0.5]), np.array([-0.1, 0.4, 0.2])]
    observer.observe(tips[0])
    for force, tip in zip(forces, tips[1:]):
        observer.commanded(force)
        observer.observe(tip)
    expected = sum(float(f @ (device_map.liver_to_device(b) - device_map.liver_to_device(a)))
                   for f, a, b in zip(forces, tips, tips[1:]))
    assert observer.energy_j == pytest.approx(expected, rel=1e-12)


def test_the_oscillation_measure_flags_a_sustained_oscillation_and_not_the_reference():
    times = np.arange(0.0, 10.0, T)
    taps = np.clip(np.sin(2 * np.pi * 1.2 * times), 0.0, None)[:, None] * np.array([0.0, 0.0, 0.5])
    wobble = taps.copy()
    wobble[(times > 2.0) & (times < 6.0), 2] += 0.3 * np.sin(2 * np.pi * 6.0 * times[(times > 2.0) & (times < 6.0)])
    assert teleop.oscillating_s((times, taps), (times, taps)) == 0.0
    assert teleop.oscillating_s((times, wobble), (times, taps)) >= teleop.OSCILLATION_SUSTAINED_S


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
    assert np.isfinite(float(bridge["energy_to_hand_j"])) and bridge["passivity_control"] == "False"
    assert 0.1 < summary["peak_haptic_force_n"] <= BRIDGE["max_force_n"].default + 1e-9


def test_teleop_bench_rows_carry_every_key_and_the_reference_matches_itself(ros_domain_id, tmp_path):
    # the reference and the variant the target is about: two closed loops of the bench's four a delay (the
    # direct-force rendering, local_model none, has its bridge tests)
    variants = (("local_model", True),)
    report = json.loads(json.dumps(teleop.run_teleop_bench((50.0,), out_dir=tmp_path, duration_s=5.0,
                                                           variants=variants, check_domain=False), default=float))
    assert report["machine"] and set(report["met"]) == set(teleop.TELEOP_TARGETS)
    assert report["reference"]["force_error_rms_n"] == 0.0 and report["reference"]["oscillating_s"] == 0.0
    assert [(r["rendering"], r["passivity_control"]) for r in report["rows"]] == list(variants)
    assert set(report["first_unstable_delay_ms"]) == {"local_model+pc"}
    for row in report["rows"]:
        assert set(teleop.ROW_KEYS) <= set(row) and row["delay_ms"] == 50.0
        assert np.isfinite(row["energy_generated_j"]) and row["energy_generated_peak_j"] >= 0.0
        assert 0.0 < row["peak_force_n"] <= BRIDGE["max_force_n"].default + 1e-9
        assert row["force_error_rms_n"] > 0.0 and row["penetration_max_mm"] > 0.0
    assert {"stable", "passive", "energy_generated_j"} <= set(report["definitions"])
    for path in report["plots"]:
        assert open(path, "rb").read(8) == b"\x89PNG\r\n\x1a\n"


def test_over_a_delayed_link_the_bridge_renders_and_still_zeroes_when_the_physics_stops(rig_factory, ros_env):
    """A bridge whose local model comes over a 100 ms link with jitter and loss renders it as without the link;
    when the physics stops, the queued models run out and the watchdog takes the force to exactly zero, as it
    does when the physics dies without a link. The device never gets more than the clamp."""
    from bridge_rig import EXPECTED_INSIDE, INSIDE, QUARTER_TURN_X, assert_safe, local_model, start_bridge, stop

    rig = rig_factory(rotation_xyzw=QUARTER_TURN_X)
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env, link_delay_s=0.1, link_jitter_s=0.01, link_loss_fraction=0.05, link_seed=3)
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
