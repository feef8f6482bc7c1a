"""The physics node's parameter table (liver_sim.base.parameters.Param: default, unit, range) and its typed record
(`PhysicsParameters`), its tools (`physics_tools`: one by default, or several, each with parameters of its own),
the ModelParams a record names (`model_params`) and the model it builds (`build_model`): declared by
`liver_physics`, read by the offline sessions, so both refuse the same values."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

from liver_sim.base import kernel_cache
from liver_sim.base.emulated_link import LINK_PARAMETERS
from liver_sim.base.parameters import Param, parameter_record, realtime_priority_parameter
from liver_sim.base.topic_names import TOOL_NAME, TOPIC_NAMES, in_namespace, tool_namespace, tool_topic
from liver_sim.mesh.io import load_mesh
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolShape
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams, from_node_values, node_parameters
from liver_sim.physics.tools.tool import LOCAL_MODELS, Tool
from liver_sim.physics.tools.use import TOOL_MODES, ToolUse

PARAMETERS = {
    "mesh_path": Param("", "volume or closed-surface mesh file (metres); empty: the embedded default liver"),
    "mesh_scale": Param(1.0, "factor from mesh_path's units to metres (dimensionless; 0.01: centimetres, 0.001: "
                        "millimetres); a mesh not 0.02-0.5 m across after scaling is refused", 1e-6, 1e6),
    "target_tets": Param(1150, "tetrahedra to aim for when mesh_path is a surface", 50, 2_000_000),
    "frame_id": Param("liver", "frame of every published position"),
    "realtime_priority": realtime_priority_parameter(60),
    **node_parameters(),  # the model's, declared with ModelParams (physics.settings)
    "tools": Param([""], "the tools on the liver, one name each (e.g. [left, right]: two hands): tool NAME takes "
                   "its pose on tool_pose_topic and publishes contact_plane_topic and tool_wrench_topic in the "
                   "namespace /NAME (relative names go under it), with parameters NAME.<name> of its own for its "
                   "shape, mode, local model and topics (tool_shape, tool_radius_m, tool_mode, …; default: the node's "
                   "<name>); '' is a tool in the root namespace that has the node's own. Default: one tool, ['']; "
                   "two need integrator implicit_euler"),
    "tool_shape": Param("sphere", "rigid tool: sphere, capsule or box", choices=("sphere", "capsule", "box")),
    "tool_radius_m": Param(ToolShape().radius_m, "sphere/capsule radius (m)", 1e-4, 0.2),
    "tool_length_m": Param(ToolShape().length_m, "capsule shaft length along the tool +z (m)", 0.0, 1.0),
    "tool_half_extents_m": Param(list(ToolShape().half_extents_m), "box half extents (m)"),
    "tool_mode": Param("press", "press: the tool pushes the surface (Eq. 3); grasp: the skin nodes it touches "
                       "follow it until tool_mode changes; cut: each stroke in contact cuts the skin (and cut_depth_m "
                       "of tissue under it) along the tool path when the tool leaves the surface (§3.5). May be "
                       "changed at run time", choices=TOOL_MODES),
    "grasp_margin_m": Param(0.005, "grasp: skin nodes this close to the tool's bounding ball are held (m)",
                            0.0, 0.05),
    "cut_depth_m": Param(0.005, "cut: depth of the cut below the tool path (m); under one element layer cuts "
                         "the capsule (membrane) only", 0.0005, 0.2),
    "local_model": Param("plane", "local model published for the haptic loop", choices=LOCAL_MODELS),
    "local_model_reach_m": Param(0.02, "publish a local model while the tool is this close to the skin (m)",
                                 0.0, 1.0),
    "local_model_lifetime_s": Param(0.05, "how long the bridge may trust one local model (s)", 0.001, 10.0),
    "tool_pose_timeout_s": Param(0.5, "a tool pose older than this is ignored: no tool (s)", 0.001, 60.0),
    "workspace_margin_m": Param(0.3, "tool poses farther than this from the liver's bounds are refused (m)",
                                0.0, 100.0),
    "marker_rate_hz": Param(30.0, "rate of the /liver/marker TRIANGLE_LIST (Hz)", 0.1, 150.0),
    # the default names of msg_defs.topics.TOPICS (which needs rclpy for its QoS profiles)
    "nodes_topic": Param(TOPIC_NAMES["nodes"], "deformed node positions (PointCloud2)"),
    "surface_topic": Param(TOPIC_NAMES["surface"], "skin triangles (shape_msgs/Mesh)"),
    "marker_topic": Param(TOPIC_NAMES["marker"], "deformed skin for viewers (Marker)"),
    "contact_plane_topic": Param(tool_topic("contact_plane"), "local model for the haptic bridge (Marker), in the "
                                 "tool's namespace"),
    "tool_wrench_topic": Param(tool_topic("tool_wrench"), "contact force on the tool (WrenchStamped), in the tool's "
                               "namespace"),
    "tool_pose_topic": Param(tool_topic("tool_pose"), "tool tip pose in the liver frame (PoseStamped), in the tool's "
                             "namespace"),
    "tool_node": Param("liver_tool", "the only node whose tool poses on tool_pose_topic are taken, judged by each "
                       "sample's writer (others are refused and counted); a relative name is the node of that name in "
                       "the tool's namespace (/left/liver_tool for tool left); read at start"),
    **LINK_PARAMETERS,  # on the inputs from the other side of a teleoperation link
}


#: The physics node's parameters as one typed record (liver_sim.base.parameters.parameter_record).
PhysicsParameters = parameter_record("PhysicsParameters", PARAMETERS, "The parameters of liver_physics (PARAMETERS).")

#: What each tool has of its own: tool NAME declares NAME.<name>, its default the node's <name>.
TOOL_PARAMETERS = ("tool_shape", "tool_radius_m", "tool_length_m", "tool_half_extents_m", "tool_mode",
                   "grasp_margin_m", "cut_depth_m", "local_model", "local_model_reach_m", "tool_pose_topic",
                   "contact_plane_topic", "tool_wrench_topic", "tool_node")
#: One tool's parameters (TOOL_PARAMETERS) as a typed record.
ToolSettings = parameter_record("ToolSettings", {name: PARAMETERS[name] for name in TOOL_PARAMETERS},
                                "One tool's parameters of liver_physics (TOOL_PARAMETERS).")
#: The topic parameters of a tool, resolved in its namespace.
TOOL_TOPIC_PARAMETERS = ("tool_pose_topic", "contact_plane_topic", "tool_wrench_topic")


@dataclass(frozen=True)
class PhysicsTool:
    """A tool of the physics node: its `name` ('' in the root namespace) and `settings`."""

    name: str
    settings: ToolSettings

    @property
    def namespace(self) -> str:
        return tool_namespace(self.name)

    def topic(self, parameter: str) -> str:
        """The absolute name of the topic parameter `parameter` (TOOL_TOPIC_PARAMETERS) in the tool's namespace."""
        return in_namespace(getattr(self.settings, parameter), self.namespace)

    @property
    def source_node(self) -> str:
        """The fully qualified name of the node whose poses the tool takes (`tool_node` in its namespace)."""
        return in_namespace(self.settings.tool_node, self.namespace)

    def parameter(self, name: str) -> str:
        """The node's name of the tool's parameter `name`: NAME.<name>, or <name> for the tool ''."""
        return f"{self.name}.{name}" if self.name else name


def tool_declarations(p: PhysicsParameters) -> dict[str, Param]:
    """The parameters NAME.<name> (TOOL_PARAMETERS) of every named tool of `p.tools`, each defaulting to `p`'s <name>
    with its range; ValueError naming `tools` when a name is not a ROS name token, or is given twice."""
    names = list(p.tools)
    bad = [name for name in names if name and not TOOL_NAME.fullmatch(name)]
    if not names or bad or len(set(names)) != len(names):
        raise ValueError(f"parameter tools={names!r} must name one tool or more, each once, each '' (the root "
                         f"namespace) or a name of letters, digits and _ starting with a letter"
                         + (f"; {bad!r} is not" if bad else ""))
    own = {name: getattr(p, name) for name in TOOL_PARAMETERS}
    return {f"{tool}.{name}": replace(PARAMETERS[name], default=list(value) if isinstance(value, tuple) else value)
            for tool in names if tool for name, value in own.items()}


def physics_tools(p: PhysicsParameters, values: Mapping[str, object] | None = None) -> tuple[PhysicsTool, ...]:
    """The tools of `p.tools`, each with its parameters: `values`[NAME.<name>] where given, else `p`'s <name>;
    ValueError naming the parameter when a value is refused, or when two tools would use one topic."""
    values = values or {}
    declared = tool_declarations(p)
    unknown = sorted(name for name in values if "." in name and name not in declared)
    if unknown:
        raise ValueError(f"unknown parameter(s) {', '.join(unknown)}: tools are {list(p.tools)!r} (parameter tools)")
    tools = []
    for tool in p.tools:
        own = {name: values.get(f"{tool}.{name}", getattr(p, name)) if tool else getattr(p, name)
               for name in TOOL_PARAMETERS}
        try:
            tools.append(PhysicsTool(tool, ToolSettings.from_values(own)))
        except ValueError as exc:
            raise ValueError(str(exc).replace("parameter ", f"parameter {tool}.", 1) if tool else str(exc)) from None
    users: dict[str, str] = {}
    for tool in tools:
        for parameter in TOOL_TOPIC_PARAMETERS:
            topic = tool.topic(parameter)
            if topic in users:
                raise ValueError(f"parameter {tool.parameter(parameter)}: {topic} is already {users[topic]}; each tool "
                                 "needs topics of its own (relative names go under its namespace)")
            users[topic] = tool.parameter(parameter)
    return tuple(tools)


def model_params(p: PhysicsParameters) -> ModelParams:
    """The ModelParams named by the node's parameters (validated; physics.settings.from_node_values)."""
    return from_node_values(p)


def model_tool(tool: PhysicsTool) -> Tool:
    """The model's Tool of a tool of the physics node: its shape, local model and use."""
    s = tool.settings
    return Tool(ToolShape(s.tool_shape, s.tool_radius_m, s.tool_length_m, tuple(s.tool_half_extents_m)),
                s.local_model, s.local_model_reach_m, ToolUse(s.tool_mode, s.grasp_margin_m, s.cut_depth_m),
                name=tool.name)


def build_model(p: PhysicsParameters, tools: tuple[PhysicsTool, ...] | None = None) -> LiverModel:
    """The LiverModel (mesh, parameters, its tools and their use) named by the node's parameters (`tools`: default
    physics_tools(p)), warmed up; its kernels compiled under the cache's lock (base.kernel_cache.compiling)."""
    tools = physics_tools(p) if tools is None else tools
    with kernel_cache.compiling():  # meshing a surface compiles kernels too, not only the warm-up
        mesh = load_mesh(p.mesh_path, p.target_tets, p.mesh_scale) if p.mesh_path else default_liver()
        model = LiverModel(mesh, model_params(p), [model_tool(tool) for tool in tools])
        model.warm_up()
    return model
