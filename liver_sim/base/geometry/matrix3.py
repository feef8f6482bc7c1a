"""3×3 decompositions inside numba kernels, without allocating: the eigensystem of a symmetric matrix (cyclic Jacobi
rotations) and the rotation-variant singular value decomposition built on it.

Per element of a mesh, numpy's `np.linalg.eigh`, `svd` and `det` each allocate their results and call LAPACK, which
costs several times the arithmetic of a 3×3 matrix; these work in the caller's arrays.
"""
from __future__ import annotations

import math

import numba

#: Jacobi sweeps at most, and the off-diagonal size (relative to the matrix's) at which they stop.
JACOBI_SWEEPS = 12
JACOBI_TOLERANCE = 1e-15


@numba.njit(cache=True)
def symmetric_eigen3(a, values, vectors):
    """values (3,) ascending and orthonormal eigenvectors (the columns of `vectors`, 3×3, det +1) of the symmetric
    3×3 `a` (left unchanged): a = vectors·diag(values)·vectorsᵀ, by cyclic Jacobi rotations until the off-diagonal
    part is below JACOBI_TOLERANCE of the matrix's size."""
    m00, m01, m02, m11, m12, m22 = a[0, 0], a[0, 1], a[0, 2], a[1, 1], a[1, 2], a[2, 2]
    for i in range(3):
        for j in range(3):
            vectors[i, j] = 1.0 if i == j else 0.0
    scale = abs(m00) + abs(m11) + abs(m22) + abs(m01) + abs(m02) + abs(m12)
    for _ in range(JACOBI_SWEEPS):
        if abs(m01) + abs(m02) + abs(m12) <= JACOBI_TOLERANCE * scale:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            if p == 0 and q == 1:
                app, aqq, apq = m00, m11, m01
            elif p == 0:
                app, aqq, apq = m00, m22, m02
            else:
                app, aqq, apq = m11, m22, m12
            if apq == 0.0:
                continue
            half = 0.5 * (aqq - app)  # t = sgn(θ)/(|θ| + √(θ² + 1)), θ = half/apq, with one division
            t = math.copysign(1.0, half) * apq / (abs(half) + math.sqrt(half * half + apq * apq))
            c = 1.0 / math.sqrt(t * t + 1.0)
            s = t * c
            # A ← Jᵀ·A·J with J the rotation in the (p, q) plane that zeroes a_pq
            if p == 0 and q == 1:
                m00, m11, m01 = app - t * apq, aqq + t * apq, 0.0
                m02, m12 = c * m02 - s * m12, s * m02 + c * m12
            elif p == 0:
                m00, m22, m02 = app - t * apq, aqq + t * apq, 0.0
                m01, m12 = c * m01 - s * m12, s * m01 + c * m12
            else:
                m11, m22, m12 = app - t * apq, aqq + t * apq, 0.0
                m01, m02 = c * m01 - s * m02, s * m01 + c * m02
            for k in range(3):
                vp, vq = vectors[k, p], vectors[k, q]
                vectors[k, p] = c * vp - s * vq
                vectors[k, q] = s * vp + c * vq
    values[0], values[1], values[2] = m00, m11, m22
    for i in range(2):  # ascending, the columns with them (a swap flips det; fixed below)
        for j in range(2 - i):
            if values[j] > values[j + 1]:
                values[j], values[j + 1] = values[j + 1], values[j]
                for k in range(3):
                    vectors[k, j], vectors[k, j + 1] = vectors[k, j + 1], vectors[k, j]
    if det3(vectors) < 0.0:
        for k in range(3):
            vectors[k, 2] = -vectors[k, 2]


@numba.njit(cache=True, inline="always")
def det3(m):
    """det of the 3×3 `m`."""
    return (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
            + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))


@numba.njit(cache=True)
def rotation_variant_svd3(f, u, sigma, v, scratch):
    """F = U·diag(σ)·Vᵀ for the 3×3 `f`, U and V rotations (det +1), σ descending in magnitude with σ₂ carrying the
    sign of det F (an inverted element has σ₂ < 0): V and σ² the eigensystem of FᵀF (symmetric_eigen3, `scratch`
    3×3 for FᵀF), u_i = F·v_i/σ_i for the two largest, u₂ = u₀ × u₁, σ₂ = u₂ᵀ·F·v₂.  A rank-deficient F gets unit
    columns of U orthogonal to the others where F·v_i vanishes."""
    for i in range(3):
        for j in range(3):
            scratch[i, j] = f[0, i] * f[0, j] + f[1, i] * f[1, j] + f[2, i] * f[2, j]
    symmetric_eigen3(scratch, sigma, v)
    for j in range(3):  # descending: reverse the columns (det unchanged: a swap of two, the middle stays)
        v[j, 0], v[j, 2] = v[j, 2], v[j, 0]
    for k in range(3):
        v[k, 2] = -v[k, 2]  # the swap flipped det V; restore +1
    for i in range(2):
        fx = f[0, 0] * v[0, i] + f[0, 1] * v[1, i] + f[0, 2] * v[2, i]
        fy = f[1, 0] * v[0, i] + f[1, 1] * v[1, i] + f[1, 2] * v[2, i]
        fz = f[2, 0] * v[0, i] + f[2, 1] * v[1, i] + f[2, 2] * v[2, i]
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        if i == 1:  # orthogonal to u₀ exactly, against rounding
            dot = fx * u[0, 0] + fy * u[1, 0] + fz * u[2, 0]
            fx, fy, fz = fx - dot * u[0, 0], fy - dot * u[1, 0], fz - dot * u[2, 0]
            norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        sigma[i] = norm
        if norm <= 1e-300:
            _unit_orthogonal(u, i)
        else:
            u[0, i], u[1, i], u[2, i] = fx / norm, fy / norm, fz / norm
    u[0, 2] = u[1, 0] * u[2, 1] - u[2, 0] * u[1, 1]
    u[1, 2] = u[2, 0] * u[0, 1] - u[0, 0] * u[2, 1]
    u[2, 2] = u[0, 0] * u[1, 1] - u[1, 0] * u[0, 1]
    sigma[2] = 0.0
    for r in range(3):
        sigma[2] += u[r, 2] * (f[r, 0] * v[0, 2] + f[r, 1] * v[1, 2] + f[r, 2] * v[2, 2])


@numba.njit(cache=True, inline="always")
def _unit_orthogonal(u, i):
    """Column i of `u` ← a unit vector orthogonal to column 0 (i = 1), or the x axis (i = 0)."""
    if i == 0:
        u[0, 0], u[1, 0], u[2, 0] = 1.0, 0.0, 0.0
        return
    ax, ay, az = u[0, 0], u[1, 0], u[2, 0]
    if abs(ax) < 0.9:  # x × u₀, normalised
        cx, cy, cz = 0.0, -az, ay
    else:  # y × u₀
        cx, cy, cz = az, 0.0, -ax
    norm = math.sqrt(cx * cx + cy * cy + cz * cz)
    u[0, 1], u[1, 1], u[2, 1] = cx / norm, cy / norm, cz / norm
