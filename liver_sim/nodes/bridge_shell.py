"""The ROS side of one haptic bridge (BridgeShell), the shell `haptic_bridge` and `haptic_bridge --managed` run
(liver_sim.nodes.bridge_node): its inputs driven from one table and read by the 1 kHz loop itself, the device map
(liver_sim.nodes.device_map_source), the loop and its supervisor, the graph checks, the diagnostics
(liver_sim.nodes.bridge_diagnostics) and the run-time parameters. The tick itself is haptic_bridge.tick.BridgeTick."""
from __future__ import annotations

import math
import time

import numpy as np
from rclpy.duration import Duration

from haptic_bridge.inputs import InputCheck
from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.supervisor import Supervisor
from haptic_bridge.tick import BridgeTick, check_passivity, checked_change
from liver_sim.base.emulated_link import link_text
from liver_sim.nodes.bridge_diagnostics import BridgeState, bridge_status
from liver_sim.nodes.device_map_source import DeviceMapSource
from liver_sim.nodes.diagnostics import loop_status_name, publish_diagnostics
from liver_sim.nodes.inputs import Handoff, Latest, LoopInputs, RosTime, emulated_link, link_report
from liver_sim.nodes.occupants import UNKNOWN_NODE_NAME, node_path
from liver_sim.nodes.rcl_take import endpoint_gid, publisher_gid
from liver_sim.nodes.run import close_ack_timeout_s
from liver_sim.realtime.rate_loop import RateLoop, warn
from msg_defs.forces import force_message_bytes, force_message_type, stamped_force_from_bytes
from msg_defs.local_model import local_model_from_bytes
from msg_defs.poses import position_from_bytes
from msg_defs.topics import TOPICS, loop_input_qos

#: How often (s) the bridge looks at the graph: another publisher on its force topic (a second bridge on the device),
#: and whether its inputs have a publisher (one without is stale); not in the 1 kHz loop.
GRAPH_CHECK_S = 0.1
#: The warning of a close whose last zero a reliable subscriber (the driver) has not acknowledged.
ZERO_NOT_ACKED = "the last zero force was not acknowledged"
#: The bridge's inputs: name → (topic parameter, TOPICS key, decoder of the serialized message). Each decoded value
#: is a tuple whose first item InputCheck judges (the local model, the force; the stylus once the device map has
#: placed it in the liver frame, by the loop).
INPUTS = {"device_pose": ("measured_cp_topic", "measured_cp", position_from_bytes),
          "local_model": ("local_model_topic", "contact_plane", local_model_from_bytes),
          "tool_wrench": ("tool_wrench_topic", "tool_wrench", stamped_force_from_bytes)}


class BridgeShell:
    """The ROS side of one bridge on `node` with checked parameters `p` (and the envelope of `start_p`, default
    `p`): inputs, device map, outputs, loop, supervisor, diagnostics, run-time parameters. :meth:`start` runs the
    loop; :meth:`stop` leaves zero on the wire."""

    def __init__(self, node, p: BridgeParameters, start_p: BridgeParameters | None = None):
        if p.drives_device:
            check_passivity(p)  # every mode; again with the device map's scale when it arrives
        self.node, self.p, self.start_p = node, p, start_p or p
        self.tick = BridgeTick(p, device_map=None)
        self.mode = p.local_model
        self.source = "tool_wrench" if self.mode == "none" else "local_model"
        checks = InputCheck(p.workspace_centre_m, p.workspace_radius_m)
        self._checks = {"device_pose": lambda _: None, "local_model": checks.model, "tool_wrench": checks.force}
        self._tip_check = checks.tip
        self._params, self._maps = Handoff(), Handoff()  # for the loop's next tick
        self._latest = {"device_pose": Latest(), self.source: Latest()}
        self._bad = {kind: 0 for kind in (*INPUTS, "device_map")}
        self._bad_reason, self._bad_logged = {}, dict(self._bad)
        self._map_problem = f"waiting for the device map on {node.resolve_topic_name(p.device_map_topic)}"
        self._sampled = None  # the device sample last mapped to a tool tip
        self._tip = None      # the newest plausible tool tip (m, liver frame)
        self._last_force = np.zeros(3)
        self._last_report = time.monotonic()
        self._loop = self.supervisor = None
        self._rivals: list[str] = []  # the other publishers on force_topic: while any, the bridge sends zero
        force_type, qos = force_message_type(p.force_output), TOPICS["servo_cf"].qos
        self._publisher = node.create_publisher(force_type, p.force_topic, qos)
        # the supervisor's zeros: a writer of their own, not held up by a publish of the loop
        self._zero_publisher = node.create_publisher(force_type, p.force_topic, qos)
        self._own_gids = {publisher_gid(self._publisher), publisher_gid(self._zero_publisher)}
        self._diagnostics = node.create_publisher(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                                  TOPICS["diagnostics"].qos)
        self.map_source = DeviceMapSource(node, p.device_map_topic, p.device_map_node, self._on_map,
                                          self._on_refused_map)
        self._inputs = LoopInputs(node)  # read by the 1 kHz loop itself, not by the executor
        self.link = emulated_link(p)  # the teleoperation link from the physics' side, if emulated
        self._subscriptions = {kind: self._subscribe(kind) for kind in self._latest}
        self._publishers_seen = dict.fromkeys(self._latest, 0)  # matched publishers per input, from the graph timer
        self._time = RosTime(node)
        self._timer = node.create_timer(1.0, self._publish_diagnostics)
        self._graph_timer = node.create_timer(GRAPH_CHECK_S, self._check_graph)

    def _subscribe(self, kind: str):
        topic_parameter, key, decode = INPUTS[kind]
        check, latest = self._checks[kind], self._latest[kind]

        def on_message(data: bytes, received: float) -> None:  # in the loop's poll
            try:
                value = decode(data)
                problem = check(value[0])
            except ValueError as exc:
                problem = str(exc)
            if problem:
                self._bad[kind] += 1
                self._bad_reason[kind] = problem  # logged by the diagnostics timer, not here in the loop
            else:
                latest.set(value, received)

        return self._inputs.subscribe(TOPICS[key].type, getattr(self.p, topic_parameter), loop_input_qos(TOPICS[key]),
                                      on_message, raw=True, received=True,
                                      link=None if kind == "device_pose" else self.link)

    # -- life cycle
    def start(self) -> None:
        """A new loop and supervisor; the force starts from zero (soft start)."""
        p = self.p
        self.tick.restart()
        self._loop = RateLoop(p.rate_hz, self._step, "haptic_bridge", on_error=self._on_error,
                              realtime_priority=p.realtime_priority, on_refused=warn(self.node))
        self.supervisor = Supervisor(p.stall_bound_s, self._loop.period_s, self._publisher.publish,
                                     self._zero_message, self._loop.is_alive,
                                     realtime_priority=p.realtime_priority,
                                     publish_zero=self._zero_publisher.publish)
        self._loop.start()
        self.supervisor.start()

    def stop(self, cause: str) -> None:
        """Zero force as the last command on each writer (nothing after it), the loop stopped, the zero
        acknowledged, and the last diagnostics too (`destroy` would take messages not yet acknowledged with their
        publisher), within run.close_ack_timeout_s(), the zero first; a zero not acknowledged by then is logged."""
        if self.supervisor is not None and not self.supervisor.closed:
            self.supervisor.close(cause)
            self._loop.stop()
            timeout_s = close_ack_timeout_s()
            deadline = time.monotonic() + timeout_s
            for publisher in (self._publisher, self._zero_publisher, self._diagnostics):
                try:
                    acked = publisher.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
                except Exception:  # noqa: BLE001 — a context already gone: nothing more can be done here
                    continue
                if not acked and publisher is not self._diagnostics:
                    self.node.get_logger().warning(
                        f"{ZERO_NOT_ACKED} on {publisher.topic_name} within {timeout_s:g} s")

    def destroy(self) -> None:
        self._inputs.destroy()
        self.map_source.destroy()
        for timer in (self._graph_timer, self._timer):
            self.node.destroy_timer(timer)
        for publisher in (self._publisher, self._zero_publisher, self._diagnostics):
            self.node.destroy_publisher(publisher)

    # -- run-time parameters (executor thread)
    def apply(self, changes: dict) -> str | None:
        """Check `changes` as at start and within the start's envelope; the loop takes them at its next tick.
        Refusal: ValueError with the reason."""
        scale = self.tick.device_map.scale if self.tick.device_map is not None else 1.0
        self.p = checked_change(self.p, changes, scale, self.start_p)
        self._params.offer(self.p)
        return None

    # -- the graph (executor thread): one bridge per device, inputs with a publisher
    def _check_graph(self) -> None:
        """Count each input's publishers (an input without one is stale), and note every publisher on force_topic
        but this bridge's own two writers (known by their GIDs): two bridges interleaving their commands would defeat
        the rate limit and the watchdog, so while any other publishes there, this one sends zero."""
        self._publishers_seen = {kind: sub.get_publisher_count() for kind, sub in self._subscriptions.items()}
        names = sorted(node_path(info.node_namespace, info.node_name) if info.node_name != UNKNOWN_NODE_NAME
                       else "a node not yet named by the graph"
                       for info in self.node.get_publishers_info_by_topic(self._publisher.topic_name)
                       if endpoint_gid(info) not in self._own_gids)
        if names and not self._rivals:
            self.node.get_logger().error(f"another publisher on {self._publisher.topic_name} ({', '.join(names)}): "
                                         "sending zero, not driving the device while it publishes there")
        elif self._rivals and not names:
            self.node.get_logger().info(f"{self._publisher.topic_name} has no other publisher: driving again "
                                        "(soft start)")
        self._rivals = names

    # -- the device map (executor thread): from device_map_node only, changed only through zero force
    def _on_map(self, device_map) -> None:
        scale_problem = None
        if self.p.drives_device:
            try:
                check_passivity(self.p, device_map.scale)
            except ValueError as exc:
                scale_problem = str(exc)
        if scale_problem:
            self._on_refused_map(f"from {self.map_source.source_node}: {scale_problem}", True)
            return
        self._map_problem = None
        self._maps.offer(device_map)
        self.node.get_logger().info(
            f"device map from {self.map_source.source_node} on {self.map_source.topic}: "
            f"R {np.round(device_map.rotation, 6).tolist()}, t {device_map.translation.tolist()} m, "
            f"scale {device_map.scale:g} (a change applies once the force is zero, then a soft start)")

    def _on_refused_map(self, reason: str, from_source: bool) -> None:
        """A refused map sample: from another node it changes nothing; from device_map_node the force goes to zero
        until a good one comes (the tool places the tool with a map the bridge cannot use)."""
        self._bad["device_map"] += 1
        if from_source:
            self._map_problem = f"device map refused: {reason}"
            self._maps.offer(None)
            self.node.get_logger().error(f"{self._map_problem}; the force stays zero")
        else:
            self.node.get_logger().error(f"device map refused, the map in use stays: {reason}")

    # -- the loop (its own thread)
    def _step(self, now: float) -> None:
        tick = self.tick
        if self.supervisor.beat(now):
            tick.restart()
        if (p := self._params.take()) is not Handoff.NOTHING:
            tick.configure(p)
        if (device_map := self._maps.take()) is not Handoff.NOTHING:
            tick.set_device_map(device_map)
        self._inputs.poll()
        wall = time.time()
        pose, pose_received = self._latest["device_pose"].get()
        source, source_received = self._latest[self.source].get()
        publishers = self._publishers_seen
        pose_age = now - pose_received if publishers["device_pose"] else math.inf
        source_age = now - source_received if publishers[self.source] else math.inf
        stamp = pose[1] if pose is not None else None
        if pose is not None and pose is not self._sampled:  # a new stylus sample: its tool tip in the liver frame
            self._sampled = pose
            tip = tick.sample(stamp[0] + stamp[1] * 1e-9, wall - (now - pose_received), pose[0])
            problem = self._tip_check(tip) if tip is not None else None
            if problem:
                self._bad["device_pose"] += 1
                self._bad_reason["device_pose"] = problem
            else:
                self._tip = tip
        tip = self._tip if tick.device_map is not None else None
        if self.mode == "none":
            source, stamp = (source[0], source[1]) if source is not None else (None, None)
        elif source is not None:
            source = (source[0], min(source[1], self.p.lifetime_s) if source[1] > 0.0 else self.p.lifetime_s)
        command = tick.step(now, tip, pose_age, source, source_age, wall)
        if self._rivals:  # another bridge on the device: zero, and a soft start once it has gone
            tick.restart()
            command = np.zeros(3)
        self._last_force = command
        if stamp is None or (source_age if self.mode == "none" else pose_age) > self.p.lifetime_s:
            stamp = self._time.stamp()  # no fresh input: the command holds now
        self.supervisor.send(force_message_bytes(self.p.force_output, command, stamp, self.p.device_frame_id))

    def _on_error(self, now: float, exc: Exception) -> None:
        self.supervisor.error(now, exc)

    def _zero_message(self) -> bytes:
        return force_message_bytes(self.p.force_output, np.zeros(3), self._time.stamp(), self.p.device_frame_id)

    # -- diagnostics (executor thread)
    def _publish_diagnostics(self) -> None:
        self._time.refresh()
        now = time.monotonic()
        logger = self.node.get_logger()
        for kind, count in self._bad.items():
            if count > self._bad_logged[kind] and kind in self._bad_reason:
                logger.warning(f"ignored {count - self._bad_logged[kind]} {kind} message(s): {self._bad_reason[kind]}")
        self._bad_logged = dict(self._bad)
        if self.supervisor is None:
            return
        report = self.supervisor.report(now, self._last_report)
        self._last_report = now
        stats = self._loop.report()
        state = BridgeState(
            {"device_pose": now - self._latest["device_pose"].get()[1],
             "source": now - self._latest[self.source].get()[1]},
            {"device_pose": self._publishers_seen["device_pose"], "source": self._publishers_seen[self.source]},
            self._bad, self._map_problem, self._rivals, float(np.linalg.norm(self._last_force)),
            self._publisher.topic_name)
        status, events = bridge_status(loop_status_name(self.node), self.p, self.tick, stats, report, state,
                                       link_report(self.link, self._inputs))
        for line in events:
            logger.error(line)
        if stats["new_gaps"]:
            logger.warning(f"loop {stats['new_gaps']}")
        publish_diagnostics(self.node, self._diagnostics, [status])

    def describe(self) -> str:
        p, topic = self.p, self.node.resolve_topic_name
        rendering = ("physics wrench held between updates" if self.mode == "none" else
                     f"local model (K {p.stiffness_n_per_m:g} N/m, B {p.damping_ns_per_m:g} N·s/m, "
                     f"glide {p.model_glide_s:g} s, tool radius {p.tool_radius_m:g} m)")
        return (f"haptic_bridge: {p.rate_hz:g} Hz, local_model {self.mode}: {rendering}; passivity controller "
                f"{'on' if self.tick.passivity.control else 'off'}; in: {topic(p.measured_cp_topic)}, "
                f"{topic(getattr(p, INPUTS[self.source][0]))}{link_text(self.link)}, device map "
                f"{self.map_source.topic} from {self.map_source.source_node}; out: {self._publisher.topic_name} "
                f"({p.force_output}, frame {p.device_frame_id}, "
                f"max {p.max_force_n:g} N, {p.max_force_rate_n_per_s:g} N/s, soft start {p.soft_start_s:g} "
                f"s); watchdog: lifetime {p.lifetime_s:g} s, ramp {p.ramp_time_s:g} s; supervisor: zero after "
                f"{p.stall_bound_s * 1e3:g} ms without a tick")
