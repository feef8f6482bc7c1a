"""numba's on-disk cache follows the kernels' sources (liver_sim.base.kernel_cache): a changed source in any folder of
kernels clears every cached kernel of those folders, an unchanged one nothing."""
import os

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
