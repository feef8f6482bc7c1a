"""The plain-NumPy oracle (physics.solver.reference) by hand: Eq. 1 on a spring, the support's ties, and one step of
each explicit integrator with a fixed node."""
import numpy as np
import pytest

from liver_sim.physics.solver import reference
from liver_sim.physics.tissue.organ_support import SupportArrays
from liver_sim.physics.tissue.springs import SpringNetwork


def one_spring(lambda1=50.0, lambda2=0.35, mu=0.0):
    """A spring of rest length 1 m between nodes 0 and 1."""
    return SpringNetwork(np.array([0]), np.array([1]), np.array([1.0]), np.array([lambda1]), np.array([lambda2]),
                         np.array([mu]), 0, 1)


def test_spring_forces_by_hand():
    # stretched 10 % along (0.6, 0.8, 0), node 1 moving apart at 0.5 m/s: T = 50·0.001 + 0.35·0.1 + 2·0.5 = 1.085 N
    x = np.array([[0.0, 0.0, 0.0], [0.66, 0.88, 0.0], [5.0, 5.0, 5.0]])
    v = np.array([[0.0, 0.0, 0.0], [0.3, 0.4, 0.0], [0.0, 0.0, 0.0]])
    f = reference.spring_forces(x, v, one_spring(mu=2.0))
    np.testing.assert_allclose(f, [[0.651, 0.868, 0.0], [-0.651, -0.868, 0.0], [0.0, 0.0, 0.0]])


def test_support_forces_by_hand():
    support = SupportArrays(np.array([1]), np.array([[0.0, 0.0, 1.0]]), np.array([10.0]), np.array([0.5]))
    x, v = np.array([[1.0, 1.0, 1.0], [0.0, 0.2, 1.0]]), np.array([[1.0, 1.0, 1.0], [0.0, 0.0, -2.0]])
    np.testing.assert_allclose(reference.support_forces(x, v, support), [[0.0, 0.0, 0.0], [0.0, -2.0, 1.0]])


@pytest.mark.parametrize("integrator", ["explicit_euler", "symplectic_euler"])
def test_one_step_of_each_integrator_by_hand(integrator):
    # node 0 fixed, node 1 (1 kg) at rest 10 % stretched: T = 0.085 N pulls it back; with c_env = 1 and gravity
    # −10 m/s² along y: a = (−0.085, −10, 0), v ← h·a (h = 0.1), x ← x + h·v_old (0) or h·v_new
    x, v = np.array([[0.0, 0.0, 0.0], [1.1, 0.0, 0.0]]), np.zeros((2, 3))
    new_x, new_v = reference.step(x, v, one_spring(), np.array([0.0, 1.0]), 0.1, 1.0, (0.0, -10.0, 0.0), integrator)
    np.testing.assert_allclose(new_v, [[0.0, 0.0, 0.0], [-0.0085, -1.0, 0.0]])
    expected = [1.1, 0.0, 0.0] if integrator == "explicit_euler" else [1.1 - 0.00085, -0.1, 0.0]
    np.testing.assert_allclose(new_x[1], expected)
    np.testing.assert_array_equal(new_x[0], x[0])
