"""The physics' and the bridge's parameters for offline runs: the nodes' own declarations
(PARAMETERS), their config/<node>.yaml values, then `name:=value` overrides, range-checked as the
nodes check them (liver_sim.base.parameters.ParameterRecord), as their typed records
(liver_sim.physics.parameters.PhysicsParameters, haptic_bridge.parameters.BridgeParameters), and the physics'
tools (liver_sim.physics.parameters.physics_tools).

An override `name:=value` applies to every node declaring `name` (tool_radius_m: both);
`liver_physics.name:=value` or `haptic_bridge.name:=value` to one; `NAME.name:=value` to the physics' tool NAME
(`-p tools:=[left,right] -p left.tool_mode:=grasp`).  Values are YAML, as after `-p`.
"""
from __future__ import annotations

import yaml

from haptic_bridge.parameters import PARAMETERS as BRIDGE
from haptic_bridge.parameters import BridgeParameters
from liver_sim.base.process_settings import config_dir
from liver_sim.physics.parameters import PARAMETERS as PHYSICS
from liver_sim.physics.parameters import PhysicsParameters, physics_tools

NODES = ("liver_physics", "haptic_bridge")


def declarations() -> dict:
    """{node: PARAMETERS} of the physics node and the haptic bridge."""

    return {"liver_physics": PHYSICS, "haptic_bridge": BRIDGE}


def _flat(values: dict, prefix: str = "") -> dict:
    """A parameter file's nested values as ROS names them: {'left': {'tool_mode': v}} → {'left.tool_mode': v}."""
    flat = {}
    for name, value in values.items():
        if isinstance(value, dict):
            flat.update(_flat(value, f"{prefix}{name}."))
        else:
            flat[f"{prefix}{name}"] = value
    return flat


def _config_values(node: str) -> dict:
    path = config_dir() / f"{node}.yaml"
    if not path.is_file():
        return {}
    try:
        return _flat((yaml.safe_load(path.read_text()) or {})[node]["ros__parameters"])
    except (yaml.YAMLError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"{path}: not a parameter file of {node} ({exc})") from None


def parse_override(text: str) -> tuple[str | None, str, object]:
    """(node or None, name, value) of 'name:=value' or 'node.name:=value' (a name may hold a dot of its own: a
    tool's parameter, 'left.tool_mode')."""
    name, sep, raw = text.partition(":=")
    if not sep or not name:
        raise ValueError(f"parameter override {text!r} must look like name:=value")
    node, dot, short = name.partition(".")
    if not (dot and node in NODES):
        node, short = None, name
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as exc:
        raise ValueError(f"parameter override {text!r}: value is not YAML ({exc})") from None
    return node, short, value


def node_parameters(overrides=()) -> dict:
    """{node: parameters} for liver_physics (a PhysicsParameters) and haptic_bridge (a BridgeParameters), and
    under `tools` the physics' tools (a tuple of PhysicsTool): defaults, config file, overrides; checked."""

    declared = declarations()
    values = {node: {name: spec.default for name, spec in declared[node].items()} for node in NODES}
    tool_values = {}  # the physics' tools' own, NAME.name
    for node in NODES:
        for name, value in _config_values(node).items():
            if name in declared[node]:
                values[node][name] = value
            elif node == "liver_physics" and "." in name:
                tool_values[name] = value
    for text in overrides:
        node, name, value = parse_override(text)
        if "." in name and node in (None, "liver_physics"):
            tool_values[name] = value
            continue
        targets = [n for n in ([node] if node else NODES) if name in declared[n]]
        if not targets:
            raise ValueError(f"unknown parameter {name!r}" + (f" of {node}" if node else
                             f": neither {' nor '.join(NODES)} declares it"))
        for target in targets:
            values[target][name] = value
    values["liver_physics"] = PhysicsParameters.from_values(values["liver_physics"])
    values["haptic_bridge"] = BridgeParameters.from_values(values["haptic_bridge"])
    values["tools"] = physics_tools(values["liver_physics"], tool_values)
    return values
