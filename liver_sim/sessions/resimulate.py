"""`liver-sim resimulate`: the physics and the haptic bridges re-run offline, as fast as the machine
allows, on the devices' samples of a recorded session, with changed parameters if asked.

The inputs are each tool's device samples (`/phantom/measured_cp` in the tool's namespace, device frame: one tool in
the root namespace by default, `-p tools:=[left,right]` for two) placed in the liver frame by the recorded device map
(`/tool/device_map` there), as the live nodes place them; a bag of the older layout, without device samples, is
re-simulated on its tool poses (`/tool/pose`, liver frame) with the identity map.  Simulation time is the samples'
stamps.  The physics is the node's FramePipeline (liver_sim.physics.pipeline): frame k starts at t₀ + k/rate_hz
(t₀: the first sample of any tool) with each tool's newest sample stamped before it (what the tool nodes publish at
the physics' rate) and is published at its end, stamped t₀ + model time.  Each tool's bridge ticks once per sample
of its device with the newest published frame (BridgeTick, the node's own tick), and its command is stamped with the
sample; `--compare` adds the Fig. 8 baseline bridge (local_model none) on the same samples.  Nothing depends on the
wall clock, the samples of all tools are taken in one order (by stamp, then tool), and the outputs' CDR padding is
zeroed (canonical_cdr), so the same bag and parameters give byte-identical messages.  Messages are built by
msg_defs' builders and serialized by rclpy's serializer (no node, no context).
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.serialization import deserialize_message, serialize_message

from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.tick import BridgeTick
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.topic_names import BASELINE_FORCE_TOPIC, in_namespace, tool_topic
from liver_sim.physics.parameters import PhysicsParameters, PhysicsTool, build_model
from liver_sim.physics.pipeline import FramePipeline
from liver_sim.physics.solver.implicit import same_arithmetic
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

#: The TOPICS keys of a session's inputs, copied out as recorded.
INPUT_KEYS = ("measured_cp", "tool_pose")


def _ns(seconds: float) -> int:
    """Nanoseconds of a time as its message stamp carries it."""

    stamp = stamp_from_seconds(seconds)
    return stamp.sec * 1_000_000_000 + stamp.nanosec


@dataclass
class _Hand:
    """One tool of the session and its bridge: the physics' tool, its inputs (the recorded samples, device frame,
    or tool poses, liver frame), its device map, its bridge (and Fig. 8 baseline) ticks, and what they last took."""

    tool: PhysicsTool
    samples: list
    input_topic: str
    input_key: str
    device_map: DeviceMap
    tick: BridgeTick
    baseline: BridgeTick | None
    force_topic: str
    baseline_topic: str
    tip: np.ndarray | None = None
    tip_time: float = -np.inf
    local: tuple | None = None
    held: np.ndarray | None = None
    source_time: float = -np.inf
    commands: int = 0
    peak_force_n: float = 0.0


class _Session:
    """The offline loop around a FramePipeline and a bridge per tool; `emit(topic, key, time_s, data)` receives every
    output message in time order."""

    def __init__(self, physics: PhysicsParameters, bridge: BridgeParameters, tools: tuple[PhysicsTool, ...], emit,
                 progress, compare: bool = False, inputs: list | None = None):
        self.p, self.b = physics, bridge
        self.model = build_model(physics, tools)
        self.pipeline = FramePipeline(self.model, physics)
        self.hands = []
        for tool, (samples, device_map, topic, key) in zip(tools, inputs or [([], DeviceMap(), "", "")] * len(tools)):
            tick = BridgeTick(bridge, device_map)
            #: the Fig. 8 baseline: a second bridge holding the physics wrench (local_model: none)
            baseline = (BridgeTick(bridge.replace(local_model="none"), device_map)
                        if compare and bridge.local_model != "none" else None)
            self.hands.append(_Hand(tool, samples, topic, key, device_map, tick, baseline,
                                    in_namespace(bridge.force_topic, tool.namespace),
                                    in_namespace(BASELINE_FORCE_TOPIC.lstrip("/"), tool.namespace)))
        self.emit, self.progress = emit, progress
        #: when a dict of lists, run() appends the first tool's every command (with its baseline) and physics force
        self.trace = None

    @property
    def commands(self) -> int:
        return sum(hand.commands for hand in self.hands)

    def _receive(self, k: int, message, t: float):
        """Hand the pipeline a recorded sample of tool k received at `t`, placed in the liver frame by its device map;
        the sample's position (device frame) for its bridge, None when malformed or implausible."""

        try:
            position, orientation = pose_to_arrays(message.pose)
            tip, tip_orientation = self.hands[k].device_map.pose(position, orientation)
        except ValueError as exc:
            self.pipeline.refuse(str(exc), t, k)
            return None
        self.pipeline.receive(tip, tip_orientation, t, k)
        return position

    def _frame(self, t0: float):
        """Step one frame; return (publish time s, messages, per tool ((local model, lifetime), contact force N))."""

        frame = self.pipeline.step(t0 + self.model.state.time_s)
        t = t0 + self.model.state.time_s
        stamp, frame_id = stamp_from_seconds(t), self.p.frame_id
        messages = [(self.p.nodes_topic, "nodes", nodes_pointcloud2_bytes(self.model.state.positions, stamp, frame_id))]
        rendered = []
        for hand, local_model, force in zip(self.hands, frame.result.local_models, frame.result.tool_forces_n):
            marker_bytes = local_model_marker_bytes(local_model, stamp, frame_id, self.p.local_model_lifetime_s)
            wrench = wrench_stamped(force, stamp, frame_id)
            messages += [(hand.tool.topic("contact_plane_topic"), "contact_plane", marker_bytes),
                         (hand.tool.topic("tool_wrench_topic"), "tool_wrench", serialize_message(wrench))]
            model, lifetime = local_model_from_bytes(marker_bytes)  # as the live bridge reads it
            rendered.append(((model, lifetime if lifetime > 0.0 else self.b.lifetime_s),
                             force_from_message("wrench_stamped", wrench)))
        if frame.surface_changed:  # the new surface before the node cloud that indexes it
            messages.insert(0, (self.p.surface_topic, "surface", serialize_message(
                skin_mesh_msg(self.model.structure.mesh.skin, self.model.structure.mesh.points))))
        if frame.marker_due:
            messages.append((self.p.marker_topic, "marker", skin_marker_serialized(
                self.model.state.positions, self.model.structure.mesh.skin, stamp, frame_id)))
        return t, messages, rendered

    def run(self) -> None:
        """Every tool's inputs (`samples` of each hand: [(time s, PoseStamped, recorded bytes)] in time order, the
        device's samples, device frame, or tool poses, the older layout, liver frame: then the map is the
        identity), in one time order (ties: in the order of the tools), each copied out on its topic."""

        inputs = sorted(((t, k, message, data) for k, hand in enumerate(self.hands)
                         for t, message, data in hand.samples), key=lambda item: (item[0], item[1]))
        t0, last = inputs[0][0], inputs[-1][0]
        mesh = self.model.structure.mesh
        self.emit(self.p.surface_topic, "surface", t0, serialize_message(skin_mesh_msg(mesh.skin, mesh.points)))
        pending = deque()
        next_progress = t0 + 1.0
        for t, k, message, data in inputs:
            while t0 + self.model.state.time_s < t:  # frames that start before this sample see the samples before it
                pending.append(self._frame(t0))
            while pending and pending[0][0] <= t:
                source_time, messages, rendered = pending.popleft()
                for topic, key, frame_data in messages:
                    self.emit(topic, key, source_time, frame_data)
                for hand, (local, held) in zip(self.hands, rendered):
                    hand.source_time, hand.local, hand.held = source_time, local, held
                if self.trace is not None:
                    self.trace["wrench_s"].append(source_time)
                    self.trace["wrench_n"].append(rendered[0][1])
            self._tick(k, t, message, data)
            if t >= next_progress:
                next_progress += 1.0
                self.progress(f"  simulated {t - t0:6.1f} / {last - t0:.1f} s")

    def _tick(self, k: int, t: float, message, data: bytes) -> None:
        """Tool k's sample at `t`: to the pipeline, and one tick of its bridge (and baseline) on it."""
        hand = self.hands[k]
        sample = self._receive(k, message, t)
        stamp_s = seconds_from_stamp(message.header.stamp)
        if sample is not None:
            hand.tip, hand.tip_time = hand.tick.sample(stamp_s, t, tuple(sample.tolist())), t
            if hand.baseline is not None:
                hand.baseline.sample(stamp_s, t, tuple(sample.tolist()))
        self.emit(hand.input_topic, hand.input_key, t, data)
        command = hand.tick.step(t, hand.tip, t - hand.tip_time,
                                 hand.held if self.b.local_model == "none" else hand.local, t - hand.source_time)
        hand.peak_force_n = max(hand.peak_force_n, float(np.linalg.norm(command)))
        self.emit(hand.force_topic, "servo_cf", t, serialize_message(force_message(
            self.b.force_output, command, message.header.stamp, self.b.device_frame_id)))
        if self.trace is not None and k == 0:
            self.trace["command_s"].append(t)
            self.trace["command_n"].append(command)
        if hand.baseline is not None:
            command = hand.baseline.step(t, hand.tip, t - hand.tip_time, hand.held, t - hand.source_time)
            self.emit(hand.baseline_topic, "servo_cf", t, serialize_message(force_message(
                self.b.force_output, command, message.header.stamp, self.b.device_frame_id)))
            if self.trace is not None and k == 0:
                self.trace["baseline_n"].append(command)
        hand.commands += 1


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


def recorded_solver(bag: Path) -> str | None:
    """The physics' solver the bag was made with (ImplicitEuler.solver): a re-simulated bag's `physics_solver`, else
    the newest `solver` of the /diagnostics it recorded; None when it says neither."""

    info, topic = bag_info(bag), TOPICS["diagnostics"]
    solver = info.custom_data.get("physics_solver")
    if solver is not None or topic.name not in info.topics:
        return solver
    for recorded in read_messages(bag, [topic.name]):
        try:
            message = deserialize_message(recorded.data, topic.type)
        except Exception as exc:
            raise BagError(bag, f"a {topic.name} message is not a diagnostic_msgs/DiagnosticArray ({exc})") from None
        for status in message.status:
            solver = next((kv.value for kv in status.values if kv.key == "solver"), solver)
    return solver


def session_inputs(bag: Path, bridge: BridgeParameters, tools: tuple[PhysicsTool, ...]) -> list[tuple]:
    """Per tool, (samples, device map, their topic, its TOPICS key) of a bag: the device's samples and the recorded
    map in the tool's namespace, or, in a bag of the older layout, the tool poses and the identity map; BagError
    when it holds neither for a tool (naming the device samples it does hold, of other tools)."""

    topics = bag_info(bag).topics
    inputs = []
    for tool in tools:
        samples_topic = in_namespace(bridge.measured_cp_topic, tool.namespace)
        samples = recorded_poses(bag, samples_topic) if samples_topic in topics else []
        if samples:
            inputs.append((samples, recorded_device_map(bag, in_namespace(bridge.device_map_topic, tool.namespace)),
                           samples_topic, "measured_cp"))
            continue
        poses_topic = tool.topic("tool_pose_topic")
        poses = recorded_poses(bag, poses_topic) if poses_topic in topics else []
        if not poses:
            held = sorted(t for t in topics if t.endswith("/" + tool_topic("measured_cp")))
            raise BagError(bag, f"holds neither {samples_topic} nor {poses_topic} messages to re-simulate"
                           + (f"; it holds {', '.join(held)}: name its tools (-p tools:=[NAME, …], and each one's "
                              "parameters, -p NAME.tool_mode:=…)" if held else ""))
        inputs.append((poses, DeviceMap(), poses_topic, "tool_pose"))
    return inputs


def resimulate(bag: Path, out: Path, overrides=(), storage: str = "mcap", progress=print,
               compare: bool = False) -> dict:
    """Re-run physics and bridges on the device's samples of `bag` (module docstring), one bridge per tool, with
    parameter `overrides` ('name:=value'); write the outputs (and the input samples) to a new bag `out`; return a
    summary.  With `compare`, a second bridge per tool without local model writes the baseline force topic
    (BASELINE_FORCE_TOPIC in the tool's namespace) from the same inputs (Fig. 8).  The summary names the solver that
    ran and the one the bag was made with (`recorded_solver`); when their arithmetic differs
    (physics.solver.implicit.same_arithmetic), a line of `progress` says so."""

    params = node_parameters(overrides)
    physics, bridge, tools = params["liver_physics"], params["haptic_bridge"], params["tools"]
    inputs = session_inputs(bag, bridge, tools)
    known = known_topics()
    types = {key: (type_name(topic.type) if topic.type else None, known[topic.name][1])
             for key, topic in TOPICS.items()}
    types["servo_cf"] = (type_name(force_message_type(bridge.force_output)), types["servo_cf"][1])
    times = [samples[i][0] for samples, *_ in inputs for i in (0, -1)]
    simulated = max(times) - min(times)
    progress(f"re-simulating {sum(len(samples) for samples, *_ in inputs)} samples of "
             f"{', '.join(topic for _, _, topic, _ in inputs)} ({simulated:.2f} s) of {bag}"
             + (f" with {' '.join(overrides)}" if overrides else ""))
    session = _Session(physics, bridge, tools, None, progress, compare, inputs)  # refuses bad parameters first
    started = time.perf_counter()
    with BagWriter(out, storage) as writer:
        writer.set_custom_data("resimulated_from", str(bag))
        writer.set_custom_data("parameter_overrides", " ".join(overrides))

        def emit(topic, key, t, data):
            msgtype, qos = types[key]
            writer.write(topic, msgtype, _ns(t), data if key in INPUT_KEYS else canonical_cdr(data, msgtype), qos)

        session.emit = emit
        session.run()
        solver = session.model.structure.step_solver
        writer.set_custom_data("physics_solver", solver)
        counts = dict(writer.counts)
    recorded = recorded_solver(bag)
    if recorded is not None and not same_arithmetic(recorded, solver):
        progress(f"the bag was made with the solver '{recorded}', re-simulated with '{solver}': their arithmetic "
                 "differs (the version, or before solver 3 the threads), so the physics differs by rounding "
                 "(docs/sessions.md)")
    wall = time.perf_counter() - started
    pipeline = session.pipeline
    peak = max(hand.peak_force_n for hand in session.hands)
    summary = {"bag": str(bag), "out": str(out), "overrides": list(overrides),
               "poses": sum(len(samples) for samples, *_ in inputs),
               "refused_poses": pipeline.refused_poses, "frames": pipeline.frames, "commands": session.commands,
               "divergences": session.model.divergences, "simulated_s": simulated, "wall_s": wall,
               "speed_vs_real_time": simulated / wall if wall > 0 else None,
               "peak_command_n": peak, "physics_solver": solver, "recorded_solver": recorded, "counts": counts,
               "tools": {hand.tool.name: {"commands": hand.commands, "peak_command_n": hand.peak_force_n,
                                          "force_topic": hand.force_topic} for hand in session.hands}}
    progress(f"wrote {out}: {pipeline.frames} physics frames, {session.commands} force commands "
             f"(peak {peak:.3f} N), {simulated:.2f} s simulated in {wall:.2f} s")
    return summary


def play_script(script, duration_s: float, overrides=(), progress=lambda line: None) -> dict:
    """Play the tool script `script` (tool_scripts.ScriptedTrajectory) for `duration_s` through the same
    offline session as resimulate, the poses at the bridge's rate_hz as a device would send them, with a
    Fig. 8 baseline bridge (local_model none) beside; nothing is written.  Returns arrays: command_s (K,),
    command_n and baseline_n (K, 3) N, the 1 kHz commands with and without the local model, and wrench_s,
    wrench_n, the physics contact force (N) as each frame was published."""

    params = node_parameters(overrides)
    physics, bridge, tools = params["liver_physics"], params["haptic_bridge"], params["tools"]
    if bridge.local_model == "none":
        raise ValueError("parameter local_model must not be none: Fig. 8 compares the local model with none")
    if len(tools) != 1:
        raise ValueError(f"parameter tools: Fig. 8 plays one tool, got {list(physics.tools)!r}")
    period_s = 1.0 / bridge.rate_hz
    poses = []
    for k in range(int(round(duration_s / period_s))):
        t = k * period_s
        poses.append((t, pose_stamped(script.position_at(t), IDENTITY_XYZW, t, physics.frame_id), b""))
    session = _Session(physics, bridge, tools, lambda *message: None, progress, compare=True,
                       inputs=[(poses, DeviceMap(), tools[0].topic("tool_pose_topic"), "tool_pose")])
    session.trace = {key: [] for key in ("command_s", "command_n", "baseline_n", "wrench_s", "wrench_n")}
    session.run()
    return {key: np.asarray(values, dtype=np.float64) for key, values in session.trace.items()}
