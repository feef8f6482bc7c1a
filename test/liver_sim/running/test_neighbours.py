"""The nodes leave the rig's machine to its other processes: only a thread that keeps a rate runs real-time (the rate
loop, and the bridge's supervisor); DDS's threads, the executor and diagnostics stay at normal priority."""
import os
import subprocess
import threading
import time

import pytest

from liver_sim.base.process_settings import command_line, set_realtime_priority
from liver_sim.realtime.rate_loop import RateLoop

from network_clients import wait_for

SCHED_FIFO = 1


def policies(pid: int) -> dict[int, int]:
    """{thread id: scheduling policy} of the threads of process `pid` (/proc: field 41 of each task's stat)."""
    found = {}
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            fields = open(f"/proc/{pid}/task/{task}/stat").read().rsplit(")", 1)[1].split()
        except OSError:
            continue  # a thread that ended meanwhile
        found[int(task)] = int(fields[38])
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


@pytest.mark.parametrize("executable, realtime_threads", [("haptic_bridge", 2), ("phantom_sim", 1)])
def test_only_the_threads_that_keep_a_rate_run_real_time(ros_env, tmp_path, executable, realtime_threads):
    """The bridge's loop and supervisor, the phantom's loop: SCHED_FIFO; every other thread of the process (DDS's, the
    executor, the garbage collector's timer) normal. The physics and the tool run the same RateLoop."""
    if not realtime_allowed():
        pytest.skip("SCHED_FIFO is refused here (no CAP_SYS_NICE or rtprio limit)")
    log = tmp_path / f"{executable}.log"
    with open(log, "w") as output:
        process = subprocess.Popen(command_line(executable), env=ros_env, stdout=output, stderr=subprocess.STDOUT)
    try:
        fifo = lambda: [tid for tid, policy in policies(process.pid).items() if policy == SCHED_FIFO]  # noqa: E731
        wait_for(lambda: len(fifo()) >= realtime_threads or process.poll() is not None, 60.0,
                 f"{realtime_threads} real-time thread(s) of {executable}", lambda: log.read_text()[-2000:])
        assert process.poll() is None, log.read_text()[-2000:]
        time.sleep(0.5)  # anything else that would turn real-time has had the time to
        everything = policies(process.pid)
        assert len(fifo()) == realtime_threads, everything
        assert len(everything) > realtime_threads + 2  # the DDS and executor threads are there, at normal priority
    finally:
        process.terminate()
        process.wait(timeout=30)
