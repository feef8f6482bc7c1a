"""The co-rotational linear tetrahedra of tissue_law 'fem' (physics.tissue.fem_kernels): an element's rest arrays by
hand, Hooke's law under an affine strain, invariance under rotation."""
import numpy as np
import pytest

from liver_sim.physics.settings import ModelParams, TissueProperties
from liver_sim.physics.solver.implicit import ImplicitEuler
from liver_sim.physics.tissue.fem_kernels import build_tets
from liver_sim.physics.tissue.springs import build_springs

from meshes import box_mesh

E_PA, NU = 3000.0, 0.45


def element_forces(mesh, x, nu=NU, viscosity=0.0):
    """f(x) (N, 3) of the elements alone (no capsule, every node held so nothing is solved)."""
    params = ModelParams(tissue_law="fem", tissue=TissueProperties(
        parenchyma_young_modulus_kpa=E_PA / 1e3, parenchyma_poisson_ratio=nu, parenchyma_viscosity_pa_s=viscosity,
        capsule_stiffness_n_per_m=0.0))
    springs = build_springs(mesh, params)
    assert springs.parenchyma_springs == 0 and not springs.lambda2_n.any()  # the parenchyma is the elements'
    solver = ImplicitEuler(springs, len(x), tets=build_tets(mesh.points, mesh.tets, E_PA, nu, viscosity))
    return solver.equilibrium(x.copy(), np.zeros(len(x)), np.zeros_like(x), 1.0)


def uniaxial(mesh, strain, nu=NU):
    """The affine field of uniaxial stress along z: z·(1 + ε), x, y·(1 − ν·ε)."""
    x = mesh.points.copy()
    x[:, :2] *= 1.0 - nu * strain
    x[:, 2] *= 1.0 + strain
    return x


def test_an_affine_uniaxial_strain_loads_only_the_ends_with_hookes_force():
    mesh = box_mesh(3, 3, 6, 0.005)
    strain = 1e-3
    f = element_forces(mesh, uniaxial(mesh, strain))
    z = mesh.points[:, 2]
    top = z > z.max() - 1e-9
    inner = (z > 1e-9) & ~top
    side = mesh.points[:, 0].max()
    assert np.abs(f[inner]).max() < 1e-6 * E_PA * side ** 2 * strain
    assert -f[top, 2].sum() == pytest.approx(E_PA * side ** 2 * strain, rel=2e-3)  # the ends pull back
    np.testing.assert_allclose(f[top, :2].sum(axis=0), 0.0, atol=1e-9)


def test_a_rotated_strained_block_feels_the_same_forces_rotated():
    mesh = box_mesh(2, 2, 4, 0.005)
    x = uniaxial(mesh, 0.01)
    angle = np.radians(70.0)
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    rotation = rotation @ np.array([[1.0, 0.0, 0.0], [0.0, np.cos(1.0), -np.sin(1.0)], [0.0, np.sin(1.0), np.cos(1.0)]])
    f = element_forces(mesh, x)
    turned = element_forces(mesh, x @ rotation.T + 0.3)
    np.testing.assert_allclose(turned, f @ rotation.T, atol=1e-6 * np.abs(f).max())
    assert np.abs(element_forces(mesh, mesh.points @ rotation.T)).max() < 1e-9  # a rigid motion: no force




def test_an_elements_rest_arrays_by_hand():
    # the unit corner tet: V = 1/6, g_1..3 = the axes, g_0 = −(1, 1, 1); E = 3 kPa, ν = 0.25: λ = μ = 1.2 kPa
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    law = build_tets(points, np.array([[0, 1, 2, 3]]), 3000.0, 0.25, 600.0)
    assert law.volume_m3[0] == pytest.approx(1.0 / 6.0)
    np.testing.assert_allclose(law.gradients[0], [[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                                                  [0.0, 0.0, 1.0]], atol=1e-15)
    assert law.lame_lambda_pa == pytest.approx(1200.0) and law.lame_mu_pa == pytest.approx(1200.0)
    assert law.viscous_time_s == pytest.approx(0.2)  # τ = η/E
    np.testing.assert_array_equal(law.quaternion, [[0.0, 0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(law.rotation, [np.eye(3)])
    assert build_tets(points, np.array([[0, 1, 2, 3]]), 0.0, 0.25, 600.0).viscous_time_s == 0.0


def test_the_gradients_reproduce_an_affine_field():
    # F = Σ x_a ⊗ g_a is the affine map itself, on any tet
    mesh = box_mesh(1, 1, 1, 0.01)
    law = build_tets(mesh.points, mesh.tets, 1.0, 0.3, 0.0)
    linear = np.array([[1.1, 0.2, 0.0], [-0.1, 0.9, 0.3], [0.05, 0.0, 1.2]])
    moved = mesh.points @ linear.T + [0.01, 0.02, 0.03]
    deformation = np.einsum("tai,taj->tij", moved[law.tets], law.gradients)
    np.testing.assert_allclose(deformation, np.broadcast_to(linear, deformation.shape), atol=1e-12)
    np.testing.assert_allclose(law.volume_m3.sum(), mesh.volume)
