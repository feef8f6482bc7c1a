"""The stable neo-Hookean tetrahedra of tissue_law 'neo_hookean' (physics.tissue.neo_hookean): the stress and the
eigensystem of the tangent against finite differences of the energy, its projection against numpy's, Hooke's law at
rest, the elements' forces beside the co-rotational law's, their system blocks, and the implicit solver on them."""
import numpy as np
import pytest

from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.settings import ModelParams, TissueProperties
from liver_sim.physics.solver import pcg
from liver_sim.physics.solver.implicit import ImplicitEuler
from liver_sim.physics.solver.records import ContactRows, Operator
from liver_sim.physics.tissue.fem_kernels import build_tets, tet_terms
from liver_sim.physics.tissue.neo_hookean import eigensystem, first_piola, projected_tangent
from liver_sim.physics.tissue.springs import build_springs

from meshes import box_mesh

E_PA, NU = 3000.0, 0.45
MU, LAM_HAT = 1.3e3, 5.2e3  # Pa: any pair for the pointwise checks
EPS = 1e-6
NO_ROWS = ContactRows.of(Contacts.none(), np.zeros(0))


def energy(f, mu=MU, lam_hat=LAM_HAT):
    """Ψ(F) of the module docstring (J/m³)."""
    jacobian = np.linalg.det(f)
    return mu / 2.0 * ((f * f).sum() - 3.0) - mu * (jacobian - 1.0) + lam_hat / 2.0 * (jacobian - 1.0) ** 2


def stress(f, mu=MU, lam_hat=LAM_HAT):
    out = np.empty((3, 3))
    first_piola(np.ascontiguousarray(f), mu, lam_hat, out)
    return out


def eigen(f, mu=MU, lam_hat=LAM_HAT):
    """(values (9,), modes as rows of a (9, 9) matrix) of the unprojected tangent."""
    values, modes = np.empty(9), np.empty((9, 9))
    eigensystem(np.ascontiguousarray(f), mu, lam_hat, values, modes, np.empty((5, 3, 3)), np.empty((2, 3)))
    return values, modes


def tangent(f, mu=MU, lam_hat=LAM_HAT):
    out = np.empty((9, 9))
    projected_tangent(np.ascontiguousarray(f), mu, lam_hat, np.empty((5, 3, 3)), np.empty((3, 9)), out)
    return out


def fd_hessian(f):
    """∂P/∂F (9, 9, row (i, j) ↔ 3i + j) by central differences of P."""
    columns = []
    for c in range(9):
        d = np.zeros(9)
        d[c] = EPS * max(1.0, np.abs(f).max())
        d = d.reshape(3, 3)
        columns.append(((stress(f + d) - stress(f - d)) / (2.0 * d.max())).ravel())
    return np.array(columns).T


def deformations():
    """Random F about I, every other one inverted (a column reversed: J < 0), and a degenerate one (J = 0)."""
    rng = np.random.default_rng(3)
    out = []
    for k in range(10):
        f = np.eye(3) + 0.6 * rng.normal(size=(3, 3))
        if k % 2:
            f[:, 1] *= -1.0 if np.linalg.det(f) > 0.0 else 1.0
        out.append(f)
    out.append(np.diag([1.2, 0.7, 0.0]))
    return out


def hooke(lam, mu):
    """Hooke's tangent C[(i, j), (k, l)] = λ·δ_ij·δ_kl + μ·(δ_ik·δ_jl + δ_il·δ_jk)."""
    eye = np.eye(3)
    return (lam * np.einsum("ij,kl->ijkl", eye, eye) + mu * (np.einsum("ik,jl->ijkl", eye, eye)
                                                              + np.einsum("il,jk->ijkl", eye, eye))).reshape(9, 9)


def test_the_stress_is_the_gradient_of_the_energy():
    for f in deformations():
        numeric = np.zeros((3, 3))
        for i in range(3):
            for j in range(3):
                d = np.zeros((3, 3))
                d[i, j] = EPS
                numeric[i, j] = (energy(f + d) - energy(f - d)) / (2.0 * EPS)
        np.testing.assert_allclose(stress(f), numeric, atol=1e-7 * np.abs(numeric).max())


def test_the_eigensystem_rebuilds_the_finite_difference_hessian_also_inverted():
    for f in deformations():
        values, modes = eigen(f)
        np.testing.assert_allclose(modes @ modes.T, np.eye(9), atol=1e-12)  # orthonormal modes
        numeric = fd_hessian(f)
        np.testing.assert_allclose(modes.T @ np.diag(values) @ modes, numeric, atol=1e-7 * np.abs(numeric).max())


def test_the_projected_tangent_is_numpys_eigen_projection_and_semi_definite():
    clamped = 0
    for f in deformations():
        numeric = fd_hessian(f)
        w, q = np.linalg.eigh(0.5 * (numeric + numeric.T))
        clamped += int((w < 0.0).sum())
        expected = q @ np.diag(np.maximum(w, 0.0)) @ q.T
        projected = tangent(f)
        np.testing.assert_allclose(projected, expected, atol=1e-8 * np.abs(expected).max())
        np.testing.assert_array_equal(projected, projected.T)
        assert np.linalg.eigvalsh(projected).min() > -1e-12 * np.abs(projected).max()
    assert clamped > 0  # the projection was put to work


def test_the_projected_tangent_is_the_eigensystems_clamped_sum_to_rounding():
    # ∂P/∂F less its negative modes against Σ max(0, w)·q·qᵀ over the analytic eigensystem, on F near rest,
    # compressed, stretched, sheared, inverted (J < 0) and flat (J = 0), with a compressible and a stiff λ̂
    rng = np.random.default_rng(12)
    turns = [np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(6)]
    fs = [np.eye(3), np.diag([1.0, 1.0, 1e-3]), np.diag([1.2, 0.7, 0.0])]
    for turn in turns:
        fs += [np.eye(3) + 1e-4 * rng.normal(size=(3, 3)), np.diag(rng.uniform(0.2, 0.9, 3)) @ turn,
               np.diag(rng.uniform(1.1, 3.0, 3)) @ turn, rng.normal(size=(3, 3)),
               np.diag([1.3, 0.8, -0.4]) @ turn, np.diag([-0.5, -0.6, -0.7]) @ turn]
    clamped = {"twist or flip": 0, "scaling": 0}
    for lam_hat in (LAM_HAT, 40.0 * MU):
        for f in fs:
            values, modes = eigen(f, lam_hat=lam_hat)
            clamped["scaling"] += int((values[:3] < 0.0).sum())
            clamped["twist or flip"] += int((values[3:] < 0.0).sum())
            expected = modes.T @ np.diag(np.maximum(values, 0.0)) @ modes
            projected = tangent(f, lam_hat=lam_hat)
            np.testing.assert_allclose(projected, expected, atol=1e-13 * np.abs(expected).max())
            np.testing.assert_array_equal(projected, projected.T)
    assert min(clamped.values()) > 0  # both kinds of correction were put to work


def test_at_rest_the_law_is_hookes_with_the_small_strain_lame_constants():
    lam = LAM_HAT - MU
    np.testing.assert_array_equal(stress(np.eye(3)), np.zeros((3, 3)))  # rest-stable
    np.testing.assert_allclose(tangent(np.eye(3)), hooke(lam, MU), atol=1e-12 * LAM_HAT)
    np.testing.assert_allclose(fd_hessian(np.eye(3)), hooke(lam, MU), atol=1e-7 * LAM_HAT)


def operator_without_springs(n, tets):
    """A records.Operator of n nodes and the elements `tets`, no spring and a zero shift: pcg.apply gives the
    elements' part alone."""
    op = Operator.allocate(np.zeros(0, np.uint32), np.zeros(0, np.uint32), n, tets)
    op.shift[:] = 0.0
    return op


def element_forces(mesh, x, law="neo_hookean", nu=NU, viscosity=0.0):
    """f(x) (N, 3) of the elements alone (no capsule, every node held so nothing is solved)."""
    params = ModelParams(tissue_law=law, tissue=TissueProperties(
        parenchyma_young_modulus_kpa=E_PA / 1e3, parenchyma_poisson_ratio=nu, parenchyma_viscosity_pa_s=viscosity,
        capsule_stiffness_n_per_m=0.0))
    springs = build_springs(mesh, params)
    assert springs.parenchyma_springs == 0 and not springs.lambda2_n.any()  # the parenchyma is the elements'
    tets = build_tets(mesh.points, mesh.tets, E_PA, nu, viscosity, neo_hookean=law == "neo_hookean")
    solver = ImplicitEuler(springs, len(x), tets=tets)
    return solver.equilibrium(x.copy(), np.zeros(len(x)), np.zeros_like(x), 1.0)


def rotation():
    angle = np.radians(70.0)
    about_z = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    return about_z @ np.array([[1.0, 0.0, 0.0], [0.0, np.cos(1.0), -np.sin(1.0)], [0.0, np.sin(1.0), np.cos(1.0)]])


def test_a_block_at_rest_or_turned_rigidly_feels_no_force():
    mesh = box_mesh(2, 2, 3, 0.005)
    assert np.abs(element_forces(mesh, mesh.points)).max() < 1e-12  # F = I to the gradients' rounding
    assert np.abs(element_forces(mesh, mesh.points @ rotation().T + 0.3)).max() < 1e-9


def test_a_rotated_strained_block_feels_the_same_forces_rotated():
    mesh = box_mesh(2, 2, 4, 0.005)
    x = mesh.points + np.random.default_rng(5).normal(scale=5e-4, size=mesh.points.shape)
    f = element_forces(mesh, x)
    turned = element_forces(mesh, x @ rotation().T + 0.3)
    np.testing.assert_allclose(turned, f @ rotation().T, atol=1e-9 * np.abs(f).max())


def test_at_small_strain_the_forces_are_the_co_rotational_laws():
    mesh = box_mesh(2, 2, 3, 0.005)
    x = mesh.points + np.random.default_rng(6).normal(scale=1e-6 * 0.005, size=mesh.points.shape)
    x = x @ rotation().T
    corotational = element_forces(mesh, x, "fem")
    # the laws differ at second order in the strain (1e-6): relative 1e-6, beside rounding
    np.testing.assert_allclose(element_forces(mesh, x), corotational, atol=1e-5 * np.abs(corotational).max())


def face_piola(mesh, f):
    """(P_xx, P_zz) Pa of an affine diagonal field from the elements' forces on the block's x = max and z = max faces:
    the load that holds a face is −Σ f = P·N·(rest area)."""
    points = mesh.points
    width, depth, height = points.max(axis=0)
    on_x, on_z = points[:, 0] > width - 1e-9, points[:, 2] > height - 1e-9
    return -f[on_x, 0].sum() / (depth * height), -f[on_z, 2].sum() / (width * depth)


def test_an_isochoric_stretch_leaves_no_bulk_pressure_where_the_co_rotational_law_has_one():
    # F = diag(1/√s, 1/√s, s), J = 1: the neo-Hookean Cauchy stress σ = P·Fᵀ/J = μ·(B − I) + (λ̂·(J − 1) − μ + μ)·I
    # = μ·(B − I), no λ in it; the co-rotational law's σ(ε) (R = I, ε = F − I) has the mean (λ + 2μ/3)·tr ε with
    # tr ε = s + 2/√s − 3 ≈ ¾·(s − 1)² > 0: a pressure of the bulk modulus, spurious for a volume-preserving motion.
    mesh = box_mesh(2, 2, 2, 0.005)
    s, nu = 1.3, 0.49
    x = mesh.points * [1.0 / np.sqrt(s), 1.0 / np.sqrt(s), s]
    lam, mu = E_PA * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E_PA / (2.0 * (1.0 + nu))
    p_xx, p_zz = face_piola(mesh, element_forces(mesh, x, nu=nu))
    sigma_xx, sigma_zz = p_xx / np.sqrt(s), p_zz * s
    assert sigma_xx == pytest.approx(mu * (1.0 / s - 1.0), rel=1e-9)
    assert sigma_zz == pytest.approx(mu * (s * s - 1.0), rel=1e-9)
    pressure = (2.0 * sigma_xx + sigma_zz) / 3.0
    assert pressure == pytest.approx(mu * (s * s + 2.0 / s - 3.0) / 3.0, rel=1e-9)
    trace = s + 2.0 / np.sqrt(s) - 3.0
    assert trace == pytest.approx(0.75 * (s - 1.0) ** 2, rel=0.25)
    fem_xx, fem_zz = face_piola(mesh, element_forces(mesh, x, "fem", nu=nu))
    corotational = (2.0 * fem_xx + fem_zz) / 3.0
    assert corotational == pytest.approx((lam + 2.0 * mu / 3.0) * trace, rel=1e-9)
    assert corotational > 10.0 * pressure


def test_the_system_blocks_are_the_tangents_k_times_y_and_its_diagonal():
    # pcg.apply's element part is (h² + h·τ)·(−K) of tet_terms' K·y, and its diagonal blocks tet_terms' `diagonal`
    mesh = box_mesh(2, 1, 1, 0.01)
    law = build_tets(mesh.points, mesh.tets, E_PA, NU, 600.0, neo_hookean=True)
    rng = np.random.default_rng(8)
    x = mesh.points + rng.normal(scale=3e-3, size=mesh.points.shape)
    x[0] = x[1] + [0.0, 0.0, 0.002]  # a flattened or inverted element or two
    n, h = len(x), 1e-2
    inv_mass = np.ones(n)
    inv_mass[2] = 0.0
    zero = np.zeros((n, 3))
    f, ky, diagonal = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3))
    tet_terms(x, zero, zero, inv_mass, h, law, f, ky, diagonal, True, np.arange(len(law.tets)), 0, len(law.tets))
    weight = h * h + h * law.viscous_time_s
    dense = np.zeros((3 * n, 3 * n))
    for k in range(3 * n):
        p = np.zeros((n, 3))
        p.flat[k] = 1.0
        p[inv_mass == 0.0] = 0.0
        out = np.zeros((n, 3))
        pcg.apply(operator_without_springs(n, law.tets), inv_mass, NO_ROWS, law, weight, p, out)
        dense[:, k] = out.ravel()
    y = rng.normal(size=(n, 3))
    y[inv_mass == 0.0] = 0.0
    ky[:] = 0.0
    tet_terms(x, zero, y, inv_mass, h, law, np.zeros((n, 3)), ky, np.zeros((n, 3, 3)), False, np.arange(len(law.tets)),
              0, len(law.tets))
    ky[inv_mass == 0.0] = 0.0
    np.testing.assert_allclose(dense @ y.ravel(), -weight * ky.ravel(), atol=1e-12 * np.abs(dense).max())
    blocks = np.array([dense[3 * a:3 * a + 3, 3 * a:3 * a + 3] for a in range(n)])
    np.testing.assert_allclose(diagonal[inv_mass > 0.0], blocks[inv_mass > 0.0], atol=1e-12 * np.abs(dense).max())
    assert np.linalg.eigvalsh(dense).min() > -1e-12 * np.abs(dense).max()  # positive semi-definite


def test_a_block_stretched_at_its_ends_settles_to_hookes_force():
    # the ends held at the affine uniaxial field z·(1 + ε), (x, y)·(1 − ν·ε): the inside, started at rest, must come
    # to that field and the ends pull back with E·A·ε, to the law's second order in ε
    mesh = box_mesh(2, 2, 4, 0.005)
    strain = 1e-3
    z = mesh.points[:, 2]
    top, bottom = z > z.max() - 1e-9, z < 1e-9
    target = mesh.points * [1.0 - NU * strain, 1.0 - NU * strain, 1.0 + strain]
    x = mesh.points.copy()
    x[top | bottom] = target[top | bottom]
    inv_mass = np.where(top | bottom, 0.0, 1.0 / mesh.lumped_masses(1060.0))
    params = ModelParams(tissue_law="neo_hookean", tissue=TissueProperties(
        parenchyma_young_modulus_kpa=E_PA / 1e3, parenchyma_poisson_ratio=NU, capsule_stiffness_n_per_m=0.0))
    solver = ImplicitEuler(build_springs(mesh, params), len(x),
                           tets=build_tets(mesh.points, mesh.tets, E_PA, NU, 0.0, neo_hookean=True))
    f = solver.equilibrium(x, inv_mass, np.zeros_like(x), 1e-9)
    np.testing.assert_allclose(x, target, atol=1e-3 * strain * z.max())
    area = mesh.points[:, 0].max() * mesh.points[:, 1].max()
    assert -f[top, 2].sum() == pytest.approx(E_PA * area * strain, rel=3e-3)
    assert f[bottom, 2].sum() == pytest.approx(-f[top, 2].sum(), rel=1e-6)


def test_the_implicit_step_converges_on_the_elements():
    # a bar held at one end sagging under gravity, with viscosity: every step within the Newton tolerance
    mesh = box_mesh(4, 1, 1, 0.01)
    params = ModelParams(tissue_law="neo_hookean")
    tissue = params.tissue
    law = build_tets(mesh.points, mesh.tets, tissue.parenchyma_young_modulus_kpa * 1e3,
                     tissue.parenchyma_poisson_ratio, tissue.parenchyma_viscosity_pa_s, neo_hookean=True)
    solver = ImplicitEuler(build_springs(mesh, params), len(mesh.points), tets=law, newton_tolerance_n=1e-6,
                           max_newton=8)
    history = solver.new_history()
    x, v = mesh.points.copy(), np.zeros_like(mesh.points)
    inv_mass = np.where(mesh.points[:, 0] < 1e-9, 0.0, 1.0 / mesh.lumped_masses(1060.0))
    for _ in range(30):
        solver.step(history, x, v, inv_mass, np.zeros_like(x), 1.0 / 150.0, 3.0, np.array([0.0, 0.0, -9.81]))
        assert history.residual_n <= 1e-6 and history.newton_iterations < 8
    assert np.isfinite(x).all() and x[:, 2].min() < -1e-4  # it sags
    np.testing.assert_array_equal(history.rotations, solver.new_history().rotations)  # no rotations of its own
