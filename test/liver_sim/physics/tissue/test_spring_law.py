"""The spring law's kernels (physics.tissue.spring_law): Eq. 1 by hand, both force kernels against the NumPy oracle
(physics.solver.reference), a collapsed spring's zero; the implicit terms' K·y against the forces' derivative, and
the system's product against its blocks."""
import numpy as np
import pytest

from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver import reference
from liver_sim.physics.solver.records import Operator
from liver_sim.physics.tissue.spring_law import (
    SpringArrays,
    spring_apply,
    spring_arrays,
    spring_forces_parallel,
    spring_forces_serial,
    spring_terms,
)
from liver_sim.physics.tissue.springs import build_springs

from meshes import perturbed_state


def two_node_state():
    """Two 0.5 kg nodes on x, rest length 1 m, stretched to 1.1 m, at rest."""
    x = np.array([[0.0, 0.0, 0.0], [1.1, 0.0, 0.0]])
    v = np.zeros((2, 3))
    law = one_spring(rest_m=1.0, lambda1_n=50.0, lambda2_n=0.35, mu_ns_per_m=0.0)
    return x, v, law


def one_spring(rest_m, lambda1_n, lambda2_n, mu_ns_per_m):
    """A spring from node 0 to node 1."""
    return SpringArrays(np.array([0]), np.array([1]), np.array([1.0 / rest_m]), np.array([lambda1_n]),
                        np.array([lambda2_n]), np.array([mu_ns_per_m]))


def test_spring_kernel_force_by_hand():
    x, v, law = two_node_state()
    f = np.zeros((2, 3))
    spring_forces_serial(x, v, law, f)
    np.testing.assert_allclose(f, [[0.085, 0, 0], [-0.085, 0, 0]])


def test_the_viscous_term_follows_the_elongation_rate_along_the_axis():
    # nodes 3-4-0 apart (length 5, rest 5: no strain); j moves at (3, 4, 7)·0.1 m/s: ḋ = (0.3·3 + 0.4·4)/5 = 0.5 m/s
    x = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])
    v = np.array([[0.0, 0.0, 0.0], [0.3, 0.4, 0.7]])
    f = np.full((2, 3), 1.0)  # the kernel adds to what is there
    spring_forces_serial(x, v, one_spring(5.0, 9.0, 9.0, 2.0), f)
    # T = μ·ḋ = 1 N along u = (0.6, 0.8, 0): +T·u on i, −T·u on j
    np.testing.assert_allclose(f, [[1.6, 1.8, 1.0], [0.4, 0.2, 1.0]])


def test_a_collapsed_spring_pulls_nothing():
    x = np.zeros((2, 3))
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    f = np.zeros((2, 3))
    spring_forces_serial(x, v, one_spring(0.01, 50.0, 1.0, 1.0), f)
    assert not f.any()


@pytest.mark.parametrize("parallel", [False, True])
def test_spring_kernels_equal_numpy_oracle(box, parallel):
    springs = build_springs(box, ModelParams())
    x, v = perturbed_state(box)
    f = np.zeros_like(x)
    law = spring_arrays(springs)
    if parallel:
        spring_forces_parallel(x, v, law, np.zeros((3, len(x), 3)), f)
    else:
        spring_forces_serial(x, v, law, f)
    expected = reference.spring_forces(x, v, springs)
    assert np.abs(expected).max() > 0.1
    np.testing.assert_allclose(f, expected, rtol=1e-10, atol=1e-12)


def test_the_implicit_terms_are_the_forces_and_their_stiffness(box):
    springs = build_springs(box, ModelParams())
    law = spring_arrays(springs)
    x, v = perturbed_state(box)
    n = len(x)
    inv_mass = np.ones(n)
    direction = np.random.default_rng(2).normal(size=x.shape)

    def terms(xs, vs):
        f, ky = np.zeros((n, 3)), np.zeros((n, 3))
        op = Operator.allocate(springs.node_i, springs.node_j, n)
        spring_terms(xs, vs, direction, inv_mass, 0.01, law, op, f, ky, True, 0, len(springs.node_i))
        return f, ky

    expected = np.zeros((n, 3))
    spring_forces_serial(x, v, law, expected)
    np.testing.assert_allclose(terms(x, v)[0], expected, rtol=1e-12, atol=1e-14)
    # K·y against the forces' derivative along y: at rest (K leaves out the viscous tension's x-derivative) and with
    # every spring stretched (K leaves out a compressed spring's geometric term)
    stretched, rest = box.points * 1.05, np.zeros((n, 3))
    eps = 1e-7
    derivative = (terms(stretched + eps * direction, rest)[0] - terms(stretched - eps * direction, rest)[0]) / (2 * eps)
    np.testing.assert_allclose(terms(stretched, rest)[1], derivative, rtol=1e-5,
                               atol=1e-6 * np.abs(derivative).max())


def test_the_product_is_the_sum_of_the_springs_blocks(box):
    springs = build_springs(box, ModelParams())
    x, v = perturbed_state(box)
    n = len(x)
    op = Operator.allocate(springs.node_i, springs.node_j, n)
    law = spring_arrays(springs).taken(op.spring_order)  # the operator's springs, in its order
    spring_terms(x, v, np.zeros((n, 3)), np.ones(n), 0.01, law, op, np.zeros((n, 3)), np.zeros((n, 3)), True, 0,
                 len(springs.node_i))
    p = np.random.default_rng(3).normal(size=(n, 3))
    out = np.zeros((n, 3))
    spring_apply(op, p, 0, len(springs.node_i), out)
    expected = np.zeros((n, 3))
    for s, (i, j) in enumerate(zip(op.node_i, op.node_j)):
        u = op.unit[s]
        block = op.iso[s] * np.eye(3) + op.axial[s] * np.outer(u, u)
        expected[i] += block @ (p[i] - p[j])
        expected[j] -= block @ (p[i] - p[j])
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-15)
