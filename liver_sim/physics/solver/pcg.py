"""Preconditioned conjugate gradients, matrix-free, on the implicit step's system A = M − h·D − h²·K
(physics.solver.implicit_kernels): A·p, the preconditioners, the solve.  The operator's parts: the springs (u, iso,
axial per spring: physics.tissue.spring_law.spring_apply), the tetrahedra of the 'fem' or 'neo_hookean' law
(physics.tissue.fem_kernels, none with the springs' law), the contacts.

The solve starts from the previous step's Δv and stops at ‖r‖ ≤ cg_tolerance·‖b‖ (default 1e-3; the Newton residual
check guards the result).  Preconditioner: block-Jacobi (the 3×3 diagonal blocks, contacts included), and on larger
livers the additive two-level one, block-Jacobi plus a coarse correction on rigid aggregates of nodes
(physics.solver.coarse_space), which keeps the iterations nearly flat as the mesh is refined (docs/performance.md, "The
physics", for the iterations and costs).  Why this solver: the values change at every step (the axes turn,
the
cubic law stiffens, contacts come and go), so a sparse factorisation would be redone each step (SuperLU: 20–70× the
cost of the solve), and matrix-free beats a block CSR pattern because it reads 5 numbers per spring instead of 36.
The coarse matrix, small and dense, is factored once per topology and step length: a preconditioner need not follow
the values exactly to leave the answer unchanged.
"""
from __future__ import annotations

import numba
import numpy as np

from liver_sim.physics.solver.coarse_space import coarse_correction
from liver_sim.physics.tissue.fem_kernels import tet_apply
from liver_sim.physics.tissue.spring_law import spring_apply

#: The `partial` of a serial solve: no per-thread slices, one chunk.
SERIAL = np.zeros((1, 0, 3))


@numba.njit(cache=True, inline="always")
def _chunk(c, chunks, count):
    """The range (first, last) of chunk c of `count` items cut into `chunks`."""
    return c * count // chunks, (c + 1) * count // chunks


@numba.njit(cache=True, inline="always")
def _apply(op, inv_mass, rows, tet_law, tet_weight, p, out, partial):
    """out = A·p (see `apply`).  With `partial` of (chunks > 1, N, 3), the springs and tetrahedra in `chunks` chunks
    on the threads, each into its own slice, summed per node after shift·p in chunk order (no atomics; the same
    sums whatever thread runs a chunk)."""
    chunks = partial.shape[0]
    shift, nodes, weights, normal, coefficient = op.shift, rows.nodes, rows.weights, rows.normal, rows.coefficient
    springs, elements = op.node_i.shape[0], tet_law.tets.shape[0]
    if chunks <= 1:
        for n in range(p.shape[0]):
            for a in range(3):
                out[n, a] = shift[n] * p[n, a]
        spring_apply(op, p, 0, springs, out)
        tet_apply(tet_law, tet_weight, p, 0, elements, out)
    else:
        for c in numba.prange(chunks):
            own = partial[c]
            own[:] = 0.0
            first, last = _chunk(c, chunks, springs)
            spring_apply(op, p, first, last, own)
            first, last = _chunk(c, chunks, elements)
            tet_apply(tet_law, tet_weight, p, first, last, own)
        for n in numba.prange(p.shape[0]):
            for a in range(3):
                total = shift[n] * p[n, a]
                for c in range(chunks):
                    total += partial[c, n, a]
                out[n, a] = total
    for e in range(nodes.shape[0]):
        if coefficient[e] == 0.0:
            continue
        nx, ny, nz = normal[e, 0], normal[e, 1], normal[e, 2]
        q = 0.0
        for a in range(3):
            n = nodes[e, a]
            if n >= 0:
                q += weights[e, a] * (nx * p[n, 0] + ny * p[n, 1] + nz * p[n, 2])
        q *= coefficient[e]
        for a in range(3):
            n = nodes[e, a]
            if n >= 0:
                g = weights[e, a] * q
                out[n, 0] += g * nx
                out[n, 1] += g * ny
                out[n, 2] += g * nz
    for n in range(p.shape[0]):
        if inv_mass[n] == 0.0:
            for a in range(3):
                out[n, a] = 0.0


@numba.njit(cache=True)
def apply(op, inv_mass, rows, tet_law, tet_weight, p, out):
    """out = A·p, matrix-free (`op` a records.Operator, `rows` a records.ContactRows): shift·p, each spring's
    B·(p_i − p_j) to i and its opposite to j, the tetrahedra of a continuum law (`tet_law`, a fem_kernels.TetArrays,
    scaled by `tet_weight` = h² + h·τ; fem_kernels.tet_apply) and the active contacts' (h·c + h²·k)·w_a·w_b·nnᵀ.
    p must vanish on held nodes; out does there too."""
    _apply(op, inv_mass, rows, tet_law, tet_weight, p, out, np.zeros((1, 0, 3)))


@numba.njit(cache=True, nogil=True)
def block_jacobi(diagonal, inv_mass, rows, inverse):
    """inverse[n] = (A_nn + Σ diagonal blocks of the contact `rows`, records.ContactRows)⁻¹ (3×3, symmetric positive
    definite)."""
    nodes, weights, normal, coefficient = rows.nodes, rows.weights, rows.normal, rows.coefficient
    inverse[:] = diagonal
    for e in range(nodes.shape[0]):
        if coefficient[e] == 0.0:
            continue
        for a in range(3):
            n = nodes[e, a]
            if n >= 0 and inv_mass[n] > 0.0:
                g = coefficient[e] * weights[e, a] * weights[e, a]
                for r in range(3):
                    for c in range(3):
                        inverse[n, r, c] += g * normal[e, r] * normal[e, c]
    for n in range(diagonal.shape[0]):
        _invert_symmetric(inverse[n])


@numba.njit(cache=True, inline="always")
def _invert_symmetric(a):
    """a ← a⁻¹ for a symmetric positive definite 3×3 block (cofactors)."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[1, 2]
    c01 = a[0, 2] * a[1, 2] - a[0, 1] * a[2, 2]
    c02 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[0, 2]
    c12 = a[0, 1] * a[0, 2] - a[0, 0] * a[1, 2]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[0, 1]
    scale = 1.0 / (a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02)
    a[0, 0], a[0, 1], a[0, 2] = c00 * scale, c01 * scale, c02 * scale
    a[1, 0], a[1, 1], a[1, 2] = c01 * scale, c11 * scale, c12 * scale
    a[2, 0], a[2, 1], a[2, 2] = c02 * scale, c12 * scale, c22 * scale


@numba.njit(cache=True, inline="always")
def _block_jacobi_node(preconditioner, r, z, n, rz):
    """z[n] ← D⁻¹_n·r[n]; returns rz + r[n]·z[n], added term by term."""
    for a in range(3):
        z[n, a] = (preconditioner[n, a, 0] * r[n, 0] + preconditioner[n, a, 1] * r[n, 1]
                   + preconditioner[n, a, 2] * r[n, 2])
        rz += r[n, a] * z[n, a]
    return rz


@numba.njit(cache=True, inline="always")
def _dot(u, w, chunks, sums):
    """u·w over (N, 3) arrays, node chunk by node chunk (each chunk's sum in order, then the chunks' in order)."""
    count = u.shape[0]
    for c in numba.prange(chunks):
        first, last = _chunk(c, chunks, count)
        total = 0.0
        for n in range(first, last):
            for a in range(3):
                total += u[n, a] * w[n, a]
        sums[c, 0] = total
    total = 0.0
    for c in range(chunks):
        total += sums[c, 0]
    return total


#: The fields of a resumable solve's `status` (4,): r·z, ‖r‖², the target ‖r‖² and whether it has ended (1.0:
#: converged, or stopped where pᵀA·p ≤ 0).
RZ, R_NORM2, TARGET, ENDED = 0, 1, 2, 3


@numba.njit(cache=True, inline="always")
def _pcg_start(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, vectors, partial,
               status):
    """The start of a solve from z0: r = b − A·z0, z = P⁻¹·r, p = z, and `status` (RZ … ENDED)."""
    r, z, p, q = vectors
    two_level = coarse.factor.shape[0] > 0
    chunks = partial.shape[0]
    count = b.shape[0]
    sums = np.zeros((chunks, 2))
    _apply(op, inv_mass, rows, tet_law, tet_weight, z0, q, partial)
    for n in range(count):
        for a in range(3):
            r[n, a] = b[n, a] - q[n, a]
    target = tolerance * tolerance * _dot(b, b, chunks, sums)
    for c in numba.prange(chunks):
        first, last = _chunk(c, chunks, count)
        rz, r_norm2 = 0.0, 0.0
        for n in range(first, last):
            rz = _block_jacobi_node(preconditioner, r, z, n, rz)
            for a in range(3):
                r_norm2 += r[n, a] * r[n, a]
        sums[c, 0], sums[c, 1] = rz, r_norm2
    rz, r_norm2 = 0.0, 0.0
    for c in range(chunks):
        rz += sums[c, 0]
        r_norm2 += sums[c, 1]
    if two_level:
        coarse_correction(coarse, inv_mass, r, z)
        rz = _dot(r, z, chunks, sums)
    p[:] = z
    status[RZ], status[R_NORM2], status[TARGET] = rz, r_norm2, target
    status[ENDED] = 1.0 if r_norm2 <= target else 0.0


@numba.njit(cache=True, inline="always")
def _pcg_steps(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, z0, steps, vectors, partial, status):
    """Up to `steps` iterations of a started solve (`_pcg_start`), z0 its iterate, until it ends; `status` carried
    from one call to the next.  Returns the iterations made."""
    r, z, p, q = vectors
    two_level = coarse.factor.shape[0] > 0
    chunks = partial.shape[0]
    count = z0.shape[0]
    sums = np.zeros((chunks, 2))
    rz, r_norm2, target = status[RZ], status[R_NORM2], status[TARGET]
    iterations = 0
    while r_norm2 > target and iterations < steps:
        _apply(op, inv_mass, rows, tet_law, tet_weight, p, q, partial)
        pq = _dot(p, q, chunks, sums)
        if pq <= 0.0:
            status[ENDED] = 1.0
            break
        alpha = rz / pq
        for c in numba.prange(chunks):
            first, last = _chunk(c, chunks, count)
            r_norm2, rz_new = 0.0, 0.0
            for n in range(first, last):
                for a in range(3):
                    z0[n, a] += alpha * p[n, a]
                    r[n, a] -= alpha * q[n, a]
                    r_norm2 += r[n, a] * r[n, a]
                rz_new = _block_jacobi_node(preconditioner, r, z, n, rz_new)
            sums[c, 0], sums[c, 1] = r_norm2, rz_new
        r_norm2, rz_new = 0.0, 0.0
        for c in range(chunks):
            r_norm2 += sums[c, 0]
            rz_new += sums[c, 1]
        if two_level:
            coarse_correction(coarse, inv_mass, r, z)
            rz_new = _dot(r, z, chunks, sums)
        beta = rz_new / rz
        rz = rz_new
        for n in numba.prange(count):
            for a in range(3):
                p[n, a] = z[n, a] + beta * p[n, a]
        iterations += 1
    status[RZ], status[R_NORM2] = rz, r_norm2
    if r_norm2 <= target:
        status[ENDED] = 1.0
    return iterations


@numba.njit(cache=True, inline="always")
def _pcg(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors, partial):
    """`pcg`'s solve: its start and its iterations; the products (`_apply`) and the vector updates in
    partial.shape[0] chunks of springs, elements and nodes (prange: on the threads of a parallel dispatcher, in order
    in a serial one)."""
    status = np.zeros(4)
    _pcg_start(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings.cg_tolerance, vectors,
               partial, status)
    return _pcg_steps(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, z0,
                      settings.max_cg_iterations, vectors, partial, status)


@numba.njit(cache=True)
def pcg(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors, partial):
    """Solve A·z = b by preconditioned conjugate gradients from z0 (overwritten by z): block-Jacobi, plus the
    coarse correction of `coarse` (a coarse_space.CoarseSpace; none: block-Jacobi alone); stops when
    ‖r‖ ≤ cg_tolerance·‖b‖ or after max_cg_iterations (`settings`, records.SolveSettings); `vectors` (r, z, p, q)
    (N, 3) each, scratch.  Returns the iterations used.  One thread, `partial` SERIAL (`pcg_parallel`: on the
    threads).  With SERIAL its sums run node by node in order."""
    return _pcg(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors, partial)


@numba.njit(cache=True, parallel=True)
def pcg_parallel(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors, partial):
    """`pcg` on the threads: springs, elements and nodes in partial.shape[0] chunks, `partial` (chunks, N, 3) the
    chunks' own sums of A·p.  The sums' order depends on the chunks alone, so a run repeats itself bit for bit with
    the same thread count; against `pcg` it differs by rounding."""
    return _pcg(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors, partial)


@numba.njit(cache=True, nogil=True)
def pcg_resumable(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, start, steps,
                  vectors, partial, status):
    """`pcg`'s solve in slices: with `start`, begin it from z0 (`status` (4,), RZ … ENDED, is then set); then up to
    `steps` iterations, z0 the iterate, `vectors` and `status` kept by the caller from one slice to the next.  The
    slices make the same iterations, in the same order, as one `pcg` call.  Returns the iterations made."""
    if start:
        _pcg_start(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, vectors,
                   partial, status)
    return _pcg_steps(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, z0, steps, vectors, partial,
                      status)


@numba.njit(cache=True, parallel=True, nogil=True)
def pcg_resumable_parallel(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, start,
                           steps, vectors, partial, status):
    """`pcg_resumable` on the threads (as `pcg_parallel`)."""
    if start:
        _pcg_start(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, vectors,
                   partial, status)
    return _pcg_steps(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, z0, steps, vectors, partial,
                      status)
