"""3×3 decompositions without allocation (liver_sim.base.geometry.matrix3): the symmetric eigensystem and the
rotation-variant SVD against numpy's, on random, repeated-eigenvalue, inverted and rank-deficient matrices."""
import numpy as np
import pytest

from liver_sim.base.geometry.matrix3 import rotation_variant_svd3, symmetric_eigen3


def symmetric_cases():
    rng = np.random.default_rng(3)
    cases = [np.diag([3.0, 1.0, 2.0]), np.eye(3), np.zeros((3, 3)), np.diag([2.0, 2.0, -1.0])]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    cases.append(q @ np.diag([1.0, 1.0, 5.0]) @ q.T)  # a repeated eigenvalue, rotated
    for _ in range(50):
        m = rng.normal(size=(3, 3))
        cases.append(m + m.T)
    return cases


@pytest.mark.parametrize("a", symmetric_cases())
def test_the_symmetric_eigensystem_is_numpys(a):
    values, vectors = np.empty(3), np.empty((3, 3))
    before = a.copy()
    symmetric_eigen3(a, values, vectors)
    np.testing.assert_array_equal(a, before)
    scale = max(np.abs(a).max(), 1.0)
    np.testing.assert_allclose(values, np.linalg.eigvalsh(a), atol=1e-13 * scale)
    np.testing.assert_allclose(vectors @ np.diag(values) @ vectors.T, a, atol=1e-13 * scale)
    np.testing.assert_allclose(vectors.T @ vectors, np.eye(3), atol=1e-13)
    assert np.linalg.det(vectors) == pytest.approx(1.0)


def general_cases():
    rng = np.random.default_rng(4)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rotation = q * np.sign(np.linalg.det(q))
    cases = [np.eye(3), rotation, np.zeros((3, 3)), np.diag([1.0, 1.0, -1.0]), np.diag([2.0, 0.0, 0.0]),
             np.outer([1.0, 2.0, 3.0], [0.5, -1.0, 2.0]),  # rank 1
             rotation @ np.diag([1.3, 0.7, 0.0])]  # rank 2 (a flattened element)
    for _ in range(50):
        cases.append(np.eye(3) + 0.4 * rng.normal(size=(3, 3)))
        cases.append(rng.normal(size=(3, 3)))  # inverted about half the time
    return cases


@pytest.mark.parametrize("f", general_cases())
def test_the_rotation_variant_svd_rebuilds_f_with_rotations_and_the_sign_of_its_determinant(f):
    u, sigma, v, scratch = np.empty((3, 3)), np.empty(3), np.empty((3, 3)), np.empty((3, 3))
    rotation_variant_svd3(np.ascontiguousarray(f), u, sigma, v, scratch)
    scale = max(np.abs(f).max(), 1.0)
    np.testing.assert_allclose(u @ np.diag(sigma) @ v.T, f, atol=1e-12 * scale)
    for rotation in (u, v):
        np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
        assert np.linalg.det(rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(np.abs(sigma), np.linalg.svd(f, compute_uv=False), atol=1e-12 * scale)
    assert sigma[0] >= sigma[1] >= abs(sigma[2]) - 1e-12 * scale
    assert sigma[0] >= 0.0 and sigma[1] >= 0.0
    if abs(np.linalg.det(f)) > 1e-9:
        assert np.sign(sigma[2]) == np.sign(np.linalg.det(f))
