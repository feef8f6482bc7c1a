"""The parenchyma as stable neo-Hookean tetrahedra (tissue_law 'neo_hookean'): the hyperelastic continuum law beside
the co-rotational one (physics.tissue.fem_kernels, which holds the elements' arrays and dispatches to these kernels).

Each tetrahedron (rest volume V, shape-function gradients g_a, F = Σ x_a ⊗ g_a as in fem_kernels) stores the energy
density of Smith, de Goes & Kim, "Stable Neo-Hookean Flesh Simulation" (ACM TOG 37(2), 2018), in the rest-stable form
of Kim & Eberle, "Dynamic Deformables" (SIGGRAPH course 2022):

    Ψ(F) = μ/2·(‖F‖² − 3) − μ·(J − 1) + λ̂/2·(J − 1)²,   J = det F,   λ̂ = λ + μ,

(λ, μ) the small-strain Lamé constants from E and ν, so that its linearisation at F = I is Hooke's law with λ, μ.  No
log and no division: it is defined through inversion (J ≤ 0).  Its first Piola stress and force on node a:

    P = μ·F + s·∂J/∂F,   s = λ̂·(J − 1) − μ,   ∂J/∂F = [f₁×f₂ | f₂×f₀ | f₀×f₁] (columns; f_i the columns of F),
    f_a = −V·P·g_a.

Tangent ∂P/∂F = μ·I₉ + λ̂·vec(∂J/∂F)·vec(∂J/∂F)ᵀ + s·∂²J/∂F², indefinite in places, projected onto the positive
semi-definite cone through its analytic eigensystem (Smith, de Goes & Kim, "Analytic eigensystems for isotropic
distortion energies", ACM TOG 38(1), 2019; Kim & Eberle ch. 7).  With the rotation-variant SVD F = U·Σ·Vᵀ
(det U = det V = +1, σ₂ carrying the sign of J; base.geometry.matrix3, without allocating) and, for each pair
(i, j) with k the third index, u_i, v_j the columns of U, V:

    twist  (u_i·v_jᵀ − u_j·v_iᵀ)/√2,  eigenvalue μ + s·σ_k;
    flip   (u_i·v_jᵀ + u_j·v_iᵀ)/√2,  eigenvalue μ − s·σ_k;
    scale  U·diag(q)·Vᵀ for the eigenpairs (w, q) of the 3×3 block ∂²Ψ/∂σ_i∂σ_j = μ·δ_ij + λ̂·γ_i·γ_j
           + s·σ_k·(1 − δ_ij), γ_i = ∂J/∂σ_i = Π_{l≠i} σ_l.

The element's tangent 𝐂̃ = Σ max(0, eigenvalue)·vec(mode)·vec(mode)ᵀ (9×9, row (i, j) ↔ 3i + j), kept per element
from the last assembly, is built as ∂P/∂F less its modes of negative eigenvalue (the scaling block's eigensystem
only where that block is not positive definite).  Kelvin–Voigt viscosity stiffness-proportional as the
co-rotational law's: P_v = τ·𝐂̃:Ḟ,
Ḟ = Σ v_a ⊗ g_a, τ = η/E, so K_ab·y = −V·(𝐂̃:(y ⊗ g_b))·g_a, D = τ·K, and in A = M − h·D − h²·K the element adds
(h² + h·τ)·V·g_aᵀ·𝐂̃·g_b, whose diagonal blocks are (h² + h·τ)·V·Σ_jl g_a[j]·g_a[l]·𝐂̃[(i, j), (k, l)].
"""
from __future__ import annotations

import math

import numba
import numpy as np

from liver_sim.base.geometry.matrix3 import det3, rotation_variant_svd3, symmetric_eigen3
from liver_sim.physics.tissue.tet_gradient import EVERY_NODE, tet_gradient

#: The pairs (i, j) of singular values of the twist and flip modes, k the third index.
PAIRS = ((1, 2, 0), (0, 2, 1), (0, 1, 2))


@numba.njit(cache=True, inline="always")
def _cofactor(f, out):
    """out ← ∂J/∂F = [f₁×f₂ | f₂×f₀ | f₀×f₁] (columns f_i of the 3×3 `f`); returns J = det F."""
    for j in range(3):
        a, b = (j + 1) % 3, (j + 2) % 3
        out[0, j] = f[1, a] * f[2, b] - f[2, a] * f[1, b]
        out[1, j] = f[2, a] * f[0, b] - f[0, a] * f[2, b]
        out[2, j] = f[0, a] * f[1, b] - f[1, a] * f[0, b]
    return f[0, 0] * out[0, 0] + f[1, 0] * out[1, 0] + f[2, 0] * out[2, 0]


@numba.njit(cache=True)
def first_piola(f, mu, lam_hat, out):
    """out ← P(F) = μ·F + (λ̂·(J − 1) − μ)·∂J/∂F (Pa; `f` 3×3, μ, λ̂ in Pa)."""
    s = lam_hat * (_cofactor(f, out) - 1.0) - mu
    for i in range(3):
        for j in range(3):
            out[i, j] = mu * f[i, j] + s * out[i, j]


@numba.njit(cache=True)
def _singular_block(f, mu, lam_hat, mats, sigma):
    """The SVD of `f` into U = mats[0], σ = `sigma`, V = mats[1] (mats[4] scratch) and the scaling block
    ∂²Ψ/∂σ_i∂σ_j into mats[2]; returns s = λ̂·(J − 1) − μ, J = σ₀σ₁σ₂."""
    block = mats[2]
    rotation_variant_svd3(f, mats[0], sigma, mats[1], mats[4])
    s = lam_hat * (sigma[0] * sigma[1] * sigma[2] - 1.0) - mu
    for i, j, k in PAIRS:
        block[i, j] = lam_hat * sigma[i] * sigma[j] * sigma[k] * sigma[k] + s * sigma[k]
        block[j, i] = block[i, j]
    for i, j, k in PAIRS:
        block[k, k] = mu + lam_hat * (sigma[i] * sigma[j]) ** 2
    return s


@numba.njit(cache=True)
def _mode(m, u, v, q, out):
    """out (9,) ← vec of mode m (the order of `eigensystem`) from U, V and the scaling block's eigenvectors `q`."""
    if m < 3:
        for r in range(3):
            for c in range(3):
                out[3 * r + c] = u[r, 0] * q[0, m] * v[c, 0] + u[r, 1] * q[1, m] * v[c, 1] + u[r, 2] * q[2, m] * v[c, 2]
        return
    i, j, _ = PAIRS[(m - 3) // 2]
    sign = -1.0 if m % 2 else 1.0  # twist (odd m), flip (even m)
    root = 1.0 / math.sqrt(2.0)
    for r in range(3):
        for c in range(3):
            out[3 * r + c] = root * (u[r, i] * v[c, j] + sign * u[r, j] * v[c, i])


@numba.njit(cache=True)
def eigensystem(f, mu, lam_hat, values, modes, mats, vecs):
    """values (9,) Pa and orthonormal modes (rows of `modes`, 9×9, row m = vec(mode m)) of the unprojected tangent at
    `f`: ∂P/∂F = Σ_m values[m]·modes[m]·modes[m]ᵀ; the three scaling modes first, then twist and flip per pair of
    PAIRS (module docstring).  `mats` (5, 3, 3) and `vecs` (2, 3): scratch (U, V, the scaling block, its
    eigenvectors, FᵀF; σ and the block's eigenvalues)."""
    sigma = vecs[0]
    s = _singular_block(f, mu, lam_hat, mats, sigma)
    symmetric_eigen3(mats[2], values[:3], mats[3])
    for p in range(3):
        k = PAIRS[p][2]
        values[3 + 2 * p] = mu + s * sigma[k]
        values[4 + 2 * p] = mu - s * sigma[k]
    for m in range(9):
        _mode(m, mats[0], mats[1], mats[3], modes[m])


@numba.njit(cache=True, inline="always")
def _subtract(w, mode, out):
    """out (9, 9) ← out − w·mode·modeᵀ, keeping it exactly symmetric."""
    for r in range(9):
        for c in range(9):
            out[r, c] -= w * (mode[r] * mode[c])
@numba.njit(cache=True)
def projected_tangent(f, mu, lam_hat, mats, vecs, out):
    """out (9, 9) ← 𝐂̃(F) (Pa), exactly symmetric: the tangent ∂P/∂F = μ·I₉ + λ̂·vec(∂J/∂F)·vec(∂J/∂F)ᵀ + s·∂²J/∂F²,
    ∂²J/∂F_ij∂F_kl = ε_ikm·ε_jln·F_mn, less w·vec(mode)·vec(mode)ᵀ for each mode of `eigensystem` whose eigenvalue
    w < 0 (the scaling block's eigensystem only when the block is not positive definite).  `mats` (5, 3, 3) and
    `vecs` (3, 9): scratch (as `eigensystem`'s, and ∂J/∂F; σ, the block's eigenvalues, a mode)."""
    u, v, block, q, cof = mats[0], mats[1], mats[2], mats[3], mats[4]
    sigma, scale, mode = vecs[0], vecs[1], vecs[2]
    s = _singular_block(f, mu, lam_hat, mats, sigma)
    _cofactor(f, cof)
    for i in range(3):
        for j in range(3):
            for k in range(3):
                for l in range(3):
                    out[3 * i + j, 3 * k + l] = cof[i, j] * cof[k, l] * lam_hat
            out[3 * i + j, 3 * i + j] += mu
    for i, k, m in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):  # ε_ikm = 1: the blocks (i, k) and (k, i) of s·∂²J/∂F²
        for j in range(3):
            l, n = (j + 1) % 3, (j + 2) % 3  # ε_jln = 1
            turn = s * f[m, n]
            out[3 * i + j, 3 * k + l] += turn
            out[3 * k + l, 3 * i + j] += turn
            out[3 * i + l, 3 * k + j] -= turn
            out[3 * k + j, 3 * i + l] -= turn
    for p in range(3):
        k = PAIRS[p][2]
        for m, w in ((3 + 2 * p, mu + s * sigma[k]), (4 + 2 * p, mu - s * sigma[k])):
            if w < 0.0:
                _mode(m, u, v, q, mode)
                _subtract(w, mode, out)
    minor = block[0, 0] * block[1, 1] - block[0, 1] * block[0, 1]
    if minor <= 0.0 or det3(block) <= 0.0:  # block[0, 0] > 0: Sylvester's criterion
        symmetric_eigen3(block, scale, q)
        for m in range(3):
            if scale[m] < 0.0:
                _mode(m, u, v, q, mode)
                _subtract(scale[m], mode, out)


@numba.njit(cache=True, inline="always")
def _contract(tangent, grad):
    """𝐂̃:G as the 9-tuple, (𝐂̃:G)[r] = Σ_c 𝐂̃[r, c]·G[c], summed down the columns of the symmetric `tangent` (9, 9)
    (`grad` G the 9-tuple)."""
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = s8 = 0.0
    for c in range(9):
        gc = grad[c]
        s0 += tangent[c, 0] * gc
        s1 += tangent[c, 1] * gc
        s2 += tangent[c, 2] * gc
        s3 += tangent[c, 3] * gc
        s4 += tangent[c, 4] * gc
        s5 += tangent[c, 5] * gc
        s6 += tangent[c, 6] * gc
        s7 += tangent[c, 7] * gc
        s8 += tangent[c, 8] * gc
    return s0, s1, s2, s3, s4, s5, s6, s7, s8


@numba.njit(cache=True, inline="always")
def _scatter(stress, tet, g, scale, out):
    """out[tet[a]] += scale·S·g_a for the element's nodes (`stress` S the 9-tuple)."""
    for a in range(4):
        n = tet[a]
        ga, gb, gc = g[a, 0], g[a, 1], g[a, 2]
        out[n, 0] += scale * (stress[0] * ga + stress[1] * gb + stress[2] * gc)
        out[n, 1] += scale * (stress[3] * ga + stress[4] * gb + stress[5] * gc)
        out[n, 2] += scale * (stress[6] * ga + stress[7] * gb + stress[8] * gc)


@numba.njit(cache=True)
def neo_hookean_terms(x, v, y, inv_mass, h, law, f, ky, diagonal, assemble_matrix, elements, first, last):
    """Add the forces at (x, v) of the elements elements[first..last−1] (`law`, a fem_kernels.TetArrays of this law)
    to f and K·y to ky (y counted on free nodes only); with assemble_matrix, first each element's projected tangent
    at x (into law.tangent) and the diagonal blocks of (h² + h·τ)·V·g_aᵀ·𝐂̃·g_a to free nodes' `diagonal`.  Without
    it the last tangents are used (for K·y and the viscous stress)."""
    tets, volume, gradients, tangent = law.tets, law.volume_m3, law.gradients, law.tangent
    mu, tau = law.lame_mu_pa, law.viscous_time_s
    lam_hat = law.lame_lambda_pa + mu
    weight = h * h + h * tau
    grad = np.empty((3, 3))
    stress = np.empty((3, 3))
    mats = np.empty((5, 3, 3))
    vecs = np.empty((3, 9))
    for k in range(first, last):
        e = elements[k]
        tet, g, c = tets[e], gradients[e], tangent[e]
        deformation = tet_gradient(x, tet, g, EVERY_NODE)
        for i in range(3):
            for j in range(3):
                grad[i, j] = deformation[3 * i + j]
        if assemble_matrix:
            projected_tangent(grad, mu, lam_hat, mats, vecs, c)
        first_piola(grad, mu, lam_hat, stress)
        if tau != 0.0:
            viscous = _contract(c, tet_gradient(v, tet, g, EVERY_NODE))
            for i in range(3):
                for j in range(3):
                    stress[i, j] += tau * viscous[3 * i + j]
        vol = volume[e]
        _scatter((stress[0, 0], stress[0, 1], stress[0, 2], stress[1, 0], stress[1, 1], stress[1, 2], stress[2, 0],
                  stress[2, 1], stress[2, 2]), tet, g, -vol, f)
        free = (inv_mass[tet[0]] > 0.0, inv_mass[tet[1]] > 0.0, inv_mass[tet[2]] > 0.0, inv_mass[tet[3]] > 0.0)
        probe = tet_gradient(y, tet, g, free)  # Y = Σ y_a ⊗ g_a
        if probe != (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0):
            _scatter(_contract(c, probe), tet, g, -vol, ky)
        if assemble_matrix:
            for a in range(4):
                if free[a]:
                    n = tet[a]
                    for i in range(3):
                        for k in range(3):
                            total = 0.0
                            for j in range(3):
                                row = 0.0
                                for l in range(3):
                                    row += c[3 * i + j, 3 * k + l] * g[a, l]
                                total += g[a, j] * row
                            diagonal[n, i, k] += weight * vol * total


@numba.njit(cache=True)
def neo_hookean_apply(law, weight, p, elements, first, last, out):
    """out += Σ over the elements elements[first..last−1] of weight·V·g_aᵀ·𝐂̃·g_b·p_b (`law` a fem_kernels.TetArrays
    of this law, weight = h² + h·τ; p zero on held nodes): with G = Σ_b p_b ⊗ g_b, node a gets weight·V·(𝐂̃:G)·g_a."""
    tets, volume, gradients, tangent = law.tets, law.volume_m3, law.gradients, law.tangent
    for k in range(first, last):
        e = elements[k]
        tet, g = tets[e], gradients[e]
        _scatter(_contract(tangent[e], tet_gradient(p, tet, g, EVERY_NODE)), tet, g, weight * volume[e], out)
