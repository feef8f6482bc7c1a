"""The cause of each long gap between two ticks of a loop thread: garbage collection, waiting for a CPU,
blocked inside the step, or blocked off CPU between steps (GapCauses)."""
from __future__ import annotations

import os
import threading
from collections import deque
from pathlib import Path

from liver_sim.realtime.garbage import GARBAGE

#: A gap between two ticks longer than this (s), or than two periods of a slower loop, gets its cause named
#: (GapCauses).
GAP_CAUSE_S = 0.005
#: Every this many ticks a loop samples its thread's scheduler statistics, the baseline a gap is measured from.
SCHEDSTAT_EVERY_TICKS = 10
#: A gap is put down to waiting for a CPU when the thread waited in the run queue for at least this share of it.
RUNQUEUE_SHARE = 0.5


def rt_throttle_s() -> float | None:
    """How long (s) the kernel stops every SCHED_FIFO thread once they used their share of a period
    (sched_rt_period_us − sched_rt_runtime_us), or None when unknown or unlimited."""
    try:
        period = int(Path("/proc/sys/kernel/sched_rt_period_us").read_text())
        runtime = int(Path("/proc/sys/kernel/sched_rt_runtime_us").read_text())
    except (OSError, ValueError):
        return None
    return None if runtime < 0 else (period - runtime) * 1e-6


class GapCauses:
    """Names the cause of each gap longer than GAP_CAUSE_S between two ticks of one loop thread, from what the
    kernel and the interpreter saw meanwhile:

    - ``garbage collection``: collector passes of this process (GARBAGE) took at least RUNQUEUE_SHARE of it;
    - ``waiting for a CPU``: the thread was runnable but not running for at least RUNQUEUE_SHARE of the gap
      (its run-queue wait in /proc/thread-self/schedstat): other processes held both cores, or — a SCHED_FIFO
      thread stopped for about sched_rt_period_us − sched_rt_runtime_us — the kernel's RT throttling once the
      real-time threads used their share of the second;
    - ``blocked in the step``: the thread was not runnable inside its step, which took at least RUNQUEUE_SHARE
      of the gap: a DDS call of the step (a publish, a take) waited for a Fast DDS lock, the writer's or the
      participant's send lock that discovery holds while it opens a newcomer's shared-memory port
      (config/fastdds.xml), or for the GIL; or the machine stalled while the step ran;
    - ``blocked off CPU``: the thread was not runnable between two steps: it woke late because the GIL was
      held by another thread of this process (rclpy's publish and take keep it while Fast DDS blocks), or
      because the machine itself stalled (a virtual CPU the host did not run: every loop of the machine
      stalls at once; `liver-sim bench loop` measures these with a sentinel, liver_sim.running.machine_stalls).

    Call :meth:`sample` from the loop thread every few ticks and :meth:`name` when a gap ended; both only
    read one small /proc file of the thread.
    """

    EVENTS_KEPT = 32

    def __init__(self):
        self._fd = None
        self._wait_ns = 0
        self.events = deque(maxlen=self.EVENTS_KEPT)  # (monotonic end s, gap s, cause)
        self.counts = {"garbage collection": 0, "waiting for a CPU": 0, "blocked in the step": 0,
                       "blocked off CPU": 0}
        self.largest = (0.0, "")
        self.reported = 0
        self._fifo = False
        self._throttle_s = rt_throttle_s()

    def _wait(self) -> int:
        """The calling thread's cumulative run-queue wait (ns)."""
        if self._fd is None:
            self._fd = os.open(f"/proc/self/task/{threading.get_native_id()}/schedstat", os.O_RDONLY)
            self._fifo = os.sched_getscheduler(0) == os.SCHED_FIFO
        return int(os.pread(self._fd, 64, 0).split()[1])

    def sample(self) -> None:
        self._wait_ns = self._wait()

    def name(self, start_s: float, end_s: float, step_s: float = 0.0) -> str:
        """The cause of the gap from `start_s` to `end_s` (monotonic s), of which the step that began at
        `start_s` took `step_s`; kept in `events`, counted."""
        gap = end_s - start_s
        wait_ns = self._wait()
        waited, self._wait_ns = (wait_ns - self._wait_ns) * 1e-9, wait_ns
        collections = GARBAGE.during(start_s, end_s)
        collecting = sum(min(c[1], end_s) - max(c[0], start_s) for c in collections)
        if collecting >= RUNQUEUE_SHARE * gap:
            kind = "garbage collection"
            cause = f"{kind}: generation {max(c[2] for c in collections)}, {collecting * 1e3:.1f} ms"
        elif waited >= RUNQUEUE_SHARE * gap:
            kind = "waiting for a CPU"
            throttled = (self._fifo and self._throttle_s is not None
                         and abs(gap - self._throttle_s) <= 0.2 * self._throttle_s)
            cause = (f"{kind}: runnable {waited * 1e3:.1f} ms without a core ("
                     + ("SCHED_FIFO, as long as the kernel's RT throttling: the real-time threads used "
                        "sched_rt_runtime_us of the period" if throttled else "other processes held the cores")
                     + ")")
        elif step_s >= RUNQUEUE_SHARE * gap:
            kind = "blocked in the step"
            cause = (f"{kind}: the step took {step_s * 1e3:.1f} ms, not runnable for {(gap - waited) * 1e3:.1f} ms "
                     f"(a DDS call waiting for a Fast DDS lock or the GIL, or the machine stalled)")
        else:
            kind = "blocked off CPU"
            cause = (f"{kind}: not runnable for {(gap - waited) * 1e3:.1f} ms between steps (the GIL held by "
                     f"another thread of this process, or the machine stalled)")
        self.counts[kind] += 1
        self.events.append((end_s, gap, cause))
        if gap > self.largest[0]:
            self.largest = (gap, cause)
        return cause

    def summary(self) -> dict:
        """Counts of the named gaps by cause, and the cause of the largest."""
        return {"gaps_named": sum(self.counts.values()),
                **{f"gaps_{kind.replace(' ', '_')}": n for kind, n in self.counts.items()},
                "largest_gap_cause": self.largest[1] or "-"}

    def new_events(self) -> list[tuple[float, float, str]]:
        """The events since the last call (for the diagnostics' log)."""
        events = list(self.events)
        total = sum(self.counts.values())
        fresh = events[max(0, len(events) - (total - self.reported)):]
        self.reported = total
        return fresh
