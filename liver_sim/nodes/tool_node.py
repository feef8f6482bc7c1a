"""`liver_tool`: publishes the tool tip on /tool/pose (frame `liver`) from the device, a script, or held still.

- source=device: every /phantom/measured_cp sample is mapped device→liver and republished at once
  with the sample's stamp; implausible samples (NaN, beyond `workspace_radius_m`) are counted,
  logged (throttled) and dropped;
- source=script: a RateLoop at `rate_hz` plays a `liver_sim.tool_scripts` script;
- source=static: a RateLoop at `rate_hz` holds `static_position_m`, `static_orientation_xyzw`.

The script and device-map parameters are shared with `phantom_sim` (SCRIPT_PARAMETERS,
DEVICE_MAP_PARAMETERS), so both nodes can be given the same values.
"""
from __future__ import annotations

import time

import numpy as np
from rclpy.node import Node

from haptic_bridge.local_model import FrameMap
from liver_sim.nodes.common import (LoopStats, RateLoop, apply_realtime_priority, declare_parameters,
                                    diagnostic_status, publish_diagnostics, run_node)
from liver_sim.parameters import Param, realtime_priority_parameter
from liver_sim.phantom import DeviceToLiver
from liver_sim.tool_scripts import SCRIPT_NAMES, ScriptedTrajectory, ScriptSettings, make_script
from msg_defs import conversions
from msg_defs.topics import TOPICS

SCRIPT = ScriptSettings()
#: Orientation of a scripted tool: the liver frame's.
IDENTITY_XYZW = (0.0, 0.0, 0.0, 1.0)
#: Durations (s) a script segment may last.
_SEGMENT_S = (0.0, 3600.0)

SCRIPT_PARAMETERS = {
    "script": Param("press_slide_release", f"scripted tool-tip trajectory: {', '.join(SCRIPT_NAMES)}",
                    choices=SCRIPT_NAMES),
    "anchor_m": Param(list(SCRIPT.anchor_m), "rest-surface point the script presses on, liver frame [x, y, z] (m); "
                      "default: the default liver's dome"),
    "tool_radius_m": Param(SCRIPT.tool_radius_m, "radius of the tool sphere centred on the tip (m)", 0.0, 0.2),
    "depth_m": Param(SCRIPT.depth_m, "press depth of the tool below the rest surface (m)", 0.0, 0.2),
    "clearance_m": Param(SCRIPT.clearance_m, "gap between tool and rest surface when up (m)", 0.0, 0.5),
    "slide_m": Param(SCRIPT.slide_m, "slide length along +x at depth (m)", 0.0, 0.5),
    "pull_m": Param(SCRIPT.pull_m, "pull length back along +z after the hold, script pull (m)", 0.0, 0.5),
    "start_delay_s": Param(SCRIPT.start_delay_s, "wait at the start point before the script (s)", *_SEGMENT_S),
    "approach_s": Param(SCRIPT.approach_s, "clearance → contact (s)", *_SEGMENT_S),
    "press_s": Param(SCRIPT.press_s, "contact → depth (s)", *_SEGMENT_S),
    "hold_s": Param(SCRIPT.hold_s, "hold at depth (s)", *_SEGMENT_S),
    "slide_s": Param(SCRIPT.slide_s, "each slide along x, or the pull (s)", *_SEGMENT_S),
    "withdraw_s": Param(SCRIPT.withdraw_s, "depth → clearance (s)", *_SEGMENT_S),
    "rest_s": Param(SCRIPT.rest_s, "rest at clearance after the release (s)", *_SEGMENT_S),
    "loop_script": Param(False, "repeat the script (press_release, slide, press_slide_release, hold)"),
}

DEVICE_MAP_PARAMETERS = {
    "device_rotation_xyzw": Param([0.0, 0.0, 0.0, 1.0], "device→liver rotation R as a quaternion (x, y, z, w): "
                                  "p_liver = device_scale·R·p_device + device_translation_m"),
    "device_translation_m": Param([0.0, 0.0, 0.0], "liver-frame position of the device origin (m)"),
    "device_scale": Param(1.0, "liver motion per device motion (dimensionless)", 0.01, 100.0),
}

PARAMETERS = {
    "source": Param("device", "where the tool pose comes from: device, script or static",
                    choices=("device", "script", "static")),
    "rate_hz": Param(1000.0, "publishing rate for script and static; expected device rate for diagnostics (Hz)",
                     1.0, 10000.0),
    "realtime_priority": realtime_priority_parameter(75),
    "frame_id": Param("liver", "frame of the published tool pose"),
    "tool_pose_topic": Param(TOPICS["tool_pose"].name, "tool tip pose out, liver frame (PoseStamped)"),
    "measured_cp_topic": Param(TOPICS["measured_cp"].name, "device stylus pose in, device frame (PoseStamped)"),
    "workspace_radius_m": Param(0.5, "device samples farther than this from the device origin are dropped (m)",
                                0.01, 10.0),
    "static_position_m": Param([SCRIPT.anchor_m[0], SCRIPT.anchor_m[1],
                                SCRIPT.anchor_m[2] + SCRIPT.tool_radius_m + SCRIPT.clearance_m],
                               "tool tip held by source=static, liver frame [x, y, z] (m)"),
    "static_orientation_xyzw": Param(list(IDENTITY_XYZW), "tool orientation held by source=static (x, y, z, w)"),
    **SCRIPT_PARAMETERS,
    **DEVICE_MAP_PARAMETERS,
}


def vector_parameter(values: dict, name: str, length: int) -> np.ndarray:
    """Parameter `name` as a finite float array of `length`, or ValueError naming it."""
    vector = np.asarray(values[name], dtype=np.float64)
    if vector.shape != (length,) or not np.isfinite(vector).all():
        raise ValueError(f"parameter {name} must be {length} finite numbers, got {values[name]!r}")
    return vector


def quaternion_parameter(values: dict, name: str) -> np.ndarray:
    """Parameter `name` as a finite, non-zero (x, y, z, w) quaternion, or ValueError naming it."""
    quaternion = vector_parameter(values, name, 4)
    if not np.linalg.norm(quaternion) > 0.0:
        raise ValueError(f"parameter {name} must be a non-zero quaternion (x, y, z, w), got {values[name]!r}")
    return quaternion


def script_from(values: dict) -> ScriptedTrajectory:
    """The script named by the SCRIPT_PARAMETERS values."""
    settings = ScriptSettings(
        anchor_m=tuple(vector_parameter(values, "anchor_m", 3)), loop=values["loop_script"],
        **{name: values[name] for name in ("tool_radius_m", "depth_m", "clearance_m", "slide_m", "pull_m",
                                           "start_delay_s", "approach_s", "press_s", "hold_s", "slide_s",
                                           "withdraw_s", "rest_s")})
    return make_script(values["script"], settings)


def frame_map_from(values: dict) -> FrameMap:
    """The device→liver FrameMap named by the DEVICE_MAP_PARAMETERS values."""
    return FrameMap(quaternion_parameter(values, "device_rotation_xyzw"),
                    vector_parameter(values, "device_translation_m", 3), values["device_scale"])


def loop_status(name: str, stats: dict, rate_hz: float, extra: dict):
    """A node loop's DiagnosticStatus: OK while it achieves 90 % of `rate_hz` (Hz)."""
    ok = stats["rate_hz"] >= 0.9 * rate_hz
    return diagnostic_status(name, stats, ok, "ok" if ok else f"below {rate_hz:g} Hz", extra)


class ToolNode(Node):
    """Publishes the tool pose from the chosen source."""

    def __init__(self):
        super().__init__("liver_tool")
        p = self.p = declare_parameters(self, PARAMETERS)
        # every parameter is checked, whichever source uses it
        script, frame_map = script_from(p), frame_map_from(p)
        static_position = vector_parameter(p, "static_position_m", 3)
        static_orientation = quaternion_parameter(p, "static_orientation_xyzw")
        self._publisher = self.create_publisher(TOPICS["tool_pose"].type, p["tool_pose_topic"],
                                                TOPICS["tool_pose"].qos)
        self._diagnostics = self.create_publisher(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                                  TOPICS["diagnostics"].qos)
        self.published = 0
        self.rejected = 0
        self._loop = None
        if p["source"] == "device":
            self._device = DeviceToLiver(frame_map, p["workspace_radius_m"])
            self._arrivals = LoopStats(1.0 / p["rate_hz"])
            self._last_arrival = None
            self.create_subscription(TOPICS["measured_cp"].type, p["measured_cp_topic"], self._on_device,
                                     TOPICS["measured_cp"].qos, raw=True)
            origin = (f"device {p['measured_cp_topic']} mapped by R={list(p['device_rotation_xyzw'])}, "
                      f"t={list(p['device_translation_m'])} m, scale {p['device_scale']:g}")
        else:
            if p["source"] == "script":
                self._trajectory, self._orientation = script, IDENTITY_XYZW
                origin = (f"script '{p['script']}' ({script.duration_s:g} s"
                          f"{', looped' if p['loop_script'] else ''}) anchored at {list(p['anchor_m'])} m")
            else:
                self._trajectory = ScriptedTrajectory("static", np.zeros(1), static_position[np.newaxis])
                self._orientation = static_orientation
                origin = f"static {static_position.tolist()} m"
            self._start = None
            self._loop = RateLoop(p["rate_hz"], self._step, "liver_tool")
        self.create_timer(1.0, self._publish_diagnostics)
        rate = "as the device" if self._loop is None else f"{p['rate_hz']:g} Hz"
        self.get_logger().info(f"liver_tool: {origin} → {p['tool_pose_topic']} (frame {p['frame_id']}, {rate})")
        apply_realtime_priority(self, p["realtime_priority"])  # before the loop starts: it inherits it
        if self._loop is not None:
            self._loop.start()

    def close(self) -> None:
        if self._loop is not None:
            self._loop.stop()

    def _on_device(self, data: bytes) -> None:
        now = time.monotonic()
        if self._last_arrival is not None:
            gap = now - self._last_arrival
            self._arrivals.record(gap, gap > 2.0 * self._arrivals.period_s)
        self._last_arrival = now
        try:
            position, orientation, stamp = conversions.pose_from_bytes(data)
            position, orientation = self._device.pose(position, orientation)
        except ValueError as exc:
            self.rejected += 1
            self.get_logger().warning(f"dropped device sample: {exc}", throttle_duration_sec=1.0)
            return
        self._publisher.publish(conversions.pose_stamped_bytes(position, orientation, stamp, self.p["frame_id"]))
        self.published += 1

    def _step(self, now: float) -> None:
        if self._start is None:
            self._start = now
        position = self._trajectory.position_at(now - self._start)
        self._publisher.publish(conversions.pose_stamped_bytes(position, self._orientation,
                                                               self.get_clock().now().to_msg(), self.p["frame_id"]))
        self.published += 1

    def _publish_diagnostics(self) -> None:
        extra = {"source": self.p["source"], "published": self.published}
        if self._loop is None:
            stats = self._arrivals.summary()
            extra["rejected_samples"] = self.rejected
            extra["sample_age_s"] = (float(time.monotonic() - self._last_arrival) if self._last_arrival is not None
                                     else float("inf"))
        else:
            stats = self._loop.stats.summary()
        publish_diagnostics(self, self._diagnostics,
                            [loop_status(f"{self.get_name()}: loop", stats, self.p["rate_hz"], extra)])


def main(args=None) -> int:
    return run_node(ToolNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
