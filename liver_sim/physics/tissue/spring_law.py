"""The paper's spring (Eq. 1) as a tissue law with its kernels, in the shape of the continuum law
(physics.tissue.fem_kernels): forces, terms of the implicit system, and the system's product.

Per connector i→j of rest length l0 (`SpringArrays`, one per edge): length l, unit axis u = (x_j − x_i)/l,
strain d = l/l0 − 1, rate ḋ = (v_j − v_i)·u; tension T = λ1·d³ + λ2·d + μ·ḋ (N, 0 for a collapsed spring);
+T·u on node i and −T·u on node j.

Its tangent stiffness Ks = (dT/dl)·uuᵀ + (T⁺/l)·(I − uuᵀ), dT/dl = (3·λ1·d² + λ2)/l0, and damping μ·uuᵀ: K gets −Ks
on (i,i), (j,j) and +Ks on (i,j), (j,i), D likewise with μ·uuᵀ.  The geometric term uses the elastic tension
T⁺ = max(λ1·d³ + λ2·d, 0): a compressed spring's negative geometric stiffness is dropped, so every block of
A = M − h·D − h²·K is positive semi-definite (the usual safeguard; the implicit step's residual check corrects what it
omits), and the viscous tension's own x-derivative (non-symmetric) is omitted likewise.  In A a spring is the block
B = iso·I + axial·uuᵀ, iso = h²·T⁺/l, axial = h²·(dT/dl − T⁺/l) + h·μ, entering (i,i) and (j,j) as +B and (i,j),
(j,i) as −B.  Held nodes (inv_mass 0) keep y = 0 and get no block (physics.solver.implicit).

Arrays: positions `x` and velocities `v` (N, 3) float64 in m and m/s; forces added to `f` (N, 3) in newtons.  The
serial and the parallel force kernels are separate functions (a cached dispatcher must never be shared between a
`parallel=True` and a serial build).  `liver_sim.physics.solver.reference` is the plain-NumPy oracle of the forces.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from liver_sim.physics.tissue.pairs import add_pair


class SpringArrays(NamedTuple):
    """One Eq. 1 connector per edge for the kernels: end nodes `node_i`, `node_j` (E,) integers, 1/l0
    `inv_rest_per_m` (E,) 1/m, λ1 `lambda1_n` and λ2 `lambda2_n` (E,) N, μ `mu_ns_per_m` (E,) N·s/m."""

    node_i: np.ndarray
    node_j: np.ndarray
    inv_rest_per_m: np.ndarray
    lambda1_n: np.ndarray
    lambda2_n: np.ndarray
    mu_ns_per_m: np.ndarray

    def taken(self, order: np.ndarray) -> "SpringArrays":
        """The same springs in `order` (a permutation of their indices)."""
        return SpringArrays(*(np.ascontiguousarray(a[order]) for a in self))


def spring_arrays(springs, node_i: np.ndarray | None = None, node_j: np.ndarray | None = None) -> SpringArrays:
    """The kernels' record of a physics.tissue.springs.SpringNetwork, with its own end nodes unless `node_i`,
    `node_j` are given (the same nodes in another integer type)."""
    return SpringArrays(springs.node_i if node_i is None else node_i, springs.node_j if node_j is None else node_j,
                        1.0 / springs.rest_length_m, springs.lambda1_n, springs.lambda2_n, springs.mu_ns_per_m)


@numba.njit(cache=True, inline="always")
def _axis(x, i, j, inv_rest):
    """(l, 1/l, u) of the connector i→j; l = 0 for a collapsed one (l/l0 ≤ 1e-12), which carries nothing."""
    ux = x[j, 0] - x[i, 0]
    uy = x[j, 1] - x[i, 1]
    uz = x[j, 2] - x[i, 2]
    length = math.sqrt(ux * ux + uy * uy + uz * uz)
    if length * inv_rest <= 1e-12:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    inv_length = 1.0 / length
    return length, inv_length, ux * inv_length, uy * inv_length, uz * inv_length


@numba.njit(cache=True, inline="always")
def _rate(v, i, j, ux, uy, uz):
    """ḋ's numerator: (v_j − v_i)·u (m/s)."""
    return (v[j, 0] - v[i, 0]) * ux + (v[j, 1] - v[i, 1]) * uy + (v[j, 2] - v[i, 2]) * uz


@numba.njit(cache=True, inline="always")
def _elastic(law, s, d):
    """λ1·d³ + λ2·d (N) of spring s at strain d."""
    return law.lambda1_n[s] * d * d * d + law.lambda2_n[s] * d


@numba.njit(cache=True, inline="always")
def accumulate_forces(x, v, law, first, last, f):
    """Add the Eq. 1 forces of springs first..last−1 to f: +T·u on node i, −T·u on node j."""
    for s in range(first, last):
        i, j = law.node_i[s], law.node_j[s]
        inv_rest = law.inv_rest_per_m[s]
        length, _, ux, uy, uz = _axis(x, i, j, inv_rest)
        if length == 0.0:
            continue
        t = _elastic(law, s, length * inv_rest - 1.0) + law.mu_ns_per_m[s] * _rate(v, i, j, ux, uy, uz)
        add_pair(f, i, j, t * ux, t * uy, t * uz)


@numba.njit(cache=True)
def spring_forces_serial(x, v, law, f):
    """Add every spring's Eq. 1 force to f (one thread)."""
    accumulate_forces(x, v, law, 0, law.node_i.shape[0], f)


@numba.njit(cache=True, parallel=True)
def spring_forces_parallel(x, v, law, partial, f):
    """As spring_forces_serial, on all threads: each of the len(partial) chunks of springs
    accumulates into its own (N, 3) slice of `partial`, then the slices are summed into f."""
    chunks = partial.shape[0]
    springs = law.node_i.shape[0]
    for c in numba.prange(chunks):
        own = partial[c]
        own[:] = 0.0
        accumulate_forces(x, v, law, c * springs // chunks, (c + 1) * springs // chunks, own)
    for n in numba.prange(f.shape[0]):
        for c in range(chunks):
            f[n, 0] += partial[c, n, 0]
            f[n, 1] += partial[c, n, 1]
            f[n, 2] += partial[c, n, 2]


@numba.njit(cache=True)
def spring_terms(x, v, y, inv_mass, h, law, op, f, ky, assemble_matrix, first, last):
    """Add the forces at (x, v) of springs first..last−1 to f and K·y to ky (y zero on held nodes); with
    assemble_matrix, also their part of A (module docstring) into `op` (the solver's records.Operator): each spring's
    axis `unit`, `iso`, `axial`, and its block B added to the `diagonal` blocks of its free nodes."""
    unit, iso, axial, diagonal = op.unit, op.iso, op.axial, op.diagonal
    for s in range(first, last):
        i, j = law.node_i[s], law.node_j[s]
        inv_l0 = law.inv_rest_per_m[s]
        length, inv_length, ux, uy, uz = _axis(x, i, j, inv_l0)
        if length == 0.0:
            if assemble_matrix:
                iso[s] = 0.0
                axial[s] = 0.0
            continue
        rate = _rate(v, i, j, ux, uy, uz)
        d = length * inv_l0 - 1.0
        elastic = _elastic(law, s, d)
        tension = elastic + law.mu_ns_per_m[s] * rate
        material = (3.0 * law.lambda1_n[s] * d * d + law.lambda2_n[s]) * inv_l0
        geometric = max(elastic, 0.0) * inv_length
        free_i = inv_mass[i] > 0.0
        free_j = inv_mass[j] > 0.0
        # Ks·(y_j − y_i), y zero on held nodes
        dx = (y[j, 0] if free_j else 0.0) - (y[i, 0] if free_i else 0.0)
        dy = (y[j, 1] if free_j else 0.0) - (y[i, 1] if free_i else 0.0)
        dz = (y[j, 2] if free_j else 0.0) - (y[i, 2] if free_i else 0.0)
        along = (material - geometric) * (dx * ux + dy * uy + dz * uz)
        kx = geometric * dx + along * ux
        ky_ = geometric * dy + along * uy
        kz = geometric * dz + along * uz
        add_pair(f, i, j, tension * ux, tension * uy, tension * uz)
        add_pair(ky, i, j, kx, ky_, kz)
        if not assemble_matrix:
            continue
        unit[s, 0], unit[s, 1], unit[s, 2] = ux, uy, uz
        g = h * h * geometric
        t = h * h * (material - geometric) + h * law.mu_ns_per_m[s]
        iso[s] = g
        axial[s] = t
        bxx, byy, bzz = t * ux * ux + g, t * uy * uy + g, t * uz * uz + g
        bxy, bxz, byz = t * ux * uy, t * ux * uz, t * uy * uz
        for n, free in ((i, free_i), (j, free_j)):
            if free:
                diagonal[n, 0, 0] += bxx
                diagonal[n, 1, 1] += byy
                diagonal[n, 2, 2] += bzz
                diagonal[n, 0, 1] += bxy
                diagonal[n, 1, 0] += bxy
                diagonal[n, 0, 2] += bxz
                diagonal[n, 2, 0] += bxz
                diagonal[n, 1, 2] += byz
                diagonal[n, 2, 1] += byz


@numba.njit(cache=True, inline="always")
def spring_apply(op, p, first, last, out):
    """out += each spring's B·(p_i − p_j) to i and its opposite to j, B = iso·I + axial·uuᵀ (the solver's
    records.Operator, as spring_terms left it), springs first..last−1."""
    node_i, node_j, unit, iso, axial = op.node_i, op.node_j, op.unit, op.iso, op.axial
    for s in range(first, last):
        i, j = node_i[s], node_j[s]
        dx = p[i, 0] - p[j, 0]
        dy = p[i, 1] - p[j, 1]
        dz = p[i, 2] - p[j, 2]
        ux, uy, uz = unit[s, 0], unit[s, 1], unit[s, 2]
        g = iso[s]
        t = axial[s] * (ux * dx + uy * dy + uz * dz)
        bx, by, bz = g * dx + t * ux, g * dy + t * uy, g * dz + t * uz
        add_pair(out, i, j, bx, by, bz)
