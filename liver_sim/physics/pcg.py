"""Preconditioned conjugate gradients, matrix-free, on the implicit step's system A = M − h·D − h²·K
(physics.implicit_kernels): A·p, the preconditioners, the solve.  The operator's parts: the springs (u, iso, axial per
spring), the tetrahedra of the 'fem' law (physics.fem_kernels, none with the springs' law), the contacts.

The solve starts from the previous step's Δv and stops at ‖r‖ ≤ cg_tolerance·‖b‖ (default 1e-3; the Newton residual
check guards the result).  Preconditioner: block-Jacobi (the 3×3 diagonal blocks, contacts included), and on larger
livers the additive two-level one, block-Jacobi plus a coarse correction on rigid aggregates of nodes
(physics.coarse_space), which keeps the iterations nearly flat as the mesh is refined (README, "What to expect on a
2-core machine", for the iterations and costs).  Why this solver: the values change at every step (the axes turn, the
cubic law stiffens, contacts come and go), so a sparse factorisation would be redone each step (SuperLU: 20–70× the
cost of the solve), and matrix-free beats a block CSR pattern because it reads 5 numbers per spring instead of 36.
The coarse matrix, small and dense, is factored once per topology and step length: a preconditioner need not follow
the values exactly to leave the answer unchanged.
"""
from __future__ import annotations

import numba

from liver_sim.physics.coarse_space import coarse_correction
from liver_sim.physics.fem_kernels import tet_apply
from liver_sim.physics.pairs import add_pair


@numba.njit(cache=True)
def apply(node_i, node_j, unit, iso, axial, shift, inv_mass, nodes, weights, normal, coefficient, tet_law, tet_weight,
          p, out):
    """out = A·p, matrix-free: shift·p, each spring's B·(p_i − p_j) to i and its opposite to j, the tetrahedra of
    the 'fem' law (`tet_law`, a fem_kernels.TetArrays, scaled by `tet_weight` = h² + h·τ; fem_kernels.tet_apply) and
    the active contacts' (h·c + h²·k)·w_a·w_b·nnᵀ.  p must vanish on held nodes; out does there too."""
    for n in range(p.shape[0]):
        for a in range(3):
            out[n, a] = shift[n] * p[n, a]
    for s in range(node_i.shape[0]):
        i, j = node_i[s], node_j[s]
        dx = p[i, 0] - p[j, 0]
        dy = p[i, 1] - p[j, 1]
        dz = p[i, 2] - p[j, 2]
        ux, uy, uz = unit[s, 0], unit[s, 1], unit[s, 2]
        g = iso[s]
        t = axial[s] * (ux * dx + uy * dy + uz * dz)
        bx, by, bz = g * dx + t * ux, g * dy + t * uy, g * dz + t * uz
        add_pair(out, i, j, bx, by, bz)
    tet_apply(tet_law, tet_weight, p, out)
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
def block_jacobi(diagonal, inv_mass, nodes, weights, normal, coefficient, inverse):
    """inverse[n] = (A_nn + Σ contacts' diagonal blocks)⁻¹ (3×3, symmetric positive definite)."""
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


@numba.njit(cache=True)
def _with_coarse(coarse, inv_mass, r, z):
    """z ← z + the coarse correction (coarse_space.coarse_correction); returns r·z."""
    coarse_correction(coarse, inv_mass, r, z)
    rz = 0.0
    for n in range(r.shape[0]):
        for a in range(3):
            rz += r[n, a] * z[n, a]
    return rz


@numba.njit(cache=True)
def pcg(node_i, node_j, unit, iso, axial, shift, inv_mass, nodes, weights, normal, coefficient, tet_law, tet_weight,
        preconditioner, coarse, b, z0, tolerance, max_iterations, r, z, p, q):
    """Solve A·z = b by preconditioned conjugate gradients from z0 (overwritten by z): block-Jacobi, plus the
    coarse correction of `coarse` (a coarse_space.CoarseSpace; none: block-Jacobi alone); stops when
    ‖r‖ ≤ tolerance·‖b‖.  Returns the iterations used."""
    two_level = coarse.factor.shape[0] > 0
    apply(node_i, node_j, unit, iso, axial, shift, inv_mass, nodes, weights, normal, coefficient, tet_law, tet_weight,
          z0, q)
    count = b.shape[0]
    b_norm2 = 0.0
    for n in range(count):
        for a in range(3):
            r[n, a] = b[n, a] - q[n, a]
            b_norm2 += b[n, a] * b[n, a]
    target = tolerance * tolerance * b_norm2
    rz = 0.0
    r_norm2 = 0.0
    for n in range(count):
        rz = _block_jacobi_node(preconditioner, r, z, n, rz)
        for a in range(3):
            r_norm2 += r[n, a] * r[n, a]
    if two_level:
        rz = _with_coarse(coarse, inv_mass, r, z)
    p[:] = z
    iterations = 0
    while r_norm2 > target and iterations < max_iterations:
        apply(node_i, node_j, unit, iso, axial, shift, inv_mass, nodes, weights, normal, coefficient, tet_law,
              tet_weight, p, q)
        pq = 0.0
        for n in range(count):
            for a in range(3):
                pq += p[n, a] * q[n, a]
        if pq <= 0.0:
            break
        alpha = rz / pq
        r_norm2 = 0.0
        rz_new = 0.0
        for n in range(count):
            for a in range(3):
                z0[n, a] += alpha * p[n, a]
                r[n, a] -= alpha * q[n, a]
                r_norm2 += r[n, a] * r[n, a]
            rz_new = _block_jacobi_node(preconditioner, r, z, n, rz_new)
        if two_level:
            rz_new = _with_coarse(coarse, inv_mass, r, z)
        beta = rz_new / rz
        rz = rz_new
        for n in range(count):
            for a in range(3):
                p[n, a] = z[n, a] + beta * p[n, a]
        iterations += 1
    return iterations
