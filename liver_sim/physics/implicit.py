"""Linearised backward Euler: one implicit step of the spring network per frame ([dLC99], paper P7).

With f(x, v) the forces of the Eq. 1 springs, environment damping, gravity, external loads and
penalty contacts, K = ∂f/∂x and D = ∂f/∂v, one step of length h solves

    (M − h·D − h²·K)·Δv = h·(f(x, v) + h·K·v),   v ← v + Δv,   x ← x + h·v

(Baraff & Witkin 1998), then — when the residual of the nonlinear step
r = M·Δv − h·f(x + h·v_new, v_new) exceeds `newton_tolerance_n`·h on some node — Newton
iterations J·δ = −r with J re-assembled at the iterate.

Second order (BDF2, default from the second step on).  Backward Euler damps the liver's slow
oscillations (about its fixed nodes) by ~(ω·h)²/2 per step, which at h = 1/150 s puts a press, slide
and release 0.4 mm away from symplectic Euler at 72 substeps.  BDF2,
x₊ = (4·x − x₋)/3 + (2h/3)·v₊ and M·(v₊ − (4·v − v₋)/3) = (2h/3)·f(x₊, v₊), is exactly the step
above of length 2h/3 from the extrapolated state ((4·x − x₋)/3, (4·v − v₋)/3) (held nodes are not
extrapolated), so the same solver makes it; it is A-stable, L-stable and its error is second order
(0.1 mm on that press).  The previous state is used only when the step starts from the state the
last step left (same free nodes' x and v, same h); otherwise (first step, reset, topology change,
state set from outside) the step is backward Euler.

Blocks.  A spring i→j with unit axis u, length l, strain d = (l − l0)/l0 and elastic tension
T = λ1·d³ + λ2·d has the tangent stiffness Ks = (dT/dl)·uuᵀ + (T⁺/l)·(I − uuᵀ), dT/dl =
(3·λ1·d² + λ2)/l0, and damping μ·uuᵀ; K gets −Ks on (i,i), (j,j) and +Ks on (i,j), (j,i), D
likewise with μ·uuᵀ.  The geometric term uses T⁺ = max(T, 0): a compressed spring's negative
geometric stiffness is dropped, so every block is positive semi-definite and the system matrix
symmetric positive definite (the usual safeguard; the residual check corrects what it omits).
The viscous tension's own x-derivative (non-symmetric) is omitted likewise.  Environment damping
a −= c_env·v gives D = −c_env·M.  Held nodes (inv_mass 0: fixed or grasped) keep Δv = 0 and do
not move (as `kernels.integrate`): their rows and columns are replaced by the identity.

Support (physics.support): a supported node n with stiffness k_n and damping c_n gets
f_n = −k_n·(x_n − x_rest,n) − c_n·v_n, so K gets −k_n·I and D −c_n·I on its diagonal block, which
adds h·c_n + h²·k_n to the node's shift (`_support_terms`).

Contacts (`Contacts`): element e with nodes a (up to 3, padding −1), weights w_a, unit normal n
(pushing the liver), stiffness k and damping c has depth δ = o − n·Σ w_a·x_a and depth rate
δ̇ = s − n·Σ w_a·v_a, force F = max(0, k·δ + c·δ̇) and f_a = w_a·F·n; active, its Jacobian blocks
are ∂f_a/∂x_b = −w_a·w_b·k·nnᵀ and ∂f_a/∂v_b = −w_a·w_b·c·nnᵀ.  Node contacts are the
1-node case, the tool's contacts with the skin triangles (contact.surface_contacts) the 3-node case.  Contacts
enter the solver matrix-free, so they need no slot in the sparse pattern.

Solver, chosen by measurement: preconditioned conjugate gradients, block-Jacobi (the 3×3 diagonal
blocks, contacts included), matrix-free (per spring only u, and the scalars of B), started from the
previous step's Δv, stopped at ‖r‖ ≤ cg_tolerance·‖b‖ (default 1e-3; the Newton residual check
guards the result).  Milliseconds per step, assembly included, one thread, this 2-core machine
while other jobs ran (median of 120 steps / 10th percentile), h = 1/150 s, default parameters,
a loaded perturbed liver (20 and 48 CG iterations):

    mesh                           unknowns   PCG matrix-free   PCG block CSR   SuperLU factor + solve
    default liver (1155 tets)          1002   0.31 / 0.30       0.40 / 0.38     6.8–9.7  (solve 0.13)
    liver ~10k tets (9991 tets)        6735   5.1  / 4.0        6.0  / 5.4      274–346  (solve 4.9–5.8)

The values change at every step (the axes turn, the cubic law stiffens, contacts come and go), so
a factorisation (scipy's SuperLU, COLAMD; L+U hold 0.16 M and 4.3 M entries) would be redone each
step, 20–70× slower than PCG; on the 10k liver its triangular solves alone cost a whole PCG step.
The matrix is dominated by M + h·C, whose block-Jacobi conditioning is fair, and consecutive
steps differ little, so PCG needs few iterations.  Matrix-free beats a block CSR pattern (built
once per topology, 9 stored values per block) because it reads 5 numbers per spring instead of 36.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse

from liver_sim.physics.springs import SpringNetwork
from liver_sim.physics.support import SupportArrays


@dataclass(frozen=True, eq=False)
class Contacts:
    """Penalty contact elements (see the module docstring), one row each.

    nodes (K, 3) int64 (−1 pads), weights (K, 3), normal (K, 3) unit vectors into the liver,
    offset_m (K,) o, normal_speed_m_s (K,) s (the tool surface's speed along n),
    stiffness_n_per_m (K,) k, damping_ns_per_m (K,) c.
    """

    nodes: np.ndarray
    weights: np.ndarray
    normal: np.ndarray
    offset_m: np.ndarray
    normal_speed_m_s: np.ndarray
    stiffness_n_per_m: np.ndarray
    damping_ns_per_m: np.ndarray

    @classmethod
    def none(cls) -> "Contacts":
        """No contact."""
        return cls(np.zeros((0, 3), np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0),
                   np.zeros(0), np.zeros(0))

    def __len__(self) -> int:
        return len(self.offset_m)


def node_contacts(nodes, normal, offset_m, normal_speed_m_s, stiffness_n_per_m, damping_ns_per_m) -> Contacts:
    """1-node contact elements (weight 1): Eq. 3 on skin nodes."""
    count = len(nodes)
    padded = np.full((count, 3), -1, dtype=np.int64)
    padded[:, 0] = nodes
    weights = np.zeros((count, 3))
    weights[:, 0] = 1.0
    return Contacts(padded, weights, np.ascontiguousarray(normal, dtype=np.float64),
                    np.asarray(offset_m, dtype=np.float64), np.asarray(normal_speed_m_s, dtype=np.float64),
                    np.broadcast_to(np.asarray(stiffness_n_per_m, dtype=np.float64), (count,)).copy(),
                    np.broadcast_to(np.asarray(damping_ns_per_m, dtype=np.float64), (count,)).copy())


@numba.njit(cache=True)
def _contact_forces(x, v, y, inv_mass, h, nodes, weights, normal, offset, speed, stiffness, damping,
                    f, ky, coefficient):
    """Add the active contacts' force at (x, v) to f and K·y to ky; coefficient[e] = h·c + h²·k when
    active (at x + h·y), else 0.  Returns the total contact force on the liver (N), clipped at 0 each."""
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


@numba.njit(cache=True)
def _assemble(x, v, y, inv_mass, external, gravity, c_env, h, node_i, node_j, inv_rest, lambda1, lambda2, mu,
              unit, iso, axial, shift, diagonal, f, ky, assemble_matrix):
    """Forces f at (x, v) and ky = K·y (y zero on held nodes); with assemble_matrix, also the system
    A = M·(1 + h·c_env) − h·D_springs − h²·K_springs in matrix-free form: per spring the block
    B = iso·I + axial·uuᵀ (unit u) that enters (i,i) and (j,j) as +B and (i,j), (j,i) as −B;
    shift = m·(1 + h·c_env) per node (1 on held ones, whose rows and columns are the identity);
    and the 3×3 diagonal blocks of A."""
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
    for s in range(node_i.shape[0]):
        i, j = node_i[s], node_j[s]
        inv_l0 = inv_rest[s]
        ux = x[j, 0] - x[i, 0]
        uy = x[j, 1] - x[i, 1]
        uz = x[j, 2] - x[i, 2]
        length = math.sqrt(ux * ux + uy * uy + uz * uz)
        if length * inv_l0 <= 1e-12:
            if assemble_matrix:
                iso[s] = 0.0
                axial[s] = 0.0
            continue
        inv_length = 1.0 / length
        ux, uy, uz = ux * inv_length, uy * inv_length, uz * inv_length
        rate = (v[j, 0] - v[i, 0]) * ux + (v[j, 1] - v[i, 1]) * uy + (v[j, 2] - v[i, 2]) * uz
        d = length * inv_l0 - 1.0
        elastic = lambda1[s] * d * d * d + lambda2[s] * d
        tension = elastic + mu[s] * rate
        material = (3.0 * lambda1[s] * d * d + lambda2[s]) * inv_l0
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
        f[i, 0] += tension * ux
        f[i, 1] += tension * uy
        f[i, 2] += tension * uz
        f[j, 0] -= tension * ux
        f[j, 1] -= tension * uy
        f[j, 2] -= tension * uz
        ky[i, 0] += kx
        ky[i, 1] += ky_
        ky[i, 2] += kz
        ky[j, 0] -= kx
        ky[j, 1] -= ky_
        ky[j, 2] -= kz
        if not assemble_matrix:
            continue
        unit[s, 0], unit[s, 1], unit[s, 2] = ux, uy, uz
        g = h * h * geometric
        t = h * h * (material - geometric) + h * mu[s]
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


@numba.njit(cache=True)
def _support_terms(x, v, y, inv_mass, h, nodes, rest, stiffness, damping, f, ky, shift, diagonal, assemble_matrix):
    """Add the support's forces at (x, v) to f and K·y to ky (free nodes); with assemble_matrix, also
    h·c_n + h²·k_n to each free supported node's shift and diagonal block (after _assemble)."""
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
def _apply(node_i, node_j, unit, iso, axial, shift, inv_mass, nodes, weights, normal, coefficient, p, out):
    """out = A·p, matrix-free: shift·p, each spring's B·(p_i − p_j) to i and its opposite to j, and the
    active contacts' (h·c + h²·k)·w_a·w_b·nnᵀ.  p must vanish on held nodes; out does there too."""
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
        out[i, 0] += bx
        out[i, 1] += by
        out[i, 2] += bz
        out[j, 0] -= bx
        out[j, 1] -= by
        out[j, 2] -= bz
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
def _block_jacobi(diagonal, inv_mass, nodes, weights, normal, coefficient, inverse):
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


@numba.njit(cache=True)
def _pcg(node_i, node_j, unit, iso, axial, shift, inv_mass, nodes, weights, normal, coefficient, preconditioner,
         b, z0, tolerance, max_iterations, r, z, p, q):
    """Solve A·z = b by block-Jacobi preconditioned conjugate gradients from z0 (overwritten by z);
    stops when ‖r‖ ≤ tolerance·‖b‖.  Returns the iterations used."""
    _apply(node_i, node_j, unit, iso, axial, shift, inv_mass, nodes, weights, normal, coefficient, z0, q)
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
        for a in range(3):
            z[n, a] = (preconditioner[n, a, 0] * r[n, 0] + preconditioner[n, a, 1] * r[n, 1]
                       + preconditioner[n, a, 2] * r[n, 2])
            p[n, a] = z[n, a]
            rz += r[n, a] * z[n, a]
            r_norm2 += r[n, a] * r[n, a]
    iterations = 0
    while r_norm2 > target and iterations < max_iterations:
        _apply(node_i, node_j, unit, iso, axial, shift, inv_mass, nodes, weights, normal, coefficient, p, q)
        pq = 0.0
        for n in range(count):
            for a in range(3):
                pq += p[n, a] * q[n, a]
        if pq <= 0.0:
            break
        alpha = rz / pq
        r_norm2 = 0.0
        for n in range(count):
            for a in range(3):
                z0[n, a] += alpha * p[n, a]
                r[n, a] -= alpha * q[n, a]
                r_norm2 += r[n, a] * r[n, a]
        rz_new = 0.0
        for n in range(count):
            for a in range(3):
                z[n, a] = (preconditioner[n, a, 0] * r[n, 0] + preconditioner[n, a, 1] * r[n, 1]
                           + preconditioner[n, a, 2] * r[n, 2])
                rz_new += r[n, a] * z[n, a]
        beta = rz_new / rz
        rz = rz_new
        for n in range(count):
            for a in range(3):
                p[n, a] = z[n, a] + beta * p[n, a]
        iterations += 1
    return iterations


@numba.njit(cache=True)
def _newton_rhs(v, v0, f, inv_mass, h, rhs):
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
def _advance(x, x0, v, v0, dv, inv_mass, h):
    """v ← v + Δv and x ← x0 + h·v on free nodes (held nodes keep x and v)."""
    for n in range(x.shape[0]):
        if inv_mass[n] == 0.0:
            continue
        for a in range(3):
            v[n, a] += dv[n, a]
            x[n, a] = x0[n, a] + h * v[n, a]


@numba.njit(cache=True)
def _bdf2_start(x, v, x_last, v_last, x_prev, v_prev, inv_mass, second_order):
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
def implicit_step(x, v, inv_mass, external, gravity, c_env, h, node_i, node_j, inv_rest, lambda1, lambda2, mu,
                  unit, iso, axial, shift, diagonal, support_nodes, support_rest, support_stiffness,
                  support_damping, nodes, weights, normal, offset, speed, stiffness,
                  damping, coefficient, preconditioner, warm, tolerance, max_iterations, newton_tolerance,
                  max_newton, work):
    """One linearised backward-Euler step of x, v in place (see the module docstring), then Newton
    iterations while the nonlinear residual exceeds `newton_tolerance` (N) on some node, up to
    `max_newton`.  `warm` holds the previous Δv (start of the solve; overwritten).  `work` is
    (10, N, 3) scratch.  Returns (contact force on the liver at the new state (3,), CG iterations,
    Newton iterations, final residual (N))."""
    f, ky, rhs, x0, v0, r, z, p, q, zero = work
    zero[:] = 0.0
    x0[:] = x
    v0[:] = v
    for n in range(x.shape[0]):
        if inv_mass[n] == 0.0:
            for a in range(3):
                warm[n, a] = 0.0  # held: Δv = 0, and CG's vectors vanish there (see _apply)
    _assemble(x, v, v, inv_mass, external, gravity, c_env, h, node_i, node_j, inv_rest, lambda1, lambda2, mu,
              unit, iso, axial, shift, diagonal, f, ky, True)
    _support_terms(x, v, v, inv_mass, h, support_nodes, support_rest, support_stiffness, support_damping, f, ky,
                   shift, diagonal, True)
    _contact_forces(x, v, v, inv_mass, h, nodes, weights, normal, offset, speed, stiffness, damping, f, ky,
                    coefficient)
    for n in range(x.shape[0]):
        for a in range(3):
            rhs[n, a] = h * (f[n, a] + h * ky[n, a]) if inv_mass[n] > 0.0 else 0.0
    total_iterations = 0
    newton = 0
    contact = np.zeros(3)
    while True:
        _block_jacobi(diagonal, inv_mass, nodes, weights, normal, coefficient, preconditioner)
        total_iterations += _pcg(node_i, node_j, unit, iso, axial, shift, inv_mass, nodes, weights, normal,
                                 coefficient, preconditioner, rhs, warm, tolerance, max_iterations, r, z, p, q)
        _advance(x, x0, v, v0, warm, inv_mass, h)
        _assemble(x, v, zero, inv_mass, external, gravity, c_env, h, node_i, node_j, inv_rest, lambda1, lambda2, mu,
                  unit, iso, axial, shift, diagonal, f, ky, False)
        _support_terms(x, v, zero, inv_mass, h, support_nodes, support_rest, support_stiffness, support_damping, f,
                       ky, shift, diagonal, False)
        tx, ty, tz = _contact_forces(x, v, zero, inv_mass, h, nodes, weights, normal, offset, speed, stiffness,
                                     damping, f, ky, coefficient)
        contact[0], contact[1], contact[2] = tx, ty, tz
        residual = _newton_rhs(v, v0, f, inv_mass, h, rhs)
        if newton >= max_newton or residual <= newton_tolerance:
            break
        newton += 1
        _assemble(x, v, zero, inv_mass, external, gravity, c_env, h, node_i, node_j, inv_rest, lambda1, lambda2, mu,
                  unit, iso, axial, shift, diagonal, f, ky, True)
        _support_terms(x, v, zero, inv_mass, h, support_nodes, support_rest, support_stiffness, support_damping, f,
                       ky, shift, diagonal, True)
        warm[:] = 0.0
    warm[:] = v - v0
    return contact, total_iterations, newton, residual


#: The step length (s) of the quasi-static solve in ImplicitEuler.compliance, and its CG tolerance (3e-2
#: leaves the compliance within ~3 % of a 1e-3 solve at a tenth of the iterations, measured on the press).
COMPLIANCE_HORIZON_S = 30.0
COMPLIANCE_TOLERANCE = 3e-2


class ImplicitEuler:
    """Linearised backward Euler on one spring network and its support (none by default): its per-spring
    matrix blocks and work arrays; with `second_order`, BDF2 from the second step on (see the module
    docstring).  Build a new one after a topology change."""

    def __init__(self, springs: SpringNetwork, n_nodes: int, cg_tolerance: float = 1e-3,
                 max_cg_iterations: int = 500, newton_tolerance_n: float = 1e-2, max_newton: int = 2,
                 second_order: bool = True, support: SupportArrays | None = None):
        self.springs = springs
        self.support = support or SupportArrays.none()
        self.n_nodes = int(n_nodes)
        self.cg_tolerance = float(cg_tolerance)
        self.max_cg_iterations = int(max_cg_iterations)
        self.newton_tolerance_n = float(newton_tolerance_n)
        self.max_newton = int(max_newton)
        self.second_order = bool(second_order)
        edges = len(springs.node_i)
        # unsigned indices spare numba's negative-index wraparound in the inner loops
        self._node_i = springs.node_i.astype(np.uint32)
        self._node_j = springs.node_j.astype(np.uint32)
        self._inv_rest = 1.0 / springs.rest_length_m
        self._unit = np.zeros((edges, 3))
        self._iso = np.zeros(edges)
        self._axial = np.zeros(edges)
        self._shift = np.ones(self.n_nodes)
        self._diagonal = np.zeros((self.n_nodes, 3, 3))
        self._preconditioner = np.zeros((self.n_nodes, 3, 3))
        self._warm = np.zeros((self.n_nodes, 3))
        self._work = np.zeros((10, self.n_nodes, 3))
        self._coefficient = np.zeros(0)
        self._inv_mass = np.zeros(self.n_nodes)
        # BDF2's history: the state the last step left (x, v) and the one before it (x₋, v₋), and its h
        self._history = np.zeros((4, self.n_nodes, 3))
        self._history_dt = 0.0
        #: CG iterations, Newton iterations and final residual (N) of the last step.
        self.last_cg_iterations = 0
        self.last_newton_iterations = 0
        self.last_residual_n = 0.0
        #: Whether the last step was BDF2 (else backward Euler).
        self.last_second_order = False

    def step(self, x: np.ndarray, v: np.ndarray, inv_mass: np.ndarray, external_force: np.ndarray, dt: float,
             environment_damping: float, gravity: np.ndarray, contacts: Contacts | None = None) -> np.ndarray:
        """Advance x, v (N, 3, in place) by one step of `dt` s; returns the contact force on the liver (N)
        at the new state (the tool feels its opposite)."""
        contacts = contacts or Contacts.none()
        if len(self._coefficient) != len(contacts):
            self._coefficient = np.zeros(len(contacts))
        self._inv_mass = inv_mass
        x_last, v_last, x_prev, v_prev = self._history
        second = _bdf2_start(x, v, x_last, v_last, x_prev, v_prev, inv_mass,
                             self.second_order and self._history_dt == dt)
        h = 2.0 * dt / 3.0 if second else float(dt)
        s = self.springs
        contact, self.last_cg_iterations, self.last_newton_iterations, self.last_residual_n = implicit_step(
            x, v, inv_mass, external_force, np.asarray(gravity, dtype=np.float64), float(environment_damping),
            h, self._node_i, self._node_j, self._inv_rest, s.lambda1_n, s.lambda2_n, s.mu_ns_per_m,
            self._unit, self._iso, self._axial, self._shift, self._diagonal, *self.support, contacts.nodes,
            contacts.weights,
            contacts.normal, contacts.offset_m, contacts.normal_speed_m_s, contacts.stiffness_n_per_m,
            contacts.damping_ns_per_m, self._coefficient, self._preconditioner, self._warm, self.cg_tolerance,
            self.max_cg_iterations, self.newton_tolerance_n, self.max_newton, self._work)
        x_last[:], v_last[:] = x, v
        self._history_dt = float(dt)
        self.last_second_order = second
        return contact

    def reset(self) -> None:
        """Forget the previous Δv (the solver's starting guess) and the previous state (the next step is
        backward Euler), e.g. after the state was reset."""
        self._warm[:] = 0.0
        self._history_dt = 0.0

    def matrix(self) -> scipy.sparse.csr_matrix:
        """The spring, support, mass and damping part of the last assembled system matrix, (3N, 3N) sparse
        (contacts excluded; held nodes' rows and columns are the identity)."""
        springs = self.springs
        free = self._inv_mass > 0.0
        blocks = self._iso[:, None, None] * np.eye(3) + self._axial[:, None, None] * (
            self._unit[:, :, None] * self._unit[:, None, :])
        blocks = blocks * (free[springs.node_i] & free[springs.node_j])[:, None, None]
        nodes = np.arange(self.n_nodes)
        rows = np.concatenate([nodes, springs.node_i, springs.node_j])
        cols = np.concatenate([nodes, springs.node_j, springs.node_i])
        values = np.concatenate([self._diagonal, -blocks, -blocks])
        r = (3 * rows)[:, None, None] + np.arange(3)[None, :, None]
        c = (3 * cols)[:, None, None] + np.arange(3)[None, None, :]
        size = 3 * self.n_nodes
        return scipy.sparse.coo_matrix((values.ravel(), (np.broadcast_to(r, values.shape).ravel(),
                                                          np.broadcast_to(c, values.shape).ravel())),
                                       shape=(size, size)).tocsr()

    def compliance(self, x: np.ndarray, inv_mass: np.ndarray, load: np.ndarray, environment_damping: float,
                   guess: np.ndarray) -> float:
        """Static compliance bᵀ·K⁻¹·b (m/N) of the network at x under the load pattern b = `load` (N, 3) N,
        held nodes (inv_mass 0) fixed: the tangent stiffness K of the springs (module docstring) and of the
        organ's supports at x, solved
        by the step's PCG as (M·(1 + H·c_env) + H·C + H²·K)·z = b with H = COMPLIANCE_HORIZON_S, so the mass
        and damping terms weigh ≲ 1 % against K; `guess` (N, 3), the previous solution ·H², starts the
        solve and is overwritten by this one."""
        h = COMPLIANCE_HORIZON_S
        zero = np.zeros_like(x)
        f, ky, r, z, p, q = (np.zeros_like(x) for _ in range(6))
        s = self.springs
        no = Contacts.none()
        _assemble(x, zero, zero, inv_mass, zero, np.zeros(3), float(environment_damping), h, self._node_i,
                  self._node_j, self._inv_rest, s.lambda1_n, s.lambda2_n, s.mu_ns_per_m, self._unit, self._iso,
                  self._axial, self._shift, self._diagonal, f, ky, True)
        _support_terms(x, zero, zero, inv_mass, h, *self.support, f, ky, self._shift, self._diagonal, True)
        coefficient = np.zeros(0)
        _block_jacobi(self._diagonal, inv_mass, no.nodes, no.weights, no.normal, coefficient, self._preconditioner)
        b = np.where((inv_mass > 0.0)[:, None], load, 0.0)
        solution = np.where((inv_mass > 0.0)[:, None], guess / (h * h), 0.0)
        _pcg(self._node_i, self._node_j, self._unit, self._iso, self._axial, self._shift, inv_mass, no.nodes,
             no.weights, no.normal, coefficient, self._preconditioner, b, solution, COMPLIANCE_TOLERANCE,
             self.max_cg_iterations, r, z, p, q)
        guess[:] = solution * (h * h)
        return float(np.einsum("ij,ij->", b, guess))

    def warm_up(self) -> None:
        """Compile the kernels (numba, cached on disk) before a timed loop starts."""
        springs = self.springs
        x = np.random.default_rng(0).normal(size=(self.n_nodes, 3))
        v = np.zeros_like(x)
        contacts = node_contacts(np.array([0]), np.array([[0.0, 0.0, 1.0]]), np.array([0.0]), np.array([0.0]),
                                 1.0, 0.0)
        probe = ImplicitEuler(springs, self.n_nodes, max_cg_iterations=1, max_newton=0, support=self.support)
        probe.step(x, v, np.ones(self.n_nodes), np.zeros_like(x), 1e-3, 0.0, np.zeros(3), contacts)
