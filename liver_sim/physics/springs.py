"""The spring-damper network built on a tet mesh (P3) and its stability bound.

Parenchyma springs sit on every tet edge, capsule springs on every skin-triangle
edge; an edge on the skin carries both.  Two Eq. 1 springs on one edge with one
rest length act exactly as one spring whose λ1, λ2 and μ are the sums, so the
kernels evaluate one connector per edge with the summed coefficients.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.params import ModelParams


@dataclass(frozen=True, eq=False)
class SpringNetwork:
    """One connector per mesh edge: node pairs, rest lengths (m) and Eq. 1 coefficients."""

    node_i: np.ndarray
    node_j: np.ndarray
    rest_length_m: np.ndarray
    lambda1_n: np.ndarray
    lambda2_n: np.ndarray
    mu_ns_per_m: np.ndarray
    capsule_springs: int
    parenchyma_springs: int

    @property
    def edges(self) -> int:
        """Connectors evaluated per step (edges; a skin edge's two springs count once)."""
        return len(self.node_i)

    @property
    def springs(self) -> int:
        """Springs of the model: parenchyma (tet edges) plus capsule (skin edges)."""
        return self.capsule_springs + self.parenchyma_springs


def build_springs(mesh: TetMesh, params: ModelParams, rest_points: np.ndarray | None = None) -> SpringNetwork:
    """Springs on `mesh`'s edges with rest lengths from `rest_points` (default: the mesh nodes)."""
    points = mesh.points if rest_points is None else rest_points
    edges = mesh.edges
    on_skin = _rows_in(edges, mesh.skin_edges)
    par, cap = params.parenchyma, params.capsule
    node_i = np.ascontiguousarray(edges[:, 0])
    node_j = np.ascontiguousarray(edges[:, 1])
    rest = np.linalg.norm(points[node_j] - points[node_i], axis=1)
    return SpringNetwork(
        node_i=node_i,
        node_j=node_j,
        rest_length_m=rest,
        lambda1_n=par.lambda1_n + cap.lambda1_n * on_skin,
        lambda2_n=par.lambda2_n + cap.lambda2_n * on_skin,
        mu_ns_per_m=par.mu_ns_per_m + cap.mu_ns_per_m * on_skin,
        capsule_springs=int(on_skin.sum()),
        parenchyma_springs=int(len(edges)),
    )


def _rows_in(rows: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Boolean mask: which rows of `rows` (sorted pairs) appear in `table` (sorted pairs)."""
    n = int(max(rows.max(), table.max())) + 1
    keys = rows[:, 0] * n + rows[:, 1]
    return np.isin(keys, table[:, 0] * n + table[:, 1])


def stable_time_step(springs: SpringNetwork, masses_kg: np.ndarray, environment_damping_per_s: float,
                     integrator: str, positions: np.ndarray) -> float:
    """Largest stable time step (s) of the linearised model at `positions` (rest: the mesh nodes).

    With K = Σ (λ2/l0)·u·uᵀ and C = Σ μ·u·uᵀ the springs' axial stiffness and damping, a mode
    x'' = −ω²x − c·x' has ω² ≤ λmax(M⁻¹K) and c ≤ λmax(M⁻¹C) + c_env.  Symplectic Euler is
    stable for h ≤ (√(c² + 4ω²) − c)/ω², taken at the largest ω and c together (conservative).
    Explicit Euler (Eq. 2) needs h < c/ω² on every mode, and c/ω² ≥ min over springs of
    μ·l0/λ2 (+ c_env/ω²max), with h·c ≤ 2: without damping it is unstable at any step.
    """
    axis = positions[springs.node_j] - positions[springs.node_i]
    unit = axis / np.linalg.norm(axis, axis=1)[:, None]
    scale = 1.0 / np.sqrt(np.repeat(masses_kg, 3))
    omega2 = _largest_eigenvalue(springs, unit, springs.lambda2_n / springs.rest_length_m, scale)
    c = _largest_eigenvalue(springs, unit, springs.mu_ns_per_m, scale) + environment_damping_per_s
    if omega2 <= 0.0:
        return math.inf
    if integrator == "explicit_euler":
        stiffness = springs.lambda2_n / springs.rest_length_m
        ratio = np.divide(springs.mu_ns_per_m, stiffness, out=np.full(len(stiffness), np.inf), where=stiffness > 0)
        return min(float(ratio.min()) + environment_damping_per_s / omega2, 2.0 / c if c > 0.0 else math.inf)
    return (math.sqrt(c * c + 4.0 * omega2) - c) / omega2


def _largest_eigenvalue(springs: SpringNetwork, unit: np.ndarray, coefficient: np.ndarray,
                        scale: np.ndarray) -> float:
    """λmax of M^-1/2·A·M^-1/2 for A = Σ coefficient·(e_i − e_j)(e_i − e_j)ᵀ ⊗ u·uᵀ."""
    block = coefficient[:, None, None] * unit[:, :, None] * unit[:, None, :]
    rows, cols, vals = [], [], []
    for a, b, sign in ((springs.node_i, springs.node_i, 1.0), (springs.node_j, springs.node_j, 1.0),
                       (springs.node_i, springs.node_j, -1.0), (springs.node_j, springs.node_i, -1.0)):
        r = (3 * a)[:, None, None] + np.arange(3)[None, :, None]
        c = (3 * b)[:, None, None] + np.arange(3)[None, None, :]
        rows.append(np.broadcast_to(r, block.shape).ravel())
        cols.append(np.broadcast_to(c, block.shape).ravel())
        vals.append((sign * block).ravel())
    size = len(scale)
    matrix = scipy.sparse.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                     shape=(size, size)).tocsr()
    scaled = scipy.sparse.diags(scale) @ matrix @ scipy.sparse.diags(scale)
    if not scaled.nnz or not np.abs(scaled.data).max() > 0.0:
        return 0.0
    start = np.random.default_rng(0).standard_normal(size)
    return float(scipy.sparse.linalg.eigsh(scaled, k=1, which="LA", v0=start,
                                           return_eigenvectors=False, tol=1e-4)[0])
