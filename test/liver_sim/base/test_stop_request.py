"""A process's main loop ends on SIGINT or SIGTERM, however many arrive and however fast (liver_sim.base.stop_request):
the handler takes no lock, so a signal arriving while another is being handled cannot hang the process."""
import os
import signal
import subprocess
import sys
import threading
import time

from liver_sim.base.stop_request import StopRequest, stop_on_signals

#: A loop waiting on a StopRequest, sent a burst of SIGTERMs and SIGINTs by a thread of its own; it leaves the block
#: once the burst is over (the handlers it restores would end the process on a late signal of the burst).
BURST = r"""
import os, signal, threading, time
from liver_sim.base.stop_request import stop_on_signals
def burst():
    time.sleep(0.2)
    for k in range(500):
        os.kill(os.getpid(), signal.SIGTERM if k % 2 else signal.SIGINT)
with stop_on_signals() as stop:
    sender = threading.Thread(target=burst, daemon=True)
    sender.start()
    while not stop.wait(0.001):
        pass
    sender.join()
print("stopped", flush=True)
"""


def test_a_wait_ends_at_once_when_a_stop_is_requested_from_another_thread():
    request = StopRequest()
    threading.Timer(0.05, request.set).start()
    start = time.monotonic()
    assert request.wait(10.0) and time.monotonic() - start < 5.0
    assert request.is_set() and request.wait(0.0)
    request.close()


def test_a_wait_times_out_without_a_request():
    request = StopRequest()
    start = time.monotonic()
    assert not request.wait(0.05) and time.monotonic() - start >= 0.04
    request.close()


def test_a_signal_ends_the_wait_and_the_previous_handlers_come_back():
    before = signal.getsignal(signal.SIGTERM)
    with stop_on_signals() as stop:
        threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGTERM)).start()
        assert stop.wait(10.0)
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_burst_of_signals_ends_the_loop():
    for _ in range(5):
        done = subprocess.run([sys.executable, "-c", BURST], capture_output=True, text=True, timeout=30)
        assert done.returncode == 0 and done.stdout.strip() == "stopped", done.stderr
