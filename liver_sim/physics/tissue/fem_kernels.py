"""The parenchyma as co-rotational linear tetrahedra (tissue_law 'fem'): the continuum law beside the paper's springs.

Each tetrahedron (nodes a = 0..3, rest volume V, shape-function gradients g_a at rest, Σ g_a = 0) has the deformation
gradient F = Σ x_a ⊗ g_a and its rotation R, the polar factor of F (Müller et al., "A robust method to extract the
rotational part of deformations", MIG 2016: iterated from the last step's quaternion, so it holds through
inversion).  With the small strain of the unrotated element ε = sym(Rᵀ·F) − I, its rate ε̇ = sym(Rᵀ·Ḟ), Ḟ = Σ v_a ⊗ g_a,
and Hooke's law σ(ε) = λ·tr(ε)·I + 2μ·ε (Lamé λ, μ from E and ν), Kelvin–Voigt viscosity σ_v = τ·σ(ε̇) with
τ = η/E (stiffness-proportional, as the springs' μ/λ2 is):

    f_a = −V·R·(σ(ε) + τ·σ(ε̇))·g_a.

Its stiffness, the rotation held fixed (the usual co-rotational tangent), K_ab·y = −V·R·σ(sym(Rᵀ·y_b ⊗ g_b))·g_a,
and D = τ·K; in the implicit system A = M − h·D − h²·K the element adds (h² + h·τ)·V·R·C_ab·Rᵀ, whose diagonal
blocks are (h² + h·τ)·V·((λ + μ)·(R·g_a)(R·g_a)ᵀ + μ·|g_a|²·I).  Every block is symmetric positive semi-definite.
Held nodes (inv_mass 0) keep y = 0 and get no block (their rows and columns are the identity, physics.solver.implicit).

The elements of tissue_law 'neo_hookean' share these arrays (TetArrays.neo_hookean set, their tangents in `tangent`);
`tet_terms` and `tet_apply` hand them to that law's kernels (physics.tissue.neo_hookean).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from liver_sim.mesh.tetmesh import signed_volumes
from liver_sim.physics.tissue.neo_hookean import neo_hookean_apply, neo_hookean_terms
from liver_sim.physics.tissue.tet_gradient import EVERY_NODE, tet_gradient

#: Iterations and tolerance (rad) of the rotation's extraction per step (warm-started: one or two suffice).
ROTATION_ITERATIONS = 20
ROTATION_TOLERANCE = 1e-8


class TetArrays(NamedTuple):
    """The tetrahedra of the 'fem' or 'neo_hookean' law for the kernels: `tets` (M, 4) int64, rest `volume_m3` (M,),
    shape-function `gradients` (M, 4, 3) 1/m, Lamé `lame_lambda_pa` and `lame_mu_pa`, Kelvin–Voigt `viscous_time_s` τ;
    the per-step `quaternion` (M, 4: x, y, z, w), `rotation` (M, 3, 3) and `rotated_gradients` R·g_a (M, 4, 3) of each
    element (scratch the step overwrites, the quaternion the warm start of the next; the neo-Hookean law leaves
    them at rest, R = I); `neo_hookean`, whether the elements are that law's, and then their projected tangents
    `tangent` (M, 9, 9) Pa of the last assembly (physics.tissue.neo_hookean; (0, 9, 9) for the co-rotational law)."""

    tets: np.ndarray
    volume_m3: np.ndarray
    gradients: np.ndarray
    lame_lambda_pa: float
    lame_mu_pa: float
    viscous_time_s: float
    quaternion: np.ndarray
    rotation: np.ndarray
    rotated_gradients: np.ndarray
    neo_hookean: bool
    tangent: np.ndarray

    @classmethod
    def none(cls) -> "TetArrays":
        """No element (the springs' law)."""
        return cls(np.zeros((0, 4), np.int64), np.zeros(0), np.zeros((0, 4, 3)), 0.0, 0.0, 0.0, np.zeros((0, 4)),
                   np.zeros((0, 3, 3)), np.zeros((0, 4, 3)), False, np.zeros((0, 9, 9)))


def build_tets(points: np.ndarray, tets: np.ndarray, young_pa: float, poisson: float,
               viscosity_pa_s: float, neo_hookean: bool = False) -> TetArrays:
    """The TetArrays of a mesh at rest (`points` m, positively oriented `tets`): volumes, gradients g_a (the rows of
    Dm⁻ᵀ for a = 1..3, g_0 = −Σ), λ = E·ν/((1 + ν)(1 − 2ν)), μ = E/(2(1 + ν)), τ = η/E; rotations the identity; with
    `neo_hookean`, that law's elements, their tangents zero until the first assembly."""
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    corners = points[tets]
    edges = np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1))  # Dm: columns x_a − x_0
    inverse = np.linalg.inv(edges)  # rows: g_1, g_2, g_3
    gradients = np.concatenate([-inverse.sum(axis=1, keepdims=True), inverse], axis=1)
    count = len(tets)
    quaternion = np.zeros((count, 4))
    quaternion[:, 3] = 1.0
    return TetArrays(tets, signed_volumes(points, tets), np.ascontiguousarray(gradients),
                     young_pa * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson)), young_pa / (2.0 * (1.0 + poisson)),
                     viscosity_pa_s / young_pa if young_pa > 0.0 else 0.0, quaternion,
                     np.broadcast_to(np.eye(3), (count, 3, 3)).copy(), np.ascontiguousarray(gradients).copy(),
                     bool(neo_hookean), np.zeros((count if neo_hookean else 0, 9, 9)))


@numba.njit(cache=True, inline="always")
def _quaternion_matrix(q, out):
    """out ← the rotation of the unit quaternion q (x, y, z, w)."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    out[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[0, 1] = 2.0 * (x * y - z * w)
    out[0, 2] = 2.0 * (x * z + y * w)
    out[1, 0] = 2.0 * (x * y + z * w)
    out[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[1, 2] = 2.0 * (y * z - x * w)
    out[2, 0] = 2.0 * (x * z - y * w)
    out[2, 1] = 2.0 * (y * z + x * w)
    out[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@numba.njit(cache=True)
def _extract_rotation(f, q, r):
    """q, r ← the rotation of F (3×3) by Müller et al.'s iteration from q: ω = Σ_i r_i × f_i / (|Σ_i r_i·f_i| +
    1e-9) over the columns, q ← exp(ω)·q, until |ω| ≤ ROTATION_TOLERANCE."""
    for _ in range(ROTATION_ITERATIONS):
        _quaternion_matrix(q, r)
        wx, wy, wz, dot = 0.0, 0.0, 0.0, 0.0
        for c in range(3):
            wx += r[1, c] * f[2, c] - r[2, c] * f[1, c]
            wy += r[2, c] * f[0, c] - r[0, c] * f[2, c]
            wz += r[0, c] * f[1, c] - r[1, c] * f[0, c]
            dot += r[0, c] * f[0, c] + r[1, c] * f[1, c] + r[2, c] * f[2, c]
        scale = 1.0 / (abs(dot) + 1e-9)
        wx, wy, wz = wx * scale, wy * scale, wz * scale
        angle = math.sqrt(wx * wx + wy * wy + wz * wz)
        if angle < ROTATION_TOLERANCE:
            break
        s = math.sin(0.5 * angle) / angle
        ax, ay, az, aw = wx * s, wy * s, wz * s, math.cos(0.5 * angle)
        x, y, z, w = q[0], q[1], q[2], q[3]
        q[0] = aw * x + ax * w + ay * z - az * y
        q[1] = aw * y - ax * z + ay * w + az * x
        q[2] = aw * z + ax * y - ay * x + az * w
        q[3] = aw * w - ax * x - ay * y - az * z
        norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        for k in range(4):
            q[k] /= norm
    _quaternion_matrix(q, r)


@numba.njit(cache=True, inline="always")
def _gradient(values, tet, g, out):
    """out ← Σ_a values[tet[a]] ⊗ g_a (3×3: tet_gradient), values zero on held nodes is the caller's business."""
    (out[0, 0], out[0, 1], out[0, 2], out[1, 0], out[1, 1], out[1, 2],
     out[2, 0], out[2, 1], out[2, 2]) = tet_gradient(values, tet, g, EVERY_NODE)


@numba.njit(cache=True, inline="always")
def _rotated_stress(r, grad, lam, mu, stress, rs):
    """stress ← σ(sym(Rᵀ·grad)) (Hooke), rs ← R·stress."""
    for i in range(3):
        for j in range(3):
            stress[i, j] = r[0, i] * grad[0, j] + r[1, i] * grad[1, j] + r[2, i] * grad[2, j]
    trace = stress[0, 0] + stress[1, 1] + stress[2, 2]
    for i in range(3):
        for j in range(i + 1, 3):
            e = 0.5 * (stress[i, j] + stress[j, i])
            stress[i, j] = 2.0 * mu * e
            stress[j, i] = 2.0 * mu * e
        stress[i, i] = lam * trace + 2.0 * mu * stress[i, i]
    for i in range(3):
        for j in range(3):
            rs[i, j] = r[i, 0] * stress[0, j] + r[i, 1] * stress[1, j] + r[i, 2] * stress[2, j]


@numba.njit(cache=True, nogil=True)
def tet_terms(x, v, y, inv_mass, h, law, f, ky, diagonal, assemble_matrix, elements, first, last):
    """Add the forces at (x, v) of the elements elements[first..last−1] (`law`, a TetArrays) to f and K·y to ky (y
    zero on held nodes); with
    assemble_matrix, first the rotations R at x (into law.quaternion, law.rotation) and the diagonal blocks of
    (h² + h·τ)·V·R·C_aa·Rᵀ to free nodes' `diagonal` (module docstring).  Without it the last rotations are used.
    The neo-Hookean law's elements: neo_hookean.neo_hookean_terms."""
    if law.neo_hookean:
        neo_hookean_terms(x, v, y, inv_mass, h, law, f, ky, diagonal, assemble_matrix, elements, first, last)
        return
    tets, volume, gradients, quaternion, rotation = law.tets, law.volume_m3, law.gradients, law.quaternion, law.rotation
    lam, mu, tau = law.lame_lambda_pa, law.lame_mu_pa, law.viscous_time_s
    grad = np.empty((3, 3))
    stress = np.empty((3, 3))
    rs = np.empty((3, 3))
    total = np.empty((3, 3))
    weight = h * h + h * tau
    for k in range(first, last):
        e = elements[k]
        tet, g, r = tets[e], gradients[e], rotation[e]
        _gradient(x, tet, g, grad)
        if assemble_matrix:
            _extract_rotation(grad, quaternion[e], r)
            hg = law.rotated_gradients[e]
            for a in range(4):
                for i in range(3):
                    hg[a, i] = r[i, 0] * g[a, 0] + r[i, 1] * g[a, 1] + r[i, 2] * g[a, 2]
        # elastic stress of ε = sym(Rᵀ·F) − I: σ(sym(Rᵀ·F)) − σ(I), R·σ(I) = (3λ + 2μ)·R
        _rotated_stress(r, grad, lam, mu, stress, rs)
        for i in range(3):
            for j in range(3):
                total[i, j] = rs[i, j] - (3.0 * lam + 2.0 * mu) * r[i, j]
        _gradient(v, tet, g, grad)
        _rotated_stress(r, grad, lam, mu, stress, rs)
        for i in range(3):
            for j in range(3):
                total[i, j] += tau * rs[i, j]
        vol = volume[e]
        for a in range(4):
            n = tet[a]
            for i in range(3):
                f[n, i] -= vol * (total[i, 0] * g[a, 0] + total[i, 1] * g[a, 1] + total[i, 2] * g[a, 2])
        # K·y with y zero on held nodes
        for i in range(3):
            for j in range(3):
                grad[i, j] = 0.0
        for a in range(4):
            n = tet[a]
            if inv_mass[n] > 0.0:
                for i in range(3):
                    for j in range(3):
                        grad[i, j] += y[n, i] * g[a, j]
        _rotated_stress(r, grad, lam, mu, stress, rs)
        for a in range(4):
            n = tet[a]
            for i in range(3):
                ky[n, i] -= vol * (rs[i, 0] * g[a, 0] + rs[i, 1] * g[a, 1] + rs[i, 2] * g[a, 2])
            if assemble_matrix and inv_mass[n] > 0.0:
                hg = law.rotated_gradients[e]
                gx, gy, gz = hg[a, 0], hg[a, 1], hg[a, 2]
                iso = weight * vol * mu * (gx * gx + gy * gy + gz * gz)
                along = weight * vol * (lam + mu)
                rg = (gx, gy, gz)
                for i in range(3):
                    diagonal[n, i, i] += iso
                    for j in range(3):
                        diagonal[n, i, j] += along * rg[i] * rg[j]


@numba.njit(cache=True)
def tet_apply(law, weight, p, elements, first, last, out):
    """out += Σ over the elements elements[first..last−1] of weight·V·R·C·Rᵀ·p (`law` a TetArrays, weight = h² + h·τ;
    p zero on held nodes): the elements' part of A·p.  With the rotated gradients h_a = R·g_a and
    G = Σ_b p_b ⊗ h_b, R·C·Rᵀ·p gives node a (λ·tr(G)·I + μ·(G + Gᵀ))·h_a.  The neo-Hookean law's elements:
    neo_hookean.neo_hookean_apply."""
    if law.neo_hookean:
        neo_hookean_apply(law, weight, p, elements, first, last, out)
        return
    tets, volume, rotated = law.tets, law.volume_m3, law.rotated_gradients
    lam, mu = law.lame_lambda_pa, law.lame_mu_pa
    for k in range(first, last):
        e = elements[k]
        tet, hg = tets[e], rotated[e]
        g00, g01, g02, g10, g11, g12, g20, g21, g22 = tet_gradient(p, tet, hg, EVERY_NODE)
        scale = weight * volume[e]
        trace = lam * (g00 + g11 + g22)
        s00, s11, s22 = trace + 2.0 * mu * g00, trace + 2.0 * mu * g11, trace + 2.0 * mu * g22
        s01, s02, s12 = mu * (g01 + g10), mu * (g02 + g20), mu * (g12 + g21)
        for a in range(4):
            n = tet[a]
            hx, hy, hz = hg[a, 0], hg[a, 1], hg[a, 2]
            out[n, 0] += scale * (s00 * hx + s01 * hy + s02 * hz)
            out[n, 1] += scale * (s01 * hx + s11 * hy + s12 * hz)
            out[n, 2] += scale * (s02 * hx + s12 * hy + s22 * hz)
