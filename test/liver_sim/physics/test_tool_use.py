"""The tool's modes on the model (no ROS): press, grasp what it touches, cut along each stroke."""
import numpy as np
import pytest

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.tools.use import ToolUse
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
