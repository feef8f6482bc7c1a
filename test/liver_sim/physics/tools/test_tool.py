"""One tool on the liver (physics.tools.tool.Tool): what it is, its sweep over a frame from where it was, and the local
model it gives the haptic loop: none away, the pull's plane while holding, the contact's otherwise."""
import numpy as np
import pytest

from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.local_stiffness import REFRESH_FRAMES
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.tools.use import ToolUse


def test_a_tool_is_a_sphere_pressing_by_default_and_refuses_an_unknown_local_model():
    tool = Tool()
    assert (tool.shape, tool.local_model_kind, tool.use.mode, tool.name) == (ToolShape(), "plane", "press", "")
    assert tool.stiffness_refresh_frames == REFRESH_FRAMES
    with pytest.raises(ValueError, match="local_model"):
        Tool(local_model="cone")


def test_the_sweep_runs_from_the_previous_pose_and_is_kept_in_the_tool_state(box):
    model = LiverModel(box, ModelParams(support="paper"))
    state = model.state.tools[0]
    first, second = ToolPose(np.array([0.04, 0.03, 0.09])), ToolPose(np.array([0.04, 0.03, 0.088]))
    model.tool.sweep(model.structure, model.state.positions, state, first)
    sweep = model.tool.sweep(model.structure, model.state.positions, state, second)
    assert state.sweep is sweep and state.previous_pose is second
    np.testing.assert_allclose(sweep.velocity_m_s, [0.0, 0.0, -0.002 * 150.0])
    np.testing.assert_array_equal(sweep.probes, [first.position])


def test_the_local_model_is_none_away_and_the_pulls_plane_while_holding(box):
    model = LiverModel(box, ModelParams(support="paper"), Tool(use=ToolUse("grasp")))
    state = model.state.tools[0]
    pose = ToolPose(np.array([0.04, 0.03, 0.07]))
    assert not model.tool.local_model(model.structure, model.state, state, None, np.zeros(3), False).valid
    pull = np.array([0.0, 0.0, -0.6])
    local = model.tool.local_model(model.structure, model.state, state, pose, pull, True)
    stiffness = model.structure.params.contact_stiffness_n_per_m
    assert local.valid and local.kind == "plane" and local.stiffness_n_per_m == stiffness
    assert local.depth_m == pytest.approx(0.6 / stiffness)
    np.testing.assert_allclose(local.normal, [0.0, 0.0, -1.0])
