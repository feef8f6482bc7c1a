"""What every node shell shares: a rate loop on absolute deadlines, its statistics and the cause of
its gaps, diagnostics, declared parameters with ranges, snapshots, the garbage-collector policy and
the process entry point.

Loops with a rate to keep run in their own thread (rclpy timers jitter by milliseconds on a
2-core machine); the executor only delivers messages and 1 Hz diagnostics.  A loop's tick does no
avoidable work: its statistics go into preallocated rings without a lock (one writer; a reader
copies), percentiles are computed by the diagnostics, and after start-up the garbage collector
never runs a full collection on its own (:func:`freeze_garbage`).
"""
from __future__ import annotations

import array
import gc
import os
import signal
import sys
import threading
import time
import traceback
from collections import deque

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.duration import Duration
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.signals import SignalHandlerOptions

from liver_sim.parameters import Param, check_parameter

#: Seconds before a deadline at which a loop stops sleeping and spins.
SPIN_MARGIN_S = 0.0001
#: A rate loop at most this many periods behind runs its missed ticks at once; further behind, it skips them.
CATCH_UP_PERIODS = 2
#: How often (Hz, at most the loop's rate) a rate loop that runs its node's executor (RateLoop.attach_executor)
#: runs its ready callbacks: parameters, services, diagnostics timers, low-rate subscriptions.
EXECUTOR_RATE_HZ = 100.0
#: How often (s) a thread holding the GIL is asked to hand it over.
GIL_SWITCH_INTERVAL_S = 0.0002
#: A loop is on rate while it achieves at least this fraction of its rate (diagnostics).
ON_RATE_FRACTION = 0.98
#: How long (s) a closing node waits for its reliable subscribers to acknowledge what it published.
CLOSE_ACK_TIMEOUT_S = 1.0


class Latest:
    """The newest value of something and when it arrived (monotonic seconds).

    One tuple swapped whole (atomic under the GIL): no lock, and a reader never sees a value with
    another's arrival time."""

    def __init__(self):
        self._item = (None, -np.inf)

    def set(self, value, received: float | None = None) -> None:
        """Keep `value`, received at monotonic `received` (s; default: now)."""
        self._item = (value, time.monotonic() if received is None else received)

    def get(self):
        """(value, monotonic arrival time); (None, -inf) before the first value."""
        return self._item


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


class GarbageLog:
    """When the garbage collector ran in this process (gc.callbacks): the last COLLECTIONS_KEPT passes as
    (monotonic start s, end s, generation), the number and longest duration of full (generation 2) ones."""

    COLLECTIONS_KEPT = 64

    def __init__(self):
        self.passes = deque(maxlen=self.COLLECTIONS_KEPT)
        self.full_collections = 0
        self.full_collection_max_s = 0.0
        self._started = 0.0
        gc.callbacks.append(self._callback)

    def _callback(self, phase: str, info: dict) -> None:
        now = time.monotonic()
        if phase == "start":
            self._started = now
            return
        self.passes.append((self._started, now, info["generation"]))
        if info["generation"] == 2:
            self.full_collections += 1
            self.full_collection_max_s = max(self.full_collection_max_s, now - self._started)

    def during(self, start_s: float, end_s: float) -> list[tuple[float, float, int]]:
        """The passes that overlapped [start_s, end_s] (monotonic s)."""
        return [p for p in list(self.passes) if p[0] < end_s and p[1] > start_s]


#: The collector's record in this process (installed on import, before any node starts).
GARBAGE = GarbageLog()
#: Generation-2 threshold after :func:`freeze_garbage`: never reached, so no automatic full collection.
NO_AUTOMATIC_FULL_COLLECTION = 2 ** 31 - 1
#: How often (s) a node runs the full collection itself, from its executor (never from a loop thread).
FULL_COLLECTION_PERIOD_S = 10.0


def freeze_garbage() -> None:
    """After start-up: collect, then move every object alive into the permanent generation (gc.freeze), which
    no collection scans again, and stop automatic full collections (generation 2 threshold never reached):
    a loop thread then only ever pays for young generations; :func:`collect_garbage` does the full one."""
    gc.collect()
    gc.freeze()
    young, middle, _ = gc.get_threshold()
    gc.set_threshold(young, middle, NO_AUTOMATIC_FULL_COLLECTION)


def collect_garbage() -> None:
    """A full collection of what is not frozen (short after :func:`freeze_garbage`); from the executor."""
    gc.collect(2)


def garbage_fields() -> dict:
    """Diagnostics of the collector policy: frozen objects, automatic full collection on or off, full
    collections run and the longest (s)."""
    return {"gc_frozen_objects": gc.get_freeze_count(),
            "gc_automatic_full_collection": gc.get_threshold()[2] < NO_AUTOMATIC_FULL_COLLECTION,
            "gc_full_collections": GARBAGE.full_collections, "gc_full_collection_max_s": GARBAGE.full_collection_max_s}


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
        period = int(open("/proc/sys/kernel/sched_rt_period_us").read())
        runtime = int(open("/proc/sys/kernel/sched_rt_runtime_us").read())
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
    - ``blocked off CPU``: the thread was not runnable: it waited for the GIL held by another thread of this
      process (the executor, a DDS callback into Python; or that thread itself waiting for a core) or for a
      lock inside rmw/DDS.

    Call :meth:`sample` from the loop thread every few ticks and :meth:`name` when a gap ended; both only
    read one small /proc file of the thread.
    """

    EVENTS_KEPT = 32

    def __init__(self):
        self._fd = None
        self._wait_ns = 0
        self.events = deque(maxlen=self.EVENTS_KEPT)  # (monotonic end s, gap s, cause)
        self.counts = {"garbage collection": 0, "waiting for a CPU": 0, "blocked off CPU": 0}
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

    def name(self, start_s: float, end_s: float) -> str:
        """The cause of the gap from `start_s` to `end_s` (monotonic s); kept in `events`, counted."""
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
        else:
            kind = "blocked off CPU"
            cause = (f"{kind}: not runnable for {(gap - waited) * 1e3:.1f} ms (the GIL held by another thread of "
                     f"this process, or a lock inside rmw/DDS)")
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


def set_realtime_priority(priority: int) -> str | None:
    """Schedule every thread of this process SCHED_FIFO at `priority` (0: leave them as they are).

    All of them: the rate loop, the executor and the DDS threads that deliver its inputs; threads
    started later inherit it. Returns None when done (or not asked), else why the system refused.
    """
    if priority <= 0:
        return None
    try:
        for thread_id in os.listdir("/proc/self/task"):
            os.sched_setscheduler(int(thread_id), os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        return (f"realtime_priority {priority} refused ({exc.strerror}): normal scheduling; grant CAP_SYS_NICE "
                f"or an rtprio limit to keep the rate under load")
    return None


class RateLoop(threading.Thread):
    """Calls `step(now_monotonic_s)` at `rate_hz` on absolute deadlines in its own thread.

    Deadline k is start + k·period: the thread sleeps until SPIN_MARGIN_S before it, then spins
    (a SCHED_FIFO thread wakes on time, and sleeps to the deadline itself).
    A step that starts more than a period late is an overrun; a gap over `gap_bound_s` (GAP_CAUSE_S, or two
    periods of a slower loop) gets its cause named (`gaps`, GapCauses). Starting the loop freezes the garbage
    collector (:func:`freeze_garbage`; not with `freeze` false): what the node built before is never scanned
    again. A loop at most CATCH_UP_PERIODS
    behind runs its missed ticks at once, so that a short stall costs no ticks; further behind,
    it skips to the newest deadline rather than run a burst. An exception in a step is counted
    (`errors`) and handed to `on_error(now, exc)` (default: printed); the loop goes on. `clock` and
    `sleep` are time.monotonic and time.sleep unless a test gives its own.

    With an executor attached (:meth:`attach_executor`, run_node does it), the loop also runs the executor's
    ready callbacks after a tick, at EXECUTOR_RATE_HZ: the node's Python then runs in this one thread, and no
    tick waits for the GIL of an executor thread (measured: pose-to-command p99 2.3 → 1.1 ms, `bench loop`).
    A failing callback is printed and counted (`executor_errors`), not taken for a failing step.
    """

    def __init__(self, rate_hz: float, step, name: str, clock=time.monotonic, sleep=time.sleep, on_error=None,
                 freeze: bool = True):
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
        self._stopping = threading.Event()
        self._executor = None
        self.executor_every_ticks = max(1, round(rate_hz / EXECUTOR_RATE_HZ))
        self.executor_errors = 0

    def attach_executor(self, executor) -> None:
        """Run `executor`'s ready callbacks from this loop's thread from now on (see the class docstring)."""
        self._executor = executor

    def _run_executor(self) -> None:
        try:
            self._executor.spin_once(timeout_sec=0.0)
        except ExternalShutdownException:
            self._executor = None
        except Exception:  # noqa: BLE001 — a callback's failure is not the loop's
            self.executor_errors += 1
            traceback.print_exc()

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
        clock, sleep = self._clock, self._sleep
        margin = 0.0 if os.sched_getscheduler(0) == os.SCHED_FIFO else SPIN_MARGIN_S
        start = clock()
        tick = 0
        previous = None
        gaps = self.gaps
        gaps.sample()
        while not self._stopping.is_set():
            deadline = start + tick * self.period_s
            remaining = deadline - clock()
            if remaining > margin:
                sleep(remaining - margin)
            while clock() < deadline:
                sleep(0)  # spin, but let another thread (the supervisor, a managed node's executor) take the GIL
            now = clock()
            if previous is not None:
                gap = now - previous
                self.stats.record(gap, now > deadline + self.period_s)
                if gap > self.gap_bound_s:
                    gaps.name(previous, now)
                elif tick % SCHEDSTAT_EVERY_TICKS == 0:
                    gaps.sample()
            previous = now
            try:
                self.step(now)
            except Exception as exc:  # a node keeps running; at shutdown the context goes first
                if not rclpy.ok():
                    return
                self.errors += 1
                if self._on_error is None:
                    traceback.print_exc()
                else:
                    self._on_error(now, exc)
            tick += 1
            if self._executor is not None and tick % self.executor_every_ticks == 0:
                self._run_executor()
            due = int((clock() - start) / self.period_s)
            if due - tick > CATCH_UP_PERIODS:
                tick = due


class LoopInputs:
    """Subscriptions that a rate loop reads itself, bypassing the executor's per-message cost.

    They belong to a hidden node (`_<node>_loop`, not spun by any executor); `poll()`, called from
    the loop, takes every waiting message of each subscription and hands the newest to its callback
    (with `received=True`, as callback(message, monotonic s at which DDS received it), so that ages count
    from reception, not from the poll), or, for a subscription made with `every=True`, each message with its
    rmw info (a dict with `source_timestamp` and `received_timestamp`, system-clock ns, and
    `publication_sequence_number`).
    """

    def __init__(self, node):
        self._node = rclpy.create_node(f"_{node.get_name()}_loop", context=node.context,
                                       use_global_arguments=False, start_parameter_services=False,
                                       enable_rosout=False)
        self._inputs = []

    def subscribe(self, msg_type, topic: str, qos, callback, raw: bool = False, every: bool = False,
                  received: bool = False):
        """Subscribe; returns the subscription (its get_publisher_count() tells whether anyone publishes)."""
        subscription = self._node.create_subscription(msg_type, topic, callback, qos, raw=raw)
        self._inputs.append((subscription, callback, every, received))
        return subscription

    def poll(self) -> None:
        for subscription, callback, every, received in self._inputs:
            newest = None
            with subscription.handle:
                while (taken := subscription.handle.take_message(subscription.msg_type, subscription.raw)):
                    if every:
                        callback(*taken)
                    else:
                        newest = taken
            if newest is None:
                continue
            if received:
                callback(newest[0], received_monotonic(newest[1]))
            else:
                callback(newest[0])

    def destroy(self) -> None:
        self._node.destroy_node()


def received_monotonic(info: dict) -> float:
    """Monotonic time (s) at which DDS received a message, from its rmw info's `received_timestamp`
    (system clock ns); now when the middleware gives none."""
    stamp = info.get("received_timestamp", 0) if info else 0
    now = time.monotonic_ns()
    if not stamp:
        return now * 1e-9
    return min(stamp + (now - time.time_ns()), now) * 1e-9


def apply_realtime_priority(node, priority: int) -> None:
    """set_realtime_priority, with a refusal logged as the node's warning."""
    refused = set_realtime_priority(priority)
    if refused:
        node.get_logger().warning(refused)


def declare_parameters(node, params: dict[str, Param]) -> dict:
    """Declare every parameter with its descriptor and range; return {name: value}.

    Out-of-range values and values outside `choices` raise ValueError naming the parameter.
    """
    values = {}
    for name, spec in params.items():
        descriptor = ParameterDescriptor(description=spec.description)
        if spec.low is not None:
            if isinstance(spec.default, int) and not isinstance(spec.default, bool):
                descriptor.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=0)]
            else:
                descriptor.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                                      to_value=float(spec.high), step=0.0)]
        if spec.choices:
            descriptor.additional_constraints = f"one of {', '.join(map(str, spec.choices))}"
        try:
            value = node.declare_parameter(name, spec.default, descriptor).value
        except ParameterException as exc:
            raise ValueError(f"parameter {name}: {exc}") from None
        values[name] = check_parameter(name, spec, value)
    return values


def on_parameter_changes(node, params: dict[str, Param], apply) -> None:
    """Answer every set_parameters on `node`: each value is checked as at start (check_parameter), then
    `apply(changes)` ({name: value}) applies them and returns None, or returns why it refuses them all.
    The answer says what happened (logged too): never a silent success. Register after declaring."""
    def callback(parameters) -> SetParametersResult:
        changes = {}
        try:
            for parameter in parameters:
                if parameter.name not in params:
                    raise ValueError(f"{parameter.name} is not a parameter of {node.get_name()}")
                changes[parameter.name] = check_parameter(parameter.name, params[parameter.name], parameter.value)
            refused = apply(changes)
        except ValueError as exc:
            refused = str(exc)
        if refused:
            node.get_logger().warning(f"refused {changes or [p.name for p in parameters]}: {refused}")
            return SetParametersResult(successful=False, reason=refused)
        node.get_logger().info(f"applied {changes}")
        return SetParametersResult(successful=True, reason=f"applied {', '.join(changes)}")
    node.add_on_set_parameters_callback(callback)


def read_at_start(node_name: str, runtime=frozenset()):
    """An `apply` for :func:`on_parameter_changes` that refuses every name outside `runtime`: such
    parameters are read once at start."""
    def refuse(changes: dict) -> str | None:
        fixed = sorted(set(changes) - set(runtime))
        if fixed:
            return f"{', '.join(fixed)}: read at start only; restart {node_name} to change it"
        return None
    return refuse


def diagnostic_status(name: str, stats: dict, level_ok: bool, message: str,
                      extra: dict | None = None, error: bool = False) -> DiagnosticStatus:
    """One DiagnosticStatus with the loop statistics (and `extra`) as key/value pairs: OK, WARN when not
    `level_ok`, ERROR when `error`."""
    level = DiagnosticStatus.ERROR if error else DiagnosticStatus.OK if level_ok else DiagnosticStatus.WARN
    status = DiagnosticStatus(name=name, hardware_id="liver_sim", message=message, level=level)
    fields = dict(stats)
    fields.update(extra or {})
    fields.update(garbage_fields())
    status.values = [KeyValue(key=key, value=f"{value:.6g}" if isinstance(value, float) else str(value))
                     for key, value in fields.items()]
    return status


def on_rate(stats: dict, rate_hz: float) -> bool:
    """Whether a loop with LoopStats.summary() `stats` achieves ON_RATE_FRACTION of `rate_hz` (Hz)."""
    return stats["rate_hz"] >= ON_RATE_FRACTION * rate_hz


def loop_status(name: str, stats: dict, rate_hz: float, extra: dict) -> DiagnosticStatus:
    """A node loop's DiagnosticStatus: OK while it is on rate (:func:`on_rate`) and had no gap over GAP_CAUSE_S
    since the last report (`new_gaps` of RateLoop.report(), named with their causes in the message)."""
    ok = on_rate(stats, rate_hz)
    problems = ([] if ok else [f"below {rate_hz:g} Hz"]) + ([stats["new_gaps"]] if stats.get("new_gaps") else [])
    return diagnostic_status(name, stats, not problems, "; ".join(problems) or "ok", extra)


def publish_diagnostics(node, publisher, statuses: list[DiagnosticStatus]) -> None:
    """Publish the node's statuses stamped now."""
    message = DiagnosticArray(status=statuses)
    message.header.stamp = node.get_clock().now().to_msg()
    publisher.publish(message)


def spin(executor, context=None, stop: threading.Event | None = None) -> None:
    """Run the executor until its context shuts down or `stop` is set.

    `EventsExecutor.spin()` of the rclpy 7.1 wheels neither runs callbacks nor returns on SIGINT
    here, so the executor is driven with spin_once.
    """
    ok = (context.ok if context is not None else rclpy.ok)
    try:
        while ok() and not (stop is not None and stop.is_set()):
            executor.spin_once(timeout_sec=0.1)
    except ExternalShutdownException:
        pass


def run_node(make_node, args=None) -> int:
    """Entry point of a node process: create it, spin an EventsExecutor until SIGINT or SIGTERM, clean up.

    The process handles SIGINT and SIGTERM itself (rclpy's handlers would shut the context down first):
    a signal ends the spin, then `node.close()` runs while the context is still up — the bridge sends its
    zero force there — then the node waits up to CLOSE_ACK_TIMEOUT_S for its reliable subscribers (a
    recorder) to acknowledge what it published; only then does the context go.  A refused parameter ends
    the process with status 2 and a message naming it.  The interpreter hands the GIL over every GIL_SWITCH_INTERVAL_S so
    that a rate loop and the executor thread do not hold each other up for Python's default 5 ms.  Once the node
    is built, the garbage collector is frozen (:func:`freeze_garbage`) and the executor runs the full collection
    every FULL_COLLECTION_PERIOD_S.  A node whose `rate_loop` (a running RateLoop) is given has its executor run
    by that loop between ticks (RateLoop.attach_executor); the others are spun by this thread.
    """
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    node = None
    try:
        node = make_node()
        freeze_garbage()
        node.create_timer(FULL_COLLECTION_PERIOD_S, collect_garbage)
        executor = EventsExecutor()
        executor.add_node(node)
        loop = getattr(node, "rate_loop", None)
        if loop is not None and loop.is_alive():  # the loop runs the executor: this thread only waits
            loop.attach_executor(executor)
            while not stop.wait(0.1) and rclpy.ok() and loop.is_alive():
                pass
            if not stop.is_set() and rclpy.ok():  # the loop ended on its own: the executor goes on here
                spin(executor, stop=stop)
        else:
            spin(executor, stop=stop)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.close()
            deadline = time.monotonic() + CLOSE_ACK_TIMEOUT_S
            for publisher in node.publishers:  # a recorder that fell behind still gets the last messages
                publisher.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
