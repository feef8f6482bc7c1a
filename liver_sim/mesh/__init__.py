"""Meshes: the validated tet mesh, the default liver, file input and output."""
from liver_sim.mesh.tetmesh import MeshError, TetMesh

__all__ = ["MeshError", "TetMesh"]
