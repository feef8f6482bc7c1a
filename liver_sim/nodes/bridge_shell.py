"""The ROS side of one haptic bridge (BridgeShell), the shell `haptic_bridge` and `haptic_bridge --managed` run
(liver_sim.nodes.bridge_node): ROS wiring only. Its inputs are read by the 1 kHz loop itself, each only from its
source node's writer (haptic_bridge.sources, through liver_sim.nodes.inputs.LoopInputs); the device map comes through
liver_sim.nodes.device_map_source; commands and zeros leave on one writer watched for rivals
(liver_sim.nodes.force_output); the diagnostics are liver_sim.nodes.bridge_diagnostics. What is rendered from what
is decided without ROS: haptic_bridge.intake (which samples count), haptic_bridge.tick (the tick),
haptic_bridge.supervisor (zero when the loop cannot vouch for its command)."""
from __future__ import annotations

import time

import numpy as np
from rclpy.duration import Duration

from haptic_bridge.intake import Handoff, Intake
from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.sources import WriterGate
from haptic_bridge.supervisor import Supervisor
from haptic_bridge.tick import BridgeTick, check_passivity, checked_change
from liver_sim.base.emulated_link import link_text
from liver_sim.nodes.bridge_diagnostics import BridgeState, bridge_status
from liver_sim.nodes.device_map_source import DeviceMapSource
from liver_sim.nodes.diagnostics import loop_status_name, publish_diagnostics
from liver_sim.nodes.force_output import ForceOutput
from liver_sim.nodes.inputs import LoopInputs, RosTime, emulated_link, link_report
from liver_sim.nodes.run import close_ack_timeout_s
from liver_sim.nodes.source_graph import source_node, update_gates
from liver_sim.realtime.rate_loop import RateLoop, warn
from msg_defs.cdr import MAX_BYTES
from msg_defs.forces import force_message_bytes, stamped_force_from_bytes
from msg_defs.local_model import local_model_from_bytes
from msg_defs.poses import position_from_bytes
from msg_defs.topics import TOPICS, loop_input_qos

#: How often (s) the bridge looks at the graph: the writers of its inputs (haptic_bridge.sources) and of its force
#: topic (liver_sim.nodes.force_output); not in the 1 kHz loop.
GRAPH_CHECK_S = 0.1
#: The warning of a close whose last zero a reliable subscriber (the driver) has not acknowledged.
ZERO_NOT_ACKED = "the last zero force was not acknowledged"
#: The bridge's inputs: name → (topic parameter, TOPICS key, decoder of the serialized message, source parameter).
INPUTS = {"device_pose": ("measured_cp_topic", "measured_cp", position_from_bytes, "device_node"),
          "local_model": ("local_model_topic", "contact_plane", local_model_from_bytes, "model_node"),
          "tool_wrench": ("tool_wrench_topic", "tool_wrench", stamped_force_from_bytes, "model_node")}
#: Samples an input's reader keeps between two ticks: other writers' samples cannot displace its source's unless
#: they send more than this in a period.
INPUT_HISTORY = 100


class BridgeShell:
    """The ROS side of one bridge on `node` with checked parameters `p` (and the envelope of `start_p`, default
    `p`): :meth:`start` runs the loop; :meth:`stop` leaves zero on the wire. The parameters in force are
    `intake.p` (:attr:`p`)."""

    def __init__(self, node, p: BridgeParameters, start_p: BridgeParameters | None = None):
        if p.drives_device:
            check_passivity(p)  # every mode; again with the device map's scale when it arrives
        self.node, self.start_p = node, start_p or p
        self.tick = BridgeTick(p, device_map=None)
        self.intake = Intake(p, {kind: decoder for kind, (_, _, decoder, _) in INPUTS.items()})
        self.link = emulated_link(p)  # the teleoperation link from the physics' side, if emulated
        self.inputs = LoopInputs(node)  # read by the 1 kHz loop itself, not by the executor
        self.gates = {kind: self._subscribe(kind) for kind in ("device_pose", self.intake.source_kind)}
        self.output = ForceOutput(node, p)
        self.diagnostics = node.create_publisher(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                                 TOPICS["diagnostics"].qos)
        self.map_source = DeviceMapSource(node, p.device_map_topic, p.device_map_node, self._on_map,
                                          self._on_refused_map)
        self.intake.map_problem = f"waiting for the device map on {self.map_source.topic}"
        self.time = RosTime(node)
        self.loop = self.supervisor = None
        self.timers = (node.create_timer(1.0, self._publish_diagnostics),
                       node.create_timer(GRAPH_CHECK_S, self._check_graph))
        self.last_report = time.monotonic()

    @property
    def p(self) -> BridgeParameters:
        return self.intake.p

    def _subscribe(self, kind: str) -> tuple[str, WriterGate]:
        """Subscribe the loop to input `kind`, taken only from its source's writer: (resolved topic, gate)."""
        topic_parameter, key, _, source_parameter = INPUTS[kind]
        gate = WriterGate(source_node(self.node, getattr(self.p, source_parameter)), source_parameter)
        type_name, intake = TOPICS[key].type.__name__, self.intake

        def on_message(taken, received_s: float) -> None:  # in the loop's poll
            if taken.data:
                intake.offer(kind, taken.data, received_s)
            else:
                intake.refuse(kind, f"{taken.size} bytes, more than the {MAX_BYTES[type_name]} a {type_name} read "
                                    "by the loop may have (msg_defs.cdr.MAX_BYTES): refused without reading it")

        subscription = self.inputs.subscribe(
            TOPICS[key].type, getattr(self.p, topic_parameter), loop_input_qos(TOPICS[key], INPUT_HISTORY),
            on_message, link=None if kind == "device_pose" else self.link, gate=gate, max_bytes=MAX_BYTES[type_name])
        return subscription.topic_name, gate

    # -- life cycle
    def start(self) -> None:
        """A new loop and supervisor; the force starts from zero (soft start). ValueError when K·scale is not
        passive with the device map in use or waiting (a managed bridge refuses its activation)."""
        self._check_scales(self.p)
        p = self.p
        self.tick.restart()
        self.loop = RateLoop(p.rate_hz, self._step, "haptic_bridge", on_error=self._on_error,
                             realtime_priority=p.realtime_priority, on_refused=warn(self.node))
        self.supervisor = Supervisor(p.stall_bound_s, self.loop.period_s, self.output.publish, self._zero_message,
                                     self.loop.is_alive, realtime_priority=p.realtime_priority)
        self.loop.start()
        self.supervisor.start()

    def stop(self, cause: str) -> None:
        """Zero force as the last command on the writer (nothing after it), the loop stopped, the zero
        acknowledged, and the last diagnostics too (`destroy` would take messages not yet acknowledged with their
        publisher), within run.close_ack_timeout_s(), the zero first; a zero not acknowledged by then is logged."""
        if self.supervisor is not None and not self.supervisor.closed:
            self.supervisor.close(cause)
            self.loop.stop()
            timeout_s = close_ack_timeout_s()
            deadline = time.monotonic() + timeout_s
            for publisher in (self.output.publisher, self.diagnostics):
                try:
                    acked = publisher.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
                except Exception:  # noqa: BLE001 — a context already gone: nothing more can be done here
                    continue
                if not acked and publisher is not self.diagnostics:
                    self.node.get_logger().warning(
                        f"{ZERO_NOT_ACKED} on {publisher.topic_name} within {timeout_s:g} s")

    def destroy(self) -> None:
        self.inputs.destroy()
        self.map_source.destroy()
        for timer in self.timers:
            self.node.destroy_timer(timer)
        self.output.destroy(self.node)
        self.node.destroy_publisher(self.diagnostics)

    # -- run-time parameters (executor thread)
    def apply(self, changes: dict) -> str | None:
        """Check `changes` as at start, with every device scale the loop may render with (the map in use, one
        waiting, the newest taken), and within the start's envelope; the loop takes them at its next tick.
        Refusal: ValueError with the reason."""
        p = checked_change(self.p, changes, 1.0, self.start_p)
        self._check_scales(p)
        self.intake.offer_params(p)
        return None

    def _check_scales(self, p: BridgeParameters) -> None:
        if p.drives_device:
            for scale in self.intake.scales(self.tick):
                check_passivity(p, scale)

    # -- the graph (executor thread): each input's source writer, one writer on the device
    def _check_graph(self) -> None:
        """Hand the inputs' gates the graph, and look for other writers on force_topic: two bridges interleaving
        their commands would defeat the rate limit and the watchdog, so while any other publishes there, this one
        sends zero."""
        update_gates(self.node, dict(self.gates.values()))
        appeared, gone = self.output.check()
        logger = self.node.get_logger()
        if appeared:
            logger.error(f"another publisher on {self.output.topic} ({', '.join(appeared)}): sending zero, not "
                         "driving the device while it publishes there")
        if gone and not self.output.rivals:
            logger.info(f"{self.output.topic} has no other publisher: driving again (soft start)")

    # -- the device map (executor thread): from device_map_node only, changed only through zero force
    def _on_map(self, device_map) -> None:
        source = self.map_source.source_node
        problem = self.intake.offer_map(device_map, source)
        if problem:
            self.node.get_logger().error(f"{problem}; the force stays zero")
            return
        self.node.get_logger().info(
            f"device map from {source} on {self.map_source.topic}: "
            f"R {np.round(device_map.rotation, 6).tolist()}, t {device_map.translation.tolist()} m, "
            f"scale {device_map.scale:g} (a change applies once the force is zero, then a soft start)")

    def _on_refused_map(self, reason: str, from_source: bool) -> None:
        """A refused map sample: from another node it changes nothing; from device_map_node (or while two nodes
        bear its name) the force goes to zero until a good one comes (the tool places the tool with a map the
        bridge cannot use)."""
        self.intake.refuse("device_map", reason)
        if from_source:
            self.intake.withdraw_map(f"device map refused: {reason}")
            self.node.get_logger().error(f"{self.intake.map_problem}; the force stays zero")
        else:
            self.node.get_logger().error(f"device map refused, the map in use stays: {reason}")

    # -- the loop (its own thread)
    def _step(self, now: float) -> None:
        tick, intake = self.tick, self.intake
        if self.supervisor.beat(now):
            tick.restart()
        if (p := intake.params.take()) is not Handoff.NOTHING:
            tick.configure(p)
        if (device_map := intake.maps.take()) is not Handoff.NOTHING:
            tick.set_device_map(device_map)
        self.inputs.poll()
        wall = time.time()  # the clock of the device's stamps
        tip, pose_age, source, source_age, stamp = intake.tick_inputs(tick, now, wall)
        command = tick.step(now, tip, pose_age, source, source_age, wall)
        if self.output.rivals:  # another bridge on the device: zero, and a soft start once it has gone
            tick.restart()
            command = np.zeros(3)
        intake.last_force_n = float(np.linalg.norm(command))
        if stamp is None or (source_age if intake.source_kind == "tool_wrench" else pose_age) > self.p.lifetime_s:
            stamp = self.time.stamp()  # no fresh input: the command holds now
        self.supervisor.send(force_message_bytes(self.p.force_output, command, stamp, self.p.device_frame_id))

    def _on_error(self, now: float, exc: Exception) -> None:
        self.supervisor.error(now, exc)

    def _zero_message(self) -> bytes:
        return force_message_bytes(self.p.force_output, np.zeros(3), self.time.stamp(), self.p.device_frame_id)

    # -- diagnostics (executor thread)
    def _publish_diagnostics(self) -> None:
        self.time.refresh()
        now = time.monotonic()
        logger = self.node.get_logger()
        intake = self.intake
        for kind, reason in list(intake.reasons.items()):
            logger.warning(f"ignored {kind} message(s) ({intake.bad[kind]} so far): {reason}")
            intake.reasons.pop(kind, None)
        bursts = self.output.take_bursts()
        for name, count in bursts.items():
            logger.error(f"{count} command(s) of another writer on {self.output.topic} ({name})")
        if self.supervisor is None:
            return
        report = self.supervisor.report(now, self.last_report)
        self.last_report = now
        stats = self.loop.report()
        gates = {**{kind: gate for kind, (_, gate) in self.gates.items()}, "device_map": self.map_source.gate}
        state = BridgeState(intake.ages(now), gates,
                            intake.bad, intake.map_problem, self.output.rivals, bursts, intake.last_force_n,
                            self.output.topic, intake.maps.pending)
        status, events = bridge_status(loop_status_name(self.node), self.p, self.tick, stats, report, state,
                                       link_report(self.link, self.inputs))
        for line in events:
            logger.error(line)
        if stats["new_gaps"]:
            logger.warning(f"loop {stats['new_gaps']}")
        publish_diagnostics(self.node, self.diagnostics, [status])

    def describe(self) -> str:
        p = self.p
        rendering = ("physics wrench held between updates" if self.p.local_model == "none" else
                     f"local model (K {p.stiffness_n_per_m:g} N/m, B {p.damping_ns_per_m:g} N·s/m, "
                     f"glide {p.model_glide_s:g} s, tool radius {p.tool_radius_m:g} m)")
        (pose_topic, pose_gate), (source_topic, source_gate) = self.gates.values()
        return (f"haptic_bridge: {p.rate_hz:g} Hz, local_model {p.local_model}: {rendering}; passivity controller "
                f"{'on' if self.tick.passivity.control else 'off'}; in: {pose_topic} from {pose_gate.source}, "
                f"{source_topic} from {source_gate.source}{link_text(self.link)}, device map "
                f"{self.map_source.topic} from {self.map_source.source_node}; out: {self.output.topic} "
                f"({p.force_output}, frame {p.device_frame_id}, "
                f"max {p.max_force_n:g} N, {p.max_force_rate_n_per_s:g} N/s, soft start {p.soft_start_s:g} "
                f"s); watchdog: lifetime {p.lifetime_s:g} s, ramp {p.ramp_time_s:g} s; supervisor: zero after "
                f"{p.stall_bound_s * 1e3:g} ms without a tick")
