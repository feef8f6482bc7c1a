"""The entry point of a node process (run_node) and the executor's spin."""
from __future__ import annotations

import os
import signal
import sys
import time

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.signals import SignalHandlerOptions

from liver_sim.base.process_settings import set_service_nice, use_dds_profile
from liver_sim.base.stop_request import ENDING_SIGNALS, STOP_SIGNALS, StopRequest
from liver_sim.realtime.garbage import FULL_COLLECTION_PERIOD_S, collect_garbage, freeze_garbage
from liver_sim.realtime.rate_loop import RateLoop, warn

#: How often (s) a thread holding the GIL is asked to hand it over.
GIL_SWITCH_INTERVAL_S = 0.0002
#: The rate (Hz) of a rate-keeping node's executor thread: each tick waits for its callbacks (timers, services,
#: parameter and graph events) until the next tick's deadline and runs each as it comes.
EXECUTOR_RATE_HZ = 10.0
#: Callbacks one executor tick runs at most: a burst is spread over ticks, its CPU bounded per period.
EXECUTOR_CALLBACKS_PER_TICK = 32
#: How long (s) a closing node waits for its reliable subscribers to acknowledge what it published.
CLOSE_ACK_TIMEOUT_S = 1.0
#: The same for a node whose parent died (a killed `liver-sim demo` or bench): its listener, which was in the parent,
#: will never acknowledge, and the run is going down as a whole.
ORPHAN_ACK_TIMEOUT_S = 0.2
#: The process that started this one (a node of a run knows when it has died: its parent changes).
_STARTED_BY = os.getppid()
#: How long (s) a closing node watches for the death of its parent, which signals it (PR_SET_PDEATHSIG) as its
#: threads end, before the kernel hands the node to a new parent.
PARENT_DEATH_WATCH_S = 0.05


def _parent_gone() -> bool:
    """Whether the process that started this one has died or is dying (its threads ending: a zombie)."""
    parent = os.getppid()
    if parent != _STARTED_BY:
        return True
    try:
        with open(f"/proc/{parent}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] in ("Z", "X", "x")
    except OSError:
        return True


def close_ack_timeout_s() -> float:
    """How long (s) a closing node waits for acknowledgements: CLOSE_ACK_TIMEOUT_S, or ORPHAN_ACK_TIMEOUT_S when
    the process that started it has died (watched for up to PARENT_DEATH_WATCH_S)."""
    deadline = time.monotonic() + PARENT_DEATH_WATCH_S
    while not _parent_gone():
        if time.monotonic() >= deadline:
            return CLOSE_ACK_TIMEOUT_S
        time.sleep(0.005)
    return ORPHAN_ACK_TIMEOUT_S


def spin(executor, context=None, stop=None) -> None:
    """Run the executor until its context shuts down or `stop` (a StopRequest or threading.Event) is set.

    `EventsExecutor.spin()` of the rclpy 7.1 wheels neither runs callbacks nor returns on SIGINT
    here, so the executor is driven with spin_once.
    """
    ok = (context.ok if context is not None else rclpy.ok)
    try:
        while ok() and not (stop is not None and stop.is_set()):
            executor.spin_once(timeout_sec=0.1)
    except ExternalShutdownException:
        pass


def executor_priority(loop_priority: int) -> int:
    """The real-time priority of a node's executor thread: just below its rate loop's (0: normal scheduling)."""
    return max(loop_priority - 1, 1) if loop_priority > 0 else 0


def serve_executor(executor, node, stop: StopRequest) -> RateLoop:
    """A RateLoop serving `executor` at EXECUTOR_RATE_HZ and :func:`executor_priority` of the node's
    `realtime_priority`: the executor's callbacks hold the GIL that the node's loop takes, so the thread running them
    keeps a rate at real-time priority, where no other process's ordinary or lower real-time threads can stop it
    while it holds the GIL. A tick waits (the GIL released) for ready callbacks until its period ends and runs at
    most EXECUTOR_CALLBACKS_PER_TICK of them; an error in one is logged and the node goes on; when the context shuts
    down, `stop` is set."""
    period_s = 1.0 / EXECUTOR_RATE_HZ

    def serve(now: float) -> None:
        try:
            for _ in range(EXECUTOR_CALLBACKS_PER_TICK):
                remaining = now + period_s - time.monotonic()
                if remaining <= 0.0:
                    return
                executor.spin_once(timeout_sec=remaining)
        except ExternalShutdownException:
            stop.set()
            raise

    def on_error(_now: float, exc: Exception) -> None:
        node.get_logger().error(f"executor callback failed: {exc!r}")

    priority = executor_priority(int(node.get_parameter("realtime_priority").value))
    return RateLoop(EXECUTOR_RATE_HZ, serve, "executor", on_error=on_error, freeze=False,
                    realtime_priority=priority, on_refused=warn(node), context=node.context)


def run_node(make_node, args=None) -> int:
    """Entry point of a node process: create it, spin an EventsExecutor until an ending signal, clean up.

    The process handles the ENDING_SIGNALS itself (SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGPIPE; rclpy's handlers
    would shut the context down first) and ignores the job-control STOP_SIGNALS (Ctrl-Z would freeze a loop
    and its supervisor with the last command held; SIGSTOP cannot be caught: after SIGCONT the bridge's loop
    sees the gap and restarts from zero with a soft start):
    a signal ends the spin, then `node.close()` runs while the context is still up — the bridge sends its
    zero force there first — then the node waits for its reliable subscribers (a recorder) to acknowledge what
    it published, until :func:`close_ack_timeout_s` after the close began (one deadline for the node's own waits
    and these: a subscriber that died, as a killed run's listener, never acknowledges); only then does the
    context go.  A refused parameter ends
    the process with status 2 and a message naming it.  The process loads the product's Fast DDS profile
    (:func:`use_dds_profile`) unless the environment names one.  The executor of a node with a `realtime_priority`
    runs in a rate loop of its own just below the node's loop (:func:`serve_executor`) while the main thread waits
    for the signal; any other node's is spun by the main thread.  Every thread that keeps no rate (DDS's) runs at
    SERVICE_NICE (:func:`set_service_nice`), so that no ordinary process starves a thread holding a lock a loop
    waits for.  The interpreter hands the GIL over every
    GIL_SWITCH_INTERVAL_S so that a rate loop and the executor thread do not hold each other up for Python's
    default 5 ms.  Once the node is built, the garbage collector is frozen (:func:`freeze_garbage`) and the
    executor runs the full collection every FULL_COLLECTION_PERIOD_S.
    """
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    nice_refused = set_service_nice()  # before rclpy starts DDS's threads, which inherit it
    dds_profile = use_dds_profile()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = StopRequest()
    for signum in ENDING_SIGNALS:
        signal.signal(signum, stop.set)
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
    node = None
    try:
        node = make_node()
        node.get_logger().info(f"DDS profile: {dds_profile}")
        if nice_refused:
            node.get_logger().warning(nice_refused)
        freeze_garbage()
        node.create_timer(FULL_COLLECTION_PERIOD_S, collect_garbage)
        executor = EventsExecutor()
        executor.add_node(node)
        if node.has_parameter("realtime_priority"):  # a node that keeps a rate
            executor.spin_once(timeout_sec=0.0)  # the executor's own threads (its timers') start here, not real-time
            served = serve_executor(executor, node, stop)
            served.start()
            stop.wait()
            served.stop()
        else:
            spin(executor, stop=stop)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            deadline = time.monotonic() + close_ack_timeout_s()  # one deadline for the node's own waits and these
            node.close()
            for publisher in node.publishers:  # a recorder that fell behind still gets the last messages
                publisher.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
