"""The nodes leave the rig's machine to its other processes: only a thread that keeps a rate runs real-time (the rate
loop, the bridge's supervisor, the executor's rate loop); DDS's threads stay at normal priority, at a nice value that
no ordinary process can starve them from."""
import os
import subprocess
import threading

import pytest
from waiting import wait_for

from liver_sim.base.process_settings import SERVICE_NICE, command_line, set_realtime_priority
from liver_sim.realtime.rate_loop import RateLoop

SCHED_FIFO = 1


def threads(pid: int) -> dict[int, tuple[int, int, int]]:
    """{thread id: (scheduling policy, real-time priority, nice)} of the threads of process `pid` (/proc: fields 41,
    40 and 19 of each task's stat)."""
    found = {}
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            fields = open(f"/proc/{pid}/task/{task}/stat").read().rsplit(")", 1)[1].split()
        except OSError:
            continue  # a thread that ended meanwhile
        found[int(task)] = (int(fields[38]), int(fields[37]), int(fields[16]))
    return found


def realtime_allowed() -> bool:
    """Whether this machine lets a thread run SCHED_FIFO (root, CAP_SYS_NICE or an rtprio limit)."""
    outcome = []
    thread = threading.Thread(target=lambda: outcome.append(set_realtime_priority(1)))
    thread.start()
    thread.join()
    return outcome == [None]


def test_a_rate_loop_makes_its_own_thread_real_time_and_no_other():
    if not realtime_allowed():
        pytest.skip("SCHED_FIFO is refused here (no CAP_SYS_NICE or rtprio limit)")
    seen = []
    loop = RateLoop(200.0, lambda now: seen.append(os.sched_getscheduler(0)), "test_loop", freeze=False,
                    realtime_priority=10)
    loop.start()
    try:
        wait_for(lambda: len(seen) > 5, 5.0, "ticks of the loop")
        others = []
        bystander = threading.Thread(target=lambda: others.append(os.sched_getscheduler(0)))
        bystander.start()
        bystander.join()
    finally:
        loop.stop()
    assert set(seen) == {os.SCHED_FIFO}
    assert os.sched_getscheduler(0) == os.SCHED_OTHER and others == [os.SCHED_OTHER]


@pytest.mark.parametrize("executable, realtime_priorities", [("haptic_bridge", [79, 80, 80]),
                                                             ("phantom_sim", [79, 80])])
def test_only_the_threads_that_keep_a_rate_run_real_time(ros_domain_id, ros_env, tmp_path, executable,
                                                         realtime_priorities):
    """The bridge's loop and supervisor, the phantom's loop: SCHED_FIFO at the node's realtime_priority, and the
    executor's rate loop just below; every other thread of the process (DDS's, the main thread waiting for a signal)
    normal, at SERVICE_NICE, which no ordinary process can starve. Judged once the node has published diagnostics,
    which its executor's timer does: every thread that turns real-time has by then. The physics and the tool run the
    same RateLoop and run_node."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from msg_defs.topics import TOPICS

    if not realtime_allowed():
        pytest.skip("SCHED_FIFO is refused here (no CAP_SYS_NICE or rtprio limit)")
    log = tmp_path / f"{executable}.log"
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("diagnostics_watch", context=context)
    diagnostics = []
    node.create_subscription(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name, diagnostics.append,
                             TOPICS["diagnostics"].qos)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    with open(log, "w") as output:
        process = subprocess.Popen(command_line(executable), env=ros_env, stdout=output, stderr=subprocess.STDOUT)
    try:
        wait_for(lambda: len(diagnostics) >= 1, 60.0, f"diagnostics of {executable}", lambda: log.read_text()[-2000:],
                 between=lambda: executor.spin_once(timeout_sec=0.05),
                 gone=lambda: None if process.poll() is None else f"{executable} exited ({process.returncode})")
        everything = threads(process.pid)
        assert sorted(priority for policy, priority, _ in everything.values() if policy == SCHED_FIFO) == \
            realtime_priorities, everything
        others = [nice for policy, _, nice in everything.values() if policy != SCHED_FIFO]
        assert len(others) > 2 and set(others) == {SERVICE_NICE}, everything  # DDS's threads, the main thread
    finally:
        process.terminate()
        process.wait(timeout=30)
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
