"""A rate loop on absolute deadlines in its own thread (RateLoop), its statistics (LoopStats) and the
real-time scheduling that keeps it on time.

Loops with a rate to keep run in their own thread (rclpy timers jitter by milliseconds on a
2-core machine); the executor only delivers messages and 1 Hz diagnostics.  A loop's tick does no
avoidable work: its statistics go into preallocated rings without a lock (one writer; a reader
copies), percentiles are computed by the diagnostics, and after start-up the garbage collector
never runs a full collection on its own (:func:`freeze_garbage`).
"""
from __future__ import annotations

import array
import os
import threading
import time
import traceback

import numpy as np
import rclpy

from liver_sim.base.process_settings import set_realtime_priority
from liver_sim.realtime.gap_causes import GAP_CAUSE_S, SCHEDSTAT_EVERY_TICKS, GapCauses
from liver_sim.realtime.garbage import freeze_garbage

#: Seconds before a deadline at which a loop stops sleeping and spins.
SPIN_MARGIN_S = 0.0001
#: A rate loop at most this many periods behind runs its missed ticks at once; further behind, it skips them.
CATCH_UP_PERIODS = 2


class LoopStats:
    """Periods of a rate loop over a sliding window: achieved rate, period error percentiles, overruns.

    :meth:`record` (the loop) writes into a preallocated ring: no lock, no allocation; :meth:`summary`
    (diagnostics) copies the ring and computes the percentiles there."""

    def __init__(self, period_s: float, window: int = 5000):
        self.period_s = period_s
        self._periods = array.array("d", bytes(8 * window))
        self._next = 0
        self.overruns = 0
        self.ticks = 0
        self.max_gap_s = 0.0

    def record(self, period_s: float, overrun: bool) -> None:
        i = self._next
        self._periods[i] = period_s
        self._next = i + 1 if i + 1 < len(self._periods) else 0
        self.ticks += 1
        if overrun:
            self.overruns += 1
        if period_s > self.max_gap_s:
            self.max_gap_s = period_s

    def summary(self) -> dict:
        """rate_hz, period error p50/p99/max (s), overruns, ticks, max_gap_s."""
        ticks, overruns, max_gap = self.ticks, self.overruns, self.max_gap_s
        periods = np.frombuffer(self._periods, dtype=np.float64).copy()[:min(ticks, len(self._periods))]
        if periods.size == 0:
            return {"rate_hz": 0.0, "jitter_p50_s": 0.0, "jitter_p99_s": 0.0, "jitter_max_s": 0.0,
                    "overruns": overruns, "ticks": ticks, "max_gap_s": max_gap}
        error = np.abs(periods - self.period_s)
        return {"rate_hz": float(1.0 / periods.mean()), "jitter_p50_s": float(np.percentile(error, 50)),
                "jitter_p99_s": float(np.percentile(error, 99)), "jitter_max_s": float(error.max()),
                "overruns": overruns, "ticks": ticks, "max_gap_s": max_gap}


class RateLoop(threading.Thread):
    """Calls `step(now_monotonic_s)` at `rate_hz` on absolute deadlines in its own thread.

    Deadline k is start + k·period: the thread sleeps until SPIN_MARGIN_S before it, then spins
    (a SCHED_FIFO thread wakes on time, and sleeps to the deadline itself). The thread runs SCHED_FIFO at
    `realtime_priority` (0: as it is; set_realtime_priority, this thread only), a refusal handed to
    `on_refused(reason)`.
    A step that starts more than a period late is an overrun; a gap over `gap_bound_s` (GAP_CAUSE_S, or two
    periods of a slower loop) gets its cause named (`gaps`, GapCauses), knowing how long the step before it
    took. Starting the loop freezes the garbage collector (:func:`freeze_garbage`; not with `freeze` false):
    what the node built before is never scanned again. A loop at most CATCH_UP_PERIODS behind runs its
    missed ticks at once, so that a short stall costs no ticks; further behind, it skips to the newest
    deadline rather than run a burst. An exception in a step is counted (`errors`) and handed to
    `on_error(now, exc)` (default: printed); the loop goes on, unless the rclpy `context` it runs in (default:
    rclpy's default context) has shut down: then the loop ends. `clock` and `sleep` are time.monotonic and
    time.sleep unless a test gives its own.
    """

    def __init__(self, rate_hz: float, step, name: str, clock=time.monotonic, sleep=time.sleep, on_error=None,
                 freeze: bool = True, realtime_priority: int = 0, on_refused=print, context=None):
        super().__init__(name=name, daemon=True)
        self.period_s = 1.0 / rate_hz
        self.step = step
        self.stats = LoopStats(self.period_s)
        self.gaps = GapCauses()
        self.gap_bound_s = max(GAP_CAUSE_S, 2.0 * self.period_s)
        self.errors = 0
        self._clock, self._sleep = clock, sleep
        self._on_error = on_error
        self._freeze = freeze
        self.realtime_priority = realtime_priority
        self._on_refused = on_refused
        self._context_ok = rclpy.ok if context is None else context.ok
        self._stopping = threading.Event()

    def report(self) -> dict:
        """For diagnostics: LoopStats.summary(), GapCauses.summary(), `gap_bound_s` and `new_gaps`, the gaps over
        it since the last report with their causes ('' when none)."""
        lines = [f"gap {gap * 1e3:.1f} ms ({cause})" for _, gap, cause in self.gaps.new_events()]
        return {**self.stats.summary(), **self.gaps.summary(), "gap_bound_s": self.gap_bound_s,
                "new_gaps": "; ".join(lines)}

    def start(self) -> None:
        if self._freeze:
            freeze_garbage()
        super().start()

    def stop(self) -> None:
        self._stopping.set()
        if self.is_alive() and threading.current_thread() is not self:
            self.join(timeout=1.0)

    def run(self) -> None:
        refused = set_realtime_priority(self.realtime_priority)  # this thread only
        if refused:
            self._on_refused(refused)
        clock, sleep = self._clock, self._sleep
        margin = 0.0 if os.sched_getscheduler(0) == os.SCHED_FIFO else SPIN_MARGIN_S
        start = clock()
        tick = 0
        previous = None
        step_s = 0.0  # how long the previous step took
        gaps = self.gaps
        gaps.sample()
        while not self._stopping.is_set():
            deadline = start + tick * self.period_s
            remaining = deadline - clock()
            if remaining > margin:
                sleep(remaining - margin)
            while clock() < deadline:
                sleep(0)  # spin, but let the executor thread take the GIL
            now = clock()
            if previous is not None:
                gap = now - previous
                self.stats.record(gap, now > deadline + self.period_s)
                if gap > self.gap_bound_s:
                    gaps.name(previous, now, step_s)
                elif tick % SCHEDSTAT_EVERY_TICKS == 0:
                    gaps.sample()
            previous = now
            try:
                self.step(now)
            except Exception as exc:  # a node keeps running; at shutdown the context goes first
                if not self._context_ok():
                    return
                self.errors += 1
                if self._on_error is None:
                    traceback.print_exc()
                else:
                    self._on_error(now, exc)
            after = clock()
            step_s = after - now
            tick += 1
            due = int((after - start) / self.period_s)
            if due - tick > CATCH_UP_PERIODS:
                tick = due


def warn(node):
    """A RateLoop's `on_refused`: a refused real-time priority logged as the node's warning."""
    return lambda refused: node.get_logger().warning(refused)
