"""`haptic_bridge`: the 1 kHz haptic loop between the physics (150 Hz) and the device driver.

Each tick of a RateLoop (own thread) turns the newest tool pose and local model into a contact
force (paper §2.5, P11 of docs/paper.md) — or, with `local_model: none`, holds the newest physics contact wrench
(the "without local model" baseline of Fig. 8, R4) — maps it into the device frame and sends it
through SafeForceOutput (clamp, rate limit, watchdog) to the driver's force topic.  Subscription
callbacks only validate and store snapshots.  The command is stamped with the stamp of the input
it was computed from (the tool pose; the wrench in `none` mode), or the node's clock before any.
The tick itself is haptic_bridge.tick.BridgeTick; the parameters are haptic_bridge.parameters.PARAMETERS.
"""
from __future__ import annotations

import time

import numpy as np
from rclpy.node import Node

from haptic_bridge.parameters import PARAMETERS
from haptic_bridge.tick import BridgeTick
from liver_sim.nodes.common import (Latest, LoopInputs, RateLoop, apply_realtime_priority, declare_parameters,
                                    diagnostic_status, on_rate, publish_diagnostics, run_node)
from msg_defs import conversions
from msg_defs.topics import TOPICS


class HapticBridge(Node):
    """Tool pose + newest local model (or physics wrench) → safe force command, at rate_hz."""

    def __init__(self):
        super().__init__("haptic_bridge")
        p = declare_parameters(self, PARAMETERS)
        self.p = p
        self._tick = BridgeTick(p)
        self._mode = p["local_model"]
        self._pose = Latest()    # (tip position (3,) m, stamp)
        self._source = Latest()  # (local model or None, lifetime s), or (force (3,) N, stamp) in none mode
        self._bad = {"tool_pose": 0, "local_model": 0, "tool_wrench": 0}
        self._last_force = np.zeros(3)
        self._publisher = self.create_publisher(conversions.force_message_type(p["force_output"]),
                                                 p["force_topic"], TOPICS["servo_cf"].qos)
        self._diagnostics = self.create_publisher(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                                  TOPICS["diagnostics"].qos)
        self._inputs = LoopInputs(self)  # read by the 1 kHz loop itself, not by the executor
        self._inputs.subscribe(TOPICS["tool_pose"].type, p["tool_pose_topic"], TOPICS["tool_pose"].qos, self._on_pose,
                               raw=True)
        if self._mode == "none":
            source = p["tool_wrench_topic"]
            self._inputs.subscribe(TOPICS["tool_wrench"].type, source, TOPICS["tool_wrench"].qos, self._on_wrench)
        else:
            source = p["local_model_topic"]
            self._inputs.subscribe(TOPICS["contact_plane"].type, source, TOPICS["contact_plane"].qos,
                                   self._on_marker)
        self.create_timer(1.0, self._publish_diagnostics)
        self._loop = RateLoop(p["rate_hz"], self._step, "haptic_bridge")
        rendering = ("physics wrench held between updates" if self._mode == "none" else
                     f"local model (K {p['stiffness_n_per_m']:g} N/m, B {p['damping_ns_per_m']:g} N·s/m, "
                     f"glide {p['model_glide_s']:g} s, "
                     f"tool radius {p['tool_radius_m']:g} m)")
        self.get_logger().info(
            f"haptic_bridge: {p['rate_hz']:g} Hz, local_model {self._mode}: {rendering}; "
            f"in: {p['tool_pose_topic']}, {source}; out: {p['force_topic']} ({p['force_output']}, frame "
            f"{p['device_frame_id']}, max {p['max_force_n']:g} N, {p['max_force_rate_n_per_s']:g} N/s); "
            f"watchdog: lifetime {p['lifetime_s']:g} s, ramp {p['ramp_time_s']:g} s")
        apply_realtime_priority(self, p["realtime_priority"])  # before the loop starts: it inherits it
        self._loop.start()

    def close(self) -> None:
        """Stop the haptic loop."""
        self._loop.stop()
        self._inputs.destroy()

    def _refuse(self, kind: str, reason: str) -> None:
        self._bad[kind] += 1
        self.get_logger().warning(f"ignored {kind} message: {reason}", throttle_duration_sec=1.0)

    def _on_pose(self, data: bytes) -> None:
        try:
            position, _, stamp = conversions.pose_from_bytes(data)
        except ValueError as exc:
            self._refuse("tool_pose", str(exc))
            return
        self._pose.set((position, stamp))

    def _on_marker(self, message) -> None:
        try:
            model, lifetime = conversions.marker_to_local_model(message)
        except ValueError as exc:
            self._refuse("local_model", str(exc))
            return
        self._source.set((model, lifetime if lifetime > 0.0 else self.p["lifetime_s"]))

    def _on_wrench(self, message) -> None:
        try:
            force = conversions.force_from_message("wrench_stamped", message)
        except ValueError as exc:
            self._refuse("tool_wrench", str(exc))
            return
        self._source.set((force, message.header.stamp))

    def _step(self, now: float) -> None:
        self._inputs.poll()
        pose, pose_received = self._pose.get()
        tip, stamp = pose if pose is not None else (None, None)
        source, source_received = self._source.get()
        if self._mode == "none":
            source, stamp = source if source is not None else (None, None)
        command = self._tick.step(now, tip, now - pose_received, source, now - source_received)
        self._last_force = command
        if stamp is None:
            stamp = self.get_clock().now().to_msg()
        message = conversions.force_message_bytes(self.p["force_output"], command, stamp, self.p["device_frame_id"])
        try:
            self._publisher.publish(message)
        except Exception:
            if self.context.ok():
                raise
            self._loop.stop()  # the context was shut down (SIGINT/SIGTERM) before close()

    def _publish_diagnostics(self) -> None:
        stats = self._loop.stats.summary()
        now = time.monotonic()
        _, pose_received = self._pose.get()
        _, source_received = self._source.get()
        state = self._tick.safety.state
        extra = {"watchdog": state, "local_model": self._mode,
                 "bad_messages": sum(self._bad.values()), **{f"bad_{k}": v for k, v in self._bad.items()},
                 "last_force_n": float(np.linalg.norm(self._last_force)),
                 "tool_pose_age_s": float(now - pose_received),
                 ("tool_wrench_age_s" if self._mode == "none" else "local_model_age_s"): float(now - source_received)}
        problems = ([] if on_rate(stats, self.p["rate_hz"]) else ["below rate"]) + ([] if state == "ok" else [f"watchdog {state}"])
        publish_diagnostics(self, self._diagnostics, [diagnostic_status(
            f"{self.get_name()}: loop", stats, not problems, "; ".join(problems) or "ok", extra)])


def main(args=None) -> int:
    return run_node(HapticBridge, args)


if __name__ == "__main__":
    raise SystemExit(main())
