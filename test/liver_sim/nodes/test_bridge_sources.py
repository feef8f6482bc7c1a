"""Every input of the force loop from its one named source, on real processes (docs/haptic-safety.md, "Who may
steer the force"): a device that reports nonsense or stamps the future is a device that reports nothing; a rival
model, a second node bearing the source's name, a flood of foreign maps and a burst on the force topic steer nothing
and are reported; K·scale is checked at every change of a managed bridge. The test side plays the physics, the tool
and the device (bridge_rig.Rig, node /test_haptic_bridge, every input's source); peers are other nodes in contexts of
their own."""
import sys
import threading
import time

import numpy as np
import rclpy

from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.local_model import LocalModel
from msg_defs.device_map import device_map_message
from msg_defs.forces import force_message_type, wrench_stamped
from msg_defs.local_model import local_model_marker
from msg_defs.topics import TOPICS

from bridge_rig import (
    CONTACT,
    HALF_TURN_X,
    INSIDE,
    NEARLY_CONTACT_N,
    STIFFNESS_N_PER_M,
    WAIT_S,
    assert_safe,
    fresh_loop_status,
    local_model,
    seconds_of,
    start_bridge,
    stop,
)

#: A device pose 50 m from the liver: an encoder glitch or a driver's bug.
FAR_AWAY = np.array([50.0, 0.0, 0.0])
#: A plane through the origin with its normal along +x: a rival's model that would push the tool sideways.
SIDEWAYS = LocalModel("plane", True, np.zeros(3), np.array([1.0, 0.0, 0.0]), np.zeros(3), 0.0, 0.0, True)


class Peer:
    """Another node, `name`, in its own context, that publishes on the bridge's topics, now or from a thread every
    `period_s`."""

    def __init__(self, name: str):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self._stop = threading.Event()
        self._threads = []

    def publisher(self, key: str, msg_type=None):
        return self.node.create_publisher(msg_type or TOPICS[key].type, TOPICS[key].name, TOPICS[key].qos)

    def repeat(self, publish, period_s: float) -> None:
        """Call `publish()` every `period_s` until close."""
        def run():
            while not self._stop.wait(period_s):
                publish()
        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        self._threads.append(thread)

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def stamp_now(node):
    return node.get_clock().now().to_msg()


def soft_start_after(rig, since: int) -> float:
    """Seconds (by the commands' stamps) from the first non-zero command after index `since` to the first near full
    contact force."""
    forces, stamps = rig.forces[since:], rig.stamps[since:]
    first = next(i for i, f in enumerate(forces) if f.any())
    full = next(i for i in range(first, len(forces)) if np.linalg.norm(forces[i]) > NEARLY_CONTACT_N)
    return seconds_of(stamps[full]) - seconds_of(stamps[first])


def test_a_device_pose_50_m_away_for_a_second_counts_as_no_pose(rig_factory, ros_env):
    """An implausible sample is no sample: the watchdog ramps the force to zero and holds it there for the second the
    device reports nonsense; plausible samples bring it back with a soft start."""
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        rig.tool = FAR_AWAY
        rig.wait_for_force(np.zeros(3), bridge)
        first_zero = len(rig.forces) - 20
        rig.spin_for(1.0)  # the device keeps reporting 50 m for a second
        assert not any(f.any() for f in rig.forces[first_zero:]), "zero for as long as the device reports nonsense"
        assert int(fresh_loop_status(rig, bridge)["bad_device_pose"]) > 0
        back = len(rig.forces)
        rig.tool = INSIDE
        rig.wait_for_force(CONTACT, bridge)
        assert soft_start_after(rig, back) >= 0.1, "a soft start once plausible samples return"
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_device_poses_stamped_in_the_future_are_refused_and_counted(rig_factory, ros_env):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        rig.pose_lead_s = 1.0  # a second ahead of the clock, beyond stamp_lead_tolerance_s
        rig.wait_for_force(np.zeros(3), bridge)
        rig.wait_until(lambda: int((rig.loop_status() or {}).get("bad_device_pose", 0)) > 0, "the samples counted",
                       bridge)
        rig.pose_lead_s = 0.0
        rig.wait_for_force(CONTACT, bridge)  # and the observer was not frozen by them: the force renders again
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_a_rival_plane_from_another_node_never_turns_the_force(rig_factory, ros_env):
    """During contact a node that is not model_node publishes a plane normal to +x, 50 times a second for 2 s: every
    command keeps the direction of the genuine contact, and diagnostics name the rival."""
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    rival = Peer("ceo_rival_physics")
    try:
        rig.wait_for_force(CONTACT, bridge)
        before = len(rig.forces)
        planes = rival.publisher("contact_plane")
        rival.repeat(lambda: planes.publish(local_model_marker(SIDEWAYS, stamp_now(rival.node), "liver", 0.05)), 0.02)
        rig.spin_for(2.0)
        rig.wait_until(lambda: "ceo_rival_physics" in (rig.loop_level() or (0, ""))[1], "the rival named", bridge)
        assert int(rig.loop_status()["refused_source"]) > 0
        rig.wait_for_force(CONTACT, bridge)
        window = np.array(rig.forces[before:])
        turned = window[np.linalg.norm(window, axis=1) > 0.0]
        cosines = turned @ CONTACT / (np.linalg.norm(turned, axis=1) * np.linalg.norm(CONTACT))
        assert cosines.min() > np.cos(np.radians(1.0)), f"turned by {np.degrees(np.arccos(cosines.min())):.1f}°"
    finally:
        stop(bridge)
        rival.close()
    assert_safe(rig.forces)


def test_two_nodes_bearing_the_sources_name_hold_zero_until_one_leaves(rig_factory, ros_env):
    """A second node named like the source of every input (a second physics with another liver, a spoofed
    liver_tool with a 180° map, a second device): nothing is taken from either while both are in the graph, the
    force goes to zero and diagnostics say so; once the newcomer leaves, the pinned source drives again with a soft
    start, never turned against the surface."""
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    twin = None
    try:
        rig.wait_for_force(CONTACT, bridge)
        twin = Peer("test_haptic_bridge")
        twin.publisher("device_map").publish(device_map_message(DeviceMap(HALF_TURN_X)))
        planes = twin.publisher("contact_plane")
        twin.repeat(lambda: planes.publish(local_model_marker(SIDEWAYS, stamp_now(twin.node), "liver", 0.05)), 0.007)
        rig.wait_for_force(np.zeros(3), bridge)
        rig.wait_until(lambda: "two nodes named /test_haptic_bridge" in (rig.loop_level() or (0, ""))[1],
                       "the ambiguity in diagnostics", bridge)
        assert rig.loop_level()[0] == 2
        back = len(rig.forces)
        twin.close()
        twin = None
        rig.wait_for_force(CONTACT, bridge)
        assert soft_start_after(rig, back) >= 0.1
    finally:
        stop(bridge)
        if twin is not None:
            twin.close()
    assert not any(float(f @ CONTACT) < 0.0 for f in rig.forces), "never turned against the surface"
    assert_safe(rig.forces)


def test_a_map_flood_from_before_the_bridge_starts_does_not_displace_the_genuine_map(rig_factory, ros_env):
    """A foreign node publishes 180° maps at about 1 kHz from before the bridge starts: the bridge still takes the
    source's one latched map, renders with it, and takes no other."""
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    flooder = Peer("map_flooder")
    maps = flooder.publisher("device_map")
    half_turn = device_map_message(DeviceMap(HALF_TURN_X))
    flooder.repeat(lambda: maps.publish(half_turn), 0.001)
    rig.spin_for(0.5)
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        # the flooder's writer is matched on its own time: wait until its maps reach the bridge and are refused
        rig.wait_until(lambda: int((rig.loop_status() or {}).get("refused_device_map", 0)) > 0,
                       "the flood's maps refused", bridge)
        rig.wait_for_force(CONTACT, bridge)
        assert int(fresh_loop_status(rig, bridge)["device_maps_taken"]) == 1
    finally:
        stop(bridge)
        flooder.close()
    assert not any(float(f @ CONTACT) < 0.0 for f in rig.forces), "never turned against the surface"
    assert_safe(rig.forces)


def test_a_40_ms_burst_of_commands_from_another_writer_is_reported(rig_factory, ros_env):
    """A writer that sends 50 commands in 40 ms on the bridge's force topic and leaves, between two looks at the
    graph: the bridge reads its samples back by their writer GIDs and reports them (ERROR)."""
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    peer = Peer("burst_writer")
    try:
        rig.wait_for_force(CONTACT, bridge)
        commands = peer.publisher("servo_cf", force_message_type("wrench_stamped"))
        # matched by the device (the rig) and the bridge's read-back before it sends
        rig.wait_until(lambda: commands.get_subscription_count() >= 2, "the burst writer matched", bridge)
        for _ in range(50):
            commands.publish(wrench_stamped(np.zeros(3), stamp_now(peer.node), "phantom_base"))
            time.sleep(0.0008)  # the burst's own pace: 50 commands in 40 ms
        peer.node.destroy_publisher(commands)
        rig.wait_until(lambda: "commands of another writer" in (rig.loop_level() or (0, ""))[1], "the burst reported",
                       bridge)
        level, message = rig.loop_level()
        assert level == 2 and ("burst_writer" in message or "gone before the graph named it" in message), message
    finally:
        stop(bridge)
        peer.close()
    assert_safe(rig.forces)


def test_a_managed_bridge_checks_k_times_scale_before_its_first_activation(rig_factory, ros_env):
    """Configured, not yet active: lower K, a scale-2 map arrives, raise K again. The raise is checked with the
    map's scale (K·2 above the passive limit) and refused; activated, the bridge renders the lower K."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env, [sys.executable, "-m", "liver_sim.nodes.bridge_node", "--managed"])
    change_state = rig.node.create_client(ChangeState, "/haptic_bridge/change_state")
    set_parameters = rig.node.create_client(SetParameters, "/haptic_bridge/set_parameters")

    def stiffness(k: float):
        value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=k)
        request = SetParameters.Request(parameters=[Parameter(name="stiffness_n_per_m", value=value)])
        return rig.call(set_parameters, request, bridge).results[0]

    low = 90.0  # K·2 = 180 N/m: passive below 200 N/m
    try:
        assert rig.call(change_state, ChangeState.Request(
            transition=Transition(id=Transition.TRANSITION_CONFIGURE)), bridge).success
        deadline = time.monotonic() + WAIT_S
        while True:  # until the scale-2 map has reached the bridge: then the raise is refused
            assert stiffness(low).successful
            rig.publish_map((0.0, 0.0, 0.0, 1.0), scale=2.0)
            rig.spin_for(0.3)
            raised = stiffness(STIFFNESS_N_PER_M)
            if not raised.successful:
                break
            assert time.monotonic() < deadline, "raising K was never checked with the scale-2 map"
        assert "device scale 2" in raised.reason, raised.reason
        assert rig.call(change_state, ChangeState.Request(
            transition=Transition(id=Transition.TRANSITION_ACTIVATE)), bridge).success
        rig.wait_for_force(CONTACT * low / STIFFNESS_N_PER_M, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_a_1_mb_local_model_from_its_source_is_refused_and_the_force_goes_on(rig_factory, ros_env):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        marker = local_model_marker(local_model("plane"), stamp_now(rig.node), "liver", 0.05)
        marker.text = "x" * 1_000_000  # 20 MB samples are lost whole by a best-effort reader: never delivered
        sent = [0.0]

        def refused() -> bool:  # best effort: a sample whose fragments did not all arrive is sent again
            if time.monotonic() - sent[0] > 0.5:
                rig._publishers["contact_plane"].publish(marker)
                sent[0] = time.monotonic()
            return int((rig.loop_status() or {}).get("bad_local_model", 0)) >= 1

        rig.wait_until(refused, "the message refused", bridge)
        rig.wait_for_force(CONTACT, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)
