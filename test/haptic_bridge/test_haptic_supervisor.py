"""The haptic core's guards without ROS: the supervisor and its gap log, soft start, run-time limits,
input plausibility, the no-latch depth rate and passivity in every mode."""
import itertools
import math
import threading
import time

import numpy as np
import pytest

from haptic_bridge.inputs import InputCheck
from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.safety import SafeForceOutput
from haptic_bridge.supervisor import GapLog, Supervisor
from haptic_bridge.tick import BridgeTick, DepthRate, check_passivity, checked_change, passivity_problem
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.local_model import LocalModel

DEFAULTS = BridgeParameters.defaults()
#: Tick times (s), 1 ms apart: the rate limit counts the time between ticks.
TICKS = itertools.count(0.0, 0.001)
ZERO = "zero"


class Wire:
    """What a supervisor put on the wire, in order."""

    def __init__(self):
        self.sent = []

    def publish(self, message) -> None:
        self.sent.append(message)


def supervisor(wire, alive=lambda: True, clock=None):
    return Supervisor(0.005, 0.001, wire.publish, lambda: ZERO, alive, clock or (lambda: 0.0))


def test_a_stall_publishes_zero_holds_it_and_drops_the_loops_late_command():
    wire = Wire()
    sup = supervisor(wire)
    assert not sup.beat(0.001) and sup.send("F1")
    sup.check(0.004)  # within the bound
    assert wire.sent == ["F1"]
    sup.check(0.0065)  # 5.5 ms without a tick
    assert wire.sent[-1] == ZERO and sup.counts["stall"] == 1 and sup.tripped is not None
    assert not sup.send("F computed before the stall")  # never after its zero
    sup.check(0.009)
    sup.check(0.0116)  # held: repeated every bound
    assert wire.sent.count(ZERO) == 2 and wire.sent[-1] == ZERO
    assert sup.beat(0.012)  # the loop is back: restart from zero
    assert sup.tripped is None and sup.events[-1].end_s == 0.012
    assert sup.send("F2") and wire.sent[-1] == "F2"
    report = sup.report(0.012, since_s=0.0)
    assert report["error"] and report["stalls"] == 1 and "no tick within 5 ms" in report["events"][0].cause


def test_a_publish_held_up_in_the_middleware_holds_up_the_zero_behind_it_not_the_trip():
    """One writer: the supervisor's zero waits on the wire behind a held command (DDS orders within the writer), and
    a zero follows that command once its publish returns, so the wire ends on zero; the trip itself is not held."""
    wire = Wire()
    held, release = threading.Event(), threading.Event()

    def publish(message) -> None:  # the writer, held for the loop's command by a transient-local reader joining
        if message != ZERO:
            held.set()
            release.wait(5.0)
        wire.publish(message)

    now = [0.001]
    sup = Supervisor(0.005, 0.001, publish, lambda: ZERO, clock=lambda: now[0])
    sup.beat(0.001)
    loop = threading.Thread(target=sup.send, args=("F held",))
    loop.start()
    assert held.wait(5.0)
    now[0] = 0.0065
    started = time.monotonic()
    sup.check(now[0])  # the loop's publish holds no lock of the supervisor
    assert time.monotonic() - started < 1.0
    assert sup.tripped is not None and sup.counts["stall"] == 1
    release.set()
    loop.join(5.0)
    assert "F held" in wire.sent and wire.sent[-1] == ZERO
    assert set(wire.sent[wire.sent.index("F held") + 1:]) == {ZERO}, "zeros follow the held command"


def test_the_writer_ends_on_zero_after_a_trip_an_error_and_a_close():
    """DDS keeps order within one writer: with commands and zeros on one, the last sample after any stop is zero."""
    wire = Wire()
    now = [0.001]
    sup = Supervisor(0.005, 0.001, wire.publish, lambda: ZERO, clock=lambda: now[0])
    sup.beat(0.001)
    sup.send("F1")
    now[0] = 0.0065
    sup.check(now[0])  # a stall
    assert wire.sent == ["F1", ZERO]
    assert sup.beat(0.007) and sup.send("F2")
    sup.error(0.0075, RuntimeError("boom"))
    assert wire.sent[-2:] == ["F2", ZERO]
    assert sup.beat(0.008) and sup.send("F3")
    sup.close("SIGTERM")
    assert wire.sent[-2:] == ["F3", ZERO]
    assert not sup.send("F4") and wire.sent[-1] == ZERO


def test_an_error_zeroes_and_the_next_tick_restarts():
    wire = Wire()
    sup = supervisor(wire)
    sup.beat(0.001)
    sup.error(0.0015, RuntimeError("boom"))
    assert wire.sent == [ZERO] and sup.counts["error"] == 1
    assert "RuntimeError: boom" in sup.events[-1].cause
    assert sup.beat(0.002) and sup.send("F")


def test_a_gap_the_supervisor_missed_is_still_a_stall_and_a_restart():
    sup = supervisor(Wire())
    sup.beat(0.001)
    assert sup.beat(0.340)  # 339 ms late; the supervisor never ran (GIL)
    assert sup.counts["stall"] == 1 and "339.0 ms" in sup.events[-1].cause
    report = sup.report(0.5, since_s=0.0)
    assert report["max_gap_s"] == pytest.approx(0.339) and report["max_gap_at_s"] == 0.340
    assert report["max_gap_1s_s"] == pytest.approx(0.339)
    assert sup.report(2.0, since_s=1.0)["max_gap_1s_s"] == 0.0  # over the last second: gone
    assert not sup.report(2.0, since_s=1.0)["error"]


def test_a_dead_loop_and_close_leave_zero_last_and_nothing_after():
    wire = Wire()
    alive = [True]
    sup = supervisor(wire, alive=lambda: alive[0])
    sup.beat(0.001)
    sup.send("F")
    alive[0] = False
    sup.check(0.002)
    assert wire.sent[-1] == ZERO and sup.counts["stop"] == 1
    sup.close("SIGTERM")
    assert wire.sent[-1] == ZERO and sup.closed
    assert not sup.send("F") and sup.beat(0.003)
    sup.check(1.0)
    assert wire.sent[-1] == ZERO


def test_the_supervisor_thread_catches_a_real_stall():
    wire = Wire()
    sup = Supervisor(0.005, 0.001, wire.publish, lambda: ZERO)
    sup.start()
    try:
        deadline = time.monotonic() + 0.05
        while time.monotonic() < deadline:  # a loop ticking at 1 kHz
            sup.beat(time.monotonic())
            sup.send("F")
            time.sleep(0.001)
        before = len(wire.sent)
        time.sleep(0.1)  # the loop stalls
        assert ZERO in wire.sent[before:] and sup.counts["stall"] >= 1
        assert set(wire.sent[wire.sent.index(ZERO, before):]) == {ZERO}
    finally:
        sup.close("test over")
    assert wire.sent[-1] == ZERO


def test_gap_log_keeps_the_largest_with_its_time():
    log = GapLog(0.001, window_s=1.0)
    for k in range(700):
        log.record(k * 0.001, 0.001 if k != 500 else 0.02)
    assert log.recent(0.7) == (0.02, 0.5)  # within the last second
    for k in range(700, 3000):
        log.record(k * 0.001, 0.001)
    assert log.max_gap_s == 0.02 and log.max_gap_end_s == 0.5  # since start
    gap, end = log.recent(3.0)  # the long gap has left the last second
    assert gap == 0.001 and 2.0 <= end <= 2.999
    assert log.recent(5.0)[0] == 0.0  # nothing ended in the last second


def test_soft_start_rises_over_its_time_after_start_and_after_restart():
    output = SafeForceOutput(2.0, 400.0, 0.001, 0.05, 0.01, soft_start_s=0.1)
    force = np.array([0.0, 0.0, 1.0])
    outs = [float(np.linalg.norm(output.step(force, 0.0, 0.0))) for _ in range(150)]
    assert outs[9] < 0.11 and outs[49] == pytest.approx(0.5, abs=0.02) and outs[-1] == pytest.approx(1.0)
    output.restart()
    assert float(np.linalg.norm(output.step(force, 0.0, 0.0))) <= 0.011
    for _ in range(30):  # stale: down within ramp_time_s (10 ms)
        output.step(force, 1.0, 0.0)
    assert not output.step(force, 1.0, 0.0).any()
    rise = [float(np.linalg.norm(output.step(force, 0.0, 0.0))) for _ in range(100)]
    assert rise[19] < 0.25  # recovery ramps up as slowly as the start, not in 10 ms


def test_a_lowered_clamp_bounds_the_very_next_command():
    output = SafeForceOutput(2.0, 400.0, 0.001, 0.05, 0.01, soft_start_s=0.1)
    for _ in range(200):
        output.step(np.array([0.0, 0.0, 1.5]), 0.0, 0.0)
    output.configure(0.05, 400.0, 0.05, 0.01, 0.1)
    assert np.linalg.norm(output.step(np.array([0.0, 0.0, 1.5]), 0.0, 0.0)) <= 0.05
    with pytest.raises(ValueError, match="max_force"):
        output.configure(5.0, 400.0, 0.05, 0.01, 0.1)
    assert output.max_force == 0.05  # a refused change leaves the limits as they were


def test_depth_rate_drops_a_bad_sample_and_never_latches():
    rate = DepthRate(0.001, 50.0)
    rate.update(0.001)
    rate.update(1e308)        # huge but finite: the difference overflows
    rate.update(float("nan"))  # not finite: dropped
    rate.update(float("inf"))
    rate.update(0.002)
    assert math.isfinite(rate.update(0.0021))


def test_a_huge_input_then_a_good_one_renders_again():
    tick = BridgeTick(DEFAULTS)
    plane = (LocalModel.plane(np.zeros(3), [0.0, 0.0, 1.0]), 0.05)
    for _ in range(300):
        tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    tick.step(next(TICKS), np.array([0.0, 0.0, -1e300]), 0.0, plane, 0.0)
    for _ in range(300):
        out = tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    np.testing.assert_allclose(out, [0.0, 0.0, 0.95], atol=1e-6)


def test_inputs_outside_the_workspace_are_refused():
    check = InputCheck([0.0, 0.0, 0.0], 0.4)
    assert check.tip(np.array([0.1, 0.0, 0.0])) is None
    assert "beyond workspace_radius_m" in check.tip(np.array([50.0, 0.0, 0.0]))
    assert "not finite" in check.tip(np.array([np.nan, 0.0, 0.0]))
    assert check.model(LocalModel.plane([0.0, 0.0, 0.1], [0.0, 0.0, 1.0])) is None
    assert "plane point" in check.model(LocalModel.plane([0.0, 0.0, 9.0], [0.0, 0.0, 1.0]))
    assert "radius" in check.model(LocalModel.sphere([0.0, 0.0, 0.0], 3.0))
    assert check.model(None) is None and check.model(LocalModel.invalid()) is None
    assert "implausible" in check.force(np.array([0.0, 0.0, 1e6]))
    assert check.force(np.array([0.0, 0.0, 2.0])) is None


def test_passivity_is_checked_for_every_mode():
    assert passivity_problem(DEFAULTS) is None
    none = DEFAULTS.replace(local_model="none")
    problem = passivity_problem(none)  # 300 N/m held for 1/150 s with 1 N·s/m: needs b > 2 N·s/m
    assert "contact_stiffness_n_per_m" in problem and "T=6.66667 ms" in problem
    check_passivity(none.replace(device_damping_ns_per_m=2.5))
    with pytest.raises(ValueError, match="stiffness_n_per_m"):
        check_passivity(DEFAULTS.replace(stiffness_n_per_m=700.0), scale=2.0)  # felt as 1400 N/m
    BridgeTick(none)  # an offline baseline drives no device: not refused by the tick


@pytest.mark.parametrize("name, looser", [("max_force_n", 2.5), ("max_force_rate_n_per_s", 500.0), ("lifetime_s", 10.0),
                                          ("ramp_time_s", 0.02), ("stiffness_n_per_m", 350.0),
                                          ("damping_ns_per_m", 0.1), ("contact_stiffness_n_per_m", 400.0),
                                          ("contact_damping_ns_per_m", 2.0), ("soft_start_s", 0.15)])
def test_run_time_changes_never_loosen_the_envelope_fixed_at_start(name, looser):
    with pytest.raises(ValueError, match=f"{name}=.* would loosen the safety envelope"):
        checked_change(DEFAULTS, {name: looser})
    tighter = {"soft_start_s": 0.5}.get(name, getattr(DEFAULTS, name) * 0.5)
    tightened = checked_change(DEFAULTS, {name: tighter})
    assert getattr(tightened, name) == tighter
    with pytest.raises(ValueError, match="would loosen"):  # the envelope is the start's, not the current value's
        checked_change(tightened, {name: looser}, start=DEFAULTS)
    start = getattr(DEFAULTS, name)
    assert getattr(checked_change(tightened, {name: start}, start=DEFAULTS), name) == start


def test_the_device_damping_is_read_at_start_only():
    with pytest.raises(ValueError, match="device_damping_ns_per_m: read at start only"):
        checked_change(DEFAULTS, {"device_damping_ns_per_m": 100.0})


def test_run_time_changes_are_checked_or_refused_with_a_reason():
    lowered = checked_change(DEFAULTS, {"max_force_n": 0.05, "stiffness_n_per_m": 100.0})
    assert lowered.max_force_n == 0.05 and DEFAULTS.max_force_n == 2.0
    with pytest.raises(ValueError, match="not passive"):  # within the envelope, not with a device map's scale 4
        checked_change(DEFAULTS, {"max_force_n": 1.0}, scale=4.0)
    with pytest.raises(ValueError, match="restart haptic_bridge"):
        checked_change(DEFAULTS, {"rate_hz": 500.0})
    with pytest.raises(ValueError, match="max_force_rate_n_per_s"):
        checked_change(DEFAULTS, {"max_force_rate_n_per_s": 100.0})
    tick = BridgeTick(DEFAULTS)
    tick.configure(lowered)
    plane = (LocalModel.plane(np.zeros(3), [0.0, 0.0, 1.0]), 0.05)
    for _ in range(300):
        out = tick.step(next(TICKS), np.array([0.0, 0.0, 0.0]), 0.0, plane, 0.0)
    assert np.linalg.norm(out) <= 0.05


def test_no_device_map_renders_zero_and_a_new_map_soft_starts():
    tick = BridgeTick(DEFAULTS, device_map=None)
    plane = (LocalModel.plane(np.zeros(3), [0.0, 0.0, 1.0]), 0.05)
    for _ in range(300):
        assert not tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0).any()
    tick.set_device_map(DeviceMap([math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)]))
    first = tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    assert np.linalg.norm(first) < 0.02
    for _ in range(300):
        out = tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    np.testing.assert_allclose(out, [0.0, 0.95, 0.0], atol=1e-6)


def test_the_marker_lifetime_is_capped_by_lifetime_s():
    tick = BridgeTick(DEFAULTS)
    plane = (LocalModel.plane(np.zeros(3), [0.0, 0.0, 1.0]), 10.0)  # a marker claiming 10 s
    for _ in range(300):
        tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    for _ in range(20):
        out = tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.2)  # 200 ms old
    assert not out.any()
