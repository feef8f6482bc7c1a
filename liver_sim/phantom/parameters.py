"""The `phantom_sim` node's parameters (liver_sim.base.parameters.Param: default, unit, range), its stylus
defaults from StylusParams."""
from __future__ import annotations

from liver_sim.base.geometry.device_map import DEVICE_MAP_PARAMETERS
from liver_sim.base.parameters import Param, parameter_record, realtime_priority_parameter
from liver_sim.base.topic_names import FORCE_OUTPUT_FORMATS, tool_topic
from liver_sim.phantom.device import StylusParams
from liver_sim.tool.scripts import SCRIPT_PARAMETERS

_STYLUS = StylusParams()
#: Force formats a simulated device can take (OmniFeedback is another driver's own message).
FORCE_FORMATS = tuple(fmt for fmt in FORCE_OUTPUT_FORMATS if fmt != "omni_feedback")
#: The `phantom_sim` node's parameters.
PARAMETERS = {
    "rate_hz": Param(1000.0, "stylus integration and publishing rate (Hz)", 100.0, 10000.0),
    "realtime_priority": realtime_priority_parameter(80),
    "stylus_mass_kg": Param(_STYLUS.mass_kg, "effective stylus mass at the tip (kg)", 0.001, 10.0),
    "hand_stiffness_n_per_m": Param(_STYLUS.hand_stiffness_n_per_m, "virtual hand spring to the script (N/m)",
                                    1.0, 10000.0),
    "hand_damping_ns_per_m": Param(_STYLUS.hand_damping_ns_per_m, "virtual hand damping (N·s/m)", 0.0, 1000.0),
    "max_force_n": Param(_STYLUS.max_force_n, "commanded force clamp, as the device's (N)", 0.01,
                         _STYLUS.max_force_n),
    "workspace_half_m": Param(_STYLUS.workspace_half_m, "the stylus stays within ±this on each device axis (m)",
                              0.01, 2.0),
    "command_timeout_s": Param(0.05, "a force command older than this counts as zero (s)", 0.001, 10.0),
    "force_output": Param("wrench_stamped", f"format of the force commands: {', '.join(FORCE_FORMATS)}",
                          choices=FORCE_FORMATS),
    "frame_id": Param("phantom_base", "frame of the published stylus pose"),
    "measured_cp_topic": Param(tool_topic("measured_cp"), "stylus pose out, device frame (PoseStamped)"),
    "servo_cf_topic": Param(tool_topic("servo_cf"), "force command in, device frame"),
    "script_start_time_s": Param(0.0, "ROS time (s) at which the script's time 0 falls, so that several devices "
                                 "play theirs together; 0: the node's first tick (one started later starts it then)",
                                 0.0, 1e12),
    **SCRIPT_PARAMETERS,
    **DEVICE_MAP_PARAMETERS,
}

#: The node's parameters as one typed record (liver_sim.base.parameters.parameter_record).
PhantomParameters = parameter_record("PhantomParameters", PARAMETERS, "The parameters of phantom_sim (PARAMETERS).")
