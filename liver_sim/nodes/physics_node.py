"""`liver_physics`: steps the liver model at 150 Hz in its own thread and publishes its state.

Publishes /liver/nodes (PointCloud2), /liver/surface (shape_msgs/Mesh, transient local, on start and
on every tear or cut, when /liver/nodes changes its node count too),
/liver/marker (TRIANGLE_LIST at marker_rate_hz), /liver/contact_plane (the local model) and
/liver/tool_wrench (force on the tool); takes the tool tip from /tool/pose.  Stamps are the
simulation time of the state, counted from the node's start on the ROS clock.
"""
from __future__ import annotations

import threading
import time

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node

from liver_sim.mesh.io import load_mesh
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.nodes.common import (Latest, LoopInputs, RateLoop, apply_realtime_priority, declare_parameters,
                                    diagnostic_status, publish_diagnostics, run_node)
from liver_sim.parameters import Param, check_parameter, realtime_priority_parameter
from liver_sim.physics.contact import ToolPose, ToolShape
from liver_sim.physics.model import LiverModel
from liver_sim.physics.params import INTEGRATORS, ModelParams, SpringLaw
from liver_sim.physics.tool_use import TOOL_MODES, ToolUse
from msg_defs import conversions
from msg_defs.topics import TOPICS

DEFAULTS = ModelParams()
PARAMETERS = {
    "mesh_path": Param("", "volume or closed-surface mesh file (metres); empty: the embedded default liver"),
    "target_tets": Param(1150, "tetrahedra to aim for when mesh_path is a surface", 50, 2_000_000),
    "frame_id": Param("liver", "frame of every published position"),
    "rate_hz": Param(DEFAULTS.frame_rate_hz, "physics frame rate (Hz)", 1.0, 1000.0),
    "realtime_priority": realtime_priority_parameter(60),
    "substeps": Param(DEFAULTS.substeps, "integration steps per frame", 1, 10_000),
    "integrator": Param(DEFAULTS.integrator, "symplectic_euler or explicit_euler (Eq. 2)", choices=INTEGRATORS),
    "capsule_lambda1_n": Param(DEFAULTS.capsule.lambda1_n, "capsule spring cubic stiffness λ1 of Eq. 1 (N)", 0.0, 1e6),
    "capsule_lambda2_n": Param(DEFAULTS.capsule.lambda2_n, "capsule linear stiffness λ2 of Eq. 1 (N)", 0.0, 1e6),
    "capsule_mu_ns_per_m": Param(DEFAULTS.capsule.mu_ns_per_m, "capsule viscosity μ of Eq. 1 (N·s/m)", 0.0, 1e4),
    "parenchyma_lambda1_n": Param(DEFAULTS.parenchyma.lambda1_n, "parenchyma cubic stiffness λ1 (N)", 0.0, 1e6),
    "parenchyma_lambda2_n": Param(DEFAULTS.parenchyma.lambda2_n, "parenchyma linear stiffness λ2 (N)", 0.0, 1e6),
    "parenchyma_mu_ns_per_m": Param(DEFAULTS.parenchyma.mu_ns_per_m, "parenchyma viscosity μ (N·s/m)", 0.0, 1e4),
    "density_kg_m3": Param(DEFAULTS.density_kg_m3, "tissue density for the lumped masses (kg/m³)", 1.0, 1e5),
    "environment_damping_per_s": Param(DEFAULTS.environment_damping_per_s,
                                       "environmental viscosity c: a −= c·v (1/s)", 0.0, 1e4),
    "gravity_m_s2": Param(list(DEFAULTS.gravity_m_s2), "gravity vector in the liver frame (m/s²)"),
    "fixed_nodes": Param([-1], "indices of fixed nodes; [-1]: the four nodes of the tet nearest the centroid"),
    "contact_stiffness_n_per_m": Param(DEFAULTS.contact_stiffness_n_per_m, "penalty λ of Eq. 3 (N/m)", 0.0, 1e6),
    "contact_damping_ns_per_m": Param(DEFAULTS.contact_damping_ns_per_m, "penalty μ of Eq. 3 (N·s/m)", 0.0, 1e4),
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
    "local_model": Param("plane", "local model published for the haptic loop", choices=("plane", "sphere")),
    "local_model_reach_m": Param(0.02, "publish a local model while the tool is this close to the skin (m)",
                                 0.0, 1.0),
    "local_model_lifetime_s": Param(0.05, "how long the bridge may trust one local model (s)", 0.001, 10.0),
    "tool_pose_timeout_s": Param(0.5, "a tool pose older than this is ignored: no tool (s)", 0.001, 60.0),
    "workspace_margin_m": Param(0.3, "tool poses farther than this from the liver's bounds are refused (m)",
                                0.0, 100.0),
    "marker_rate_hz": Param(30.0, "rate of the /liver/marker TRIANGLE_LIST (Hz)", 0.1, 150.0),
    "nodes_topic": Param(TOPICS["nodes"].name, "deformed node positions (PointCloud2)"),
    "surface_topic": Param(TOPICS["surface"].name, "skin triangles (shape_msgs/Mesh)"),
    "marker_topic": Param(TOPICS["marker"].name, "deformed skin for viewers (Marker)"),
    "contact_plane_topic": Param(TOPICS["contact_plane"].name, "local model for the haptic bridge (Marker)"),
    "tool_wrench_topic": Param(TOPICS["tool_wrench"].name, "contact force on the tool (WrenchStamped)"),
    "tool_pose_topic": Param(TOPICS["tool_pose"].name, "tool tip pose in the liver frame (PoseStamped)"),
}


def model_params(values: dict) -> ModelParams:
    """The ModelParams named by the node's parameter values (validated)."""
    fixed = tuple(values["fixed_nodes"]) if list(values["fixed_nodes"]) != [-1] else None
    return ModelParams(
        capsule=SpringLaw(values["capsule_lambda1_n"], values["capsule_lambda2_n"], values["capsule_mu_ns_per_m"]),
        parenchyma=SpringLaw(values["parenchyma_lambda1_n"], values["parenchyma_lambda2_n"],
                             values["parenchyma_mu_ns_per_m"]),
        density_kg_m3=values["density_kg_m3"], environment_damping_per_s=values["environment_damping_per_s"],
        gravity_m_s2=tuple(values["gravity_m_s2"]), integrator=values["integrator"],
        frame_rate_hz=values["rate_hz"], substeps=values["substeps"], fixed_nodes=fixed,
        contact_stiffness_n_per_m=values["contact_stiffness_n_per_m"],
        contact_damping_ns_per_m=values["contact_damping_ns_per_m"], tearing=values["tearing"],
        tear_strain_parenchyma=values["tear_strain_parenchyma"],
        tear_strain_capsule=values["tear_strain_capsule"]).validate()


def build_model(values: dict) -> LiverModel:
    """The LiverModel (mesh, parameters, tool, local model) named by the node's parameter values, warmed up."""
    mesh = load_mesh(values["mesh_path"], values["target_tets"]) if values["mesh_path"] else default_liver()
    tool = ToolShape(values["tool_shape"], values["tool_radius_m"], values["tool_length_m"],
                     tuple(values["tool_half_extents_m"]))
    model = LiverModel(mesh, model_params(values), tool, values["local_model"], values["local_model_reach_m"])
    model.warm_up()
    return model


class PhysicsNode(Node):
    """The physics node: a LiverModel stepped by a RateLoop, its state published each frame."""

    def __init__(self):
        super().__init__("liver_physics")
        p = declare_parameters(self, PARAMETERS)
        self.p = p
        self.model = build_model(p)
        mesh = self.model.mesh
        lower, upper = mesh.bounds
        self._workspace = (lower - p["workspace_margin_m"], upper + p["workspace_margin_m"])
        self._pose = Latest()
        self._bad_poses = 0
        self._frame_seconds = []  # compute time of each frame since the last diagnostics (s)
        self._frame_seconds_lock = threading.Lock()
        self._marker_every = max(1, round(p["rate_hz"] / p["marker_rate_hz"]))
        self._frames = 0
        self._outputs = {
            key: self.create_publisher(TOPICS[key].type, p[f"{key}_topic"], TOPICS[key].qos)
            for key in ("nodes", "surface", "marker", "contact_plane", "tool_wrench")}
        self._diagnostics = self.create_publisher(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                                  TOPICS["diagnostics"].qos)
        # 1 kHz of poses for a 150 Hz consumer: the loop takes the newest bytes each frame
        self._inputs = LoopInputs(self)
        self._inputs.subscribe(TOPICS["tool_pose"].type, p["tool_pose_topic"], TOPICS["tool_pose"].qos,
                               self._pose.set, raw=True)
        self._last_pose_bytes, self._last_pose = None, None
        self._clock_origin_s = self.get_clock().now().nanoseconds * 1e-9
        self._tool_use = ToolUse(self.model, p["tool_mode"], p["grasp_margin_m"], p["cut_depth_m"])
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.publish_surface()
        self.create_timer(1.0, self._publish_diagnostics)
        self._loop = RateLoop(p["rate_hz"], self._step, "liver_physics")
        self.get_logger().info(
            f"liver_physics: mesh '{mesh.source}' ({len(mesh.points)} nodes, {len(mesh.tets)} tets, "
            f"{len(mesh.skin)} skin triangles), {p['rate_hz']:g} Hz × {p['substeps']} substeps "
            f"(dt {self.model.params.dt_s * 1e6:.0f} us, stable below {self.model.stable_dt_s * 1e6:.0f} us); "
            f"in: {p['tool_pose_topic']}; out: {p['nodes_topic']}, {p['surface_topic']}, {p['marker_topic']} "
            f"({p['marker_rate_hz']:g} Hz), {p['contact_plane_topic']} ({p['local_model']}), {p['tool_wrench_topic']}; "
            f"tool {p['tool_shape']} in mode {p['tool_mode']}, tearing {'on' if p['tearing'] else 'off'}")
        apply_realtime_priority(self, p["realtime_priority"])  # before the loop starts: it inherits it
        self._loop.start()

    def close(self) -> None:
        self._loop.stop()
        self._inputs.destroy()

    def publish_surface(self) -> None:
        """Skin triangles and rest positions: on start and on every topology change."""
        self._outputs["surface"].publish(conversions.skin_mesh_msg(self.model.mesh.skin, self.model.mesh.points))

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """Accept a new tool_mode (press, grasp, cut) at run time; every other parameter is read at start."""
        for parameter in parameters:
            if parameter.name != "tool_mode":
                return SetParametersResult(successful=False, reason=f"{parameter.name} is read at start: restart "
                                           "liver_physics to change it (only tool_mode changes at run time)")
            try:
                check_parameter("tool_mode", PARAMETERS["tool_mode"], parameter.value)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        for parameter in parameters:
            self._tool_use.mode = parameter.value  # read by the loop at its next frame
            self.get_logger().info(f"tool_mode: {parameter.value}")
        return SetParametersResult(successful=True)

    def _topology_changed(self, cause: str) -> None:
        mesh = self.model.mesh
        self.publish_surface()
        self.get_logger().info(
            f"{cause}: {len(mesh.points)} nodes, {len(mesh.tets)} tets, {len(mesh.skin)} skin triangles; "
            f"{self.model.params.substeps} substeps per frame (stable below {self.model.stable_dt_s * 1e6:.0f} us)",
            throttle_duration_sec=0.5)

    def _tool_pose(self, now: float) -> ToolPose | None:
        """The newest valid tool pose, None when it is older than tool_pose_timeout_s or refused."""
        data, received = self._pose.get()
        if data is None or now - received > self.p["tool_pose_timeout_s"]:
            return None
        if data is not self._last_pose_bytes:
            self._last_pose_bytes, self._last_pose = data, self._parse_pose(data)
        return self._last_pose

    def _parse_pose(self, data: bytes) -> ToolPose | None:
        try:
            position, orientation, _ = conversions.pose_from_bytes(data)
        except ValueError as exc:  # malformed bytes or a NaN/zero-quaternion pose
            self._refuse_pose(str(exc))
            return None
        if np.any(position < self._workspace[0]) or np.any(position > self._workspace[1]):
            self._refuse_pose(f"tool position {position.round(3).tolist()} m is outside the workspace")
            return None
        return ToolPose(position, tuple(orientation))

    def _refuse_pose(self, reason: str) -> None:
        self._bad_poses += 1
        self.get_logger().warning(f"ignored tool pose: {reason}", throttle_duration_sec=1.0)

    def _stamp(self):
        return conversions.stamp_from_seconds(self._clock_origin_s + self.model.time_s)

    def _step(self, now: float) -> None:
        started = time.perf_counter()
        self._inputs.poll()
        pose = self._tool_pose(now)
        result, cut = self._tool_use.step_frame(pose)
        if result.divergence:
            self.get_logger().error(result.divergence, throttle_duration_sec=1.0)
        if result.topology_changed:
            self._topology_changed("torn")
        if cut:
            self._topology_changed("cut")
        while self._tool_use.events:
            self.get_logger().info(self._tool_use.events.pop(0))
        stamp = self._stamp()
        frame = self.p["frame_id"]
        self._outputs["nodes"].publish(conversions.nodes_to_pointcloud2(self.model.positions, stamp, frame))
        self._outputs["contact_plane"].publish(conversions.local_model_marker(
            result.local_model, stamp, frame, self.p["local_model_lifetime_s"]))
        self._outputs["tool_wrench"].publish(conversions.wrench_stamped_bytes(result.tool_force_n, stamp, frame))
        if self._frames % self._marker_every == 0:
            self._outputs["marker"].publish(conversions.skin_marker_serialized(
                self.model.positions, self.model.mesh.skin, stamp, frame))
        self._frames += 1
        with self._frame_seconds_lock:
            self._frame_seconds.append(time.perf_counter() - started)

    def _publish_diagnostics(self) -> None:
        stats = self._loop.stats.summary()
        with self._frame_seconds_lock:
            compute, self._frame_seconds = np.array(self._frame_seconds), []
        _, received = self._pose.get()
        extra = {"frame_compute_p99_s": float(np.percentile(compute, 99)) if compute.size else 0.0,
                 "divergences": self.model.divergences, "bad_tool_poses": self._bad_poses,
                 "tool_mode": self._tool_use.mode, "topology_changes": self.model.topology_version,
                 "nodes": len(self.model.positions), "substeps": self.model.params.substeps,
                 "tool_pose_age_s": float(time.monotonic() - received), "simulated_s": self.model.time_s}
        ok = stats["rate_hz"] > 0.98 * self.p["rate_hz"]
        status = diagnostic_status(f"{self.get_name()}: loop", stats, ok,
                                   "ok" if ok else "below rate", extra)
        publish_diagnostics(self, self._diagnostics, [status])


def main(args=None) -> int:
    return run_node(PhysicsNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
