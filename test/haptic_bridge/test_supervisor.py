"""haptic_bridge.supervisor: zero on the wire when the loop stalls, fails or ends, one writer ending on zero, and the
gap log."""
import threading
import time

import pytest

from haptic_bridge.supervisor import GapLog, Supervisor

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
