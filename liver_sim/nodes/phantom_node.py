"""`phantom_sim`: a simulated PHANToM for use without hardware (paper P12, docs/paper.md).

A RateLoop at `rate_hz` (1 kHz) steps `liver_sim.phantom.device.PhantomSim` — a stylus with mass held by a
virtual hand playing a `tool_scripts` script — and publishes the stylus on /phantom/measured_cp (frame
`phantom_base`, stamped with the sample's time). The newest force command from /phantom/servo_cf (format
`force_output`, taken best effort and volatile as the loop's input: a simulator may drop one, a real driver
subscribes reliable) pushes the stylus; a command older than `command_timeout_s` (counted from its reception), or a
malformed one, counts as zero, as a real driver's safety would do. Its diagnostics carry the energy the commands
really gave the hand (the applied force times the stylus's own motion) and the largest energy generated in a
window (haptic_bridge.passivity): the truth a bridge's passivity observer estimates. A running node changes only
`command_timeout_s`; every other parameter change is refused with the reason.
Its parameters are liver_sim.phantom.parameters.PARAMETERS.
"""
from __future__ import annotations

import time

import numpy as np
from rclpy.node import Node

from haptic_bridge.passivity import GenerationMonitor
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.nodes.diagnostics import loop_status, loop_status_name, publish_diagnostics
from liver_sim.nodes.inputs import Latest, LoopInputs, RosTime
from liver_sim.nodes.parameters import declare_parameters, on_parameter_changes, read_at_start
from liver_sim.nodes.run import run_node
from liver_sim.phantom.device import PhantomSim, StylusParams
from liver_sim.phantom.parameters import PARAMETERS, PhantomParameters
from liver_sim.realtime.rate_loop import RateLoop, warn
from liver_sim.tool.scripts import ScriptParameters, script_from
from msg_defs.forces import force_from_bytes, force_message_type
from msg_defs.poses import IDENTITY, pose_stamped_bytes
from msg_defs.topics import TOPICS, loop_input_qos

_ZERO = np.zeros(3)


class PhantomNode(Node):
    """Steps the simulated stylus at `rate_hz` and publishes its pose; applies the newest force command."""

    def __init__(self):
        super().__init__("phantom_sim")
        p = self.p = PhantomParameters.from_values(declare_parameters(self, PARAMETERS))
        stylus = StylusParams(p.stylus_mass_kg, p.hand_stiffness_n_per_m, p.hand_damping_ns_per_m,
                              p.max_force_n, p.workspace_half_m)
        self.sim = PhantomSim(script_from(ScriptParameters.take(p)), DeviceMap.from_parameters(p), stylus)
        self._command = Latest()
        self.bad_commands = 0
        self._publisher = self.create_publisher(TOPICS["measured_cp"].type, p.measured_cp_topic,
                                                TOPICS["measured_cp"].qos)
        self._diagnostics = self.create_publisher(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                                  TOPICS["diagnostics"].qos)
        self._inputs = LoopInputs(self)  # read by the 1 kHz loop itself, not by the executor
        self._inputs.subscribe(force_message_type(p.force_output), p.servo_cf_topic,
                               loop_input_qos(TOPICS["servo_cf"]), self._on_command, raw=True, received=True)
        self._time = RosTime(self)
        self.create_timer(1.0, self._publish_diagnostics)
        self._refuse = read_at_start("phantom_sim", {"command_timeout_s"})
        on_parameter_changes(self, PARAMETERS, self._apply)
        self._loop = RateLoop(p.rate_hz, self._step, "phantom_sim", realtime_priority=p.realtime_priority,
                              on_refused=warn(self))
        self._start = None
        self._generation = GenerationMonitor(self._loop.period_s)
        self.get_logger().info(
            f"phantom_sim: {p.rate_hz:g} Hz stylus ({p.stylus_mass_kg:g} kg, hand "
            f"{p.hand_stiffness_n_per_m:g} N/m, {p.hand_damping_ns_per_m:g} N·s/m) playing "
            f"'{p.script}' ({self.sim.trajectory.duration_s:g} s{', looped' if p.loop_script else ''}) "
            f"anchored at {list(p.anchor_m)} m in the liver frame; in: {p.servo_cf_topic} "
            f"({p.force_output}, clamp {p.max_force_n:g} N, timeout {p.command_timeout_s:g} s); "
            f"out: {p.measured_cp_topic} (frame {p.frame_id})")
        self._loop.start()

    def _until_script_start(self) -> float:
        """Seconds from now to `script_start_time_s` (ROS time); 0 without one, or when it has passed (warned)."""
        if self.p.script_start_time_s <= 0.0:
            return 0.0
        wait = self.p.script_start_time_s - self.get_clock().now().nanoseconds * 1e-9
        if wait < 0.0:
            self.get_logger().warning(f"started {-wait:.2f} s after script_start_time_s: the script starts now")
        return max(wait, 0.0)

    def close(self) -> None:
        self._loop.stop()
        self._inputs.destroy()

    def _apply(self, changes: dict) -> str | None:
        refused = self._refuse(changes)
        if refused is None:
            self.p = self.p.replace(**changes)  # command_timeout_s: read by the next tick
        return refused

    def _on_command(self, data: bytes, received: float) -> None:
        try:
            force = force_from_bytes(self.p.force_output, data)
        except ValueError as exc:
            self.bad_commands += 1
            self.get_logger().warning(f"force command taken as zero: {exc}", throttle_duration_sec=1.0)
            force = _ZERO
        self._command.set(force, received)

    def _step(self, now: float) -> None:
        self._inputs.poll()
        if self._start is None:
            self._start = now + self._until_script_start()
        force, received = self._command.get()
        if now - received > self.p.command_timeout_s:
            force = _ZERO
        if self.sim.advance_to(now - self._start, force, self._loop.period_s) == 0 and self.sim.time_s > 0.0:
            return  # a late tick already caught up with this one's sample
        self._generation.record(now, self.sim.energy_to_hand_j, self.sim.pushing)
        stamp = self._time.stamp()  # the sample holds now: the stylus is advanced to it
        self._publisher.publish(pose_stamped_bytes(self.sim.tip, IDENTITY, stamp,
                                                   self.p.frame_id))

    def _publish_diagnostics(self) -> None:
        self._time.refresh()
        _, received = self._command.get()
        extra = {"commanded_force_n": float(np.linalg.norm(self.sim.force)),
                 "command_age_s": float(time.monotonic() - received), "bad_commands": self.bad_commands,
                 "script_time_s": self.sim.time_s, "energy_to_hand_j": self.sim.energy_to_hand_j,
                 "energy_generated_max_j": self._generation.update()}
        status = loop_status(loop_status_name(self), self._loop.report(), self.p.rate_hz, extra)
        publish_diagnostics(self, self._diagnostics, [status])


def main(args=None) -> int:
    return run_node(PhantomNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
