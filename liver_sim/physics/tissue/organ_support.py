"""How the liver is held (paper P8's scene, or as a liver is held in the body).

`support` 'paper': the four nodes of the tet nearest the volume centroid are fixed (§3.1); the organ
pivots about them.  `support` 'organ' (default): the capsule nodes inside the `support_regions` (spheres x, y, z,
radius in the liver frame, m, each with its stiffness per unit skin area k_A, N/m per m² = N/m³) are
tied to their rest positions by spring-dampers, as the liver is held by the bare area fused to the
diaphragm, the inferior vena cava, its ligaments and the viscera it rests on:

    f_n = −k_n·(x_n − x_rest,n) − c_n·v_n,   k_n = Σ k_A·A_n,   c_n = τ·k_n,

A_n a third of the area of the capsule triangles around node n at rest (m²), the sum over the regions
holding n, and τ `support_damping_s` (the ties' Kelvin–Voigt time constant, s).  Its Jacobian
is −k_n·I (∂f/∂x) and −c_n·I (∂f/∂v) on the node's diagonal block (physics.solver.implicit_kernels; the forces:
`support_forces`).
The default regions sit on the default liver (liver_sim.mesh.liver_shape, DICOM LPS axes); on a mesh
where they hold no capsule node the scene is the paper's (physics.model).
"""
from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tissue.materials import triangle_areas


class SupportArrays(NamedTuple):
    """The support's spring-dampers for the kernels: nodes (S,) int64, rest positions (S, 3) m,
    stiffness k_n (S,) N/m and damping c_n (S,) N·s/m."""

    nodes: np.ndarray
    rest_m: np.ndarray
    stiffness_n_per_m: np.ndarray
    damping_ns_per_m: np.ndarray

    @classmethod
    def none(cls) -> "SupportArrays":
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), np.zeros(0))


def node_areas_m2(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """A third of the area (m²) of the `triangles` around each node of `points`."""
    return np.bincount(triangles.ravel(), np.repeat(triangle_areas(points, triangles) / 3.0, 3),
                       minlength=len(points))


def region_stiffness_n_per_m3(points: np.ndarray, regions) -> np.ndarray:
    """Per point, the summed stiffness per unit area k_A of the regions (x, y, z, radius, k_A) holding it."""
    stiffness = np.zeros(len(points))
    for centre_x, centre_y, centre_z, radius, per_area in np.asarray(regions, dtype=np.float64).reshape(-1, 5):
        inside = np.linalg.norm(points - (centre_x, centre_y, centre_z), axis=1) <= radius
        stiffness += per_area * inside
    return stiffness


def build_support(mesh: TetMesh, capsule_triangles: np.ndarray, params: ModelParams) -> SupportArrays:
    """The support springs of `mesh` (rest: mesh.points) on the capsule nodes inside
    `params.support_regions`; none for the 'paper' support (or when no capsule node lies inside)."""
    triangles = np.asarray(capsule_triangles, dtype=np.int64).reshape(-1, 3)
    if params.support == "paper" or len(triangles) == 0:
        return SupportArrays.none()
    capsule = np.unique(triangles)
    per_area = region_stiffness_n_per_m3(mesh.points[capsule], params.support_regions)
    nodes = capsule[per_area > 0.0]
    stiffness = (per_area * node_areas_m2(mesh.points, triangles)[capsule])[per_area > 0.0]
    return SupportArrays(nodes, mesh.points[nodes].copy(), stiffness, params.support_damping_s * stiffness)


@numba.njit(cache=True)
def support_forces(x, v, nodes, rest, stiffness, damping, f):
    """Add the support's spring-dampers to f: −k_n·(x_n − rest_n) − c_n·v_n on each supported node n."""
    for s in range(nodes.shape[0]):
        n = nodes[s]
        for a in range(3):
            f[n, a] -= stiffness[s] * (x[n, a] - rest[s, a]) + damping[s] * v[n, a]
