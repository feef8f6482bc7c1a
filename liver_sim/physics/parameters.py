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
from liver_sim.physics.settings import (
    CONTACT_MODELS,
    INTEGRATOR_SUBSTEPS,
    INTEGRATORS,
    SOLVER_THREADS,
    SPRING_CONSTANTS,
    SUPPORTS,
    TISSUE_LAWS,
    ModelParams,
    SpringLaw,
    TissueProperties,
)
from liver_sim.physics.tools.tool import LOCAL_MODELS, Tool
from liver_sim.physics.tools.use import TOOL_MODES, ToolUse

DEFAULTS = ModelParams()
TISSUE = DEFAULTS.tissue
PARAMETERS = {
    "mesh_path": Param("", "volume or closed-surface mesh file (metres); empty: the embedded default liver"),
    "mesh_scale": Param(1.0, "factor from mesh_path's units to metres (dimensionless; 0.01: centimetres, 0.001: "
                        "millimetres); a mesh not 0.02-0.5 m across after scaling is refused", 1e-6, 1e6),
    "target_tets": Param(1150, "tetrahedra to aim for when mesh_path is a surface", 50, 2_000_000),
    "frame_id": Param("liver", "frame of every published position"),
    "rate_hz": Param(DEFAULTS.frame_rate_hz, "physics frame rate (Hz)", 1.0, 1000.0),
    "realtime_priority": realtime_priority_parameter(60),
    "integrator": Param(DEFAULTS.integrator, "implicit_euler (linearised backward Euler), symplectic_euler or "
                        "explicit_euler (Eq. 2)", choices=INTEGRATORS),
    "substeps": Param(0, "integration steps per frame; 0: the integrator's own ("
                      + ", ".join(f"{k} {n}" for k, n in INTEGRATOR_SUBSTEPS.items()) + ")", 0, 10_000),
    "tissue_law": Param(DEFAULTS.tissue_law, "the parenchyma: springs (Eq. 1 on the tet edges, the paper's) or fem "
                        "(co-rotational linear tetrahedra with parenchyma E, ν and η; implicit_euler and material "
                        "only)",
                        choices=TISSUE_LAWS),
    "solver_threads": Param(DEFAULTS.solver_threads, "threads of a frame's numba kernels (the implicit step's PCG, "
                            "the explicit spring pass): auto (all from 20 000 springs on), one (beside the 1 kHz "
                            "loops on a 2-core machine) or all", choices=SOLVER_THREADS),
    "spring_constants": Param(DEFAULTS.spring_constants, "material: each spring's λ1, λ2, μ from the tissue "
                              "properties and the mesh; paper: the paper's per-spring constants below",
                              choices=SPRING_CONSTANTS),
    "parenchyma_young_modulus_kpa": Param(TISSUE.parenchyma_young_modulus_kpa, "parenchyma Young's modulus (kPa)",
                                          0.01, 1e4),
    "parenchyma_poisson_ratio": Param(TISSUE.parenchyma_poisson_ratio, "parenchyma Poisson's ratio (the network "
                                      "matches the indentation modulus E/(1-ν²))", 0.0, 0.499),
    "parenchyma_viscosity_pa_s": Param(TISSUE.parenchyma_viscosity_pa_s, "parenchyma viscosity η (Pa·s)", 0.0, 1e6),
    "cubic_ratio": Param(TISSUE.cubic_ratio, "material: λ1/λ2 of Eq. 1 on every spring (dimensionless; Fig. 2's "
                         "143 by default, 0: linear springs)", 0.0, 1e5),
    "capsule_stiffness_n_per_m": Param(TISSUE.capsule_stiffness_n_per_m, "capsule membrane stiffness E·t (N/m)",
                                       0.0, 1e6),
    "capsule_viscosity_ns_per_m": Param(TISSUE.capsule_viscosity_ns_per_m, "capsule membrane viscosity η·t (N·s/m)",
                                        0.0, 1e4),
    "capsule_lambda1_n": Param(DEFAULTS.capsule.lambda1_n, "paper: capsule spring cubic stiffness λ1 of Eq. 1 (N)",
                               0.0, 1e6),
    "capsule_lambda2_n": Param(DEFAULTS.capsule.lambda2_n, "paper: capsule linear stiffness λ2 of Eq. 1 (N)",
                               0.0, 1e6),
    "capsule_mu_ns_per_m": Param(DEFAULTS.capsule.mu_ns_per_m, "paper: capsule viscosity μ of Eq. 1 (N·s/m)",
                                 0.0, 1e4),
    "parenchyma_lambda1_n": Param(DEFAULTS.parenchyma.lambda1_n, "paper: parenchyma cubic stiffness λ1 (N)",
                                  0.0, 1e6),
    "parenchyma_lambda2_n": Param(DEFAULTS.parenchyma.lambda2_n, "paper: parenchyma linear stiffness λ2 (N)",
                                  0.0, 1e6),
    "parenchyma_mu_ns_per_m": Param(DEFAULTS.parenchyma.mu_ns_per_m, "paper: parenchyma viscosity μ (N·s/m)",
                                    0.0, 1e4),
    "density_kg_m3": Param(DEFAULTS.density_kg_m3, "tissue density for the lumped masses (kg/m³)", 1.0, 1e5),
    "environment_damping_per_s": Param(DEFAULTS.environment_damping_per_s,
                                       "environmental viscosity c: a −= c·v (1/s)", 0.0, 1e4),
    "gravity_m_s2": Param(list(DEFAULTS.gravity_m_s2), "gravity vector in the liver frame (m/s²)"),
    "fixed_nodes": Param([-1], "indices of fixed nodes; [-1]: none with support organ (the central tet's four "
                         "nodes if support_regions hold no skin node), the central tet's with support paper"),
    "support": Param(DEFAULTS.support, "how the liver is held: organ (skin in support_regions tied to its rest "
                     "position) or paper (the four nodes of the tet nearest the centroid fixed, paper §3.1)",
                     choices=SUPPORTS),
    "support_regions": Param([float(v) for region in DEFAULTS.support_regions for v in region],
                             "support organ: spheres, five numbers each: centre x, y, z (m, liver frame), radius "
                             "(m), stiffness per unit skin area (N/m³); each skin node inside is tied to its rest "
                             "position with that stiffness times its share of skin area (m²). Default: the "
                             "default liver's bare area, vena cava, left triangular ligament, visceral bed"),
    "support_damping_s": Param(DEFAULTS.support_damping_s, "support organ: damping of each tie over its stiffness "
                               "(s, Kelvin-Voigt time constant)", 0.0, 10.0),
    "contact_stiffness_n_per_m": Param(DEFAULTS.contact_stiffness_n_per_m, "penalty λ of Eq. 3 (N/m)", 0.0, 1e6),
    "contact_damping_ns_per_m": Param(DEFAULTS.contact_damping_ns_per_m, "penalty μ of Eq. 3 (N·s/m)", 0.0, 1e4),
    "contact_model": Param(DEFAULTS.contact_model, "probe: Eq. 3, one penalty per contact probe; surface: a sphere or "
                           "capsule meets the skin as a surface, contact_stiffness_per_area_n_per_m3 at every node and "
                           "face it presses (implicit_euler only)", choices=CONTACT_MODELS),
    "contact_stiffness_per_area_n_per_m3": Param(DEFAULTS.contact_stiffness_per_area_n_per_m3,
                                                 "contact_model surface: penalty per unit skin area (N/m³, a pressure "
                                                 "per metre of depth)", 0.0, 1e10),
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
    "tearing": Param(DEFAULTS.tearing, "separate tetrahedra stretched beyond the tearing strains (paper §2.6); "
                     "the torn mesh is republished on surface_topic"),
    "tear_strain_parenchyma": Param(DEFAULTS.tear_strain_parenchyma, "stretch across a face between two tets "
                                    "(mean normal strain, dimensionless) above which they separate", 0.01, 10.0),
    "tear_strain_capsule": Param(DEFAULTS.tear_strain_capsule, "the same for a face with an edge on the capsule "
                                 "(dimensionless)", 0.01, 10.0),
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
    """The ModelParams named by the node's parameters (validated)."""
    fixed = tuple(p.fixed_nodes) if list(p.fixed_nodes) != [-1] else None
    regions = list(p.support_regions)
    if len(regions) % 5:
        raise ValueError(f"parameter support_regions must hold five numbers per region (x, y, z, radius m, "
                         f"stiffness N/m³), got {len(regions)} numbers")
    return ModelParams(
        spring_constants=p.spring_constants, tissue_law=p.tissue_law, solver_threads=p.solver_threads,
        tissue=TissueProperties(p.parenchyma_young_modulus_kpa, p.parenchyma_poisson_ratio,
                                p.parenchyma_viscosity_pa_s, p.capsule_stiffness_n_per_m, p.capsule_viscosity_ns_per_m,
                                p.cubic_ratio),
        capsule=SpringLaw(p.capsule_lambda1_n, p.capsule_lambda2_n, p.capsule_mu_ns_per_m),
        parenchyma=SpringLaw(p.parenchyma_lambda1_n, p.parenchyma_lambda2_n, p.parenchyma_mu_ns_per_m),
        density_kg_m3=p.density_kg_m3, environment_damping_per_s=p.environment_damping_per_s,
        gravity_m_s2=tuple(p.gravity_m_s2), integrator=p.integrator,
        frame_rate_hz=p.rate_hz, substeps=p.substeps or None, fixed_nodes=fixed,
        support=p.support, support_regions=tuple(tuple(regions[i:i + 5]) for i in range(0, len(regions), 5)),
        support_damping_s=p.support_damping_s,
        contact_stiffness_n_per_m=p.contact_stiffness_n_per_m,
        contact_damping_ns_per_m=p.contact_damping_ns_per_m, contact_model=p.contact_model,
        contact_stiffness_per_area_n_per_m3=p.contact_stiffness_per_area_n_per_m3, tearing=p.tearing,
        tear_strain_parenchyma=p.tear_strain_parenchyma,
        tear_strain_capsule=p.tear_strain_capsule).validate()


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
