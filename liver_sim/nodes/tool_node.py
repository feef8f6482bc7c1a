"""`liver_tool`: publishes the tool tip on /tool/pose (frame `liver`) at `rate_hz` (the physics' rate, 150 Hz) from
the device, a script, or held still.

- source=device: a RateLoop at `rate_hz` takes the newest /phantom/measured_cp sample (a subscription the loop
  polls, not an executor callback per sample), maps it device→liver and publishes it with the sample's stamp;
  implausible samples (NaN, beyond `workspace_radius_m`) are counted, logged (throttled) and dropped. The haptic
  loop takes the device's samples itself (one hop): this node feeds the physics only;
- source=script: a RateLoop at `rate_hz` plays a `liver_sim.tool.scripts` script;
- source=static: a RateLoop at `rate_hz` holds `static_position_m`, `static_orientation_xyzw`.

Whatever the source, the device map is published once, latched (transient local), on `device_map_topic`:
haptic_bridge turns its forces with this map and no other, so the two can never disagree. A running node
changes only `workspace_radius_m`; every other parameter change is refused with the reason.

The parameters are liver_sim.tool.parameters.PARAMETERS; the script and device-map ones are shared with
`phantom_sim`, so both nodes can be given the same values.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from rclpy.node import Node

from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.parameters import quaternion_parameter, vector_parameter
from liver_sim.nodes.diagnostics import loop_status, loop_status_name, publish_diagnostics
from liver_sim.nodes.inputs import Latest, LoopInputs
from liver_sim.nodes.parameters import declare_parameters, on_parameter_changes, read_at_start
from liver_sim.nodes.run import run_node
from liver_sim.realtime.rate_loop import RateLoop, warn
from liver_sim.tool.parameters import PARAMETERS, ToolParameters
from liver_sim.tool.scripts import IDENTITY_XYZW, ScriptedTrajectory, ScriptParameters, script_from
from msg_defs.device_map import device_map_message
from msg_defs.poses import pose_from_bytes, pose_stamped_bytes
from msg_defs.topics import TOPICS, loop_input_qos


class ToolNode(Node):
    """Publishes the tool pose from the chosen source."""

    def __init__(self):
        super().__init__("liver_tool")
        p = self.p = ToolParameters.from_values(declare_parameters(self, PARAMETERS))
        # every parameter is checked, whichever source uses it
        script = script_from(ScriptParameters.take(p))
        device_map = DeviceMap.from_parameters(p, p.workspace_radius_m)
        static_position = vector_parameter(p, "static_position_m", 3)
        static_orientation = quaternion_parameter(p, "static_orientation_xyzw")
        self._publisher = self.create_publisher(TOPICS["tool_pose"].type, p.tool_pose_topic,
                                                TOPICS["tool_pose"].qos)
        self._diagnostics = self.create_publisher(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                                  TOPICS["diagnostics"].qos)
        self._map_publisher = self.create_publisher(TOPICS["device_map"].type, p.device_map_topic,
                                                    TOPICS["device_map"].qos)
        self._map_publisher.publish(device_map_message(device_map))
        self._device_map = device_map
        self.published = 0
        self.rejected = 0
        self._device = self._inputs = None
        if p.source == "device":
            self._device, self._last_sample = Latest(), None
            self._inputs = LoopInputs(self)  # read by the loop at its rate, not by the executor per sample
            self._inputs.subscribe(TOPICS["measured_cp"].type, p.measured_cp_topic,
                                   loop_input_qos(TOPICS["measured_cp"]), self._device.set, raw=True, received=True)
            step = self._step_device
            origin = (f"device {p.measured_cp_topic} mapped by R={list(p.device_rotation_xyzw)}, "
                      f"t={list(p.device_translation_m)} m, scale {p.device_scale:g}")
        else:
            if p.source == "script":
                self._trajectory, self._orientation = script, IDENTITY_XYZW
                origin = (f"script '{p.script}' ({script.duration_s:g} s"
                          f"{', looped' if p.loop_script else ''}) anchored at {list(p.anchor_m)} m")
            else:
                self._trajectory = ScriptedTrajectory("static", np.zeros(1), static_position[np.newaxis])
                self._orientation = static_orientation
                origin = f"static {static_position.tolist()} m"
            self._start = None
            step = self._step
        self._loop = RateLoop(p.rate_hz, step, "liver_tool", realtime_priority=p.realtime_priority,
                              on_refused=warn(self))
        self.create_timer(1.0, self._publish_diagnostics)
        self._refuse = read_at_start("liver_tool", {"workspace_radius_m"})
        on_parameter_changes(self, PARAMETERS, self._apply)
        self.get_logger().info(f"liver_tool: {origin} → {p.tool_pose_topic} (frame {p.frame_id}, "
                               f"{p.rate_hz:g} Hz); device map latched on {p.device_map_topic}")
        self._loop.start()

    def close(self) -> None:
        self._loop.stop()
        if self._inputs is not None:
            self._inputs.destroy()

    def _apply(self, changes: dict) -> str | None:
        refused = self._refuse(changes)
        if refused is None:  # workspace_radius_m: the next device sample is checked against it
            self._device_map = replace(self._device_map, workspace_radius_m=changes["workspace_radius_m"])
            self.p = self.p.replace(**changes)
        return refused

    def _step_device(self, now: float) -> None:
        """Publish the newest device sample, mapped, once (none new: nothing)."""
        self._inputs.poll()
        data, _ = self._device.get()
        if data is None or data is self._last_sample:
            return
        self._last_sample = data
        try:
            position, orientation, stamp = pose_from_bytes(data)
            position, orientation = self._device_map.pose(position, orientation)
        except ValueError as exc:
            self.rejected += 1
            self.get_logger().warning(f"dropped device sample: {exc}", throttle_duration_sec=1.0)
            return
        self._publisher.publish(pose_stamped_bytes(position, orientation, stamp, self.p.frame_id))
        self.published += 1

    def _step(self, now: float) -> None:
        if self._start is None:
            self._start = now
        position = self._trajectory.position_at(now - self._start)
        self._publisher.publish(pose_stamped_bytes(position, self._orientation,
                                                   self.get_clock().now().to_msg(), self.p.frame_id))
        self.published += 1

    def _publish_diagnostics(self) -> None:
        extra = {"source": self.p.source, "published": self.published}
        if self._device is not None:
            extra["rejected_samples"] = self.rejected
            extra["sample_age_s"] = float(time.monotonic() - self._device.get()[1])
        publish_diagnostics(self, self._diagnostics,
                            [loop_status(loop_status_name(self), self._loop.report(), self.p.rate_hz, extra)])


def main(args=None) -> int:
    return run_node(ToolNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
