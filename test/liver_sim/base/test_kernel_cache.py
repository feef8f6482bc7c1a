"""numba's on-disk cache follows the kernels' sources (liver_sim.base.kernel_cache): a changed source in any folder of
kernels clears every cached kernel of those folders, an unchanged one nothing; a warm-up compiles under a lock that
other processes wait for."""
import os
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

from liver_sim.base import kernel_cache


def make_tree(root):
    for folder in kernel_cache.KERNEL_FOLDERS:
        (root / folder / "__pycache__").mkdir(parents=True)
        (root / folder / "kernels.py").write_text("def f(): pass\n")
        (root / folder / "__pycache__" / "kernels.f-1.py311.nbi").write_bytes(b"index")
        (root / folder / "__pycache__" / "kernels.f-1.py311.1.nbc").write_bytes(b"code")


def cached(root):
    return sorted(p.name for folder in kernel_cache.KERNEL_FOLDERS
                  for p in (root / folder / "__pycache__").glob("*.nb?"))


def test_a_changed_kernel_source_clears_every_cached_kernel_and_an_unchanged_one_nothing(tmp_path):
    make_tree(tmp_path)
    assert kernel_cache.refresh(tmp_path)  # no stamp yet: the cache is of unknown sources
    assert cached(tmp_path) == []
    for folder in kernel_cache.KERNEL_FOLDERS:  # numba compiles them again
        (tmp_path / folder / "__pycache__" / "kernels.f-1.py311.nbi").write_bytes(b"index")
    assert not kernel_cache.refresh(tmp_path)  # nothing changed: the cache stays
    assert len(cached(tmp_path)) == len(kernel_cache.KERNEL_FOLDERS)
    source = tmp_path / "base/geometry" / "kernels.py"  # a kernel another folder's kernels call
    source.write_text("def f(x): pass\n")
    os.utime(source, ns=(source.stat().st_atime_ns, source.stat().st_mtime_ns + 1_000_000))
    assert kernel_cache.refresh(tmp_path)
    assert cached(tmp_path) == []


def _try_lock(path) -> int:
    """The exit status of another process taking the lock file at `path` without waiting: 0 taken, 1 held."""
    code = ("import fcntl, sys\nf = open(sys.argv[1], 'a')\ntry:\n    fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)\n"
            "except BlockingIOError:\n    sys.exit(1)\n")
    return subprocess.run([sys.executable, "-c", code, str(path)]).returncode


def test_compiling_holds_the_cache_against_other_processes_and_not_against_itself(tmp_path):
    make_tree(tmp_path)
    lock = tmp_path / kernel_cache.LOCK
    with kernel_cache.compiling(tmp_path):
        assert _try_lock(lock) == 1  # another process's warm-up waits
        with kernel_cache.compiling(tmp_path):  # this process again (a refresh within a warm-up): no wait
            assert _try_lock(lock) == 1
        assert _try_lock(lock) == 1  # the inner block did not release the outer one's lock
    assert _try_lock(lock) == 0


def test_a_warm_up_compiles_under_the_cache_lock(monkeypatch):
    from liver_sim.mesh.liver_shape import default_liver
    from liver_sim.physics.model import LiverModel
    held = []

    @contextmanager
    def recording():
        held.append(True)
        yield

    monkeypatch.setattr(kernel_cache, "compiling", recording)
    LiverModel(default_liver()).warm_up()
    assert held == [True]


def test_every_folder_of_numba_kernels_is_fingerprinted():
    """A kernel in a folder the fingerprint misses would keep a stale cache after its source changed."""
    root = Path(kernel_cache.__file__).resolve().parents[1]
    folders = {str(path.parent.relative_to(root)) for path in root.rglob("*.py") if "numba.njit" in path.read_text()}
    assert folders and folders <= set(kernel_cache.KERNEL_FOLDERS), folders - set(kernel_cache.KERNEL_FOLDERS)
