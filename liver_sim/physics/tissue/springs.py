"""The spring-damper network built on a tet mesh (paper P3, docs/paper.md) and its stability bound.

Parenchyma springs sit on every tet edge, capsule springs on every capsule-triangle
edge (the skin, less faces opened by tears and cuts); such an edge carries both.  Two Eq. 1 springs on one edge with one
rest length act exactly as one spring whose λ1, λ2 and μ are the sums, so the
kernels evaluate one connector per edge with the summed coefficients.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numba
import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from liver_sim.mesh.tetmesh import TRIANGLE_EDGES, TetMesh, isin_keys, unique_edges
from liver_sim.physics.settings import CONTINUUM_LAWS, ModelParams
from liver_sim.physics.tissue.materials import material_coefficients
from liver_sim.physics.tissue.organ_support import SupportArrays


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


def build_springs(mesh: TetMesh, params: ModelParams, rest_points: np.ndarray | None = None,
                  capsule_triangles: np.ndarray | None = None) -> SpringNetwork:
    """Springs on `mesh`'s edges with rest lengths from `rest_points` (default: the mesh nodes).

    Capsule springs sit on the edges of `capsule_triangles` (default: the whole skin); skin opened
    by a tear or a cut is parenchyma surface and carries none.  Their coefficients: from
    `params.tissue` and the mesh (materials.material_coefficients) with spring_constants 'material',
    else the paper's `params.parenchyma` on every edge plus `params.capsule` on capsule edges.  With
    `params.tissue_law` 'fem' or 'neo_hookean' the parenchyma is the elements' (physics.tissue.fem_kernels,
    physics.tissue.neo_hookean): capsule edges only.
    """
    points = mesh.points if rest_points is None else rest_points
    edges = mesh.edges
    if capsule_triangles is None:
        capsule_edges = mesh.skin_edges
    else:
        capsule_edges = unique_edges(np.asarray(capsule_triangles, dtype=np.int64).reshape(-1, 3), TRIANGLE_EDGES)
    on_skin = _rows_in(edges, capsule_edges) if len(capsule_edges) else np.zeros(len(edges), dtype=bool)
    node_i = np.ascontiguousarray(edges[:, 0])
    node_j = np.ascontiguousarray(edges[:, 1])
    rest = np.linalg.norm(points[node_j] - points[node_i], axis=1)
    if params.spring_constants == "material":
        tissue = params.tissue
        if params.tissue_law in CONTINUUM_LAWS:  # the parenchyma is the elements': the capsule's springs only
            tissue = replace(tissue, parenchyma_young_modulus_kpa=0.0, parenchyma_viscosity_pa_s=0.0)
        lambda1, lambda2, mu = material_coefficients(mesh, tissue, rest_points, capsule_triangles)
    else:
        par, cap = params.parenchyma, params.capsule
        lambda1 = par.lambda1_n + cap.lambda1_n * on_skin
        lambda2 = par.lambda2_n + cap.lambda2_n * on_skin
        mu = par.mu_ns_per_m + cap.mu_ns_per_m * on_skin
    parenchyma = len(edges)
    if params.tissue_law in CONTINUUM_LAWS:
        keep = on_skin
        node_i, node_j, rest, lambda1, lambda2, mu = (np.ascontiguousarray(a[keep]) for a in
                                                      (node_i, node_j, rest, lambda1, lambda2, mu))
        parenchyma = 0
    return SpringNetwork(node_i=node_i, node_j=node_j, rest_length_m=rest, lambda1_n=lambda1, lambda2_n=lambda2,
                         mu_ns_per_m=mu, capsule_springs=int(on_skin.sum()), parenchyma_springs=int(parenchyma))


def _rows_in(rows: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Boolean mask: which rows of `rows` (sorted pairs) appear in `table` (sorted pairs)."""
    n = int(max(rows.max(), table.max())) + 1
    keys = rows[:, 0] * n + rows[:, 1]
    return isin_keys(keys, table[:, 0] * n + table[:, 1])


def stable_time_step(springs: SpringNetwork, masses_kg: np.ndarray, environment_damping_per_s: float,
                     integrator: str, positions: np.ndarray, support: SupportArrays | None = None) -> float:
    """Largest stable time step (s) of the linearised model at `positions` (rest: the mesh nodes).

    With K = Σ (λ2/l0)·u·uᵀ and C = Σ μ·u·uᵀ the springs' axial stiffness and damping, a mode
    x'' = −ω²x − c·x' has ω² ≤ λmax(M⁻¹K) and c ≤ λmax(M⁻¹C) + c_env.  Symplectic Euler is
    stable for h ≤ (√(c² + 4ω²) − c)/ω², taken at the largest ω and c together (conservative).
    Explicit Euler (Eq. 2) needs h < c/ω² on every mode, and c/ω² ≥ min over springs of
    μ·l0/λ2 (+ c_env/ω²max), with h·c ≤ 2: without damping it is unstable at any step.
    The `support`'s ties (physics.tissue.organ_support) add at most max k_n/m_n to ω² and c_n/m_n to c (Weyl), and
    their c_n/k_n to the explicit bound's minimum.
    """
    axis = positions[springs.node_j] - positions[springs.node_i]
    unit = axis / np.linalg.norm(axis, axis=1)[:, None]
    scale = 1.0 / np.sqrt(np.repeat(masses_kg, 3))
    omega2 = _largest_eigenvalue(springs, unit, springs.lambda2_n / springs.rest_length_m, scale)
    c = _largest_eigenvalue(springs, unit, springs.mu_ns_per_m, scale) + environment_damping_per_s
    return _time_step(springs, omega2, c, environment_damping_per_s, integrator, masses_kg, support)


def estimate_stable_time_step(springs: SpringNetwork, masses_kg: np.ndarray, environment_damping_per_s: float,
                              integrator: str, positions: np.ndarray, max_iterations: int = 400,
                              tolerance: float = 1e-2, support: SupportArrays | None = None) -> float:
    """stable_time_step's bound (s) with λmax from a matrix-free power iteration (fast; for topology changes).

    λmax is the larger of ρ + ‖A·v − ρ·v‖ (Rayleigh quotient plus residual of the iterate, started from a
    fixed random vector: within that of an eigenvalue, the largest once converged) and the stiffest
    two-node spring, coefficient·(1/m_i + 1/m_j) (a lower bound of λmax that catches a short spring a
    cut or a tear just made before the iteration has found its mode).
    """
    axis = positions[springs.node_j] - positions[springs.node_i]
    unit = np.ascontiguousarray(axis / np.linalg.norm(axis, axis=1)[:, None])
    scale = 1.0 / np.sqrt(masses_kg)
    pair = 1.0 / masses_kg[springs.node_i] + 1.0 / masses_kg[springs.node_j]
    modes = np.random.default_rng(0).standard_normal((2, len(masses_kg), 3))
    estimates = []
    for coefficient, mode in ((springs.lambda2_n / springs.rest_length_m, modes[0]), (springs.mu_ns_per_m, modes[1])):
        iterated = _power_iteration(springs.node_i, springs.node_j, unit, coefficient, scale, mode, max_iterations,
                                    tolerance)
        estimates.append(max(iterated, float((coefficient * pair).max()) if len(pair) else 0.0))
    omega2, c = estimates
    return _time_step(springs, omega2, c + environment_damping_per_s, environment_damping_per_s, integrator,
                      masses_kg, support)


def _time_step(springs: SpringNetwork, omega2: float, c: float, environment_damping_per_s: float,
               integrator: str, masses_kg: np.ndarray, support: SupportArrays | None) -> float:
    """The integrator's stable step (s) for largest ω² and damping rate c of the springs, with the support's
    ties added (see stable_time_step)."""
    ratios = [np.inf]
    if support is not None and len(support.nodes):
        mass = masses_kg[support.nodes]
        omega2 += float((support.stiffness_n_per_m / mass).max())
        c += float((support.damping_ns_per_m / mass).max())
        ratios.append(float((support.damping_ns_per_m / np.maximum(support.stiffness_n_per_m, 1e-300)).min()))
    if omega2 <= 0.0:
        return math.inf
    if integrator == "explicit_euler":
        stiffness = springs.lambda2_n / springs.rest_length_m
        ratio = np.divide(springs.mu_ns_per_m, stiffness, out=np.full(len(stiffness), np.inf), where=stiffness > 0)
        return min(min(float(ratio.min()), *ratios) + environment_damping_per_s / omega2,
                   2.0 / c if c > 0.0 else math.inf)
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


@numba.njit(cache=True)
def _apply_scaled(node_i, node_j, unit, coefficient, scale, v, out):
    """out = M^-1/2·A·M^-1/2·v for A = Σ coefficient·(e_i − e_j)(e_i − e_j)ᵀ ⊗ u·uᵀ."""
    out[:] = 0.0
    for s in range(len(node_i)):
        i, j = node_i[s], node_j[s]
        si, sj = scale[i], scale[j]
        d = 0.0
        for a in range(3):
            d += (si * v[i, a] - sj * v[j, a]) * unit[s, a]
        t = coefficient[s] * d
        ti, tj = si * t, sj * t
        for a in range(3):
            out[i, a] += ti * unit[s, a]
            out[j, a] -= tj * unit[s, a]


@numba.njit(cache=True)
def _power_iteration(node_i, node_j, unit, coefficient, scale, v, max_iterations, tolerance):
    """Power iteration on M^-1/2·A·M^-1/2 from v (overwritten by the mode); returns ρ + residual."""
    y = np.empty_like(v)
    flat_v, flat_y = v.reshape(-1), y.reshape(-1)
    flat_v /= max(math.sqrt(np.dot(flat_v, flat_v)), 1e-300)
    bound = 0.0
    for _ in range(max_iterations):
        _apply_scaled(node_i, node_j, unit, coefficient, scale, v, y)
        rho = np.dot(flat_v, flat_y)
        norm2 = np.dot(flat_y, flat_y)
        if norm2 == 0.0:
            return 0.0
        residual = math.sqrt(max(norm2 - rho * rho, 0.0))
        bound = rho + residual
        flat_v[:] = flat_y / math.sqrt(norm2)
        if residual <= tolerance * rho:
            break
    return bound
