"""What every node shell shares: a rate loop on absolute deadlines, its statistics, diagnostics,
declared parameters with ranges, lock-protected snapshots, and the process entry point.

Loops with a rate to keep run in their own thread (rclpy timers jitter by milliseconds on a
2-core machine); the executor only delivers messages and 1 Hz diagnostics.
"""
from __future__ import annotations

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
#: How often (s) a thread holding the GIL is asked to hand it over.
GIL_SWITCH_INTERVAL_S = 0.0002
#: A loop is on rate while it achieves at least this fraction of its rate (diagnostics).
ON_RATE_FRACTION = 0.98
#: How long (s) a closing node waits for its reliable subscribers to acknowledge what it published.
CLOSE_ACK_TIMEOUT_S = 1.0


class Latest:
    """The newest value of something and when it arrived (monotonic seconds), behind a lock."""

    def __init__(self):
        self._lock = threading.Lock()
        self._value = None
        self._received = -np.inf

    def set(self, value, received: float | None = None) -> None:
        """Keep `value`, received at monotonic `received` (s; default: now)."""
        with self._lock:
            self._value, self._received = value, time.monotonic() if received is None else received

    def get(self):
        """(value, monotonic arrival time); (None, -inf) before the first value."""
        with self._lock:
            return self._value, self._received


class LoopStats:
    """Periods of a rate loop over a sliding window: achieved rate, period error percentiles, overruns."""

    def __init__(self, period_s: float, window: int = 5000):
        self.period_s = period_s
        self._periods = deque(maxlen=window)
        self._lock = threading.Lock()
        self.overruns = 0
        self.ticks = 0
        self.max_gap_s = 0.0

    def record(self, period_s: float, overrun: bool) -> None:
        with self._lock:
            self._periods.append(period_s)
            self.ticks += 1
            self.overruns += int(overrun)
            self.max_gap_s = max(self.max_gap_s, period_s)

    def summary(self) -> dict:
        """rate_hz, period error p50/p99/max (s), overruns, ticks, max_gap_s."""
        with self._lock:
            periods = np.array(self._periods)
            overruns, ticks, max_gap = self.overruns, self.ticks, self.max_gap_s
        if periods.size == 0:
            return {"rate_hz": 0.0, "jitter_p50_s": 0.0, "jitter_p99_s": 0.0, "jitter_max_s": 0.0,
                    "overruns": overruns, "ticks": ticks, "max_gap_s": max_gap}
        error = np.abs(periods - self.period_s)
        return {"rate_hz": float(1.0 / periods.mean()), "jitter_p50_s": float(np.percentile(error, 50)),
                "jitter_p99_s": float(np.percentile(error, 99)), "jitter_max_s": float(error.max()),
                "overruns": overruns, "ticks": ticks, "max_gap_s": max_gap}


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
    A step that starts more than a period late is an overrun. A loop at most CATCH_UP_PERIODS
    behind runs its missed ticks at once, so that a short stall costs no ticks; further behind,
    it skips to the newest deadline rather than run a burst. An exception in a step is counted
    (`errors`) and handed to `on_error(now, exc)` (default: printed); the loop goes on. `clock` and
    `sleep` are time.monotonic and time.sleep unless a test gives its own.
    """

    def __init__(self, rate_hz: float, step, name: str, clock=time.monotonic, sleep=time.sleep, on_error=None):
        super().__init__(name=name, daemon=True)
        self.period_s = 1.0 / rate_hz
        self.step = step
        self.stats = LoopStats(self.period_s)
        self.errors = 0
        self._clock, self._sleep = clock, sleep
        self._on_error = on_error
        self._stopping = threading.Event()

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
        while not self._stopping.is_set():
            deadline = start + tick * self.period_s
            remaining = deadline - clock()
            if remaining > margin:
                sleep(remaining - margin)
            while clock() < deadline:
                sleep(0)  # spin, but let the executor thread take the GIL
            now = clock()
            if previous is not None:
                self.stats.record(now - previous, now > deadline + self.period_s)
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
    status.values = [KeyValue(key=key, value=f"{value:.6g}" if isinstance(value, float) else str(value))
                     for key, value in fields.items()]
    return status


def on_rate(stats: dict, rate_hz: float) -> bool:
    """Whether a loop with LoopStats.summary() `stats` achieves ON_RATE_FRACTION of `rate_hz` (Hz)."""
    return stats["rate_hz"] >= ON_RATE_FRACTION * rate_hz


def loop_status(name: str, stats: dict, rate_hz: float, extra: dict) -> DiagnosticStatus:
    """A node loop's DiagnosticStatus: OK while it is on rate (:func:`on_rate`)."""
    ok = on_rate(stats, rate_hz)
    return diagnostic_status(name, stats, ok, "ok" if ok else f"below {rate_hz:g} Hz", extra)


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
    that a rate loop and the executor thread do not hold each other up for Python's default 5 ms.
    """
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    node = None
    try:
        node = make_node()
        executor = EventsExecutor()
        executor.add_node(node)
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
