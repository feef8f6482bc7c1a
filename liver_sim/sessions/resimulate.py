"""`liver-sim resimulate`: the physics and the haptic bridge re-run offline, as fast as the machine
allows, on the device's samples of a recorded session, with changed parameters if asked.

The inputs are the device's samples (`/phantom/measured_cp`, device frame) placed in the liver frame by the
recorded device map (`/tool/device_map`), as the live nodes place them; a bag of the older layout, without
device samples, is re-simulated on its tool poses (`/tool/pose`, liver frame) with the identity map.
Simulation time is the samples' stamps.  The physics is the node's FramePipeline
(liver_sim.physics.pipeline): frame k starts at t₀ + k/rate_hz (t₀: the first sample) with the newest
sample stamped before it (what the tool node publishes at the physics' rate) and is published at its end,
stamped t₀ + model time.  The bridge ticks once per sample with the newest published frame (BridgeTick, the
node's own tick), and its command is stamped with the sample; `--compare` adds the Fig. 8 baseline bridge
(local_model none) on the same samples.  Nothing depends on the wall clock, and the outputs' CDR
padding is zeroed (canonical_cdr), so the same bag and parameters give byte-identical messages.
Messages are built by msg_defs' builders and serialized by rclpy's serializer (no node, no context).
"""
from __future__ import annotations

import time
from collections import deque
from pathlib import Path

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.serialization import deserialize_message, serialize_message

from haptic_bridge.tick import BridgeTick
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.topic_names import BASELINE_FORCE_TOPIC
from liver_sim.physics.parameters import PhysicsParameters, build_model
from liver_sim.physics.pipeline import FramePipeline
from liver_sim.sessions.bag import BagError, BagWriter, bag_info, canonical_cdr, read_messages
from liver_sim.sessions.parameters import node_parameters
from liver_sim.sessions.record import known_topics, type_name
from liver_sim.tool.scripts import IDENTITY_XYZW
from msg_defs.device_map import device_map_from_message
from msg_defs.forces import force_from_message, force_message, force_message_type, wrench_stamped
from msg_defs.local_model import local_model_from_bytes, local_model_marker_bytes
from msg_defs.point_cloud import nodes_pointcloud2_bytes
from msg_defs.poses import pose_stamped, pose_to_arrays
from msg_defs.skin import skin_marker_serialized, skin_mesh_msg
from msg_defs.stamps import seconds_from_stamp, stamp_from_seconds
from msg_defs.topics import TOPICS


def _ns(seconds: float) -> int:
    """Nanoseconds of a time as its message stamp carries it."""

    stamp = stamp_from_seconds(seconds)
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class _Session:
    """The offline loop around a FramePipeline; `emit(topic, msg_class, time_s, data)` receives every output
    message in time order."""

    def __init__(self, physics: PhysicsParameters, bridge: dict, emit, progress, compare: bool = False,
                 device_map: DeviceMap = DeviceMap()):
        self.p, self.b = physics, bridge
        self.model = build_model(physics)
        self.pipeline = FramePipeline(self.model, physics)
        self.device_map = device_map
        self.tick = BridgeTick(bridge, device_map)
        #: the Fig. 8 baseline: a second bridge holding the physics wrench (local_model: none)
        self.baseline = (BridgeTick(bridge.replace(local_model="none"), device_map)
                         if compare and bridge.local_model != "none" else None)
        self.emit, self.progress = emit, progress
        self.commands = 0
        self.peak_force_n = 0.0
        #: when a dict of lists, run() appends every command (with its baseline) and physics force to it
        self.trace = None

    def _receive(self, message, t: float):
        """Hand the pipeline a recorded sample received at `t`, placed in the liver frame by the device map; the
        sample's position (device frame) for the bridge, None when malformed or implausible."""

        try:
            position, orientation = pose_to_arrays(message.pose)
            tip, tip_orientation = self.device_map.pose(position, orientation)
        except ValueError as exc:
            self.pipeline.refuse(str(exc), t)
            return None
        self.pipeline.receive(tip, tip_orientation, t)
        return position

    def _frame(self, t0: float):
        """Step one frame; return (publish time s, messages, (local model, lifetime), contact force N)."""

        frame = self.pipeline.step(t0 + self.model.state.time_s)
        t = t0 + self.model.state.time_s
        stamp, frame_id = stamp_from_seconds(t), self.p.frame_id
        marker_bytes = local_model_marker_bytes(frame.result.local_model, stamp, frame_id,
                                                self.p.local_model_lifetime_s)
        wrench = wrench_stamped(frame.result.tool_force_n, stamp, frame_id)
        messages = [(self.p.nodes_topic, "nodes",
                     nodes_pointcloud2_bytes(self.model.state.positions, stamp, frame_id)),
                    (self.p.contact_plane_topic, "contact_plane", marker_bytes),
                    (self.p.tool_wrench_topic, "tool_wrench", serialize_message(wrench))]
        if frame.surface_changed:  # the new surface before the node cloud that indexes it
            messages.insert(0, (self.p.surface_topic, "surface", serialize_message(
                skin_mesh_msg(self.model.structure.mesh.skin, self.model.structure.mesh.points))))
        if frame.marker_due:
            messages.append((self.p.marker_topic, "marker", skin_marker_serialized(
                self.model.state.positions, self.model.structure.mesh.skin, stamp, frame_id)))
        model, lifetime = local_model_from_bytes(marker_bytes)  # as the live bridge reads it
        return (t, messages, (model, lifetime if lifetime > 0.0 else self.b.lifetime_s),
                force_from_message("wrench_stamped", wrench))

    def run(self, poses: list, input_topic: str, input_key: str) -> None:
        """`poses`: [(time s, PoseStamped, recorded bytes)] in time order, the device's samples (device frame) or
        tool poses (the older layout, liver frame: then the map is the identity), copied out on `input_topic`
        (TOPICS key `input_key`)."""

        t0 = poses[0][0]
        mesh = self.model.structure.mesh
        self.emit(self.p.surface_topic, "surface", t0, serialize_message(skin_mesh_msg(mesh.skin, mesh.points)))
        tip, tip_time = None, -np.inf
        pending = deque()
        local, held, source_time = None, None, -np.inf
        next_progress = t0 + 1.0
        for t, message, data in poses:
            while t0 + self.model.state.time_s < t:  # frames that start before this pose see the poses before it
                pending.append(self._frame(t0))
            while pending and pending[0][0] <= t:
                source_time, messages, local, held = pending.popleft()
                for topic, key, frame_data in messages:
                    self.emit(topic, key, source_time, frame_data)
                if self.trace is not None:
                    self.trace["wrench_s"].append(source_time)
                    self.trace["wrench_n"].append(held)
            sample = self._receive(message, t)
            if sample is not None:
                tip, tip_time = self.tick.sample(seconds_from_stamp(message.header.stamp), t, tuple(sample.tolist())), t
                if self.baseline is not None:
                    self.baseline.sample(seconds_from_stamp(message.header.stamp), t, tuple(sample.tolist()))
            self.emit(input_topic, input_key, t, data)
            command = self.tick.step(t, tip, t - tip_time, held if self.b.local_model == "none" else local,
                                     t - source_time)
            self.peak_force_n = max(self.peak_force_n, float(np.linalg.norm(command)))
            self.emit(self.b.force_topic, "servo_cf", t, serialize_message(force_message(
                self.b.force_output, command, message.header.stamp, self.b.device_frame_id)))
            if self.trace is not None:
                self.trace["command_s"].append(t)
                self.trace["command_n"].append(command)
            if self.baseline is not None:
                command = self.baseline.step(t, tip, t - tip_time, held, t - source_time)
                self.emit(BASELINE_FORCE_TOPIC, "servo_cf", t, serialize_message(force_message(
                    self.b.force_output, command, message.header.stamp, self.b.device_frame_id)))
                if self.trace is not None:
                    self.trace["baseline_n"].append(command)
            self.commands += 1
            if t >= next_progress:
                next_progress += 1.0
                self.progress(f"  simulated {t - t0:6.1f} / {poses[-1][0] - t0:.1f} s")


def recorded_poses(bag: Path, topic: str) -> list:
    """[(stamp s, PoseStamped, bytes)] of the bag's `topic`, ordered by stamp (stable); [] when it holds none."""

    poses = []
    for recorded in read_messages(bag, [topic]):
        try:
            message = deserialize_message(recorded.data, PoseStamped)
        except Exception as exc:  # rclpy raises its own error types on bad CDR
            raise BagError(bag, f"a {topic} message is not a geometry_msgs/PoseStamped ({exc})") from None
        poses.append((seconds_from_stamp(message.header.stamp), message, recorded.data))
    poses.sort(key=lambda item: item[0])
    return poses


def recorded_device_map(bag: Path, topic: str) -> DeviceMap:
    """The first device map of the bag's `topic`, or BagError when it holds none or a bad one."""

    for recorded in read_messages(bag, [topic]):
        try:
            return device_map_from_message(deserialize_message(recorded.data, TOPICS["device_map"].type))
        except Exception as exc:  # a bad layout (ValueError) or bad CDR (rclpy's own errors)
            raise BagError(bag, f"its {topic} message is not a device map ({exc})") from None
    raise BagError(bag, f"holds device samples but no {topic} to place them in the liver frame")


def session_inputs(bag: Path, physics: PhysicsParameters, bridge: dict) -> tuple[list, DeviceMap, str, str]:
    """(samples, device map, their topic, its TOPICS key) of a bag: the device's samples and the recorded map, or,
    in a bag of the older layout, the tool poses and the identity map; BagError when it holds neither."""

    topics = bag_info(bag).topics
    samples = recorded_poses(bag, bridge.measured_cp_topic) if bridge.measured_cp_topic in topics else []
    if samples:
        return samples, recorded_device_map(bag, bridge.device_map_topic), bridge.measured_cp_topic, \
            "measured_cp"
    poses = recorded_poses(bag, physics.tool_pose_topic) if physics.tool_pose_topic in topics else []
    if not poses:
        raise BagError(bag, f"holds neither {bridge.measured_cp_topic} nor {physics.tool_pose_topic} messages "
                            "to re-simulate")
    return poses, DeviceMap(), physics.tool_pose_topic, "tool_pose"


def resimulate(bag: Path, out: Path, overrides=(), storage: str = "mcap", progress=print,
               compare: bool = False) -> dict:
    """Re-run physics and bridge on the device's samples of `bag` (module docstring) with parameter `overrides`
    ('name:=value'); write the outputs (and the input samples) to a new bag `out`; return a summary.  With `compare`, a
    second bridge without local model writes BASELINE_FORCE_TOPIC from the same inputs (Fig. 8)."""

    params = node_parameters(overrides)
    physics, bridge = params["liver_physics"], params["haptic_bridge"]
    poses, device_map, input_topic, input_key = session_inputs(bag, physics, bridge)
    known = known_topics()
    types = {key: (type_name(topic.type) if topic.type else None, known[topic.name][1])
             for key, topic in TOPICS.items()}
    types["servo_cf"] = (type_name(force_message_type(bridge.force_output)), types["servo_cf"][1])
    progress(f"re-simulating {len(poses)} samples of {input_topic} ({poses[-1][0] - poses[0][0]:.2f} s) of {bag}"
             + (f" with {' '.join(overrides)}" if overrides else ""))
    session = _Session(physics, bridge, None, progress, compare, device_map)  # refuses bad parameters first
    started = time.perf_counter()
    with BagWriter(out, storage) as writer:
        writer.set_custom_data("resimulated_from", str(bag))
        writer.set_custom_data("parameter_overrides", " ".join(overrides))

        def emit(topic, key, t, data):
            msgtype, qos = types[key]
            writer.write(topic, msgtype, _ns(t), data if key == input_key else canonical_cdr(data, msgtype), qos)

        session.emit = emit
        session.run(poses, input_topic, input_key)
        writer.set_custom_data("physics_solver", session.model.structure.step_solver)
        counts = dict(writer.counts)
    wall = time.perf_counter() - started
    simulated = poses[-1][0] - poses[0][0]
    pipeline = session.pipeline
    summary = {"bag": str(bag), "out": str(out), "overrides": list(overrides), "poses": len(poses),
               "refused_poses": pipeline.refused_poses, "frames": pipeline.frames, "commands": session.commands,
               "divergences": session.model.divergences, "simulated_s": simulated, "wall_s": wall,
               "speed_vs_real_time": simulated / wall if wall > 0 else None,
               "peak_command_n": session.peak_force_n, "physics_solver": session.model.structure.step_solver,
               "counts": counts}
    progress(f"wrote {out}: {pipeline.frames} physics frames, {session.commands} force commands "
             f"(peak {session.peak_force_n:.3f} N), {simulated:.2f} s simulated in {wall:.2f} s")
    return summary


def play_script(script, duration_s: float, overrides=(), progress=lambda line: None) -> dict:
    """Play the tool script `script` (tool_scripts.ScriptedTrajectory) for `duration_s` through the same
    offline session as resimulate, the poses at the bridge's rate_hz as a device would send them, with a
    Fig. 8 baseline bridge (local_model none) beside; nothing is written.  Returns arrays: command_s (K,),
    command_n and baseline_n (K, 3) N, the 1 kHz commands with and without the local model, and wrench_s,
    wrench_n, the physics contact force (N) as each frame was published."""

    params = node_parameters(overrides)
    physics, bridge = params["liver_physics"], params["haptic_bridge"]
    if bridge.local_model == "none":
        raise ValueError("parameter local_model must not be none: Fig. 8 compares the local model with none")
    session = _Session(physics, bridge, lambda *message: None, progress, compare=True)
    session.trace = {key: [] for key in ("command_s", "command_n", "baseline_n", "wrench_s", "wrench_n")}
    period_s = 1.0 / bridge.rate_hz
    poses = []
    for k in range(int(round(duration_s / period_s))):
        t = k * period_s
        poses.append((t, pose_stamped(script.position_at(t), IDENTITY_XYZW, t, physics.frame_id), b""))
    session.run(poses, physics.tool_pose_topic, "tool_pose")
    return {key: np.asarray(values, dtype=np.float64) for key, values in session.trace.items()}
