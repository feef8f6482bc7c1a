"""The LiverModel (physics.model): one pose per tool, grasping and letting go, reset to rest keeping the clock and the
loads, a cut that misses the mesh leaving it as it was."""
import numpy as np
import pytest

from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.tool import Tool

#: The box is held as in the paper's scene (its central tet fixed).
PAPER_SCENE = ModelParams(support="paper")


def test_a_model_steps_one_pose_per_tool_and_none_means_every_tool_away(box):
    model = LiverModel(box, PAPER_SCENE, [Tool(name="a"), Tool(name="b")])
    assert model.tool is model.tools[0] and model.tool.name == "a"
    with pytest.raises(ValueError, match="one pose per tool: 2, got 1"):
        model.step_frame(None)
    result = model.step_frame()
    assert len(result.tool_forces_n) == 2 and not np.any(result.tool_forces_n)
    assert all(not m.valid for m in result.local_models)
    assert result.time_s == pytest.approx(model.structure.frame_period_s)


def test_grasp_holds_the_skin_nodes_in_reach_and_release_lets_them_go(box):
    model = LiverModel(box, PAPER_SCENE, Tool(ToolShape(radius_m=0.025)))  # reach 3 cm: 7 nodes of 2 cm cubes
    corner = box.points[np.argmax(box.points.sum(axis=1))]  # (0.08, 0.06, 0.06): a skin node
    count = model.grasp(ToolPose(corner))
    reach = model.tool.shape.radius_m + model.tool.use.grasp_margin_m
    expected = np.flatnonzero(np.linalg.norm(box.points - corner, axis=1) <= reach)
    assert count == len(expected) == 7
    np.testing.assert_array_equal(np.sort(model.state.held_nodes), expected)
    assert (model.state.inv_mass[expected] == 0.0).all()
    model.release()
    assert model.state.held_nodes.size == 0 and (model.state.inv_mass[expected] > 0.0).all()


def test_reset_is_the_rest_shape_at_rest_with_the_clock_and_the_loads_kept(box):
    model = LiverModel(box, PAPER_SCENE)
    model.state.external_forces_n[:, 2] = -0.01
    for _ in range(5):
        model.step_frame()
    assert not np.array_equal(model.state.positions, box.points)  # the loads moved it
    clock, loads = model.state.time_s, model.state.external_forces_n
    model.reset()
    np.testing.assert_array_equal(model.state.positions, box.points)
    assert not model.state.velocities.any() and model.state.time_s == clock
    assert model.state.external_forces_n is loads


def test_a_cut_that_misses_the_mesh_changes_nothing(box):
    model = LiverModel(box, PAPER_SCENE)
    far = np.array([[1.0, 1.0, 1.0], [1.1, 1.0, 1.0]])
    assert not model.cut(far, 0.01)
    assert model.structure.version == 0 and len(model.state.positions) == len(box.points)
