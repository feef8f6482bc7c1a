"""The co-rotational linear tetrahedra of tissue_law 'fem' (physics.tissue.fem_kernels): Hooke's law under an affine
strain, invariance under rotation, the liver pressed, cut and torn with it."""
import numpy as np
import pytest

from liver_sim.mesh.landmarks import press_anchor, upper_skin_path
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
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


def test_the_liver_with_elements_is_pressed_cut_and_torn():
    mesh = default_liver()
    model = LiverModel(mesh, ModelParams(tissue_law="fem", tearing=True))
    anchor = press_anchor(mesh)
    radius = model.tool.shape.radius_m
    for frame in range(60):
        depth = min(frame, 30) / 30 * 0.01
        result = model.step_frame(ToolPose(anchor + np.array([0.0, 0.0, radius - depth])))
    assert result.divergence is None and result.tool_force_n[2] > 0.05
    assert result.local_model.valid and result.local_model.in_contact
    path = upper_skin_path(mesh, (-0.08, 0.0), (-0.02, 0.0))
    assert model.cut(path, 0.01)
    assert len(model.structure.solver.tets.tets) == len(model.structure.mesh.tets) > len(mesh.tets)
    for _ in range(30):
        result = model.step_frame(None)
    assert result.divergence is None and np.isfinite(model.state.positions).all()


def test_the_elements_need_the_implicit_integrator_and_material_constants():
    with pytest.raises(ValueError, match="tissue_law"):
        ModelParams(tissue_law="fem", integrator="symplectic_euler").validate()
    with pytest.raises(ValueError, match="tissue_law"):
        ModelParams(tissue_law="fem", spring_constants="paper").validate()
    with pytest.raises(ValueError, match="tissue_law"):
        ModelParams(tissue_law="neo_hookean").validate()
