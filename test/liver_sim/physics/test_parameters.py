"""The physics node's parameters as the model's (physics.parameters): the config's defaults, the support's regions
checked, each tool's parameters and topics in its namespace, the model's Tool of a tool's settings."""
from dataclasses import fields, is_dataclass

import pytest

from liver_sim.physics.parameters import PARAMETERS, PhysicsParameters, model_params, model_tool, physics_tools
from liver_sim.physics.settings import ModelParams, TissueProperties
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


#: Node parameters named otherwise than the model's field, and values that are no default's.
RENAMED = {"rate_hz": "frame_rate_hz"}
LIST_VALUES = {"gravity_m_s2": [0.0, 0.0, -9.81], "fixed_nodes": [0], "support_regions": [0.0, 0.0, 0.0, 0.01, 1e5]}


def field_path(name: str) -> str:
    """The ModelParams field (record.field for a nested one) the node parameter `name` is meant to set."""
    if name in RENAMED:
        return RENAMED[name]
    for record in ("capsule", "parenchyma"):
        rest = name.removeprefix(record + "_")
        if rest in ("lambda1_n", "lambda2_n", "mu_ns_per_m"):
            return f"{record}.{rest}"
    return f"tissue.{name}" if name in {f.name for f in fields(TissueProperties)} else name


def other_value(name: str, default):
    """A valid value of parameter `name` other than its `default`."""
    spec = PARAMETERS[name]
    if name in LIST_VALUES:
        return LIST_VALUES[name]
    if spec.choices:
        return next(choice for choice in spec.choices if choice != default)
    if isinstance(default, bool):
        return not default
    if isinstance(default, int):
        return 5
    return (default + spec.high) / 2 if spec.high is not None else default + 1.0


def differing(a, b, path: str = "") -> set:
    """The field paths where the records `a` and `b` differ."""
    out = set()
    for f in fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if is_dataclass(x):
            out |= differing(x, y, f"{path}{f.name}.")
        elif x != y:
            out.add(path + f.name)
    return out


def test_every_model_parameter_of_the_node_sets_its_field_and_no_other():
    p = PhysicsParameters.defaults()
    default = model_params(p)
    model_fields = {field_path(name) for name in PARAMETERS} & (
        {f.name for f in fields(ModelParams)} | {f"tissue.{f.name}" for f in fields(TissueProperties)}
        | {f"{r}.{k}" for r in ("capsule", "parenchyma") for k in ("lambda1_n", "lambda2_n", "mu_ns_per_m")})
    assert len(model_fields) == 32  # every model field the node exposes
    for name in PARAMETERS:
        path = field_path(name)
        if path not in model_fields:
            continue
        changed = model_params(p.replace(**{name: other_value(name, getattr(p, name))}))
        expected = {path} | ({"substeps"} if name == "integrator" else set())  # a new integrator: its own substeps
        assert differing(changed, default) == expected, name
