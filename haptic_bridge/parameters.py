"""The haptic bridge's parameters (no ROS): declared by the `haptic_bridge` node, read by BridgeTick and by
the offline sessions (liver_sim.sessions), so both refuse the same values. Topic names and the device's and the
map's source nodes are relative: a bridge started in a namespace (`__ns:=/left`) takes them there, one in the root
namespace today's. The model's source is absolute (`/liver_physics`): one physics node serves every bridge.

The device map is not among them: the bridge takes the one `liver_tool` publishes on device_map_topic
(latched), so the map that places the tool and the map that turns the force can never differ."""
from haptic_bridge.safety import DEFAULT_MAX_FORCE_N, PHANTOM_MAX_FORCE_N
from liver_sim.base.emulated_link import LINK_PARAMETERS
from liver_sim.base.parameters import Param, parameter_record, realtime_priority_parameter
from liver_sim.base.topic_names import FORCE_OUTPUT_FORMATS, tool_topic

MODES = ("plane", "sphere", "none")
PARAMETERS = {
    "rate_hz": Param(1000.0, "haptic loop rate (Hz); its period is the T of the passivity bound", 50.0, 5000.0),
    "realtime_priority": realtime_priority_parameter(80),
    "local_model": Param("plane", "plane or sphere: render the local model on local_model_topic (the marker's "
                         "kind decides: CUBE plane, SPHERE sphere); none: hold the physics contact wrench "
                         "(Fig. 8 baseline)", choices=MODES),
    "stiffness_n_per_m": Param(190.0, "local-model stiffness K (N/m of penetration in the liver frame), the cap "
                               "on the tissue's own K a marker carries; K·device_scale must stay below "
                               "2·(device_damping_ns_per_m − damping_ns_per_m·device_scale)/T (Colgate), T the "
                               "longer of 1/rate_hz and stall_bound_s", 0.0, 10000.0),
    "model_glide_s": Param(round(1.0 / 150.0, 4), "time over which a new local model replaces the rendered one "
                           "(s): the surface glides to its new place instead of jumping at each physics update; "
                           "about one physics period; 0: at once", 0.0, 0.1),
    "damping_ns_per_m": Param(0.0, "local-model damping B on the penetration rate (N·s/m), added to the local "
                              "model's force; 0 by default: the physics force the local model carries already "
                              "holds Eq. 3's damping, so any B makes the rendered force differ from it at each "
                              "update", 0.0, 10.0),
    "passive_model_update": Param("auto", "render each new local model only as far as the energy it puts into "
                                  "the contact was taken out by earlier updates (haptic_bridge.rendering."
                                  "PassiveModelUpdate), so that a delayed model never gives the hand more than it "
                                  "put in; the rendered force then lags the physics force where it would. always, "
                                  "never, or auto: when the inputs come over an emulated link (link_delay_s, "
                                  "link_jitter_s or link_loss_fraction set; over a real link, declare always); "
                                  "read at start", choices=("auto", "always", "never")),
    "passivity_control": Param(False, "time-domain passivity controller (Hannaford and Ryu; "
                               "haptic_bridge.passivity): when the current contact has given the hand more energy "
                               "than the hand put in, damp the stylus's measured motion until it is taken out; "
                               "read at start"),
    "passivity_max_damping_ns_per_m": Param(20.0, "the controller's largest damping (N·s/m, device frame); read "
                                            "at start", 0.0, 100.0),
    "device_damping_ns_per_m": Param(0.5, "physical damping b of the device at the stylus (N·s/m), for the "
                                     "passivity check b > K·T/2 + B; PHANToM-like default, identify yours",
                                     0.0, 100.0),
    "depth_rate_cutoff_hz": Param(50.0, "one-pole low-pass on the finite-difference penetration rate (Hz); "
                                  "0: unfiltered", 0.0, 500.0),
    "tool_radius_m": Param(0.015, "radius of the tool tip sphere (m); same as the physics tool", 0.0, 0.2),
    "max_force_n": Param(DEFAULT_MAX_FORCE_N, f"force clamp by norm (N), at most {PHANTOM_MAX_FORCE_N} N "
                         "(PHANToM peak)", 0.01, PHANTOM_MAX_FORCE_N),
    "max_force_rate_n_per_s": Param(400.0, "largest change of the commanded force (N/s); at least "
                                    "max_force_n/ramp_time_s", 1.0, 100000.0),
    "lifetime_s": Param(0.05, "age (s) since reception beyond which the tool pose, the physics wrench or a "
                        "local model is stale (a marker's own lifetime may only shorten it)", 0.001, 10.0),
    "ramp_time_s": Param(0.01, "time (s) for the watchdog to ramp the force to zero on stale data", 0.001, 0.01),
    "soft_start_s": Param(0.2, "time (s) over which the force rises from zero after start and after every "
                          "recovery (fresh data again, a stall or error of the loop, a new device map)", 0.1, 10.0),
    "stall_bound_s": Param(0.005, "the supervisor publishes zero when the loop has not ticked for this long (s) "
                           "and holds it until the loop is back; the T of the passivity bound when longer than a "
                           "period", 0.002, 0.1),
    "workspace_centre_m": Param([0.0, 0.0, 0.0], "centre of the plausible workspace around the liver (m, liver "
                                "frame)"),
    "workspace_radius_m": Param(0.4, "a tool tip, plane point or sphere centre farther than this from "
                                "workspace_centre_m is refused as implausible (m)", 0.01, 10.0),
    "contact_stiffness_n_per_m": Param(300.0, "liver_physics' contact_stiffness_n_per_m: the stiffness rendered "
                                       "with local_model none, for its passivity check", 0.0, 1e6),
    "contact_damping_ns_per_m": Param(1.0, "liver_physics' contact_damping_ns_per_m: the damping rendered with "
                                      "local_model none, for its passivity check", 0.0, 1e4),
    "physics_rate_hz": Param(150.0, "liver_physics' rate_hz: with local_model none the force is held for a "
                             "physics period, the T of its passivity check", 1.0, 5000.0),
    "drives_device": Param(True, "false: force_topic drives no device (a comparison bridge); a rendering that "
                           "is not passive is then reported, not refused"),
    "device_map_topic": Param(tool_topic("device_map"), "the device map liver_tool publishes (latched); no "
                              "force is rendered before it arrives"),
    "device_map_node": Param("liver_tool", "the only node whose device map the bridge takes: maps on "
                             "device_map_topic from any other node are refused; a relative name is the node of that "
                             "name in the bridge's own namespace (/left/liver_tool for a bridge in /left)"),
    "model_node": Param("/liver_physics", "the only node whose local model (or, with local_model none, contact "
                        "wrench) the bridge takes, judged by each sample's writer; a relative name is the node of that "
                        "name in the bridge's own namespace; read at start"),
    "device_node": Param("phantom_sim", "the only node whose stylus samples on measured_cp_topic the bridge takes "
                         "(the device's driver: set it to your driver's node name), judged by each sample's writer; a "
                         "relative name is the node of that name in the bridge's own namespace (/left/phantom_sim for "
                         "a bridge in /left); read at start"),
    "stamp_lead_tolerance_s": Param(0.05, "a stylus sample stamped more than this (s) ahead of the bridge's clock is "
                                    "refused (a device clock ahead of this host's, or a bad stamp); read at start",
                                    0.001, 10.0),
    "force_output": Param("wrench_stamped", "message type of the force command", choices=FORCE_OUTPUT_FORMATS),
    "force_topic": Param(tool_topic("servo_cf"), "force command to the device driver"),
    "measured_cp_topic": Param(tool_topic("measured_cp"), "the device's stylus pose, device frame (PoseStamped, "
                               "CRTK measured_cp): the loop's 1 kHz input, placed in the liver frame with the device "
                               "map"),
    "local_model_topic": Param(tool_topic("contact_plane"), "local model from the physics (Marker)"),
    "tool_wrench_topic": Param(tool_topic("tool_wrench"), "physics contact force on the tool, liver frame "
                               "(WrenchStamped); rendered with local_model: none"),
    "device_frame_id": Param("phantom_base", "frame_id of the force command"),
    **LINK_PARAMETERS,  # on the inputs from the other side of a teleoperation link
}

#: The bridge's parameters as one typed record (liver_sim.base.parameters.parameter_record): a wrong name fails where
#: the values are read, not in the 1 kHz tick.
BridgeParameters = parameter_record("BridgeParameters", PARAMETERS, "The parameters of haptic_bridge (PARAMETERS).")
