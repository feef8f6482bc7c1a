"""The spring network on a tet mesh (physics.tissue.springs): one connector per edge with the capsule's law added on
the skin's edges, and the explicit integrators' stability bound, by hand on two nodes and against divergence."""
import math

import numpy as np
import pytest

from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams, SpringLaw
from liver_sim.physics.tissue.springs import SpringNetwork, build_springs, estimate_stable_time_step, stable_time_step

from meshes import perturbed_state


def test_stable_time_step_predicts_divergence(box):
    stable = LiverModel(box, ModelParams(support="paper", integrator="symplectic_euler")).structure.stable_dt_s
    assert 0 < stable < math.inf
    assert LiverModel(box, ModelParams(support="paper")).structure.stable_dt_s == math.inf  # implicit: no bound
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


def test_paper_constants_put_the_capsule_law_on_the_skin_edges_only(box):
    params = ModelParams(spring_constants="paper")
    springs = build_springs(box, params)
    assert springs.edges == len(box.edges) == springs.parenchyma_springs
    skin_edges = {tuple(e) for e in box.skin_edges.tolist()}
    on_skin = np.array([(i, j) in skin_edges for i, j in zip(springs.node_i.tolist(), springs.node_j.tolist())])
    assert springs.capsule_springs == on_skin.sum() == len(skin_edges)
    assert springs.springs == springs.edges + springs.capsule_springs
    par, cap = params.parenchyma, params.capsule
    np.testing.assert_allclose(springs.lambda2_n, np.where(on_skin, par.lambda2_n + cap.lambda2_n, par.lambda2_n))
    np.testing.assert_allclose(springs.mu_ns_per_m, np.where(on_skin, par.mu_ns_per_m + cap.mu_ns_per_m,
                                                             par.mu_ns_per_m))
    ends = box.points[springs.node_j] - box.points[springs.node_i]
    np.testing.assert_allclose(springs.rest_length_m, np.linalg.norm(ends, axis=1))


def two_masses(stiffness_n: float, mu_ns_per_m: float) -> SpringNetwork:
    """One spring of rest length 1 m between nodes 0 and 1 (λ2 = `stiffness_n`, so k = λ2/l0 in N/m)."""
    return SpringNetwork(np.array([0]), np.array([1]), np.array([1.0]), np.array([0.0]), np.array([stiffness_n]),
                         np.array([mu_ns_per_m]), 0, 1)


def test_the_bound_of_two_masses_is_the_closed_form_of_their_mode():
    # masses 1 and 3 kg on a spring of k = 12 N/m, μ = 0.5 N·s/m: ω² = k·(1/1 + 1/3) = 16, c = μ·(4/3) + c_env
    springs, masses = two_masses(12.0, 0.5), np.array([1.0, 3.0])
    x = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    c = 0.5 * 4.0 / 3.0 + 0.2
    symplectic = (math.sqrt(c * c + 4.0 * 16.0) - c) / 16.0
    assert stable_time_step(springs, masses, 0.2, "symplectic_euler", x) == pytest.approx(symplectic, rel=1e-6)
    # explicit Euler: min(μ·l0/λ2 + c_env/ω², 2/c)
    explicit = min(0.5 / 12.0 + 0.2 / 16.0, 2.0 / c)
    assert stable_time_step(springs, masses, 0.2, "explicit_euler", x) == pytest.approx(explicit, rel=1e-6)
    assert estimate_stable_time_step(springs, masses, 0.2, "symplectic_euler", x) == pytest.approx(symplectic,
                                                                                                    rel=1e-6)
