"""A tool's use (physics.tools.use.ToolUse): its decisions before a frame, the grasped nodes held in the tool frame, a
cutting stroke's path; and on the model (no ROS): press, grasp what it touches, cut along each stroke."""
import numpy as np
import pytest
from pulls import pull_the_dome

from liver_sim.base.local_model import LocalModel, penetration
from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape
from liver_sim.physics.model import LiverModel
from liver_sim.physics.state import ToolState
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.tools.use import CUT_PATH_STEP_M, ToolUse, held_positions, release
from liver_sim.tool.scripts import ScriptSettings, make_script


def play(mode, script_name="press_slide_release", **settings):
    """Play a script on the default liver with the tool in `mode`; (model, what the tool's use did, frames the mesh
    changed at, frames in contact)."""
    liver = default_liver()
    model = LiverModel(liver, tool=Tool(use=ToolUse(mode, cut_depth_m=0.008)))
    script = make_script(script_name, ScriptSettings(anchor_m=tuple(press_anchor(liver)), **settings))
    changed, contact, events = [], [], []
    for k in range(int(script.duration_s * model.structure.params.frame_rate_hz)):
        result = model.step_frame(ToolPose(script.position_at(k * model.structure.frame_period_s)))
        contact.append(result.local_model.in_contact)
        events += result.tool_events + result.topology_failures
        if "cut" in result.topology_changes:
            changed.append(k)
    return model, events, changed, np.array(contact)


def test_a_cutting_stroke_opens_the_mesh_once_when_the_tool_leaves_the_surface():
    model, events, changed, contact = play("cut", depth_m=0.012, slide_m=0.06, slide_s=3.0, rest_s=0.5)
    assert changed and model.structure.version == len(changed) == 1
    assert contact[changed[0] - 1] and not contact[changed[0]]  # the frame the tool left the surface
    assert len(model.state.positions) > len(default_liver().points)
    assert not events  # nothing refused


def test_pressing_never_changes_the_mesh():
    model, _, changed, contact = play("press", depth_m=0.012, slide_m=0.06, slide_s=3.0, rest_s=0.5)
    assert contact.any() and not changed and model.structure.version == 0


def test_grasp_holds_on_contact_and_lets_go_when_the_mode_changes():
    model, events, _, _ = play("grasp", script_name="press", depth_m=0.004)
    assert model.state.held_nodes.size > 0 and events[0].startswith("grasped")
    model.tool.use.mode = "press"
    events = model.before_frame(ToolPose(model.state.positions[model.state.held_nodes[0]]))
    assert model.state.held_nodes.size == 0 and events[-1] == "released the grasped nodes"


def test_an_unknown_mode_is_refused_by_parameter_name():
    with pytest.raises(ValueError, match="tool_mode"):
        ToolUse("scalpel")


def test_before_a_frame_the_use_grasps_on_contact_and_lets_go_in_another_mode():
    use, state, pose = ToolUse("grasp"), ToolState(), ToolPose(np.zeros(3))
    assert use.before_frame(state, pose) is None  # not in contact at the last frame
    state.in_contact = True
    assert use.before_frame(state, None) is None  # away
    assert use.before_frame(state, pose) == "grasp"
    state.held_nodes = np.array([3])
    assert use.before_frame(state, pose) is None  # holds already
    use.mode = "press"
    assert use.before_frame(state, pose) == "release"
    release(state)
    assert not state.holding and use.before_frame(state, pose) is None


def test_the_held_nodes_keep_their_place_in_the_tool_frame():
    use, state = ToolUse("grasp", grasp_margin_m=0.0), ToolState()
    shape = ToolShape(radius_m=0.01)
    positions = np.array([[0.005, 0.0, 0.0], [0.0, 0.008, 0.0], [0.0, 0.0, 0.5]])
    held = use.grasp(state, shape, ToolPose(np.zeros(3)), positions, np.arange(3))
    np.testing.assert_array_equal(held, [0, 1])  # within the sphere; node 2 is out of reach
    quarter = (0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4))  # a quarter turn about z
    moved = held_positions(state, ToolPose(np.array([1.0, 2.0, 3.0]), quarter))
    np.testing.assert_allclose(moved, [[1.0, 2.005, 3.0], [0.992, 2.0, 3.0]], atol=1e-15)


def test_a_cutting_stroke_is_the_contact_points_a_step_apart_until_the_tool_leaves():
    use, state = ToolUse("cut"), ToolState()

    def touching(x):
        return LocalModel("plane", True, [x, 0.0, 0.0], [0.0, 0.0, 1.0], [x, 0.0, 0.0], 0.0, 0.001, True)

    for x in (0.0, CUT_PATH_STEP_M / 2, CUT_PATH_STEP_M, 2.5 * CUT_PATH_STEP_M):
        assert use.after_frame(state, touching(x)) is None
    path = use.after_frame(state, LocalModel.invalid())
    np.testing.assert_allclose(path[:, 0], [0.0, CUT_PATH_STEP_M, 2.5 * CUT_PATH_STEP_M])  # the half step: left out
    assert state.cut_path == [] and not state.in_contact
    assert use.after_frame(state, touching(0.0)) is None
    assert use.after_frame(state, LocalModel.invalid()) is None  # one point: no stroke


def test_grasped_nodes_follow_the_tool_and_pull_it_back_towards_the_liver():
    model, use, results, tips = pull_the_dome(tearing=False)
    held = model.state.held_nodes
    offsets = model.state.positions[held] - tips[-1]
    np.testing.assert_allclose(offsets, model.structure.mesh.points[held] - tips[0], atol=1e-12)  # carried rigidly
    assert not any(r.divergence or r.topology_changed for r in results)
    assert results[-1].tool_force_n[2] < -1.0       # the tissue pulls the tool back down
    # the local model renders the pull: the bridge's λ·depth·n for the tool sphere is the tissue's force
    last = results[-1].local_model
    depth, direction = penetration(last, tips[-1], model.tool.shape.radius_m)
    np.testing.assert_allclose(model.structure.params.contact_stiffness_n_per_m * depth * direction,
                               results[-1].tool_force_n, rtol=1e-9)
    model.release()
    assert model.state.held_nodes.size == 0 and (model.state.inv_mass[held] > 0).all()
    for _ in range(150):
        model.step_frame()
    assert model.state.positions[held, 2].max() < tips[-1][2] - 0.03  # let go, the dome falls back

