"""`haptic_bridge`: the 1 kHz haptic loop between the physics (150 Hz) and the device driver.

Each tick of a RateLoop (own thread) turns the newest tool pose and local model into a contact
force (paper §2.5, P11 of docs/paper.md) — or, with `local_model: none`, holds the newest physics contact wrench
(the "without local model" baseline of Fig. 8, R4) — maps it into the device frame with the device
map `liver_tool` publishes (latched on device_map_topic; zero force before it arrives) and sends it
through SafeForceOutput (clamp, rate limit, watchdog, soft start) to the driver's force topic.
The loop reads its inputs itself; each input's age counts from its reception by DDS, an input
without a matched publisher is stale, and an implausible one is refused and counted.  The command
is stamped with the stamp of the input it was computed from (the tool pose; the wrench in `none`
mode), or the node's clock before any.

A Supervisor thread (haptic_bridge.supervisor) publishes zero whenever the loop stalls beyond
stall_bound_s, raises, or ends, and holds it until the loop is back; on an ending signal (run_node)
or close the last message is a zero force, acknowledged before the context goes.  Run-time
parameter changes are checked like start-up values and applied from the next tick, or refused with
the reason.  `haptic_bridge --managed` runs the same bridge as a lifecycle node: activate starts the
loop, deactivate and shutdown zero the force and stop it.
The tick itself is haptic_bridge.tick.BridgeTick; the parameters are haptic_bridge.parameters.PARAMETERS.
"""
from __future__ import annotations

import math
import sys
import time
from datetime import datetime, timezone

import numpy as np
from rclpy.duration import Duration
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node

from haptic_bridge.inputs import InputCheck
from haptic_bridge.parameters import PARAMETERS
from haptic_bridge.supervisor import Supervisor
from haptic_bridge.tick import BridgeTick, check_passivity, checked_change, passivity_problem
from liver_sim.base.link import link_text
from liver_sim.nodes.diagnostics import diagnostic_status, on_rate, publish_diagnostics
from liver_sim.nodes.inputs import Latest, LoopInputs, emulated_link, link_report
from liver_sim.nodes.occupants import node_path, publisher_nodes
from liver_sim.nodes.parameters import declare_parameters, on_parameter_changes
from liver_sim.nodes.rate_loop import RateLoop, warn
from liver_sim.nodes.run import run_node
from msg_defs.device_map import device_map_from_message
from msg_defs.forces import force_message_bytes, force_message_type, stamped_force_from_bytes
from msg_defs.local_model import local_model_from_bytes
from msg_defs.poses import pose_from_bytes
from msg_defs.topics import TOPICS, loop_input_qos

#: How long (s) after a device map arrives the bridge checks who publishes on its topic: the graph learns of a new
#: publisher about when its first message arrives.
MAP_SOURCE_CHECK_S = 0.2
#: How often (s) the bridge looks for another publisher on its force topic (a second bridge on the device).
RIVAL_CHECK_S = 0.1
#: The bridge's own writers on its force topic: the loop's and the supervisor's zeros.
OWN_FORCE_WRITERS = 2
#: How long (s) close waits for the driver to acknowledge the last zero (and a recorder the last diagnostics).
ZERO_ACK_TIMEOUT_S = 1.0
#: The warning of a close whose last zero a reliable subscriber (the driver) has not acknowledged.
ZERO_NOT_ACKED = "the last zero force was not acknowledged"


def wall_time(monotonic_s: float) -> str:
    """ISO-8601 UTC time (ms) of a monotonic time of this process."""
    if not math.isfinite(monotonic_s):
        return "-"
    wall = time.time() - (time.monotonic() - monotonic_s)
    return datetime.fromtimestamp(wall, tz=timezone.utc).isoformat(timespec="milliseconds")


class BridgeShell:
    """The ROS side of one bridge on `node` with checked parameters `p`: inputs, outputs, loop, supervisor,
    diagnostics, run-time parameters. :meth:`start` runs the loop; :meth:`stop` leaves zero on the wire."""

    def __init__(self, node, p: dict):
        if p["drives_device"]:
            check_passivity(p)  # every mode; again with the device map's scale when it arrives
        self.node, self.p, self.start_p = node, p, p
        self.tick = BridgeTick(p, device_map=None)
        self.checks = InputCheck(p["workspace_centre_m"], p["workspace_radius_m"])
        self.mode = p["local_model"]
        self.scale = 1.0
        self._pose = Latest()    # (tip position (3,) m, stamp)
        self._source = Latest()  # (local model or None, lifetime s), or (force (3,) N, stamp) in none mode
        self._bad = {"tool_pose": 0, "local_model": 0, "tool_wrench": 0, "device_map": 0}
        self._bad_reason = {}
        self._bad_logged = dict(self._bad)
        self._pending = (0, None)      # (version, parameters) for the loop's next tick
        self._pending_map = (0, None)  # (version, DeviceMap or None)
        self._applied = self._applied_map = 0
        self._map_problem = f"waiting for the device map on {p['device_map_topic']}"
        self._device_map = None        # the map the loop renders through (executor thread's view)
        self._map_resubscribe = False  # a map was refused for its source: take the latched one again later
        self._offered_map = self._offer_timer = None  # the newest map received, until MAP_SOURCE_CHECK_S later
        self._maps_taken = 0
        self._last_force = np.zeros(3)
        self._last_report = time.monotonic()
        self._loop = self.supervisor = None
        self._publisher = node.create_publisher(force_message_type(p["force_output"]), p["force_topic"],
                                                TOPICS["servo_cf"].qos)
        # the supervisor's zeros: a writer of their own, not held up by a publish of the loop
        self._zero_publisher = node.create_publisher(force_message_type(p["force_output"]), p["force_topic"],
                                                     TOPICS["servo_cf"].qos)
        self._diagnostics = node.create_publisher(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                                  TOPICS["diagnostics"].qos)
        self._map_subscription = self._subscribe_map()
        self._inputs = LoopInputs(node)  # read by the 1 kHz loop itself, not by the executor
        self.link = emulated_link(p)  # the teleoperation link from the physics' side, if emulated
        self._pose_input = self._inputs.subscribe(TOPICS["tool_pose"].type, p["tool_pose_topic"],
                                                  loop_input_qos(TOPICS["tool_pose"]), self._on_pose, raw=True,
                                                  received=True)
        if self.mode == "none":
            self.source_topic = p["tool_wrench_topic"]
            self._source_input = self._inputs.subscribe(TOPICS["tool_wrench"].type, self.source_topic,
                                                        loop_input_qos(TOPICS["tool_wrench"]), self._on_wrench,
                                                        raw=True, received=True, link=self.link)
        else:
            self.source_topic = p["local_model_topic"]
            self._source_input = self._inputs.subscribe(TOPICS["contact_plane"].type, self.source_topic,
                                                        loop_input_qos(TOPICS["contact_plane"]), self._on_marker,
                                                        raw=True, received=True, link=self.link)
        self._rivals: list[str] = []  # the other publishers on force_topic: while any, the bridge sends zero
        self._timer = node.create_timer(1.0, self._publish_diagnostics)
        self._rival_timer = node.create_timer(RIVAL_CHECK_S, self._check_rivals)

    # -- life cycle
    def start(self) -> None:
        """A new loop and supervisor; the force starts from zero (soft start)."""
        p = self.p
        self.tick.restart()
        self._loop = RateLoop(p["rate_hz"], self._step, "haptic_bridge", on_error=self._on_error,
                              realtime_priority=p["realtime_priority"], on_refused=warn(self.node))
        self.supervisor = Supervisor(p["stall_bound_s"], self._loop.period_s, self._publisher.publish,
                                     self._zero_message, self._loop.is_alive,
                                     realtime_priority=p["realtime_priority"],
                                     publish_zero=self._zero_publisher.publish)
        self._loop.start()
        self.supervisor.start()

    def stop(self, cause: str) -> None:
        """Zero force as the last command (nothing after it), the loop stopped, the zero acknowledged, and the
        last diagnostics too: `destroy` would take messages not yet acknowledged with their publisher (a recorded
        demo lost the bridge's last /diagnostics). Both within ZERO_ACK_TIMEOUT_S, the zero first; a zero not
        acknowledged by then is logged as a warning (the profile's writers send a heartbeat, which asks for the
        acknowledgement, every 0.1 s)."""
        if self.supervisor is not None and not self.supervisor.closed:
            self.supervisor.close(cause)
            self._loop.stop()
            deadline = time.monotonic() + ZERO_ACK_TIMEOUT_S
            for publisher in (self._publisher, self._zero_publisher, self._diagnostics):
                try:
                    acked = publisher.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
                except Exception:  # noqa: BLE001 — a context already gone: nothing more can be done here
                    continue
                if not acked and publisher is not self._diagnostics:
                    self.node.get_logger().warning(
                        f"{ZERO_NOT_ACKED} on {publisher.topic_name} within {ZERO_ACK_TIMEOUT_S:g} s")

    def destroy(self) -> None:
        self._inputs.destroy()
        self.node.destroy_timer(self._rival_timer)
        if self._offer_timer is not None:
            self.node.destroy_timer(self._offer_timer)
        self.node.destroy_timer(self._timer)
        self.node.destroy_subscription(self._map_subscription)
        self.node.destroy_publisher(self._publisher)
        self.node.destroy_publisher(self._zero_publisher)
        self.node.destroy_publisher(self._diagnostics)

    # -- run-time parameters (executor thread)
    def apply(self, changes: dict) -> str | None:
        """Check `changes` as at start; the loop takes them at its next tick. Refusal: ValueError with the reason."""
        self.p = checked_change(self.p, changes, self.scale, self.start_p)
        self._pending = (self._pending[0] + 1, self.p)
        return None

    # -- one bridge per device (executor thread)
    def _check_rivals(self) -> None:
        """Note every publisher on force_topic but this bridge's own: two bridges interleaving their commands
        would defeat the rate limit and the watchdog, so while any other publishes there, this one sends zero."""
        names = publisher_nodes(self.node, self._publisher.topic_name)
        own = node_path(self.node.get_namespace(), self.node.get_name())
        for _ in range(OWN_FORCE_WRITERS):  # the loop's and the supervisor's
            if own in names:
                names.remove(own)
            elif names:
                names.pop()  # ours, under a name the graph has not caught up with
        if names and not self._rivals:
            self.node.get_logger().error(f"another publisher on {self.p['force_topic']} ({', '.join(names)}): "
                                         "sending zero, not driving the device while it publishes there")
        elif self._rivals and not names:
            self.node.get_logger().info(f"{self.p['force_topic']} has no other publisher: driving again (soft start)")
        self._rivals = names

    # -- the device map (executor thread): one source, never re-aimed in contact
    def _subscribe_map(self):
        return self.node.create_subscription(TOPICS["device_map"].type, self.p["device_map_topic"],
                                             self._on_device_map, TOPICS["device_map"].qos)

    def _foreign_map_publishers(self) -> list[str]:
        """The nodes other than device_map_node that publish on device_map_topic."""
        return sorted(set(publisher_nodes(self.node, self._map_subscription.topic_name)) - {self.p["device_map_node"]})

    def _refuse_map(self, reason: str) -> None:
        self._bad["device_map"] += 1
        self.node.get_logger().error(f"device map refused: {reason}")

    def _retake_map(self) -> None:
        """After a map refused for its source while the bridge has none (its own may have come in the meantime,
        refused with it): once device_map_node alone publishes, subscribe again, so that its latched map
        arrives again. With a map in use nothing is done (a new reader can hold up the loop's publish)."""
        if self._map_resubscribe and self._device_map is None and not self._foreign_map_publishers():
            self._map_resubscribe = False
            self.node.destroy_subscription(self._map_subscription)
            self._map_subscription = self._subscribe_map()

    def _on_device_map(self, message) -> None:
        """A map is taken MAP_SOURCE_CHECK_S after it arrived, when the graph has caught up with whoever sent it
        (:meth:`_take_offered_map`); a map that cannot be decoded or is not passive is refused at once."""
        try:
            device_map = device_map_from_message(message)
            if self.p["drives_device"]:
                check_passivity(self.p, device_map.scale)
        except ValueError as exc:
            self._bad["device_map"] += 1
            self._map_problem = f"device map refused: {exc}"
            self.node.get_logger().error(f"{self._map_problem}; the force stays zero")
            self._device_map = None
            self._pending_map = (self._pending_map[0] + 1, None)
            return
        self._offered_map = device_map
        if self._offer_timer is None:
            self._offer_timer = self.node.create_timer(MAP_SOURCE_CHECK_S, self._take_offered_map)

    def _take_offered_map(self) -> None:
        """Take the newest offered map from device_map_node only (checked against the topic's publishers: a
        message carries no sender); equal to the current one: nothing; new while in contact: refused; else
        rendered from the next tick with a soft start."""
        if self._offer_timer is not None:
            self.node.destroy_timer(self._offer_timer)
            self._offer_timer = None
        device_map, self._offered_map = self._offered_map, None
        if device_map is None:  # a timer event queued before the timer was destroyed
            return
        foreign = self._foreign_map_publishers()
        if foreign:
            self._map_resubscribe = True
            self._refuse_map(f"{', '.join(foreign)} also publish(es) on {self.p['device_map_topic']}; only "
                             f"{self.p['device_map_node']} may (parameter device_map_node)")
            return
        if device_map.same_as(self._device_map):
            return
        if self._device_map is not None and self._last_force.any():
            self._refuse_map("a new map while the tool is in contact (the force would turn); the current map "
                             "stays")
            return
        self.scale, self._map_problem, self._device_map = device_map.scale, None, device_map
        self._maps_taken += 1
        self._pending_map = (self._pending_map[0] + 1, device_map)
        self.node.get_logger().info(
            f"device map from {self.p['device_map_topic']}: R {np.round(device_map.rotation, 6).tolist()}, "
            f"t {device_map.translation.tolist()} m, scale {device_map.scale:g}")

    # -- the loop (its own thread)
    def _on_pose(self, data: bytes, received: float) -> None:
        try:
            position, _, stamp = pose_from_bytes(data)
        except ValueError as exc:
            self._refuse("tool_pose", str(exc))
            return
        problem = self.checks.tip(position)
        if problem:
            self._refuse("tool_pose", problem)
            return
        self._pose.set((position, stamp), received)

    def _on_marker(self, data: bytes, received: float) -> None:
        try:
            model, lifetime = local_model_from_bytes(data)
        except ValueError as exc:
            self._refuse("local_model", str(exc))
            return
        problem = self.checks.model(model)
        if problem:
            self._refuse("local_model", problem)
            return
        cap = self.p["lifetime_s"]
        self._source.set((model, min(lifetime, cap) if lifetime > 0.0 else cap), received)

    def _on_wrench(self, data: bytes, received: float) -> None:
        try:
            force, stamp = stamped_force_from_bytes(data)
        except ValueError as exc:
            self._refuse("tool_wrench", str(exc))
            return
        problem = self.checks.force(force)
        if problem:
            self._refuse("tool_wrench", problem)
            return
        self._source.set((force, stamp), received)

    def _refuse(self, kind: str, reason: str) -> None:
        self._bad[kind] += 1
        self._bad_reason[kind] = reason  # logged by the diagnostics timer, not here in the loop

    def _step(self, now: float) -> None:
        if self.supervisor.beat(now):
            self.tick.restart()
        version, p = self._pending
        if version != self._applied:
            self._applied = version
            self.tick.configure(p)
        version, device_map = self._pending_map
        if version != self._applied_map:
            self._applied_map = version
            if device_map is None:
                self.tick.device_map = None  # a refused map: zero until a good one
            else:
                self.tick.set_device_map(device_map)
        self._inputs.poll()
        pose, pose_received = self._pose.get()
        tip, stamp = pose if pose is not None else (None, None)
        source, source_received = self._source.get()
        if self.mode == "none":
            source, stamp = source if source is not None else (None, None)
        pose_age = now - pose_received if self._pose_input.get_publisher_count() else math.inf
        source_age = now - source_received if self._source_input.get_publisher_count() else math.inf
        command = self.tick.step(now, tip, pose_age, source, source_age)
        if self._rivals:  # another bridge on the device: zero, and a soft start once it has gone
            self.tick.restart()
            command = np.zeros(3)
        self._last_force = command
        if stamp is None or (source_age if self.mode == "none" else pose_age) > self.p["lifetime_s"]:
            stamp = self.node.get_clock().now().seconds_nanoseconds()  # no fresh input: the command holds now
        self.supervisor.send(force_message_bytes(self.p["force_output"], command, stamp,
                                                 self.p["device_frame_id"]))

    def _on_error(self, now: float, exc: Exception) -> None:
        self.supervisor.error(now, exc)

    def _zero_message(self) -> bytes:
        return force_message_bytes(self.p["force_output"], np.zeros(3), self.node.get_clock().now().to_msg(),
                                   self.p["device_frame_id"])

    # -- diagnostics (executor thread)
    def _publish_diagnostics(self) -> None:
        self._retake_map()
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
        events = [f"{e.kind} at {wall_time(e.start_s)}: {e.cause}"
                  + (f" (zero held {(e.end_s - e.start_s) * 1e3:.1f} ms)" if e.end_s is not None else " (now)")
                  for e in report.pop("events")]
        for line in events:
            logger.error(line)
        stats = self._loop.report()
        _, pose_received = self._pose.get()
        _, source_received = self._source.get()
        state = self.tick.safety.state
        extra = {"watchdog": state, "local_model": self.mode, "drives_device": self.p["drives_device"],
                 "bad_messages": sum(self._bad.values()), **{f"bad_{k}": v for k, v in self._bad.items()},
                 "last_force_n": float(np.linalg.norm(self._last_force)), "max_force_n": self.p["max_force_n"],
                 "tool_pose_age_s": float(now - pose_received),
                 ("tool_wrench_age_s" if self.mode == "none" else "local_model_age_s"): float(now - source_received),
                 "tool_pose_publishers": self._pose_input.get_publisher_count(),
                 "source_publishers": self._source_input.get_publisher_count(),
                 "device_scale": self.scale if self._map_problem is None else float("nan"),
                 "device_maps_taken": self._maps_taken, **self.tick.passivity.report(),
                 **link_report(self.link, self._inputs), **report,
                 "max_gap_1s_at": wall_time(report["max_gap_1s_at_s"]), "max_gap_at": wall_time(report["max_gap_at_s"])}
        del extra["max_gap_1s_at_s"], extra["max_gap_at_s"], extra["error"]
        if stats["new_gaps"]:
            logger.warning(f"loop {stats['new_gaps']}")
        problems = [] if on_rate(stats, self.p["rate_hz"]) else ["below rate"]
        if stats["new_gaps"]:
            problems.append(stats["new_gaps"])
        if state != "ok":
            problems.append(f"watchdog {state}")
        if self._map_problem:
            problems.append(self._map_problem)
        if self._rivals:
            problems.append(f"another publisher on {self.p['force_topic']} ({', '.join(self._rivals)}): not driving")
        if not self.p["drives_device"]:
            problems += filter(None, [passivity_problem(self.p, self.scale)])
        error = report["error"] or (self._map_problem or "").startswith("device map refused") or bool(self._rivals)
        message = "; ".join(events + problems) or "ok"
        publish_diagnostics(self.node, self._diagnostics, [diagnostic_status(
            f"{self.node.get_name()}: loop", stats, not problems, message, extra, error=error)])

    def describe(self) -> str:
        p = self.p
        rendering = ("physics wrench held between updates" if self.mode == "none" else
                     f"local model (K {p['stiffness_n_per_m']:g} N/m, B {p['damping_ns_per_m']:g} N·s/m, "
                     f"glide {p['model_glide_s']:g} s, tool radius {p['tool_radius_m']:g} m)")
        return (f"haptic_bridge: {p['rate_hz']:g} Hz, local_model {self.mode}: {rendering}; "
                f"in: {p['tool_pose_topic']}, {self.source_topic}{link_text(self.link)}, "
                f"device map {p['device_map_topic']}; "
                f"out: {p['force_topic']} ({p['force_output']}, frame {p['device_frame_id']}, max "
                f"{p['max_force_n']:g} N, {p['max_force_rate_n_per_s']:g} N/s, soft start {p['soft_start_s']:g} s); "
                f"watchdog: lifetime {p['lifetime_s']:g} s, ramp {p['ramp_time_s']:g} s; supervisor: zero after "
                f"{p['stall_bound_s'] * 1e3:g} ms without a tick")


class HapticBridge(Node):
    """Tool pose + newest local model (or physics wrench) → safe force command, at rate_hz, from start to close."""

    def __init__(self):
        super().__init__("haptic_bridge")
        self.p = declare_parameters(self, PARAMETERS)
        self.shell = BridgeShell(self, self.p)
        on_parameter_changes(self, PARAMETERS, self.shell.apply)
        self.get_logger().info(self.shell.describe())
        self.shell.start()

    def close(self) -> None:
        """Zero force on the wire, then stop the loop."""
        self.shell.stop("node closed (an ending signal or exit)")
        self.shell.destroy()


class ManagedHapticBridge(LifecycleNode):
    """The bridge as a lifecycle node: configure builds it, activate runs the loop, deactivate and shutdown
    leave zero force on the wire and stop it, cleanup removes it. Parameters set before configure apply then."""

    def __init__(self):
        super().__init__("haptic_bridge")
        self.p = declare_parameters(self, PARAMETERS)
        self.shell = None
        on_parameter_changes(self, PARAMETERS, self._apply)

    def _apply(self, changes: dict) -> str | None:
        if self.shell is not None:
            return self.shell.apply(changes)
        self.p = {**self.p, **changes}  # checked at configure
        return None

    def on_configure(self, state) -> TransitionCallbackReturn:
        try:
            self.shell = BridgeShell(self, self.p)
        except ValueError as exc:
            self.get_logger().error(f"configure refused: {exc}")
            return TransitionCallbackReturn.FAILURE
        self.get_logger().info(self.shell.describe())
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.shell.start()
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.shell.stop("deactivated")
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        self.p = self.shell.p
        self.shell.destroy()
        self.shell = None
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state) -> TransitionCallbackReturn:
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state) -> TransitionCallbackReturn:
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:
        if self.shell is not None:
            self.shell.stop("shut down")
            self.shell.destroy()
            self.shell = None


def main(args=None) -> int:
    argv = list(sys.argv if args is None else args)
    managed = "--managed" in argv
    return run_node(ManagedHapticBridge if managed else HapticBridge, [a for a in argv if a != "--managed"])


if __name__ == "__main__":
    raise SystemExit(main())
