"""The explicit frame's kernels (physics.solver.explicit_kernels): both integrators by hand, gravity, environment
damping and fixed nodes, the divergence guard's speed, and a frame against the NumPy oracle's steps."""
import math

import numpy as np
import pytest

from liver_sim.physics.contact.tool_geometry import ToolShape, tool_sweep
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver import explicit_kernels, reference
from liver_sim.physics.structure import initial_structure

from meshes import perturbed_state


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


def test_max_speed_is_the_fastest_node_and_nan_on_a_non_finite_state():
    x = np.zeros((3, 3))
    v = np.array([[1.0, 0.0, 0.0], [0.0, 3.0, 4.0], [0.0, -2.0, 0.0]])
    assert explicit_kernels.max_speed(x, v) == pytest.approx(5.0)
    x[2, 1] = math.inf
    assert math.isnan(explicit_kernels.max_speed(x, v))
    x[2, 1] = 0.0
    v[0, 0] = math.nan
    assert math.isnan(explicit_kernels.max_speed(x, v))


@pytest.mark.parametrize("symplectic", [False, True])
def test_a_frame_without_a_tool_is_the_oracles_substeps(box, symplectic):
    params = ModelParams(support_regions=((0.0, 0.0, 0.0, 0.03, 1.0e5),), environment_damping_per_s=1.5,
                         gravity_m_s2=(0.0, 0.0, -9.81), integrator="symplectic_euler" if symplectic
                         else "explicit_euler")
    structure = initial_structure(box, params)
    assert len(structure.support.nodes) > 0
    x, v = perturbed_state(box, seed=4)
    inv_mass = 1.0 / structure.masses_kg
    inv_mass[:3] = 0.0
    external = np.random.default_rng(5).normal(scale=0.01, size=x.shape)
    settings = explicit_kernels.StepSettings(2e-5, 5, 1.5, np.array([0.0, 0.0, -9.81]), symplectic)
    no_tool = tool_sweep(ToolShape(), None, None, params, 0.0, x, structure.skin)
    work = explicit_kernels.WorkArrays(np.zeros_like(x), np.zeros((1, len(x), 3)), False)
    expected_x, expected_v = x.copy(), v.copy()
    for _ in range(5):
        f = reference.spring_forces(expected_x, expected_v, structure.springs) + external
        f += reference.support_forces(expected_x, expected_v, structure.support)
        free = (inv_mass > 0.0)[:, None]
        a = f * inv_mass[:, None] + [0.0, 0.0, -9.81] - 1.5 * expected_v
        new_v = np.where(free, expected_v + 2e-5 * a, expected_v)
        expected_x = np.where(free, expected_x + 2e-5 * (new_v if symplectic else expected_v), expected_x)
        expected_v = new_v
    contact = explicit_kernels.run_frame(x, v, inv_mass, external, structure.spring_arrays, structure.support,
                                         settings, no_tool, work)
    assert not contact.any()
    np.testing.assert_allclose(x, expected_x, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(v, expected_v, rtol=1e-9, atol=1e-12)
