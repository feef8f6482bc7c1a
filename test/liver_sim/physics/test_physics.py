"""The physics core as a whole model: a frame of each explicit integrator against the NumPy oracle's steps, and the
energy of a damped liver decaying (the parts: test/liver_sim/physics/<room>/test_<module>.py)."""
import math

import numpy as np
import pytest

from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver import reference

from meshes import kinetic_energy_j, perturbed_state

#: The box is held as in the paper's scene (its central tet fixed), which these tests are written for.
PAPER_SCENE = ModelParams(support="paper")


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
