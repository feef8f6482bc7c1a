"""RateLoop's schedule, on a simulated clock: absolute deadlines, catching up a short stall, skipping a long one."""
import pytest

from liver_sim.base.process_settings import set_realtime_priority
from liver_sim.realtime.rate_loop import CATCH_UP_PERIODS, RateLoop

PERIOD_S = 0.001


class SimulatedTime:
    """A clock that only moves when the loop sleeps or a step takes time."""

    def __init__(self):
        self.now = 100.0

    def clock(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += max(seconds, 1e-6)


def run_schedule(step_durations_s: dict[int, float], ticks: int) -> list[float]:
    """Start times (s after the loop's start) of `ticks` steps; step k takes step_durations_s.get(k, 0)."""
    time = SimulatedTime()
    origin = time.now
    starts = []

    def step(now: float) -> None:
        starts.append(now - origin)
        time.now += step_durations_s.get(len(starts) - 1, 0.0)
        if len(starts) == ticks:
            loop.stop()

    loop = RateLoop(1.0 / PERIOD_S, step, "test", clock=time.clock, sleep=time.sleep)
    loop.run()
    return starts


def test_steps_start_on_absolute_deadlines():
    starts = run_schedule({}, 20)
    assert starts == pytest.approx([k * PERIOD_S for k in range(20)], abs=5e-6)


def test_a_short_stall_is_caught_up_without_losing_ticks():
    starts = run_schedule({3: 2.5 * PERIOD_S}, 10)
    stalled_until = 3 * PERIOD_S + 2.5 * PERIOD_S
    assert starts[4] == pytest.approx(stalled_until, abs=5e-6) and starts[5] == pytest.approx(stalled_until, abs=5e-6)
    assert starts[6:] == pytest.approx([k * PERIOD_S for k in range(6, 10)], abs=5e-6)


def test_a_long_stall_skips_to_the_newest_deadline():
    stall_periods = CATCH_UP_PERIODS + 5.5
    starts = run_schedule({2: stall_periods * PERIOD_S}, 6)
    resumed = 2 * PERIOD_S + stall_periods * PERIOD_S
    assert starts[3] == pytest.approx(resumed, abs=5e-6)  # the newest passed deadline, at once
    next_deadline = (int(resumed / PERIOD_S) + 1) * PERIOD_S
    assert starts[4] == pytest.approx(next_deadline, abs=5e-6)
    assert len(starts) == 6


def test_realtime_priority_zero_leaves_the_process_alone_and_a_refusal_is_explained():
    import os

    before = os.sched_getscheduler(0)
    assert set_realtime_priority(0) is None and os.sched_getscheduler(0) == before
    refused = set_realtime_priority(100)  # beyond SCHED_FIFO's 1-99: refused whatever the privileges
    assert refused.startswith("realtime_priority 100 refused") and "normal scheduling" in refused
    assert os.sched_getscheduler(0) == before



def test_a_gap_gets_its_cause_named_from_what_the_thread_did_meanwhile():
    """Sleeping is not runnable: blocked in the step when the step took most of the gap, else blocked off CPU;
    spinning beside a busier thread with one core is runnable (waiting for a CPU); a collection that fills the
    gap is garbage collection."""
    import gc
    import os
    import subprocess
    import sys
    import threading
    import time

    from liver_sim.realtime.gap_causes import GapCauses
    from liver_sim.realtime.garbage import GARBAGE

    causes = GapCauses()
    causes.sample()
    start = time.monotonic()
    time.sleep(0.02)
    assert causes.name(start, time.monotonic(), step_s=0.001).startswith("blocked off CPU")
    causes.sample()
    start = time.monotonic()
    time.sleep(0.02)
    assert causes.name(start, time.monotonic(), step_s=0.015).startswith("blocked in the step: the step took 15.0 ms")

    GARBAGE.passes.append((start + 1.0, start + 1.018, 2))  # a full collection of 18 ms within a 20 ms gap
    assert causes.name(start + 1.0, start + 1.02).startswith("garbage collection: generation 2")
    assert causes.counts == {"garbage collection": 1, "waiting for a CPU": 0, "blocked in the step": 1,
                             "blocked off CPU": 1}
    assert causes.summary()["gaps_named"] == 3
    assert [cause for _, _, cause in causes.new_events()][0].startswith("blocked")
    assert causes.new_events() == []
    gc.collect()  # the fake pass leaves the log

    if not hasattr(os, "sched_setaffinity"):
        return
    named = []

    def contended():
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # this thread only
        own = GapCauses()
        own.sample()
        begin = time.monotonic()
        while time.monotonic() - begin < 0.3:
            pass
        named.append(own.name(begin, time.monotonic()))

    # processes spinning on the same core make the thread wait for them (another thread would only hold the
    # GIL); two of them, so that the thread waits for about two thirds of the gap, well past RUNQUEUE_SHARE
    core = min(os.sched_getaffinity(0))
    hogs = [subprocess.Popen([sys.executable, "-c",
                              f"import os; os.sched_setaffinity(0, {{{core}}})\nwhile True: pass"])
            for _ in range(2)]
    try:
        time.sleep(0.2)
        thread = threading.Thread(target=contended)
        thread.start()
        thread.join()
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    assert named[0].startswith("waiting for a CPU"), named[0]


def test_loop_statistics_keep_a_ring_of_the_newest_periods():
    from liver_sim.nodes.inputs import Latest
    from liver_sim.realtime.rate_loop import LoopStats

    stats = LoopStats(0.001, window=10)
    for k in range(25):
        stats.record(0.002 if k < 15 else 0.001, overrun=k == 3)
    summary = stats.summary()
    assert summary["ticks"] == 25 and summary["overruns"] == 1 and summary["max_gap_s"] == 0.002
    assert summary["rate_hz"] == pytest.approx(1000.0)  # only the newest 10 periods
    assert LoopStats(0.001).summary()["rate_hz"] == 0.0
    latest = Latest()
    assert latest.get()[0] is None
    latest.set("x", 5.0)
    assert latest.get() == ("x", 5.0)


def test_freezing_the_collector_moves_everything_to_the_permanent_generation_and_stops_full_collections():
    import subprocess
    import sys

    script = ("import gc; from liver_sim.realtime.garbage import freeze_garbage, garbage_fields, collect_garbage\n"
              "freeze_garbage(); f = garbage_fields(); collect_garbage()\n"
              "assert f['gc_frozen_objects'] > 1000, f\n"
              "assert f['gc_automatic_full_collection'] is False, f\n"
              "junk = [[[] for _ in range(100)] for _ in range(10000)]\n"
              # freeze_garbage's own and collect_garbage's; none for the junk
              "assert garbage_fields()['gc_full_collections'] == 2, garbage_fields()\n"
              # diagnostics report the count taken at the freeze: counting walks every frozen object with the
              # GIL held (4 ms in a node, a gap in its 1 kHz loop every second)
              "count = gc.get_freeze_count(); assert abs(f['gc_frozen_objects'] - count) <= count // 100, (f, count)\n"
              "gc.get_freeze_count = None\n"
              "assert garbage_fields()['gc_frozen_objects'] == f['gc_frozen_objects']\n"
              "print('ok')")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "ok", out.stderr
