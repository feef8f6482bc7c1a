"""RateLoop's schedule, on a simulated clock: absolute deadlines, catching up a short stall, skipping a long one."""
import pytest

from liver_sim.nodes.common import CATCH_UP_PERIODS, RateLoop, set_realtime_priority

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

