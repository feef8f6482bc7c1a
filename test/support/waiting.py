"""The one way the tests wait: poll a condition until it holds, with a deadline and a message that says what was
awaited and what was seen."""
import time

#: How long (s) between two polls when the caller has nothing to do between them.
POLL_S = 0.02


def wait_for(condition, timeout_s: float, what: str, seen=lambda: "", between=None, gone=lambda: None) -> None:
    """Poll `condition()` until it holds. Between polls call `between()` (e.g. spin an executor for a few ms), or
    sleep POLL_S. AssertionError naming `what` and `seen()` after `timeout_s`, or as soon as `gone()` returns a
    reason (a process the wait depends on has exited)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        reason = gone()
        if reason:
            raise AssertionError(f"{reason} while waiting for {what}; seen: {seen()}")
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} not within {timeout_s:g} s; seen: {seen()}")
        if between is None:
            time.sleep(POLL_S)
        else:
            between()
