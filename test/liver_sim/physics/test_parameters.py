"""The physics node's parameters as the model's (physics.parameters): the config's defaults, the support's regions
checked, each tool's parameters and topics in its namespace, the model's Tool of a tool's settings."""
import pytest

from liver_sim.physics.parameters import PhysicsParameters, model_params, model_tool, physics_tools
from liver_sim.physics.settings import ModelParams
from liver_sim.sessions.parameters import node_parameters


def test_support_parameters_are_checked_and_the_config_gives_the_defaults():
    assert model_params(node_parameters()["liver_physics"]) == ModelParams()
    values = node_parameters()["liver_physics"].replace(support_regions=[0.0, 0.0, 0.0, 0.01])
    with pytest.raises(ValueError, match="support_regions"):
        model_params(values)
    with pytest.raises(ValueError, match="support_regions"):
        ModelParams(support_regions=((0.0, 0.0, 0.0, -0.01, 1.0),)).validate()
    with pytest.raises(ValueError, match="support"):
        ModelParams(support="pinned").validate()


def test_fixed_nodes_minus_one_means_none_and_a_list_fixes_those():
    p = PhysicsParameters.defaults()
    assert model_params(p).fixed_nodes is None
    assert model_params(p.replace(fixed_nodes=[3, 1])).fixed_nodes == (3, 1)


def test_each_named_tool_takes_its_own_parameters_and_topics_in_its_namespace():
    p = PhysicsParameters.defaults().replace(tools=["left", "right"], tool_mode="press")
    left, right = physics_tools(p, {"right.tool_mode": "grasp", "right.tool_radius_m": 0.01})
    assert (left.name, left.settings.tool_mode, right.settings.tool_mode) == ("left", "press", "grasp")
    assert left.topic("tool_pose_topic") == "/left/tool/pose" and right.topic("tool_pose_topic") == "/right/tool/pose"
    assert right.parameter("tool_mode") == "right.tool_mode"
    tool = model_tool(right)
    assert (tool.name, tool.use.mode, tool.shape.radius_m) == ("right", "grasp", 0.01)
    (root,) = physics_tools(PhysicsParameters.defaults())
    assert root.name == "" and root.topic("tool_pose_topic") == "/tool/pose"
    assert root.parameter("tool_mode") == "tool_mode"


@pytest.mark.parametrize("tools, values, message", [
    (["left", "left"], {}, "parameter tools="),
    (["1st"], {}, "parameter tools="),
    (["left"], {"right.tool_mode": "press"}, "unknown parameter.*right.tool_mode"),
    (["left"], {"left.tool_mode": "scalpel"}, "parameter left.tool_mode"),
    (["left", "right"], {"left.tool_pose_topic": "/pose", "right.tool_pose_topic": "/pose"},
     "parameter right.tool_pose_topic: /pose is already left.tool_pose_topic"),
])
def test_bad_tools_are_refused_by_parameter_name(tools, values, message):
    with pytest.raises(ValueError, match=message):
        physics_tools(PhysicsParameters.defaults().replace(tools=tools), values)
