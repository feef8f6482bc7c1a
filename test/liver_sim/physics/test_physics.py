"""The physics core: Eq. 1, both integrators, kernels against the NumPy oracle, damping, divergence guard."""
import math

import numba
import numpy as np
import pytest

from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import FIG2_LAW, ModelParams, SpringLaw
from liver_sim.physics.solver import explicit_kernels, reference
from liver_sim.physics.structure import default_fixed_nodes
from liver_sim.physics.tissue import spring_law
from liver_sim.physics.tissue.springs import build_springs

from meshes import box_mesh, kinetic_energy_j


@pytest.mark.parametrize("strain, expected", [(0.0, 0.0), (0.1, 0.085), (0.2, 0.47), (-0.1, -0.085), (0.3, 1.455)])
def test_spring_law_matches_fig2(strain, expected):
    # Fig. 2: λ1 = 50, λ2 = 0.35; F = 50·d³ + 0.35·d
    assert FIG2_LAW.force_n(strain) == pytest.approx(expected)


def test_spring_law_is_linear_below_ten_percent_and_stiffens_beyond():
    small = FIG2_LAW.force_n(0.01) / 0.01
    assert small == pytest.approx(FIG2_LAW.lambda2_n, rel=0.02)
    slope_at = lambda d: (FIG2_LAW.force_n(d + 1e-6) - FIG2_LAW.force_n(d - 1e-6)) / 2e-6  # noqa: E731
    assert slope_at(0.3) > 10 * slope_at(0.0)


def test_spring_law_viscous_term():
    law = SpringLaw(lambda1_n=0.0, lambda2_n=0.0, mu_ns_per_m=2.0)
    assert law.force_n(0.0, 0.5) == pytest.approx(1.0)


def two_node_state():
    """Two 0.5 kg nodes on x, rest length 1 m, stretched to 1.1 m, at rest."""
    x = np.array([[0.0, 0.0, 0.0], [1.1, 0.0, 0.0]])
    v = np.zeros((2, 3))
    law = spring_law.SpringArrays(node_i=np.array([0]), node_j=np.array([1]), inv_rest_per_m=np.array([1.0]),
                                  lambda1_n=np.array([50.0]), lambda2_n=np.array([0.35]), mu_ns_per_m=np.array([0.0]))
    return x, v, law


def test_spring_kernel_force_by_hand():
    x, v, law = two_node_state()
    f = np.zeros((2, 3))
    spring_law.spring_forces_serial(x, v, law, f)
    np.testing.assert_allclose(f, [[0.085, 0, 0], [-0.085, 0, 0]])


@pytest.mark.parametrize("symplectic", [False, True])
def test_integrators_by_hand(symplectic):
    x = np.array([[0.0, 0.0, 0.0]])
    v = np.array([[1.0, 0.0, 0.0]])
    f = np.array([[2.0, 0.0, 0.0]])
    dt, mass = 0.1, 0.5
    explicit_kernels.integrate(x, v, f, np.array([1.0 / mass]), dt, 0.0, np.zeros(3), symplectic)
    # a = 4 m/s²: v ← 1 + 0.1·4 = 1.4; x ← 0.1·v_old = 0.1 (Eq. 2) or 0.1·v_new = 0.14
    assert v[0, 0] == pytest.approx(1.4)
    assert x[0, 0] == pytest.approx(0.14 if symplectic else 0.1)


def test_integrate_applies_gravity_environment_damping_and_fixed_nodes():
    x = np.zeros((2, 3))
    v = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    explicit_kernels.integrate(x, v, np.zeros((2, 3)), np.array([1.0, 0.0]), 0.1, 2.0, np.array([0.0, 0.0, -9.81]),
                               True)
    np.testing.assert_allclose(v[0], [1.0 - 0.1 * 2.0, 0.0, -0.981])
    np.testing.assert_allclose(v[1], [1.0, 0.0, 0.0])  # fixed: untouched
    np.testing.assert_allclose(x[1], 0.0)


#: The box is held as in the paper's scene (its central tet fixed), which these tests are written for.
PAPER_SCENE = ModelParams(support="paper")


@pytest.fixture(scope="module")
def box():
    return box_mesh(4, 3, 3, 0.02)


def perturbed_state(mesh, seed=1):
    rng = np.random.default_rng(seed)
    x = mesh.points + rng.normal(scale=0.003, size=mesh.points.shape)
    v = rng.normal(scale=0.05, size=mesh.points.shape)
    return x, v


@pytest.mark.parametrize("parallel", [False, True])
def test_spring_kernels_equal_numpy_oracle(box, parallel):
    springs = build_springs(box, ModelParams())
    x, v = perturbed_state(box)
    f = np.zeros_like(x)
    law = spring_law.spring_arrays(springs)
    if parallel:
        spring_law.spring_forces_parallel(x, v, law, np.zeros((3, len(x), 3)), f)
    else:
        spring_law.spring_forces_serial(x, v, law, f)
    expected = reference.spring_forces(x, v, springs)
    assert np.abs(expected).max() > 0.1
    np.testing.assert_allclose(f, expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("integrator", ["explicit_euler", "symplectic_euler"])
@pytest.mark.parametrize("solver_threads", ["one", "all"])
def test_model_frame_equals_numpy_oracle_steps(box, integrator, solver_threads):
    params = ModelParams(integrator=integrator, substeps=1, environment_damping_per_s=1.5,
                         gravity_m_s2=(0.0, 0.0, -9.81), spring_constants="paper")
    stable = LiverModel(box, params).structure.stable_dt_s
    params = params.with_changes(substeps=math.ceil(1.0 / (150.0 * 0.9 * stable)))
    model = LiverModel(box, params.with_changes(solver_threads=solver_threads))
    x, v = perturbed_state(box)
    model.state.positions[:], model.state.velocities[:] = x, v
    model.step_frame(None)
    for _ in range(params.substeps):
        x, v = reference.step(x, v, model.structure.springs, model.state.inv_mass, params.dt_s, 1.5,
                              params.gravity_m_s2, integrator, model.structure.support)
    np.testing.assert_allclose(model.state.positions, x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(model.state.velocities, v, rtol=1e-9, atol=1e-12)


def total_energy(model):
    """Kinetic plus the elastic energy of the springs' λ2 and λ1 terms: ∫(λ1 d³ + λ2 d) l0 dd."""
    s = model.structure.springs
    length = np.linalg.norm(model.state.positions[s.node_j] - model.state.positions[s.node_i], axis=1)
    d = (length - s.rest_length_m) / s.rest_length_m
    elastic = (s.rest_length_m * (s.lambda1_n * d ** 4 / 4 + s.lambda2_n * d ** 2 / 2)).sum()
    return kinetic_energy_j(model) + elastic


def test_energy_decays_with_damping(box):
    model = LiverModel(box, PAPER_SCENE)
    model.state.positions[:] = perturbed_state(box)[0]
    energies = [total_energy(model)]
    for _ in range(60):
        model.step_frame(None)
        energies.append(total_energy(model))
    assert energies[-1] < 0.05 * energies[0]
    assert all(b <= a * (1 + 1e-6) for a, b in zip(energies, energies[1:]))


def test_fixed_nodes_default_to_the_middle_tet_and_stay_put(box):
    fixed = default_fixed_nodes(box)
    assert len(fixed) == 4
    centroid = box.points[fixed].mean(axis=0)
    assert np.linalg.norm(centroid - box.points.mean(axis=0)) < 0.02
    model = LiverModel(box, PAPER_SCENE)
    model.state.positions[:] = perturbed_state(box)[0]
    before = model.state.positions[fixed].copy()
    for _ in range(10):
        model.step_frame(None)
    np.testing.assert_array_equal(model.state.positions[fixed], before)


def test_fixed_nodes_out_of_range_are_refused(box):
    with pytest.raises(ValueError, match="fixed_nodes"):
        LiverModel(box, ModelParams(fixed_nodes=(0, 10_000)))


@pytest.mark.parametrize("change, name", [
    (dict(substeps=0), "substeps"),
    (dict(integrator="rk4"), "integrator"),
    (dict(density_kg_m3=-1.0), "density_kg_m3"),
    (dict(capsule=SpringLaw(math.nan, 1.0, 0.0)), "capsule.lambda1_n"),
    (dict(gravity_m_s2=(0.0, math.inf, 0.0)), "gravity_m_s2"),
])
def test_out_of_range_parameters_are_refused_by_name(change, name):
    with pytest.raises(ValueError, match=name.replace(".", r"\.")):
        ModelParams().with_changes(**change)


def test_stable_time_step_predicts_divergence(box):
    stable = LiverModel(box, ModelParams(support="paper", integrator="symplectic_euler")).structure.stable_dt_s
    assert 0 < stable < math.inf
    assert LiverModel(box, PAPER_SCENE).structure.stable_dt_s == math.inf  # the implicit integrator has no bound
    # Just below the bound the model stays finite.
    steps_ok = math.ceil(1.0 / (150.0 * stable * 0.9))
    ok = LiverModel(box, ModelParams(support="paper", integrator="symplectic_euler", substeps=steps_ok))
    ok.state.positions[:] = perturbed_state(box)[0]
    assert all(ok.step_frame(None).divergence is None for _ in range(30))


def test_undamped_explicit_euler_has_no_stable_step(box):
    law = SpringLaw(43.0, 0.3, 0.0)
    params = ModelParams(support="paper", integrator="explicit_euler", spring_constants="paper", capsule=law,
                         parenchyma=law, environment_damping_per_s=0.0)
    assert LiverModel(box, params).structure.stable_dt_s == 0.0


def test_divergence_is_reported_with_its_cause_and_the_model_resets(box):
    params = ModelParams(support="paper", integrator="symplectic_euler", substeps=1, contact_stiffness_n_per_m=300.0)
    model = LiverModel(box, params)
    model.state.positions[:] = perturbed_state(box)[0] * 1.3
    reports = [model.step_frame(None).divergence for _ in range(40)]
    report = next(r for r in reports if r is not None)
    assert "stability bound" in report and "substeps" in report
    assert model.divergences >= 1
    assert np.isfinite(model.state.positions).all()


def test_non_finite_state_is_caught_within_one_frame(box):
    model = LiverModel(box, PAPER_SCENE)
    model.state.velocities[5, 0] = math.nan
    result = model.step_frame(ToolPose(np.array([0.04, 0.03, 0.1])))
    assert result.divergence is not None and "non-finite" in result.divergence
    np.testing.assert_array_equal(model.state.positions, box.points)
    assert np.isfinite(result.tool_force_n).all() and not result.local_model.valid


@pytest.mark.parametrize("solver_threads, parallel", [("one", False), ("all", True), ("auto", False)])
def test_solver_threads_choose_the_kernels_threads(solver_threads, parallel):
    """'one' and 'all' as said; 'auto' by the spring count (a small box: one thread); the implicit step's PCG runs on
    the threads the structure has, and says so."""
    box = box_mesh(3, 3, 3, 0.01)
    model = LiverModel(box, ModelParams(solver_threads=solver_threads))
    assert model.structure.parallel is parallel
    threads = numba.get_num_threads() if parallel else 1
    assert model.structure.solver.threads == threads
    assert ("threads" in model.structure.step_solver) is (threads > 1)
    model.step_frame(None)  # steps on those threads


def test_an_unknown_solver_threads_is_refused_by_name():
    with pytest.raises(ValueError, match="solver_threads"):
        ModelParams(solver_threads="two").validate()
