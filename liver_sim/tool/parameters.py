"""The `liver_tool` node's parameters (no ROS): where the tool pose comes from (device, script or static),
the script's settings and the device map: declared here, published latched for haptic_bridge."""
from liver_sim.base.geometry.device_map import DEVICE_MAP_PARAMETERS
from liver_sim.base.parameters import Param, parameter_record, realtime_priority_parameter
from liver_sim.base.topic_names import tool_topic
from liver_sim.tool.scripts import IDENTITY_XYZW, SCRIPT_PARAMETERS, ScriptSettings

_SCRIPT = ScriptSettings()
PARAMETERS = {
    "source": Param("device", "where the tool pose comes from: device, script or static",
                    choices=("device", "script", "static")),
    "rate_hz": Param(150.0, "publishing rate of the tool pose, whatever the source (Hz): the physics' rate, the "
                     "only consumer (source device: the newest device sample at each tick)", 1.0, 10000.0),
    "realtime_priority": realtime_priority_parameter(75),
    "frame_id": Param("liver", "frame of the published tool pose"),
    "tool_pose_topic": Param(tool_topic("tool_pose"), "tool tip pose out, liver frame (PoseStamped)"),
    "measured_cp_topic": Param(tool_topic("measured_cp"), "device stylus pose in, device frame (PoseStamped)"),
    "device_map_topic": Param(tool_topic("device_map"), "the device map out, latched, for haptic_bridge"),
    "workspace_radius_m": Param(0.5, "device samples farther than this from the device origin are dropped (m)",
                                0.01, 10.0),
    "static_position_m": Param([_SCRIPT.anchor_m[0], _SCRIPT.anchor_m[1],
                                _SCRIPT.anchor_m[2] + _SCRIPT.tool_radius_m + _SCRIPT.clearance_m],
                               "tool tip held by source=static, liver frame [x, y, z] (m)"),
    "static_orientation_xyzw": Param(list(IDENTITY_XYZW), "tool orientation held by source=static (x, y, z, w)"),
    **SCRIPT_PARAMETERS,
    **DEVICE_MAP_PARAMETERS,
}

#: The node's parameters as one typed record (liver_sim.base.parameters.parameter_record).
ToolParameters = parameter_record("ToolParameters", PARAMETERS, "The parameters of liver_tool (PARAMETERS).")
