"""Preconditioned conjugate gradients, matrix-free, on the implicit step's system A = M − h·D − h²·K
(physics.solver.implicit_kernels): A·p, the preconditioners, the solve.  The operator's parts: the springs (u, iso,
axial per spring: physics.tissue.spring_law.spring_apply), the tetrahedra of the 'fem' or 'neo_hookean' law
(physics.tissue.fem_kernels, none with the springs' law), the contacts.

The sums' order is fixed in the code, whatever the threads, so one thread and several give the same bits: A·p adds
the springs and elements group by group (physics.solver.partition), and every pass over the nodes runs in NODE_CHUNKS
chunks whose sums are added in chunk order.  An iteration: A·p with p·q; the update of z0 and r with z = D⁻¹·r, ‖r‖²,
r·z and the coarse restriction, in one pass; the coarse solve; the prolongation with the update of p, in one pass.

The solve starts from the previous step's Δv and stops at ‖r‖ ≤ max(cg_tolerance·‖b‖, cg_floor_ns) (the relative
tolerance 1e-3 by default, and an absolute floor the step sets well below what its Newton check accepts,
physics.solver.implicit.CG_FLOOR_OF_NEWTON; the Newton residual check guards the result).  Preconditioner: block-Jacobi
(the 3×3 diagonal blocks, contacts included), and on larger livers the additive two-level one, block-Jacobi plus a
coarse correction on rigid aggregates of nodes (physics.solver.coarse_space), which keeps the iterations nearly flat as
the mesh is refined (docs/performance.md, "The physics", for the iterations and costs).  Why this solver: the values
change at every step (the axes turn, the cubic law stiffens, contacts come and go), so a sparse factorisation would be
redone each step (SuperLU: 20–70× the cost of the solve), and matrix-free beats a block CSR pattern because it reads 5
numbers per spring instead of 36. The coarse matrix, small and dense, is factored once per topology and step length: a
preconditioner need not follow the values exactly to leave the answer unchanged.
"""
from __future__ import annotations

import numba
import numpy as np

from liver_sim.physics.solver.coarse_space import coarse_solve, prolong, restrict
from liver_sim.physics.solver.partition import LEVELS
from liver_sim.physics.tissue.fem_kernels import tet_apply
from liver_sim.physics.tissue.spring_law import spring_apply

#: The chunks every pass over the nodes is cut into, whatever the threads: their sums are added in chunk order.
NODE_CHUNKS = 16


@numba.njit(cache=True, inline="always")
def _chunk(c, chunks, count):
    """The range (first, last) of chunk c of `count` items cut into `chunks`."""
    return c * count // chunks, (c + 1) * count // chunks


@numba.njit(cache=True, inline="always")
def _group(op, tet_law, tet_weight, p, g, out):
    """Add group g's springs and elements (physics.solver.partition) to out."""
    spring_apply(op, p, op.spring_start[g], op.spring_start[g + 1], out)
    if tet_law.tets.shape[0] > 0:
        tet_apply(tet_law, tet_weight, p, op.tet_order, op.tet_start[g], op.tet_start[g + 1], out)


@numba.njit(cache=True, inline="always")
def _check_groups(op, tet_law):
    """ValueError unless `op`'s element groups are those of `tet_law`'s elements (records.Operator.allocate)."""
    if int(op.tet_start[op.tet_start.shape[0] - 1]) != tet_law.tets.shape[0]:
        raise ValueError("the operator's element groups are not the elements': allocate it with them")


@numba.njit(cache=True, inline="always")
def _apply(op, inv_mass, rows, tet_law, tet_weight, p, out, sums):
    """out = A·p (see `apply`); returns p·out.  Per part its nodes' shift·p and its springs and elements, then the
    halves' cuts, then the whole's (physics.solver.partition: the groups of a level on the threads, each node's sum
    in the same order); the contacts in row order; then per node chunk the held nodes' rows zeroed and p·out, its
    chunks' sums (`sums`[:, 0], (NODE_CHUNKS, 2)) in order."""
    shift, part_nodes, part_start = op.shift, op.part_nodes, op.part_start
    for g in numba.prange(LEVELS[0][1]):  # the parts: groups 0.. of the first level
        for k in range(part_start[g], part_start[g + 1]):
            n = part_nodes[k]
            for a in range(3):
                out[n, a] = shift[n] * p[n, a]
        _group(op, tet_law, tet_weight, p, g, out)
    first_level, last_level = LEVELS[1]
    for g in numba.prange(last_level - first_level):
        _group(op, tet_law, tet_weight, p, first_level + g, out)
    _group(op, tet_law, tet_weight, p, LEVELS[2][0], out)
    nodes, weights, normal, coefficient = rows.nodes, rows.weights, rows.normal, rows.coefficient
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
    count = p.shape[0]
    for c in numba.prange(NODE_CHUNKS):
        first, last = _chunk(c, NODE_CHUNKS, count)
        total = 0.0
        for n in range(first, last):
            if inv_mass[n] == 0.0:
                out[n, 0] = out[n, 1] = out[n, 2] = 0.0
                continue
            total += p[n, 0] * out[n, 0] + p[n, 1] * out[n, 1] + p[n, 2] * out[n, 2]
        sums[c, 0] = total
    pq = 0.0
    for c in range(NODE_CHUNKS):
        pq += sums[c, 0]
    return pq


@numba.njit(cache=True)
def apply(op, inv_mass, rows, tet_law, tet_weight, p, out):
    """out = A·p, matrix-free (`op` a records.Operator, `rows` a records.ContactRows): shift·p, each spring's
    B·(p_i − p_j) to i and its opposite to j, the tetrahedra of a continuum law (`tet_law`, a fem_kernels.TetArrays,
    scaled by `tet_weight` = h² + h·τ; fem_kernels.tet_apply) and the active contacts' (h·c + h²·k)·w_a·w_b·nnᵀ.
    p must vanish on held nodes; out does there too.  Returns p·out."""
    _check_groups(op, tet_law)
    return _apply(op, inv_mass, rows, tet_law, tet_weight, p, out, np.zeros((NODE_CHUNKS, 2)))


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
def _dot(u, w, sums):
    """u·w over (N, 3) arrays in NODE_CHUNKS node chunks (each chunk's sum in order, then the chunks' in order)."""
    count = u.shape[0]
    for c in numba.prange(NODE_CHUNKS):
        first, last = _chunk(c, NODE_CHUNKS, count)
        total = 0.0
        for n in range(first, last):
            for a in range(3):
                total += u[n, a] * w[n, a]
        sums[c, 0] = total
    total = 0.0
    for c in range(NODE_CHUNKS):
        total += sums[c, 0]
    return total


#: The fields of a solve's `status` (4,): r·z, ‖r‖², the target ‖r‖² and whether it has ended (1.0: converged, or
#: stopped where pᵀA·p ≤ 0).
RZ, R_NORM2, TARGET, ENDED = 0, 1, 2, 3


@numba.njit(cache=True, inline="always")
def _precondition(preconditioner, coarse, r, z, sums, restricted, first_pass, alpha, z0, p, q):
    """The second pass: per node chunk (with `first_pass` False, first z0 += α·p and r −= α·q), z = D⁻¹·r, the
    chunk's ‖r‖² and r·z into `sums` and its Tᵀ·r into its row of `restricted`; then the coarse solve.  Returns
    (‖r‖², r·z with the coarse correction's part); coarse.work holds the coarse motions w."""
    two_level = coarse.factor.shape[0] > 0
    count = r.shape[0]
    for c in numba.prange(NODE_CHUNKS):
        first, last = _chunk(c, NODE_CHUNKS, count)
        r_norm2, rz = 0.0, 0.0
        for n in range(first, last):
            if not first_pass:
                for a in range(3):
                    z0[n, a] += alpha * p[n, a]
                    r[n, a] -= alpha * q[n, a]
            for a in range(3):
                r_norm2 += r[n, a] * r[n, a]
            rz = _block_jacobi_node(preconditioner, r, z, n, rz)
        sums[c, 0], sums[c, 1] = r_norm2, rz
        if two_level:
            own = restricted[c]
            own[:] = 0.0
            restrict(coarse, r, first, last, own)
    r_norm2, rz = 0.0, 0.0
    for c in range(NODE_CHUNKS):
        r_norm2 += sums[c, 0]
        rz += sums[c, 1]
    if two_level:
        rz += coarse_solve(coarse, restricted)
    return r_norm2, rz


@numba.njit(cache=True, inline="always")
def _next_direction(coarse, inv_mass, z, p, beta):
    """The third pass: p = z + F·T·w + β·p per node chunk (w the coarse motions in coarse.work)."""
    two_level = coarse.factor.shape[0] > 0
    w = coarse.work
    count = p.shape[0]
    for c in numba.prange(NODE_CHUNKS):
        first, last = _chunk(c, NODE_CHUNKS, count)
        for n in range(first, last):
            zx, zy, zz = z[n, 0], z[n, 1], z[n, 2]
            if two_level and inv_mass[n] > 0.0:
                cx, cy, cz = prolong(coarse, w, n)
                zx += cx
                zy += cy
                zz += cz
            if beta != 0.0:  # β = 0 starts the directions: p's old values unread
                zx += beta * p[n, 0]
                zy += beta * p[n, 1]
                zz += beta * p[n, 2]
            p[n, 0], p[n, 1], p[n, 2] = zx, zy, zz


@numba.njit(cache=True, inline="always")
def _restricted(coarse):
    """The chunks' rows of Tᵀ·r: (NODE_CHUNKS, 6C)."""
    return np.zeros((NODE_CHUNKS, coarse.work.shape[0]))


@numba.njit(cache=True, inline="always")
def _pcg_start(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, floor, vectors,
               status):
    """The start of a solve from z0: r = b − A·z0, z = P⁻¹·r, p = z, and `status` (RZ … ENDED), its target
    ‖r‖ ≤ max(tolerance·‖b‖, floor)."""
    r, z, p, q = vectors
    count = b.shape[0]
    sums = np.zeros((NODE_CHUNKS, 2))
    _check_groups(op, tet_law)
    _apply(op, inv_mass, rows, tet_law, tet_weight, z0, q, sums)
    for c in numba.prange(NODE_CHUNKS):
        first, last = _chunk(c, NODE_CHUNKS, count)
        for n in range(first, last):
            for a in range(3):
                r[n, a] = b[n, a] - q[n, a]
    target = max(tolerance * tolerance * _dot(b, b, sums), floor * floor)
    r_norm2, rz = _precondition(preconditioner, coarse, r, z, sums, _restricted(coarse), True, 0.0, z0, p, q)
    _next_direction(coarse, inv_mass, z, p, 0.0)
    status[RZ], status[R_NORM2], status[TARGET] = rz, r_norm2, target
    status[ENDED] = 1.0 if r_norm2 <= target else 0.0


@numba.njit(cache=True, inline="always")
def _pcg_steps(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, z0, steps, vectors, status):
    """Up to `steps` iterations of a started solve (`_pcg_start`), z0 its iterate, until it ends; `status` carried
    from one call to the next.  Returns the iterations made."""
    r, z, p, q = vectors
    sums = np.zeros((NODE_CHUNKS, 2))
    restricted = _restricted(coarse)
    rz, r_norm2, target = status[RZ], status[R_NORM2], status[TARGET]
    iterations = 0
    while r_norm2 > target and iterations < steps:
        pq = _apply(op, inv_mass, rows, tet_law, tet_weight, p, q, sums)
        if pq <= 0.0:
            status[ENDED] = 1.0
            break
        alpha = rz / pq
        r_norm2, rz_new = _precondition(preconditioner, coarse, r, z, sums, restricted, False, alpha, z0, p, q)
        beta = rz_new / rz
        rz = rz_new
        _next_direction(coarse, inv_mass, z, p, beta)
        iterations += 1
    status[RZ], status[R_NORM2] = rz, r_norm2
    if r_norm2 <= target:
        status[ENDED] = 1.0
    return iterations


@numba.njit(cache=True, inline="always")
def _pcg(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors):
    """`pcg`'s solve: its start and its iterations (prange: on the threads of a parallel dispatcher, in order in a
    serial one)."""
    status = np.zeros(4)
    _pcg_start(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings.cg_tolerance,
               settings.cg_floor_ns, vectors, status)
    return _pcg_steps(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, z0,
                      settings.max_cg_iterations, vectors, status)


@numba.njit(cache=True)
def pcg(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors):
    """Solve A·z = b by preconditioned conjugate gradients from z0 (overwritten by z): block-Jacobi, plus the
    coarse correction of `coarse` (a coarse_space.CoarseSpace; none: block-Jacobi alone); stops when
    ‖r‖ ≤ max(cg_tolerance·‖b‖, cg_floor_ns) or after max_cg_iterations (`settings`, records.SolveSettings);
    `vectors` (r, z, p, q) (N, 3) each, scratch.  Returns the iterations used.  One thread (`pcg_parallel`: on the
    threads, the same bits)."""
    return _pcg(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors)


@numba.njit(cache=True, parallel=True)
def pcg_parallel(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors):
    """`pcg` on the threads: its groups of springs and elements and its chunks of nodes shared among them; the same
    sums in the same order, so the same bits as `pcg`."""
    return _pcg(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, settings, vectors)


@numba.njit(cache=True, nogil=True)
def pcg_resumable(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, start, steps,
                  vectors, status):
    """`pcg`'s solve in slices: with `start`, begin it from z0 (`status` (4,), RZ … ENDED, is then set); then up to
    `steps` iterations, z0 the iterate, `vectors` and `status` kept by the caller from one slice to the next.  The
    slices make the same iterations, in the same order, as one `pcg` call with no floor.  Returns the iterations
    made."""
    if start:
        _pcg_start(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, 0.0, vectors,
                   status)
    return _pcg_steps(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, z0, steps, vectors, status)


@numba.njit(cache=True, parallel=True, nogil=True)
def pcg_resumable_parallel(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, start,
                           steps, vectors, status):
    """`pcg_resumable` on the threads (as `pcg_parallel`)."""
    if start:
        _pcg_start(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, b, z0, tolerance, 0.0, vectors,
                   status)
    return _pcg_steps(op, inv_mass, rows, tet_law, tet_weight, preconditioner, coarse, z0, steps, vectors, status)
