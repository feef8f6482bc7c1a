"""Meshes: the validated tet mesh, the default liver, file input and output. Importing it first brings numba's cache
of the kernels in line with their sources (liver_sim.base.kernel_cache)."""
from liver_sim.base import kernel_cache

kernel_cache.refresh()

from liver_sim.mesh.tetmesh import MeshError, TetMesh  # noqa: E402 — after the cache is in line

__all__ = ["MeshError", "TetMesh"]
