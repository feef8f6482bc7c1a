"""The entry point of a node process (run_node) and the executor's spin."""
from __future__ import annotations

import signal
import sys
import time

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.signals import SignalHandlerOptions

from liver_sim.base.process_settings import use_dds_profile
from liver_sim.base.stop_request import ENDING_SIGNALS, STOP_SIGNALS, StopRequest
from liver_sim.nodes.garbage import FULL_COLLECTION_PERIOD_S, collect_garbage, freeze_garbage

#: How often (s) a thread holding the GIL is asked to hand it over.
GIL_SWITCH_INTERVAL_S = 0.0002
#: How long (s) a closing node waits for its reliable subscribers to acknowledge what it published.
CLOSE_ACK_TIMEOUT_S = 1.0


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


def run_node(make_node, args=None) -> int:
    """Entry point of a node process: create it, spin an EventsExecutor until an ending signal, clean up.

    The process handles the ENDING_SIGNALS itself (SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGPIPE; rclpy's handlers
    would shut the context down first) and ignores the job-control STOP_SIGNALS (Ctrl-Z would freeze a loop
    and its supervisor with the last command held; SIGSTOP cannot be caught: after SIGCONT the bridge's loop
    sees the gap and restarts from zero with a soft start):
    a signal ends the spin, then `node.close()` runs while the context is still up — the bridge sends its
    zero force there — then the node waits up to CLOSE_ACK_TIMEOUT_S for its reliable subscribers (a
    recorder) to acknowledge what it published; only then does the context go.  A refused parameter ends
    the process with status 2 and a message naming it.  The process loads the product's Fast DDS profile
    (:func:`use_dds_profile`) unless the environment names one.  The interpreter hands the GIL over every
    GIL_SWITCH_INTERVAL_S so that a rate loop and the executor thread do not hold each other up for Python's
    default 5 ms.  Once the node is built, the garbage collector is frozen (:func:`freeze_garbage`) and the
    executor runs the full collection every FULL_COLLECTION_PERIOD_S.
    """
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
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
        freeze_garbage()
        node.create_timer(FULL_COLLECTION_PERIOD_S, collect_garbage)
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
