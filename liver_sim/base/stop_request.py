"""How a process's main loop learns it must stop (ENDING_SIGNALS): a StopRequest, set by the signal handler and
waited on by the loop, standard library only.

The handler takes no lock. threading.Event.set() in a handler can deadlock the process for good: Python runs a
handler in the main thread between two bytecodes, a second signal arriving while the first handler holds the
Event's lock runs a second handler in the same thread, and that one waits for the lock forever. A recorder hung
so when its demo was killed (parent-death SIGTERM, then another signal); any node could.
"""
from __future__ import annotations

import os
import select
import signal
from contextlib import contextmanager

#: The signals that end a node or a command cleanly (a bridge's last command is zero, a recorder closes its bag):
#: SIGINT (Ctrl-C), SIGTERM (kill, a launcher), SIGHUP (a closing terminal or SSH session), SIGQUIT (Ctrl-\\),
#: SIGPIPE (a closed pipe on stdout or stderr, or kill -PIPE).
ENDING_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGPIPE)
#: Job-control stops a node ignores (Ctrl-Z, background terminal I/O): a stopped loop would hold its last output.
STOP_SIGNALS = (signal.SIGTSTP, signal.SIGTTIN, signal.SIGTTOU)


class StopRequest:
    """A flag and a pipe: `set` (the handler) sets the flag and writes a byte, `wait` selects on the pipe."""

    def __init__(self):
        self._requested = False
        self._read, self._write = os.pipe()
        os.set_blocking(self._write, False)

    def set(self, *_signal) -> None:
        """Ask the loop to stop; safe in a signal handler (no lock, a non-blocking write)."""
        self._requested = True
        try:
            os.write(self._write, b"\0")
        except OSError:  # the pipe is full or closed: the request is made already
            pass

    def is_set(self) -> bool:
        return self._requested

    def wait(self, timeout_s: float | None = None) -> bool:
        """Until a stop is requested or `timeout_s` (None: forever) has passed; whether one was requested."""
        if not self._requested:
            select.select([self._read], [], [], timeout_s)
        return self._requested

    def close(self) -> None:
        os.close(self._read)
        os.close(self._write)


@contextmanager
def stop_on_signals(signals=ENDING_SIGNALS):
    """A StopRequest set by any of `signals` while the block runs; the previous handlers come back after it."""
    request = StopRequest()
    previous = {signum: signal.signal(signum, request.set) for signum in signals}
    try:
        yield request
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        request.close()
