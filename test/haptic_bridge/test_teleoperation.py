"""Teleoperation under delay across the modules: the emulated link (liver_sim.base.emulated_link) and the parameters
both sides declare for it, the teleop benchmark's definitions, the command line's link options, and the link on real
nodes (behaviour, no timing thresholds). The bridge's own parts have their files: the passivity observer and
controller test_passivity.py, passive model updates test_rendering.py and test_tick.py."""
import json
import subprocess
import sys

import numpy as np
import pytest

from haptic_bridge.parameters import PARAMETERS as BRIDGE
from liver_sim.base.emulated_link import LINK_PARAMETERS, EmulatedLink, LinkSettings
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
