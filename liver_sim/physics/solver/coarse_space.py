"""The coarse space of the implicit step's two-level preconditioner (physics.solver.pcg): aggregates of nearby nodes,
each moving rigidly, and the Cholesky factor of the step's system restricted to their motions.

Node n of aggregate a moves by t_a + ω_a × d_n (d_n its offset from the aggregate's centroid): T, the (3N × 6C) map
from the C aggregates' translations and rotations to node displacements, T_n = [I | −[d_n]×].  With F the zeroing of
held nodes (inv_mass 0) and D⁻¹ the block-Jacobi inverse, the preconditioner is the additive two-level one

    z = D⁻¹·r + F·T·A_c⁻¹·Tᵀ·F·r,   A_c = Tᵀ·F·A·F·T,

symmetric positive definite whatever SPD A_c is, so PCG stays conjugate gradients and its answer stays the one the
tolerance allows; the nearer A_c is to the system's, the fewer iterations.  A_c is assembled from the system of the
state it is first needed at (matrix-free arrays of physics.solver.implicit_kernels and the tetrahedra of
physics.tissue.fem_kernels;
contacts left out) and kept for the topology and step length: the system's values change little from step to step.
Aggregates: from each node not yet taken, in node order, every node within `hops` edges not yet taken (a greedy
graph aggregation); `hops` the least that leaves at most TARGET_AGGREGATES aggregates.
"""
from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

#: The most aggregates a coarse space is built with: its dense solve costs (6C)² per iteration, and more aggregates
#: save few iterations (docs/performance.md, "The physics").
TARGET_AGGREGATES = 64
#: Rigid motions per aggregate: three translations, three rotations.
MODES = 6


class CoarseSpace(NamedTuple):
    """The coarse space for the kernels: `aggregate` (N,) int64 per node, `offset_m` (N, 3) its offset from its
    aggregate's centroid, `factor` (6C, 6C) the lower Cholesky factor of A_c ((0, 0): none, block-Jacobi alone), and
    `work` (6C,) scratch."""

    aggregate: np.ndarray
    offset_m: np.ndarray
    factor: np.ndarray
    work: np.ndarray

    @classmethod
    def none(cls) -> "CoarseSpace":
        """No coarse space: the preconditioner is block-Jacobi alone."""
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 0)), np.zeros(0))

    @property
    def aggregates(self) -> int:
        return self.factor.shape[0] // MODES


def node_graph(n_nodes: int, *edge_lists: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(indptr, indices): the CSR adjacency of the nodes joined by the (E, 2) `edge_lists`, both ways."""
    pairs = np.concatenate([np.asarray(e, np.int64).reshape(-1, 2) for e in edge_lists])
    heads = np.concatenate([pairs[:, 0], pairs[:, 1]])
    tails = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.lexsort((tails, heads))
    heads, tails = heads[order], tails[order]
    indptr = np.zeros(n_nodes + 1, np.int64)
    np.cumsum(np.bincount(heads, minlength=n_nodes), out=indptr[1:])
    return indptr, np.ascontiguousarray(tails)


@numba.njit(cache=True)
def _aggregate(indptr, indices, hops):
    """(aggregate per node, count): from each node not yet taken, in order, every node within `hops` edges of it
    (through any node) not yet taken."""
    n = indptr.shape[0] - 1
    aggregate = np.full(n, -1, np.int64)
    visited = np.full(n, -1, np.int64)
    queue = np.empty(n, np.int64)
    depth = np.empty(n, np.int64)
    count = 0
    for seed in range(n):
        if aggregate[seed] >= 0:
            continue
        aggregate[seed] = count
        visited[seed] = seed
        queue[0], depth[0] = seed, 0
        head, tail = 0, 1
        while head < tail:
            node, d = queue[head], depth[head]
            head += 1
            if d == hops:
                continue
            for k in range(indptr[node], indptr[node + 1]):
                m = indices[k]
                if visited[m] == seed:
                    continue
                visited[m] = seed
                if aggregate[m] < 0:
                    aggregate[m] = count
                queue[tail], depth[tail] = m, d + 1
                tail += 1
        count += 1
    return aggregate, count


def aggregates(indptr: np.ndarray, indices: np.ndarray, target: int = TARGET_AGGREGATES) -> np.ndarray:
    """The aggregate of each node (module docstring): the fewest hops leaving at most `target` aggregates."""
    hops = 1
    while True:
        aggregate, count = _aggregate(indptr, indices, hops)
        if count <= target or hops >= len(indptr):
            return aggregate
        hops += 1


@numba.njit(cache=True, inline="always")
def _rotations(dx, dy, dz, m):
    """m ← M(d) = −[d]×, the rotations' columns of T_n = [I | M(d_n)]: column k the displacement e_k × d."""
    m[0, 0], m[0, 1], m[0, 2] = 0.0, dz, -dy
    m[1, 0], m[1, 1], m[1, 2] = -dz, 0.0, dx
    m[2, 0], m[2, 1], m[2, 2] = dy, -dx, 0.0


@numba.njit(cache=True, inline="always")
def _add_block(matrix, a, ma, b, mb, block, scale, work):
    """matrix[6a:6a+6, 6b:6b+6] += scale·T_aᵀ·block·T_b, T = [I | M] (`ma`, `mb` the M of its two nodes):
    [[B, B·M_b], [M_aᵀ·B, M_aᵀ·B·M_b]]; `work` (3, 3) scratch."""
    ra, rb = MODES * a, MODES * b
    for r in range(3):
        for c in range(3):
            work[r, c] = block[r, 0] * mb[0, c] + block[r, 1] * mb[1, c] + block[r, 2] * mb[2, c]
    for r in range(3):
        for c in range(3):
            matrix[ra + r, rb + c] += scale * block[r, c]
            matrix[ra + r, rb + 3 + c] += scale * work[r, c]
            matrix[ra + 3 + r, rb + c] += scale * (ma[0, r] * block[0, c] + ma[1, r] * block[1, c]
                                                   + ma[2, r] * block[2, c])
            matrix[ra + 3 + r, rb + 3 + c] += scale * (ma[0, r] * work[0, c] + ma[1, r] * work[1, c]
                                                       + ma[2, r] * work[2, c])


@numba.njit(cache=True, inline="always")
def _add_rotations(matrix, a, m, block, work):
    """matrix's rotations of aggregate a += Mᵀ·block·M: a spring within the aggregate, whose four blocks add up to
    (T_i − T_j)ᵀ·B·(T_i − T_j) with T_i − T_j = [0 | M(d_i − d_j)]; `work` (3, 3) scratch."""
    ra = MODES * a + 3
    for r in range(3):
        for c in range(3):
            work[r, c] = block[r, 0] * m[0, c] + block[r, 1] * m[1, c] + block[r, 2] * m[2, c]
    for r in range(3):
        for c in range(3):
            matrix[ra + r, ra + c] += m[0, r] * work[0, c] + m[1, r] * work[1, c] + m[2, r] * work[2, c]


@numba.njit(cache=True)
def coarse_matrix(node_i, node_j, unit, iso, axial, shift, inv_mass, tet_law, tet_weight, aggregate, offset, count):
    """A_c = Tᵀ·F·A·F·T (6·count square) of the system's matrix-free form (pcg.apply's arrays, contacts left out):
    shift·I on free nodes, each spring's ±B = iso·I + axial·uuᵀ, each tetrahedron's weight·V·(λ·h_a·h_bᵀ +
    μ·h_b·h_aᵀ + μ·(h_a·h_b)·I) between its free nodes a, b (h = R·g, fem_kernels)."""
    matrix = np.zeros((MODES * count, MODES * count))
    ma = np.empty((3, 3))
    mb = np.empty((3, 3))
    block = np.empty((3, 3))
    work = np.empty((3, 3))
    for n in range(shift.shape[0]):
        if inv_mass[n] > 0.0:
            _rotations(offset[n, 0], offset[n, 1], offset[n, 2], ma)
            block[:] = 0.0
            for i in range(3):
                block[i, i] = shift[n]
            _add_block(matrix, aggregate[n], ma, aggregate[n], ma, block, 1.0, work)
    for s in range(node_i.shape[0]):
        i, j = node_i[s], node_j[s]
        for r in range(3):
            for c in range(3):
                block[r, c] = axial[s] * unit[s, r] * unit[s, c]
            block[r, r] += iso[s]
        free_i, free_j = inv_mass[i] > 0.0, inv_mass[j] > 0.0
        if free_i and free_j and aggregate[i] == aggregate[j]:
            _rotations(offset[i, 0] - offset[j, 0], offset[i, 1] - offset[j, 1], offset[i, 2] - offset[j, 2], ma)
            _add_rotations(matrix, aggregate[i], ma, block, work)
            continue
        _rotations(offset[i, 0], offset[i, 1], offset[i, 2], ma)
        _rotations(offset[j, 0], offset[j, 1], offset[j, 2], mb)
        if free_i:
            _add_block(matrix, aggregate[i], ma, aggregate[i], ma, block, 1.0, work)
        if free_j:
            _add_block(matrix, aggregate[j], mb, aggregate[j], mb, block, 1.0, work)
        if free_i and free_j:
            _add_block(matrix, aggregate[i], ma, aggregate[j], mb, block, -1.0, work)
            _add_block(matrix, aggregate[j], mb, aggregate[i], ma, block, -1.0, work)
    lam, mu = tet_law.lame_lambda_pa, tet_law.lame_mu_pa
    for e in range(tet_law.tets.shape[0]):
        tet, hg = tet_law.tets[e], tet_law.rotated_gradients[e]
        scale = tet_weight * tet_law.volume_m3[e]
        for a in range(4):
            na = tet[a]
            if inv_mass[na] == 0.0:
                continue
            _rotations(offset[na, 0], offset[na, 1], offset[na, 2], ma)
            for b in range(4):
                nb = tet[b]
                if inv_mass[nb] == 0.0:
                    continue
                _rotations(offset[nb, 0], offset[nb, 1], offset[nb, 2], mb)
                dot = hg[a, 0] * hg[b, 0] + hg[a, 1] * hg[b, 1] + hg[a, 2] * hg[b, 2]
                for r in range(3):
                    for c in range(3):
                        block[r, c] = lam * hg[a, r] * hg[b, c] + mu * hg[b, r] * hg[a, c]
                    block[r, r] += mu * dot
                _add_block(matrix, aggregate[na], ma, aggregate[nb], mb, block, scale, work)
    return matrix


def build_coarse_space(positions: np.ndarray, aggregate: np.ndarray, matrix_arrays: tuple) -> CoarseSpace:
    """The CoarseSpace of `aggregate` (per node) at `positions` (N, 3) m, its A_c from `matrix_arrays` (node_i, node_j,
    unit, iso, axial, shift, inv_mass, tet_law, tet_weight: the system as pcg.apply takes it).  Motions A_c does not
    see (an aggregate of held nodes, the rotations of one of a single node) get a diagonal of 1e-12 × its largest."""
    count = int(aggregate.max()) + 1 if len(aggregate) else 0
    sizes = np.bincount(aggregate, minlength=count).astype(np.float64)
    centroids = np.stack([np.bincount(aggregate, positions[:, k], count) for k in range(3)], axis=1) / sizes[:, None]
    offset = np.ascontiguousarray(positions - centroids[aggregate])
    matrix = coarse_matrix(*matrix_arrays, aggregate, offset, count)
    matrix[np.diag_indices_from(matrix)] += 1e-12 * max(float(np.abs(np.diag(matrix)).max(initial=0.0)), 1e-300)
    factor = cholesky(matrix)
    return CoarseSpace(aggregate, offset, factor, np.zeros(len(factor)))


@numba.njit(cache=True, inline="always")
def _dot4(u, w, count):
    """Σ_{j<count} u[j]·w[j] in four interleaved partial sums added as (s0 + s1) + (s2 + s3): an order fixed in the
    code, so the bits do not depend on the CPU's vector width."""
    s0 = s1 = s2 = s3 = 0.0
    j = 0
    while j + 4 <= count:
        s0 += u[j] * w[j]
        s1 += u[j + 1] * w[j + 1]
        s2 += u[j + 2] * w[j + 2]
        s3 += u[j + 3] * w[j + 3]
        j += 4
    while j < count:
        s0 += u[j] * w[j]
        j += 1
    return (s0 + s1) + (s2 + s3)


@numba.njit(cache=True)
def cholesky(matrix):
    """The lower triangular L of L·Lᵀ = `matrix` (symmetric positive definite), row by row (Cholesky–Banachiewicz,
    its sums `_dot4`'s), in one thread (a threaded LAPACK would contend with the loops for the cores).  ValueError
    when a pivot is not positive."""
    size = matrix.shape[0]
    factor = np.zeros_like(matrix)
    for i in range(size):
        for j in range(i + 1):
            total = _dot4(factor[i], factor[j], j)
            if j < i:
                factor[i, j] = (matrix[i, j] - total) / factor[j, j]
            else:
                pivot = matrix[i, i] - total
                if not pivot > 0.0:
                    raise ValueError("coarse matrix not positive definite")
                factor[i, i] = np.sqrt(pivot)
    return factor


@numba.njit(cache=True)
def cholesky_solve(factor, y):
    """y ← (L·Lᵀ)⁻¹·y for the lower triangular `factor` L: forward by its rows (`_dot4`), backward by the columns of
    Lᵀ (the rows of L), each y element updated in a fixed order: the bits do not depend on the CPU's vector width
    (no fastmath: the compiler may neither reassociate a sum nor fuse a product into it)."""
    size = y.shape[0]
    for i in range(size):
        y[i] = (y[i] - _dot4(factor[i], y, i)) / factor[i, i]
    for i in range(size - 1, -1, -1):
        y[i] /= factor[i, i]
        u = y[i]
        for j in range(i):
            y[j] -= factor[i, j] * u


@numba.njit(cache=True, inline="always")
def restrict(coarse, r, first, last, y):
    """y += Tᵀ·r over nodes first..last−1 (r vanishing on held nodes: Tᵀ·F·r), in node order: per aggregate its
    nodes' Σ r and Σ d × r."""
    aggregate, offset = coarse.aggregate, coarse.offset_m
    for n in range(first, last):
        k = MODES * aggregate[n]
        dx, dy, dz = offset[n, 0], offset[n, 1], offset[n, 2]
        rx, ry, rz = r[n, 0], r[n, 1], r[n, 2]
        y[k] += rx
        y[k + 1] += ry
        y[k + 2] += rz
        y[k + 3] += dy * rz - dz * ry
        y[k + 4] += dz * rx - dx * rz
        y[k + 5] += dx * ry - dy * rx


@numba.njit(cache=True, inline="always")
def prolong(coarse, w, n):
    """(T·w)_n = t_a + ω_a × d_n for node n of aggregate a, w (6C,) the aggregates' motions (zero it on held
    nodes: F)."""
    k = MODES * coarse.aggregate[n]
    dx, dy, dz = coarse.offset_m[n, 0], coarse.offset_m[n, 1], coarse.offset_m[n, 2]
    wx, wy, wz = w[k + 3], w[k + 4], w[k + 5]
    return w[k] + wy * dz - wz * dy, w[k + 1] + wz * dx - wx * dz, w[k + 2] + wx * dy - wy * dx


@numba.njit(cache=True, inline="always")
def coarse_solve(coarse, restricted):
    """w = A_c⁻¹·y into coarse.work, y = Σ of the `restricted` rows (chunks, 6C) in row order; returns y·w
    (= r·F·T·w, the coarse correction's part of r·z)."""
    y = coarse.work
    y[:] = 0.0
    for c in range(restricted.shape[0]):
        for k in range(y.shape[0]):
            y[k] += restricted[c, k]
    cholesky_solve(coarse.factor, y)
    total = 0.0
    for c in range(restricted.shape[0]):
        for k in range(y.shape[0]):
            total += restricted[c, k] * y[k]
    return total
