"""`liver_physics`: steps the liver model at 150 Hz in its own thread and publishes its state.

Publishes /liver/nodes (PointCloud2), /liver/surface (shape_msgs/Mesh, transient local, on start and
on every tear or cut, when /liver/nodes changes its node count too),
/liver/marker (TRIANGLE_LIST at marker_rate_hz), and for each tool (parameter `tools`; one by default, in the root
namespace) its local model (/liver/contact_plane) and the force on it (/liver/tool_wrench), in the tool's namespace
(/left/liver/contact_plane for tool `left`); takes each tool's tip from its /tool/pose, only from its `tool_node`
(judged by each sample's writer, haptic_bridge.sources).  Stamps are the ROS time
at which each frame starts.
"""
from __future__ import annotations

import threading
import time

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node

from haptic_bridge.sources import WriterGate
from liver_sim.base.emulated_link import link_text
from liver_sim.base.parameters import check_parameter
from liver_sim.nodes.diagnostics import loop_status, loop_status_name, publish_diagnostics
from liver_sim.nodes.inputs import Latest, LoopInputs, emulated_link, link_report
from liver_sim.nodes.parameters import declare_parameters
from liver_sim.nodes.run import run_node
from liver_sim.nodes.source_graph import update_gates
from liver_sim.physics.parameters import (
    PARAMETERS,
    PhysicsParameters,
    build_model,
    physics_tools,
    tool_declarations,
)
from liver_sim.physics.pipeline import Frame, FramePipeline
from liver_sim.realtime.rate_loop import RateLoop, warn
from msg_defs.cdr import MAX_BYTES
from msg_defs.forces import wrench_stamped_bytes
from msg_defs.local_model import local_model_marker_bytes
from msg_defs.point_cloud import nodes_pointcloud2_bytes
from msg_defs.poses import pose_from_bytes
from msg_defs.skin import skin_marker_serialized, skin_mesh_msg
from msg_defs.topics import TOPICS, loop_input_qos

#: How often (s) the node looks at the graph for the writers of its tools' poses (not in the 150 Hz loop).
GRAPH_CHECK_S = 0.1
#: Tool poses a reader keeps between two frames: 1 kHz devices for 1/150 s, and other writers' samples beside them.
POSE_HISTORY = 100


class PhysicsNode(Node):
    """The physics node: a FramePipeline stepped by a RateLoop, its outputs published each frame."""

    def __init__(self):
        super().__init__("liver_physics")
        p = PhysicsParameters.from_values(declare_parameters(self, PARAMETERS))
        self.p = p
        self.tools = physics_tools(p, declare_parameters(self, tool_declarations(p)))
        self.model = build_model(p, self.tools)
        self._pipeline = FramePipeline(self.model, p)
        structure = self.model.structure
        mesh = structure.mesh
        self._frame_seconds = []  # compute time of each frame since the last diagnostics (s)
        self._frame_seconds_lock = threading.Lock()
        self._outputs = {
            key: self.create_publisher(TOPICS[key].type, getattr(p, f"{key}_topic"), TOPICS[key].qos)
            for key in ("nodes", "surface", "marker")}
        self._tool_outputs = [{key: self.create_publisher(TOPICS[key].type, tool.topic(f"{key}_topic"),
                                                          TOPICS[key].qos) for key in ("contact_plane", "tool_wrench")}
                              for tool in self.tools]
        self._diagnostics = self.create_publisher(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                                  TOPICS["diagnostics"].qos)
        # 1 kHz of poses for a 150 Hz consumer: the loop takes the newest bytes of each tool's each frame
        self._inputs = LoopInputs(self)
        self._links = [emulated_link(p) for _ in self.tools]  # the teleoperation link from each operator, if emulated
        self._poses = [Latest() for _ in self.tools]
        # each tool's poses only from its tool_node's writer (haptic_bridge.sources), the graph looked at by a timer
        self._gates = {tool.topic("tool_pose_topic"): WriterGate(tool.source_node, tool.parameter("tool_node"))
                       for tool in self.tools}
        for tool, pose, link, gate in zip(self.tools, self._poses, self._links, self._gates.values()):
            self._inputs.subscribe(TOPICS["tool_pose"].type, tool.topic("tool_pose_topic"),
                                   loop_input_qos(TOPICS["tool_pose"], POSE_HISTORY), pose.set, link=link, gate=gate,
                                   max_bytes=MAX_BYTES["PoseStamped"])
        self.create_timer(GRAPH_CHECK_S, lambda: update_gates(self, self._gates))
        self._last_pose_bytes = [None] * len(self.tools)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.publish_surface()
        self.create_timer(1.0, self._publish_diagnostics)
        self._loop = RateLoop(p.rate_hz, self._step, "liver_physics", realtime_priority=p.realtime_priority,
                              on_refused=warn(self))
        self.get_logger().info(
            f"liver_physics: mesh '{mesh.source}' ({len(mesh.points)} nodes, {len(mesh.tets)} tets, "
            f"{len(mesh.skin)} skin triangles), {p.rate_hz:g} Hz × {structure.params.substeps} "
            f"{structure.params.integrator} steps (dt {structure.params.dt_s * 1e6:.0f} us"
            f"{'' if structure.implicit else f', stable below {structure.stable_dt_s * 1e6:.0f} us'}); "
            f"out: {p.nodes_topic}, {p.surface_topic}, {p.marker_topic} ({p.marker_rate_hz:g} Hz); "
            + "; ".join(f"{'tool ' + tool.name + ': ' if tool.name else ''}in: {tool.topic('tool_pose_topic')}"
                        f"{link_text(link)}; out: {tool.topic('contact_plane_topic')} ({tool.settings.local_model}), "
                        f"{tool.topic('tool_wrench_topic')}; tool {tool.settings.tool_shape} in mode "
                        f"{tool.settings.tool_mode}" for tool, link in zip(self.tools, self._links))
            + f"; tearing {'on' if p.tearing else 'off'}")
        self._loop.start()

    def close(self) -> None:
        self._loop.stop()
        self._inputs.destroy()

    def publish_surface(self) -> None:
        """Skin triangles and rest positions: on start and on every topology change."""
        mesh = self.model.structure.mesh
        self._outputs["surface"].publish(skin_mesh_msg(mesh.skin, mesh.points))

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        """Accept a new tool mode (press, grasp, cut) of a tool at run time (`tool_mode` of the tool '',
        NAME.tool_mode of tool NAME); every other parameter is read at start."""
        uses = {tool.parameter("tool_mode"): self.model.tools[k].use for k, tool in enumerate(self.tools)}
        for parameter in parameters:
            if parameter.name not in uses:
                return SetParametersResult(successful=False, reason=f"{parameter.name} is read at start: restart "
                                           f"liver_physics to change it (only {', '.join(uses)} change at run time)")
            try:
                check_parameter(parameter.name, PARAMETERS["tool_mode"], parameter.value)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        for parameter in parameters:
            uses[parameter.name].mode = parameter.value  # read by the loop at its next frame
            self.get_logger().info(f"{parameter.name}: {parameter.value}")
        return SetParametersResult(successful=True)

    def _receive_poses(self) -> None:
        """Hand the pipeline each tool's newest pose message, once (malformed bytes or a NaN pose: refused)."""
        for k, pose in enumerate(self._poses):
            taken, received = pose.get()
            if taken is None or taken is self._last_pose_bytes[k]:
                continue
            self._last_pose_bytes[k] = taken
            try:
                if not taken.data:
                    raise ValueError(f"PoseStamped: {taken.size} bytes, more than the {MAX_BYTES['PoseStamped']} a "
                                     "tool pose may have (msg_defs.cdr.MAX_BYTES): refused without reading it")
                position, orientation, _ = pose_from_bytes(taken.data)
            except ValueError as exc:
                self._pipeline.refuse(str(exc), received, k)
            else:
                self._pipeline.receive(position, orientation, received, k)

    def _log(self, frame: Frame) -> None:
        logger = self.get_logger()
        for event in frame.events:  # one call site per kind: rclpy throttles by call site
            if event.kind == "refused":
                logger.warning(event.text, throttle_duration_sec=1.0)
            elif event.kind == "diverged":
                logger.error(event.text, throttle_duration_sec=1.0)
            elif event.kind == "topology":
                logger.info(event.text, throttle_duration_sec=0.5)
            elif event.kind == "topology_failed":
                logger.error(event.text, throttle_duration_sec=1.0)
            else:
                logger.info(event.text)

    def _step(self, now: float) -> None:
        started = time.perf_counter()
        stamp = self.get_clock().now().seconds_nanoseconds()  # ROS time at which this frame's state holds
        self._inputs.poll()
        self._receive_poses()
        frame = self._pipeline.step(now)
        self._log(frame)
        if frame.surface_changed:
            self.publish_surface()
        result = frame.result
        frame_id = self.p.frame_id
        positions = self.model.state.positions
        self._outputs["nodes"].publish(nodes_pointcloud2_bytes(positions, stamp, frame_id))
        for outputs, local_model, force in zip(self._tool_outputs, result.local_models, result.tool_forces_n):
            outputs["contact_plane"].publish(local_model_marker_bytes(local_model, stamp, frame_id,
                                                                      self.p.local_model_lifetime_s))
            outputs["tool_wrench"].publish(wrench_stamped_bytes(force, stamp, frame_id))
        if frame.marker_due:
            self._outputs["marker"].publish(skin_marker_serialized(
                positions, self.model.structure.mesh.skin, stamp, frame_id))
        with self._frame_seconds_lock:
            self._frame_seconds.append(time.perf_counter() - started)

    def _publish_diagnostics(self) -> None:
        stats = self._loop.report()
        with self._frame_seconds_lock:
            compute, self._frame_seconds = np.array(self._frame_seconds), []
        now = time.monotonic()
        tools = {}  # per tool, under its parameter prefix
        for tool, contact, pose, link in zip(self.tools, self.model.tools, self._poses, self._links):
            tools[tool.parameter("tool_mode")] = contact.use.mode
            tools[tool.parameter("tool_pose_age_s")] = float(now - pose.get()[1])
            gate = self._gates[tool.topic("tool_pose_topic")]
            tools[tool.parameter("tool_node")] = gate.source
            tools[tool.parameter("refused_tool_poses")] = gate.refused
            tools[tool.parameter("tool_pose_source")] = gate.problem() or "ok"
            tools[tool.parameter("tool_pose_rivals")] = ", ".join(gate.rivals())
            tools.update({tool.parameter(k): v for k, v in link_report(link, self._inputs).items()})
        extra = {"frame_compute_p99_s": float(np.percentile(compute, 99)) if compute.size else 0.0,
                 "divergences": self.model.divergences, "bad_tool_poses": self._pipeline.refused_poses,
                 "topology_changes": self.model.structure.version,
                 "topology_failures": self._pipeline.topology_failures,
                 "nodes": len(self.model.state.positions), "substeps": self.model.structure.params.substeps,
                 "solver": self.model.structure.step_solver,
                 "simulated_s": self.model.state.time_s, **tools}
        publish_diagnostics(self, self._diagnostics,
                            [loop_status(loop_status_name(self), stats, self.p.rate_hz, extra)])


def main(args=None) -> int:
    return run_node(PhysicsNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
