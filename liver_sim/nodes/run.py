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

from liver_sim.base.process_settings import use_dds_profile
from liver_sim.base.stop_request import ENDING_SIGNALS, STOP_SIGNALS, StopRequest
from liver_sim.realtime.garbage import FULL_COLLECTION_PERIOD_S, collect_garbage, freeze_garbage

#: How often (s) a thread holding the GIL is asked to hand it over.
GIL_SWITCH_INTERVAL_S = 0.0002
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
            deadline = time.monotonic() + close_ack_timeout_s()  # one deadline for the node's own waits and these
            node.close()
            for publisher in node.publishers:  # a recorder that fell behind still gets the last messages
                publisher.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
