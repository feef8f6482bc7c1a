"""A frame's stages (physics.frame): the divergence guard and its report, the forces the held nodes' pull is read
from, the tools' labels, what a FrameResult names the first tool's, a topology change applied all or nothing."""
import dataclasses
import math

import numpy as np
import pytest
from pulls import SPACING_M, pulled_bar

from liver_sim.base.local_model import LocalModel
from liver_sim.mesh.tetmesh import TET_FACES
from liver_sim.physics import frame
from liver_sim.physics import structure as structure_module
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver import reference
from liver_sim.physics.state import rest_state
from liver_sim.physics.structure import initial_structure
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.topology.tearing import duplication_change

from meshes import assert_same_state, model_state, perturbed_state

#: The box is held as in the paper's scene (its central tet fixed), which these tests are written for.
PAPER_SCENE = ModelParams(support="paper")


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


def test_divergence_is_none_up_to_the_speed_limit_and_names_the_speed_beyond(box):
    structure = initial_structure(box, PAPER_SCENE)
    state = rest_state(structure)
    state.velocities[3] = [0.0, 20.0, 0.0]  # max_node_speed_m_s itself
    assert frame.divergence(structure, state) is None
    state.velocities[3] = [0.0, 30.0, 40.0]  # 50 m/s
    state.time_s = 0.25
    report = frame.divergence(structure, state)
    assert report.startswith("simulation diverged at t=0.2500 s: node speed 50 m/s above max_node_speed_m_s=20")
    assert "stability bound" not in report  # the implicit integrator has none
    state.positions[0, 2] = math.inf
    assert "non-finite positions or velocities" in frame.divergence(structure, state)


def test_spring_forces_are_the_loads_the_springs_and_the_support_at_the_state(box):
    params = ModelParams(support_regions=((0.0, 0.0, 0.0, 0.03, 1.0e5),))  # holds the box's corner
    structure = initial_structure(box, params)
    assert len(structure.support.nodes) > 0
    state = rest_state(structure)
    state.positions[:], state.velocities[:] = perturbed_state(box, seed=2)
    state.external_forces_n[:] = np.random.default_rng(3).normal(size=state.positions.shape)
    expected = (state.external_forces_n + reference.spring_forces(state.positions, state.velocities,
                                                                  structure.springs)
                + reference.support_forces(state.positions, state.velocities, structure.support))
    np.testing.assert_allclose(frame.spring_forces(structure, state), expected, rtol=1e-10, atol=1e-12)


def test_a_named_tools_events_carry_its_name():
    tools = [Tool(), Tool(name="left")]
    assert frame.label(tools, 0, "released the grasped nodes") == "released the grasped nodes"
    assert frame.label(tools, 1, "grasped 3 skin node(s)") == "left: grasped 3 skin node(s)"


def test_a_frame_results_single_tool_view_is_its_first_tool():
    first, second = np.array([1.0, 0.0, 0.0]), np.array([0.0, 2.0, 0.0])
    model = LocalModel.plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 10.0)
    result = frame.FrameResult(0.5, (first, second), (model, LocalModel.invalid()), None)
    assert result.tool_force_n is first and result.local_model is model
    assert not result.topology_changed
    assert frame.FrameResult(0.5, (first,), (model,), None, topology_changes=("cut",)).topology_changed




def test_apply_topology_change_is_all_or_nothing(monkeypatch):
    model = pulled_bar(16.0)
    for _ in range(3):
        model.step_frame()
    mesh = model.structure.mesh
    faces = mesh.tets[:, TET_FACES].reshape(-1, 3)
    plane = np.isclose(mesh.points[faces][:, :, 0], 5 * SPACING_M).all(axis=1)
    change = duplication_change(mesh.points, mesh.tets, model.structure.capsule_triangles, faces[plane])
    before = model_state(model)

    def broken(*args, **kwargs):  # build_structure calls it after carrying the node state over
        raise RuntimeError("injected")

    monkeypatch.setattr(structure_module, "build_springs", broken)
    with pytest.raises(RuntimeError, match="injected"):
        model.apply(change)
    assert_same_state(dict(before, arrays=list(before["arrays"])), model)
    with pytest.raises(ValueError, match="node_sources"):  # checked before the model is touched
        model.apply(dataclasses.replace(change, node_sources=change.node_sources[:-1]))
    assert_same_state(before, model)
    monkeypatch.undo()
    model.apply(change)
    assert model.structure.version == 1 and len(model.state.positions) == len(change.rest_points)

