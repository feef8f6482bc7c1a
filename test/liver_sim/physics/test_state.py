"""Everything a frame changes is the State (liver_sim.physics.state): reset is rest_state, and a model reset after a
divergence steps as a fresh one does, the co-rotational elements' rotations included; a tear or a cut carries the
state over and leaves the old one as it was."""
import numpy as np
import pytest

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.state import rest_state
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.tools.use import ToolUse

FEM = ModelParams(tissue_law="fem")


def press(liver, frames: int) -> list[ToolPose]:
    """A press 6 mm into the dome over `frames` frames."""
    anchor = press_anchor(liver)
    return [ToolPose(anchor + [0.0, 0.0, 0.01 - 0.016 * k / frames]) for k in range(frames)]


@pytest.mark.parametrize("params", [FEM, ModelParams()], ids=["fem", "springs"])
def test_after_a_nan_divergence_the_model_steps_as_a_fresh_one(params):
    liver = default_liver()
    poses = press(liver, 20)
    fresh = LiverModel(liver, params, Tool(use=ToolUse("grasp")))
    diverged = LiverModel(liver, params, Tool(use=ToolUse("grasp")))
    for pose in poses[:10]:  # in contact, with a past: rotations turned, a compliance solved, a grasp pending
        diverged.step_frame(pose)
    assert diverged.state.tools[0].in_contact
    if params.tissue_law == "fem":
        assert not np.allclose(diverged.state.history.rotations, fresh.state.history.rotations)
    diverged.state.positions[0] = np.nan
    result = diverged.step_frame(poses[10])
    assert result.divergence is not None and diverged.divergences == 1
    assert np.isfinite(diverged.state.history.rotations).all()
    expected = [fresh.step_frame(pose) for pose in poses]
    after = [diverged.step_frame(pose) for pose in poses]
    for a, b in zip(expected, after):
        assert a.divergence is None and b.divergence is None
        np.testing.assert_array_equal(a.tool_force_n, b.tool_force_n)
    np.testing.assert_array_equal(fresh.state.positions, diverged.state.positions)
    np.testing.assert_array_equal(fresh.state.history.rotations, diverged.state.history.rotations)


def test_rest_state_keeps_the_clock_and_loads_it_is_given_and_nothing_else():
    model = LiverModel(default_liver(), FEM)
    loads = np.ones_like(model.state.positions)
    state = rest_state(model.structure, 2, 1.5, loads)
    assert state.time_s == 1.5 and state.external_forces_n is loads and len(state.tools) == 2
    np.testing.assert_array_equal(state.positions, model.structure.mesh.points)
    assert not state.velocities.any() and state.held_nodes.size == 0 and state.futile_tear_faces is None
    assert state.history.dt_s == 0.0 and (state.history.rotations == [0.0, 0.0, 0.0, 1.0]).all()
    assert len(state.history.rotations) == len(model.structure.mesh.tets)
    assert state.positions is not model.structure.mesh.points  # stepping it leaves the rest shape alone


def test_a_cut_carries_the_tools_state_and_leaves_the_old_state_as_it_was():
    liver = default_liver()
    model = LiverModel(liver, tool=Tool(use=ToolUse("grasp")))
    anchor = press_anchor(liver)
    for k in range(8):
        model.step_frame(ToolPose(anchor + [0.0, 0.0, 0.004 - 0.001 * k]))
    before = model.state
    positions = before.positions.copy()
    assert model.cut(np.array([anchor + [-0.03, 0.0, 0.0], anchor + [0.03, 0.0, 0.0]]), 0.01)
    after = model.state
    assert after is not before and len(after.positions) > len(positions)
    np.testing.assert_array_equal(before.positions, positions)
    assert after.tools[0].previous_pose is before.tools[0].previous_pose
    assert after.tools[0].in_contact == before.tools[0].in_contact
    assert after.tools[0].compliance_m_per_n is None  # of the old network
    assert after.history is not before.history and after.history.dt_s == 0.0
