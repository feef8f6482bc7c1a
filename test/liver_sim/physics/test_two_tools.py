"""Two tools on one liver (no ROS): their contacts in one implicit step, so that what one does changes the force
the other feels within the frame, and each local model fitted with the other tool's contact and hold in place."""
from dataclasses import fields

import numpy as np
import pytest

from liver_sim.base.local_model import LocalModel
from liver_sim.mesh.landmarks import upper_skin_path
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.tool import Tool
from liver_sim.physics.tools.use import ToolUse

RADIUS_M = 0.015
#: The lift starts at this frame (0.5 s at 150 Hz) and takes 150 frames.
LIFT_FRAME = 75
LIFT_M = 0.015


@pytest.fixture(scope="module")
def liver():
    return default_liver()


def top(liver, x: float, y: float) -> np.ndarray:
    """The upper skin of the liver at rest above (x, y) (m)."""
    return upper_skin_path(liver, (x, y), (x, y), 1)[0]


def two_hands(liver, left_mode="grasp", right_mode="press"):
    return LiverModel(liver, tool=[Tool(use=ToolUse(left_mode), name="left"),
                                   Tool(use=ToolUse(right_mode), name="right")])


def grasp_and_lift(liver, lift: bool, frames: int = 240):
    """The left tool grasps the anterior edge 4 mm deep and (with `lift`) lifts it LIFT_M from LIFT_FRAME on,
    while the right tool presses 6 mm deep 4 cm beside it; the frames' results."""
    model = two_hands(liver)
    left, right = top(liver, -0.04, -0.055), top(liver, 0.0, -0.035)
    results = []
    for k in range(frames):
        raised = LIFT_M * min(1.0, max(0.0, (k - LIFT_FRAME) / 150)) if lift else 0.0
        results.append(model.step_frame(ToolPose(left + [0.0, 0.0, RADIUS_M - 0.004 + raised]),
                                        ToolPose(right + [0.0, 0.0, RADIUS_M - 0.006])))
    return model, results


def test_lifting_with_one_tool_changes_the_force_on_the_other_in_the_same_frame(liver):
    model, lifted = grasp_and_lift(liver, lift=True)
    _, still = grasp_and_lift(liver, lift=False)
    assert model.state.tools[0].holding and not model.state.tools[1].holding
    assert lifted[1].tool_events == ("left: grasped 1 skin node(s)",)
    right = np.array([r.tool_forces_n[1] for r in lifted])
    right_still = np.array([r.tool_forces_n[1] for r in still])
    # identical until the lift, different from the first frame that moves the grasped tissue on
    np.testing.assert_array_equal(right[:LIFT_FRAME + 1], right_still[:LIFT_FRAME + 1])
    assert not np.array_equal(right[LIFT_FRAME + 1], right_still[LIFT_FRAME + 1])
    # lifted 1.5 cm, the edge raises the tissue under the right tool: it is pushed back harder
    assert right[-1][2] > 1.5 * right_still[-1][2] > 0.0
    assert lifted[-1].tool_forces_n[0][2] < -1.0  # the left tool feels the tissue pull it back down
    # each tool's local model renders its own force
    assert lifted[-1].local_models[1].in_contact and lifted[-1].local_models[0].in_contact


def test_each_local_model_is_stiffer_with_the_other_tool_holding_the_tissue(liver):
    """The tissue under the right tool is held by the left tool's grasp, or by its press: stiffer than alone."""
    right = top(liver, 0.0, -0.035) + [0.0, 0.0, RADIUS_M - 0.006]
    left = top(liver, -0.035, -0.035) + [0.0, 0.0, RADIUS_M - 0.005]
    stiffness = {}
    for case, left_pose, mode in (("alone", None, "press"), ("pressed", left, "press"), ("held", left, "grasp")):
        model = two_hands(liver, left_mode=mode)
        for _ in range(60):
            result = model.step_frame(None if left_pose is None else ToolPose(left_pose), ToolPose(right))
        stiffness[case] = result.local_models[1].stiffness_n_per_m
    assert stiffness["pressed"] > stiffness["alone"] and stiffness["held"] > stiffness["alone"]


def test_a_single_tool_in_a_list_is_the_default_tool_bit_for_bit(liver):
    anchor = top(liver, -0.046, 0.004)
    poses = [ToolPose(anchor + [0.0, 0.0, RADIUS_M - 0.008 * min(1.0, k / 60)]) for k in range(90)]
    one, listed = LiverModel(liver), LiverModel(liver, tool=[Tool()])
    for pose in poses:
        a, b = one.step_frame(pose), listed.step_frame(pose)
        np.testing.assert_array_equal(a.tool_force_n, b.tool_forces_n[0])
        for field in fields(LocalModel):
            np.testing.assert_array_equal(getattr(a.local_model, field.name), getattr(b.local_model, field.name))
    np.testing.assert_array_equal(one.state.positions, listed.state.positions)


def test_tools_away_a_node_held_twice_and_the_explicit_integrators_are_refused_or_handled(liver):
    model = two_hands(liver, right_mode="grasp")
    left = top(liver, -0.04, -0.055) + [0.0, 0.0, RADIUS_M - 0.004]
    for _ in range(3):  # both tools at the same place: the second grasps nothing the first holds
        model.step_frame(ToolPose(left), ToolPose(left))
    held = [tool.held_nodes for tool in model.state.tools]
    assert held[0].size and not np.intersect1d(held[0], held[1]).size
    assert np.array_equal(np.sort(model.state.held_nodes), np.sort(np.concatenate(held)))
    result = model.step_frame()  # every tool away
    assert all(not m.valid for m in result.local_models) and not np.any(result.tool_forces_n)
    model.release(1)
    assert model.state.tools[0].holding and not model.state.tools[1].holding
    with pytest.raises(ValueError, match="one pose per tool"):
        model.step_frame(ToolPose(left))
    with pytest.raises(ValueError, match="integrator='symplectic_euler'.*implicit_euler"):
        LiverModel(liver, ModelParams(integrator="symplectic_euler"), [Tool(name="a"), Tool(name="b")])
    with pytest.raises(ValueError, match="each once"):
        LiverModel(liver, tool=[Tool(name="a"), Tool(name="a")])


def test_two_tools_in_one_place_pass_through_each_other_and_both_press_the_tissue(liver):
    """Tools touching each other are not solved: they do not collide, each meets only the tissue, so two pressing at
    one place both feel it push back, and the frame stays finite."""
    model = two_hands(liver, left_mode="press", right_mode="press")
    spot = top(liver, 0.0, -0.035)
    for k in range(60):
        pose = ToolPose(spot + [0.0, 0.0, RADIUS_M - 0.006 * min(1.0, k / 30)])
        result = model.step_frame(pose, pose)
    assert result.divergence is None and np.isfinite(model.state.positions).all()
    left, right = result.tool_forces_n
    assert left[2] > 0.1 and right[2] > 0.1  # each pushed back by the tissue, neither by the other tool
