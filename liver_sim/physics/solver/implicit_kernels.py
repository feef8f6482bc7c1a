"""The numba kernels of one implicit step (physics.solver.implicit): forces f and K·y, the system matrix
A = M − h·D − h²·K in matrix-free form, the Newton residual, the BDF2 start, the step itself.

Blocks.  A spring's forces, tangent stiffness and damping and its block of the system are its law's
(physics.tissue.spring_law.spring_terms), a tetrahedron's likewise (physics.tissue.fem_kernels.tet_terms); every
block is positive semi-definite and the system matrix symmetric positive definite.  Environment damping
a −= c_env·v gives D = −c_env·M.  Held nodes (inv_mass 0: fixed or grasped) keep Δv = 0 and do
not move (as `explicit_kernels.integrate`): their rows and columns are replaced by the identity.

Support (physics.tissue.organ_support): a supported node n with stiffness k_n and damping c_n gets
f_n = −k_n·(x_n − x_rest,n) − c_n·v_n, so K gets −k_n·I and D −c_n·I on its diagonal block, which
adds h·c_n + h²·k_n to the node's shift (`support_terms`).

Contacts (`implicit.Contacts`): element e with nodes a (up to 3, padding −1), weights w_a, unit normal n
(pushing the liver), stiffness k and damping c has depth δ = o − n·Σ w_a·x_a and depth rate
δ̇ = s − n·Σ w_a·v_a, force F = max(0, k·δ + c·δ̇) and f_a = w_a·F·n; active, its Jacobian blocks
are ∂f_a/∂x_b = −w_a·w_b·k·nnᵀ and ∂f_a/∂v_b = −w_a·w_b·c·nnᵀ.  Node contacts are the
1-node case, the tool's contacts with the skin triangles (contact.tool_geometry.contact_rows) the 3-node case.  Contacts
enter the solver matrix-free, so they need no slot in the sparse pattern.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from liver_sim.physics.solver.partition import LEVELS
from liver_sim.physics.solver.pcg import block_jacobi, pcg, pcg_parallel
from liver_sim.physics.tissue.fem_kernels import tet_terms
from liver_sim.physics.tissue.spring_law import accumulate_forces, spring_terms


@numba.njit(cache=True)
def surface_rows(x, rows):
    """Rebuild the rows on the tool's true surface (radius > 0: a node against a ball swept along its core
    segment, contact.rows.Contacts) at x: c the core's point nearest the node, n = (x − c)/|x − c|,
    offset = r + n·c + bias, speed = n·v_core (a node on the core keeps its last normal)."""
    nodes, normal, offset, speed, core, radius = rows.nodes, rows.normal, rows.offset, rows.speed, rows.core, \
        rows.radius
    for e in range(nodes.shape[0]):
        if radius[e] <= 0.0:
            continue
        n = nodes[e, 0]
        ax, ay, az = core[e, 0, 0], core[e, 0, 1], core[e, 0, 2]
        ux, uy, uz = core[e, 1, 0] - ax, core[e, 1, 1] - ay, core[e, 1, 2] - az
        length2 = ux * ux + uy * uy + uz * uz
        t = 0.0
        if length2 > 0.0:
            t = min(max(((x[n, 0] - ax) * ux + (x[n, 1] - ay) * uy + (x[n, 2] - az) * uz) / length2, 0.0), 1.0)
        cx, cy, cz = ax + t * ux, ay + t * uy, az + t * uz
        dx, dy, dz = x[n, 0] - cx, x[n, 1] - cy, x[n, 2] - cz
        distance = math.sqrt(dx * dx + dy * dy + dz * dz)
        if distance <= 1e-12:
            continue
        nx, ny, nz = dx / distance, dy / distance, dz / distance
        normal[e, 0], normal[e, 1], normal[e, 2] = nx, ny, nz
        offset[e] = radius[e] + nx * cx + ny * cy + nz * cz + rows.bias[e]
        speed[e] = nx * rows.core_velocity[e, 0] + ny * rows.core_velocity[e, 1] + nz * rows.core_velocity[e, 2]


@numba.njit(cache=True)
def contact_forces(x, v, y, inv_mass, h, rows, f, ky):
    """Add the active contacts' force at (x, v) to f and K·y to ky (`rows` a records.ContactRows);
    rows.coefficient[e] = h·c + h²·k when active (at x + h·y), else 0.  Returns the total contact force on the liver
    (N), clipped at 0 each."""
    nodes, weights, normal, coefficient = rows.nodes, rows.weights, rows.normal, rows.coefficient
    offset, speed, stiffness, damping = rows.offset, rows.speed, rows.stiffness, rows.damping
    tx, ty, tz = 0.0, 0.0, 0.0
    for e in range(nodes.shape[0]):
        nx, ny, nz = normal[e, 0], normal[e, 1], normal[e, 2]
        px = 0.0
        py = 0.0
        pr = 0.0
        for a in range(3):
            n = nodes[e, a]
            if n < 0:
                continue
            w = weights[e, a]
            px += w * (nx * x[n, 0] + ny * x[n, 1] + nz * x[n, 2])
            pr += w * (nx * v[n, 0] + ny * v[n, 1] + nz * v[n, 2])
            if inv_mass[n] > 0.0:
                py += w * (nx * y[n, 0] + ny * y[n, 1] + nz * y[n, 2])
        k, c = stiffness[e], damping[e]
        force = k * (offset[e] - px) + c * (speed[e] - pr)
        if force - k * h * py <= 0.0:
            coefficient[e] = 0.0
            continue
        coefficient[e] = h * c + h * h * k
        tx += max(force, 0.0) * nx
        ty += max(force, 0.0) * ny
        tz += max(force, 0.0) * nz
        for a in range(3):
            n = nodes[e, a]
            if n < 0:
                continue
            w = weights[e, a]
            g = w * force
            gy = -w * k * py
            f[n, 0] += g * nx
            f[n, 1] += g * ny
            f[n, 2] += g * nz
            ky[n, 0] += gy * nx
            ky[n, 1] += gy * ny
            ky[n, 2] += gy * nz
    return tx, ty, tz


@numba.njit(cache=True, nogil=True)
def load_terms(x, v, y, inv_mass, loads, h, op, f, ky, assemble_matrix):
    """Start f and ky = K·y at (x, v): f the `loads` (records.Loads: external forces, gravity, the environment's
    damping), ky 0; with assemble_matrix, also each node's shift m·(1 + h·c_env) in `op` (a records.Operator; 1 on
    held nodes, whose rows and columns are the identity) and its diagonal block shift·I."""
    external, gravity, c_env = loads.external, loads.gravity, loads.c_env
    shift, diagonal = op.shift, op.diagonal
    for n in range(x.shape[0]):
        w = inv_mass[n]
        for a in range(3):
            ky[n, a] = 0.0
            f[n, a] = external[n, a]
        if w > 0.0:
            m = 1.0 / w
            for a in range(3):
                f[n, a] += m * (gravity[a] - c_env * v[n, a])
            if assemble_matrix:
                shift[n] = m * (1.0 + h * c_env)
        elif assemble_matrix:
            shift[n] = 1.0
        if assemble_matrix:
            diagonal[n] = 0.0
            for a in range(3):
                diagonal[n, a, a] = shift[n]


@numba.njit(cache=True, inline="always")
def _group_terms(x, v, y, inv_mass, h, springs, tet_law, op, f, ky, assemble_matrix, stiffness, g):
    """The terms of group g's springs (spring_law.spring_terms; without `stiffness`, their forces alone,
    spring_law.accumulate_forces, the same sums) and elements (fem_kernels.tet_terms)."""
    first, last = op.spring_start[g], op.spring_start[g + 1]
    if stiffness:
        spring_terms(x, v, y, inv_mass, h, springs, op, f, ky, assemble_matrix, first, last)
    else:
        accumulate_forces(x, v, springs, first, last, f)
    if tet_law.tets.shape[0] > 0:
        tet_terms(x, v, y, inv_mass, h, tet_law, f, ky, op.diagonal, assemble_matrix, op.tet_order, op.tet_start[g],
                  op.tet_start[g + 1])


@numba.njit(cache=True, inline="always")
def _groups_terms(x, v, y, inv_mass, h, springs, tet_law, op, f, ky, assemble_matrix, stiffness):
    """The springs' and elements' terms group by group (physics.solver.partition): the groups of a level on the
    threads of a parallel dispatcher, each node's sum in the same order."""
    for g in numba.prange(LEVELS[0][1]):
        _group_terms(x, v, y, inv_mass, h, springs, tet_law, op, f, ky, assemble_matrix, stiffness, g)
    first_group, last_group = LEVELS[1]
    for g in numba.prange(last_group - first_group):
        _group_terms(x, v, y, inv_mass, h, springs, tet_law, op, f, ky, assemble_matrix, stiffness, first_group + g)
    _group_terms(x, v, y, inv_mass, h, springs, tet_law, op, f, ky, assemble_matrix, stiffness, LEVELS[2][0])


@numba.njit(cache=True, nogil=True)
def groups_terms(x, v, y, inv_mass, h, springs, tet_law, op, f, ky, assemble_matrix, stiffness):
    """`_groups_terms` on one thread (groups_terms_parallel: on the threads, the same bits)."""
    _groups_terms(x, v, y, inv_mass, h, springs, tet_law, op, f, ky, assemble_matrix, stiffness)


@numba.njit(cache=True, nogil=True, parallel=True)
def groups_terms_parallel(x, v, y, inv_mass, h, springs, tet_law, op, f, ky, assemble_matrix, stiffness):
    """`groups_terms` on the threads."""
    _groups_terms(x, v, y, inv_mass, h, springs, tet_law, op, f, ky, assemble_matrix, stiffness)


@numba.njit(cache=True, nogil=True)
def system_terms(x, v, y, inv_mass, loads, h, tissue, op, f, ky, assemble_matrix, parallel):
    """Forces f at (x, v) and ky = K·y (y zero on held nodes) of the `loads` and the `tissue` (records.Tissue), and
    with assemble_matrix the system A = M·(1 + h·c_env) − h·D − h²·K into `op` (records.Operator): the loads and
    shifts (load_terms), the support (support_terms), then the springs and elements group by group (groups_terms;
    with `parallel`, on the threads)."""
    load_terms(x, v, y, inv_mass, loads, h, op, f, ky, assemble_matrix)
    support_terms(x, v, y, inv_mass, h, tissue.support, f, ky, op, assemble_matrix)
    if parallel:
        groups_terms_parallel(x, v, y, inv_mass, h, tissue.springs, tissue.tets, op, f, ky, assemble_matrix, True)
    else:
        groups_terms(x, v, y, inv_mass, h, tissue.springs, tissue.tets, op, f, ky, assemble_matrix, True)


@numba.njit(cache=True, nogil=True)
def system_forces(x, v, zero, inv_mass, loads, h, tissue, op, f, ky, parallel):
    """The forces f at (x, v) of `system_terms` with no matrix, bit for bit, without the springs' K·y: the
    Newton check's (`zero` (N, 3) zeros; ky receives the support's and elements' K·0)."""
    load_terms(x, v, zero, inv_mass, loads, h, op, f, ky, False)
    support_terms(x, v, zero, inv_mass, h, tissue.support, f, ky, op, False)
    if parallel:
        groups_terms_parallel(x, v, zero, inv_mass, h, tissue.springs, tissue.tets, op, f, ky, False, False)
    else:
        groups_terms(x, v, zero, inv_mass, h, tissue.springs, tissue.tets, op, f, ky, False, False)


@numba.njit(cache=True, nogil=True)
def support_terms(x, v, y, inv_mass, h, support, f, ky, op, assemble_matrix):
    """Add the forces of the `support` (organ_support.SupportArrays) at (x, v) to f and K·y to ky (free nodes); with
    assemble_matrix, also h·c_n + h²·k_n to each free supported node's shift and diagonal block in `op`
    (records.Operator, after load_terms)."""
    nodes, rest, stiffness, damping = support
    shift, diagonal = op.shift, op.diagonal
    for s in range(nodes.shape[0]):
        n = nodes[s]
        if inv_mass[n] == 0.0:
            continue
        k, c = stiffness[s], damping[s]
        for a in range(3):
            f[n, a] -= k * (x[n, a] - rest[s, a]) + c * v[n, a]
            ky[n, a] -= k * y[n, a]
        if assemble_matrix:
            extra = h * c + h * h * k
            shift[n] += extra
            for a in range(3):
                diagonal[n, a, a] += extra


@numba.njit(cache=True)
def newton_rhs(v, v0, f, inv_mass, h, rhs):
    """Minus the residual of the nonlinear step, rhs = h·f(x, v) − M·(v − v0) on free nodes (0 on held
    ones), f evaluated at the iterate; returns max over nodes of |rhs|/h (N)."""
    worst = 0.0
    for n in range(v.shape[0]):
        w = inv_mass[n]
        if w == 0.0:
            for a in range(3):
                rhs[n, a] = 0.0
            continue
        norm2 = 0.0
        for a in range(3):
            rhs[n, a] = h * f[n, a] - (v[n, a] - v0[n, a]) / w
            norm2 += rhs[n, a] * rhs[n, a]
        worst = max(worst, math.sqrt(norm2) / h)
    return worst


@numba.njit(cache=True)
def advance(x, x0, v, v0, dv, inv_mass, h):
    """v ← v + Δv and x ← x0 + h·v on free nodes (held nodes keep x and v)."""
    for n in range(x.shape[0]):
        if inv_mass[n] == 0.0:
            continue
        for a in range(3):
            v[n, a] += dv[n, a]
            x[n, a] = x0[n, a] + h * v[n, a]


@numba.njit(cache=True)
def bdf2_start(x, v, x_last, v_last, x_prev, v_prev, inv_mass, second_order):
    """With `second_order` and x, v equal to x_last, v_last on every free node: x, v ← the extrapolated
    start of a BDF2 step, (4·x − x_prev)/3 and (4·v − v_prev)/3 on free nodes, and True; else False,
    x and v unchanged.  Either way x_prev, v_prev ← the incoming x, v (the next step's x₋, v₋)."""
    same = second_order
    for n in range(x.shape[0]):
        if not same:
            break
        if inv_mass[n] == 0.0:
            continue
        for a in range(3):
            if x[n, a] != x_last[n, a] or v[n, a] != v_last[n, a]:
                same = False
    for n in range(x.shape[0]):
        for a in range(3):
            px, pv = x_prev[n, a], v_prev[n, a]
            x_prev[n, a], v_prev[n, a] = x[n, a], v[n, a]
            if same and inv_mass[n] > 0.0:
                x[n, a] = (4.0 * x[n, a] - px) / 3.0
                v[n, a] = (4.0 * v[n, a] - pv) / 3.0
    return same


@numba.njit(cache=True, nogil=True)
def implicit_step(x, v, inv_mass, loads, h, tissue, op, rows, coarse, warm, settings, scratch):
    """One linearised backward-Euler step of x, v in place (see the module docstring), then Newton
    iterations while the nonlinear residual exceeds settings.newton_tolerance_n (N) on some node, up to
    settings.max_newton (`settings` a records.SolveSettings).  `loads` (records.Loads) act beside the `tissue`
    (records.Tissue: springs, support, the tetrahedra of the 'fem' law), `rows` the contacts
    (records.ContactRows; those on the tool's true surface rebuilt at every iterate, surface_rows), `op`
    (records.Operator) receives the system.  `coarse`: the preconditioner's coarse space
    (physics.solver.coarse_space; none: block-Jacobi alone).  `warm` holds the previous Δv (start of the solve;
    overwritten).  `scratch` a records.Scratch (with `parallel`, the assembly and solve on the threads).  Returns
    (contact force on the liver at the new state (3,), CG iterations, Newton iterations, final residual (N))."""
    f, ky, rhs, x0, v0, r, z, p, q, zero = scratch.work
    tet_law = tissue.tets
    zero[:] = 0.0
    x0[:] = x
    v0[:] = v
    for n in range(x.shape[0]):
        if inv_mass[n] == 0.0:
            for a in range(3):
                warm[n, a] = 0.0  # held: Δv = 0, and CG's vectors vanish there (see pcg.apply)
    system_terms(x, v, v, inv_mass, loads, h, tissue, op, f, ky, True, scratch.parallel)
    tet_weight = h * h + h * tet_law.viscous_time_s
    contact_forces(x, v, v, inv_mass, h, rows, f, ky)
    for n in range(x.shape[0]):
        for a in range(3):
            rhs[n, a] = h * (f[n, a] + h * ky[n, a]) if inv_mass[n] > 0.0 else 0.0
    total_iterations = 0
    newton = 0
    contact = np.zeros(3)
    vectors = (r, z, p, q)
    while True:
        block_jacobi(op.diagonal, inv_mass, rows, scratch.preconditioner)
        if scratch.parallel:
            total_iterations += pcg_parallel(op, inv_mass, rows, tet_law, tet_weight, scratch.preconditioner, coarse,
                                             rhs, warm, settings, vectors)
        else:
            total_iterations += pcg(op, inv_mass, rows, tet_law, tet_weight, scratch.preconditioner, coarse, rhs,
                                    warm, settings, vectors)
        advance(x, x0, v, v0, warm, inv_mass, h)
        surface_rows(x, rows)
        system_forces(x, v, zero, inv_mass, loads, h, tissue, op, f, ky, scratch.parallel)
        tx, ty, tz = contact_forces(x, v, zero, inv_mass, h, rows, f, ky)
        contact[0], contact[1], contact[2] = tx, ty, tz
        residual = newton_rhs(v, v0, f, inv_mass, h, rhs)
        if newton >= settings.max_newton or residual <= settings.newton_tolerance_n:
            break
        newton += 1
        system_terms(x, v, zero, inv_mass, loads, h, tissue, op, f, ky, True, scratch.parallel)
        warm[:] = 0.0
    warm[:] = v - v0
    return contact, total_iterations, newton, residual

