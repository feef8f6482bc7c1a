"""A supervisor beside the haptic loop (no ROS): zero force on the wire whenever the loop cannot vouch for its
command, and an account of every stall, error and gap.

The loop calls :meth:`Supervisor.beat` at the start of each tick, sends its command through
:meth:`Supervisor.send` and reports an exception of its step with :meth:`Supervisor.error`. A thread that is
not the loop (:meth:`Supervisor.start`) checks, when the bound would run out, that the loop has ticked within `bound_s`;
when it has not, or the loop has ended, it publishes a zero force and repeats it every `bound_s` until the
loop is back. Commands and zeros go out on one writer: DDS keeps order within a writer only, so with one writer
no retransmitted command can arrive after the last zero. The trip is decided under a lock and its zero published
outside it: a publish of the loop held up in the middleware (a transient-local reader joining holds the writer while
its history is sent) holds up the zero behind it on the wire, not the decision. While tripped the loop's own commands
are dropped, and a command the loop was publishing when the trip came is followed by a zero once its publish
returns, so the last word on the wire is zero; the loop's first tick after a trip is told to restart its output from
zero (soft start). :meth:`close` sends the last zero and lets nothing after it.

A supervisor in the loop's own interpreter cannot preempt a loop that holds the GIL: the device driver's own
command timeout stays the last line of defence (docs/haptic-safety.md).
"""
from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from liver_sim.base.checks import positive
from liver_sim.base.process_settings import set_realtime_priority

#: How many stall/error/stop events the supervisor keeps for diagnostics.
EVENT_HISTORY = 32
#: The supervisor wakes this long (s) after the bound would run out, so that the bound has run out.
WAKE_SLACK_S = 0.0001


@dataclass
class Event:
    """A stall, error or stop of the loop: `kind`, monotonic `start_s`, `cause`, and `end_s` (None while it lasts)."""

    kind: str
    start_s: float
    cause: str
    end_s: float | None = None


class GapLog:
    """Gaps (s) between consecutive ticks: the largest since start with the monotonic time it ended, and the
    largest over the last `window_s`. A fixed ring of arrays, written once per tick without allocation."""

    def __init__(self, period_s: float, window_s: float = 1.0):
        size = int(math.ceil(2.0 * window_s / positive(period_s, "period_s"))) + 1  # room for a loop twice as fast
        self.window_s = positive(window_s, "window_s")
        self._ends = np.full(size, -np.inf)
        self._gaps = np.zeros(size)
        self._next = 0
        self.max_gap_s = 0.0
        self.max_gap_end_s = math.nan

    def record(self, end_s: float, gap_s: float) -> None:
        i = self._next
        self._ends[i] = end_s
        self._gaps[i] = gap_s
        self._next = (i + 1) % self._ends.size
        if gap_s > self.max_gap_s:
            self.max_gap_s, self.max_gap_end_s = gap_s, end_s

    def recent(self, now_s: float) -> tuple[float, float]:
        """(largest gap s, monotonic time it ended) among the gaps ending in the last `window_s`; (0, nan) if none."""
        ends, gaps = self._ends.copy(), self._gaps.copy()
        inside = ends >= now_s - self.window_s
        if not inside.any():
            return 0.0, math.nan
        i = int(np.argmax(np.where(inside, gaps, -np.inf)))
        return float(gaps[i]), float(ends[i])


class Supervisor:
    """Holds the device at zero force while the loop is stalled, failing or gone (see the module doc).

    `publish(message)` puts a message on the wire (the loop's commands and the supervisor's zeros, one writer);
    `zero_message()` builds a zero-force command; `loop_alive()` says whether the loop thread still runs;
    `period_s` is the loop's period (for the gap log).
    """

    def __init__(self, bound_s: float, period_s: float, publish, zero_message, loop_alive=lambda: True,
                 clock=time.monotonic, realtime_priority: int = 0):
        self.bound_s = positive(bound_s, "bound_s")
        self._publish, self._zero_message, self._loop_alive, self._clock = publish, zero_message, loop_alive, clock
        self._lock = threading.Lock()
        self._beat = clock()
        self._last_zero = -math.inf
        self._closed = False
        self._stopping = threading.Event()
        self._thread = None
        self.realtime_priority = realtime_priority
        self.tripped: Event | None = None
        self.events: deque[Event] = deque(maxlen=EVENT_HISTORY)
        self.counts = {"stall": 0, "error": 0, "stop": 0}
        self.zeros_sent = 0
        self.publish_failures = 0
        self.gaps = GapLog(period_s)

    # -- the loop's side
    def beat(self, now_s: float) -> bool:
        """Start of a tick at `now_s`; True when the loop must restart its output from zero (after a trip, or
        after a gap beyond the bound that the supervisor did not get to see)."""
        with self._lock:
            gap = now_s - self._beat
            self._beat = now_s
            self.gaps.record(now_s, gap)
            if self._closed:
                return True
            if self.tripped is not None:
                self.tripped.end_s = now_s
                self.tripped = None
                return True
            if gap > self.bound_s:
                self._record("stall", now_s - gap, f"no tick for {gap * 1e3:.1f} ms (seen by the loop)").end_s = now_s
                return True
            return False

    def send(self, message) -> bool:
        """Publish the loop's command unless the output is held at zero; whether it was published. The publish
        runs outside the lock: if the output was tripped or closed meanwhile, a zero follows it on the writer."""
        with self._lock:
            if self.tripped is not None or self._closed:
                return False
        try:
            self._publish(message)
        finally:
            with self._lock:
                zero_after = self.tripped is not None or self._closed
            if zero_after:
                self._send_zero()
        return True

    def error(self, now_s: float, exc: BaseException) -> None:
        """The loop's step raised `exc`: zero now; the next tick restarts from zero."""
        with self._lock:
            if self._closed:
                return
            self._trip("error", now_s, f"{type(exc).__name__}: {exc}")
        self._send_zero()

    # -- the supervisor's side
    def check(self, now_s: float) -> None:
        """Trip when the loop has ended or not ticked within `bound_s`; while tripped, repeat the zero every
        `bound_s`."""
        with self._lock:
            if self._closed:
                return
            if self.tripped is None:
                if not self._loop_alive():
                    self._trip("stop", now_s, "the loop thread ended")
                elif now_s - self._beat > self.bound_s:
                    self._trip("stall", self._beat, f"no tick within {self.bound_s * 1e3:g} ms")
                else:
                    return
            elif now_s - self._last_zero < self.bound_s:
                return
            self._last_zero = now_s
        self._send_zero()

    def start(self) -> None:
        """Run :meth:`check` in a thread of its own, woken when the bound would run out (WAKE_SLACK_S after the
        newest beat + `bound_s`, or after the last zero + `bound_s` while tripped), not on a fixed period."""
        self._beat = self._clock()
        self._thread = threading.Thread(target=self._run, name="haptic_supervisor", daemon=True)
        self._thread.start()

    def close(self, cause: str) -> None:
        """Send the last zero (`cause` recorded as a stop) and nothing after it; stop the thread."""
        with self._lock:
            closing = not self._closed
            if closing:
                self._trip("stop", self._clock(), cause)
                self._closed = True
        if closing:
            self._send_zero()
        self._stopping.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)

    @property
    def closed(self) -> bool:
        return self._closed

    def _run(self) -> None:
        set_realtime_priority(self.realtime_priority)  # as the loop: a refusal is the loop's to report
        while True:
            with self._lock:
                due = (self._last_zero if self.tripped is not None else self._beat) + self.bound_s
            if self._stopping.wait(max(0.0, due - self._clock()) + WAKE_SLACK_S):
                return
            self.check(self._clock())

    def _record(self, kind: str, start_s: float, cause: str) -> Event:
        event = Event(kind, start_s, cause)
        self.events.append(event)
        self.counts[kind] += 1
        return event

    def _trip(self, kind: str, start_s: float, cause: str) -> None:
        """Under the lock: the output held at zero from now; the caller sends the zero once it has let go."""
        if self.tripped is not None:
            self.tripped.end_s = start_s
        self.tripped = self._record(kind, start_s, cause)
        self._last_zero = self._clock()

    def _send_zero(self) -> None:
        """A zero on the writer, outside the lock: a publish of the loop that holds the writer delays it on the
        wire, behind that command, and holds up no decision."""
        try:
            self._publish(self._zero_message())
            self.zeros_sent += 1
        except Exception:  # the context is gone: nothing can be sent any more
            self.publish_failures += 1

    # -- diagnostics
    def report(self, now_s: float, since_s: float) -> dict:
        """What diagnostics show: `error` (tripped now, or an event since `since_s`), `events` (those since
        `since_s` and the one lasting now), counts since start, the gaps over the last window and since start."""
        with self._lock:
            events = [e for e in self.events if e.start_s >= since_s or e.end_s is None or e.end_s >= since_s]
            tripped = self.tripped
        recent, recent_end = self.gaps.recent(now_s)
        return {"error": tripped is not None or bool(events), "events": events,
                "tripped": tripped.cause if tripped is not None else "",
                **{f"{kind}s": n for kind, n in self.counts.items()}, "zeros_sent": self.zeros_sent,
                "max_gap_1s_s": recent, "max_gap_1s_at_s": recent_end,
                "max_gap_s": self.gaps.max_gap_s, "max_gap_at_s": self.gaps.max_gap_end_s}
