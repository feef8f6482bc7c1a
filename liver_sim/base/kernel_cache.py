"""numba's on-disk cache of the product's kernels, kept consistent with their sources.

numba keys a cached kernel on its own source file only: when a kernel it calls, in another module, changes its
signature, the stale machine code is loaded and can crash the interpreter (an updated checkout, a branch switch).
:func:`refresh` fingerprints every module of the folders that hold kernels (names, sizes, modification times) and,
when the fingerprint differs from the one stored with the cache, deletes those folders' cached kernels so that numba
compiles them again (`liver-sim warm` does it at once). The physics package calls it when it is imported.

numba's cache is not safe when two processes compile the same kernels at once: the index of one and the machine code
of the other can end up side by side, and the next process to load them crashes (numba issues 4807 and 10128; seen
here once, a `liver_physics` started while `liver-sim warm` ran). :func:`compiling` is the lock a warm-up holds while
it compiles, and :func:`refresh` while it deletes.
"""
from __future__ import annotations

import fcntl
import hashlib
import os
from contextlib import contextmanager
from pathlib import Path

#: The folders of liver_sim whose modules hold numba kernels that call one another.
KERNEL_FOLDERS = ("physics", "physics/contact", "physics/solver", "physics/tissue", "physics/topology", "base/geometry",
                  "mesh")
#: The stored fingerprint, beside the physics kernels' cache.
STAMP = Path("physics") / "__pycache__" / "kernel_sources.sha256"
#: The lock of the kernels' cache (compiling), beside the stamp.
LOCK = STAMP.with_name("kernels.lock")


def fingerprint(root: Path) -> str:
    """A digest of the name, size and modification time of every module of KERNEL_FOLDERS under `root`."""
    digest = hashlib.sha256()
    for folder in KERNEL_FOLDERS:
        for source in sorted((root / folder).glob("*.py")):
            status = source.stat()
            digest.update(f"{folder}/{source.name}:{status.st_size}:{status.st_mtime_ns};".encode())
    return digest.hexdigest()


def refresh(root: Path | None = None) -> bool:
    """Delete the cached kernels of KERNEL_FOLDERS under `root` (liver_sim's folder by default) when their sources
    changed since the cache was written; True when it did. A cache folder it cannot write is left alone."""
    root = root or Path(__file__).resolve().parents[1]
    current = fingerprint(root)
    stamp = root / STAMP
    try:
        if stamp.read_text() == current:
            return False
    except OSError:
        pass
    try:
        with compiling(root):
            for folder in KERNEL_FOLDERS:
                for cached in (root / folder / "__pycache__").glob("*.nb[ic]"):
                    cached.unlink(missing_ok=True)
            written = stamp.with_name(f"{stamp.name}.{os.getpid()}")
            written.write_text(current)
            written.replace(stamp)
    except OSError:
        return False
    return True


@contextmanager
def compiling(root: Path | None = None):
    """Hold the exclusive lock of the kernels' cache under `root` (liver_sim's folder by default) for the block:
    around a warm-up that compiles kernels into it, so that two processes never write it at once (module docstring);
    another process's warm-up waits, then loads what this one wrote. Without a writable cache folder, no lock."""
    root = (root or Path(__file__).resolve().parents[1]).resolve()
    handle = None
    if root not in _HELD:  # a lock this process holds is held (flock would wait for itself on a second file)
        try:
            (root / LOCK).parent.mkdir(exist_ok=True)
            handle = open(root / LOCK, "a")
        except OSError:
            pass
    if handle is None:
        yield
        return
    with handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        _HELD.add(root)
        try:
            yield
        finally:
            _HELD.discard(root)
            fcntl.flock(handle, fcntl.LOCK_UN)


#: The roots whose lock this process holds.
_HELD: set[Path] = set()
