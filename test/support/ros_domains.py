"""ROS domains of the test suite's own: each test that starts ROS processes or contexts locks one, machine-wide,
so that no two tests (of this session, of pytest-xdist workers or of another checkout's run) ever share one."""
import fcntl
import os
import tempfile
from pathlib import Path

# Domain ids whose Fast DDS ports stay clear of the Linux ephemeral range.
# 0 is left out: it is every ROS installation's default.
VALID_DOMAIN_IDS = tuple(range(1, 102)) + tuple(range(215, 233))
_LOCK_DIR = Path(tempfile.gettempdir()) / "liver_sim-ros-domain-locks"


def try_lock(domain_id):
    """Open file handle holding the exclusive lock of ``domain_id``, or None."""
    _LOCK_DIR.mkdir(mode=0o777, parents=True, exist_ok=True)
    handle = open(_LOCK_DIR / f"{domain_id}.lock", "a+")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        return None
    return handle


_next_index = (os.getpid() * 7919) % len(VALID_DOMAIN_IDS)


def claim_domain_id(exclude=()):
    """Lock a free domain id; return ``(domain_id, handle)``.

    The lock lasts until ``handle`` is closed or the process ends (even by a
    crash), so a dead test run never keeps a domain. The search starts where
    the previous claim of this process stopped (first: at a place derived
    from the process id), so consecutive tests get different domains -- a
    process a test failed to stop cannot talk to the next test -- and
    concurrent runs rarely contend for the same lock.
    """
    global _next_index
    n = len(VALID_DOMAIN_IDS)
    for k in range(n):
        index = (_next_index + k) % n
        domain_id = VALID_DOMAIN_IDS[index]
        if domain_id in exclude:
            continue
        handle = try_lock(domain_id)
        if handle is not None:
            _next_index = (index + 1) % n
            return domain_id, handle
    raise RuntimeError(
        f"no free ROS domain id among {n}: too many liver_sim test sessions "
        f"on this machine (locks in {_LOCK_DIR})")
