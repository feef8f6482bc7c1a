"""Who may steer a running bridge, on real processes. The device map: only `device_map_node`'s is taken, judged by
each sample's own writer; a foreign map, good or bad, changes nothing, one published and withdrawn at once is never
taken; a new map from the tool applies through zero force with a soft start, a bad one zeroes the force until a good
one. The envelope: a managed bridge's lifecycle cannot loosen it. The device: a second bridge of the same name is
seen and both hold zero. The test side plays the physics and the tool (bridge_rig.Rig)."""
import signal
import sys
import time

import numpy as np
import rclpy
from std_msgs.msg import Float64MultiArray

from liver_sim.base.geometry.device_map import DeviceMap
from msg_defs.device_map import device_map_message
from msg_defs.topics import TOPICS

from bridge_rig import (
    ABOVE,
    CONTACT,
    HALF_TURN_X,
    INSIDE,
    LOOP,
    NEARLY_CONTACT_N,
    WAIT_S,
    assert_safe,
    fresh_loop_status,
    local_model,
    seconds_of,
    start_bridge,
    stop,
    terminate_to_zero,
)


class Intruder:
    """Another node, `intruder`, in its own context: it publishes device maps as liver_tool would (latched)."""

    def __init__(self):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("intruder", context=self.context)

    def publisher(self):
        return self.node.create_publisher(TOPICS["device_map"].type, TOPICS["device_map"].name,
                                          TOPICS["device_map"].qos)

    def close(self) -> None:
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def not_a_map() -> Float64MultiArray:
    """A message on the map topic that does not decode as a device map (no layout, three numbers)."""
    return Float64MultiArray(data=[1.0, 2.0, 3.0])


def test_an_equal_map_from_its_node_changes_nothing(rig_factory, ros_env):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        taken = int(fresh_loop_status(rig, bridge)["device_maps_taken"])
        for _ in range(10):  # a stall of the loop or inputs gone stale (a busy machine) restart the force: retry
            published = rig.node.get_clock().now().seconds_nanoseconds()
            rig.publish_map((0.0, 0.0, 0.0, 1.0))  # the same map again: nothing changes, no restart
            rig.wait_until(lambda: sum(stamp > published for stamp in rig.stamps[-600:]) >= 500, "commands", bridge)
            after = [f for f, stamp in zip(rig.forces, rig.stamps) if stamp > published]  # by stamps: this side lags
            if all(np.allclose(f, CONTACT, atol=1e-3) for f in after):
                break
            rig.wait_for_force(CONTACT, bridge)
        assert all(np.allclose(f, CONTACT, atol=1e-3) for f in after), "an equal map changes nothing"
        assert int(fresh_loop_status(rig, bridge)["device_maps_taken"]) == taken, "an equal map is not taken again"
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_maps_from_another_node_good_or_bad_change_nothing(rig_factory, ros_env):
    """A foreign map that would turn the force 180°, and one that does not decode, while the tool is in contact and
    while the intruder keeps publishing: both refused, the force unchanged, the map in use kept for the next press."""
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    intruder = Intruder()
    try:
        rig.wait_for_force(CONTACT, bridge)
        foreign = intruder.publisher()
        foreign.publish(device_map_message(DeviceMap(HALF_TURN_X)))
        rig.wait_until(lambda: int((rig.loop_status() or {}).get("bad_device_map", 0)) >= 1, "a refused map", bridge)
        foreign.publish(not_a_map())
        rig.wait_until(lambda: int(rig.loop_status()["bad_device_map"]) >= 2, "the bad map refused", bridge)
        rig.wait_for_force(CONTACT, bridge)
        rig.tool = ABOVE
        rig.wait_for_force(np.zeros(3), bridge)
        rig.tool = INSIDE  # the next press: the same map
        rig.wait_for_force(CONTACT, bridge)
        assert int(fresh_loop_status(rig, bridge)["device_maps_taken"]) == 1
    finally:
        stop(bridge)
        intruder.close()
    assert not any(float(f @ CONTACT) < 0.0 for f in rig.forces), "never turned against the surface"
    assert_safe(rig.forces)


def test_a_map_published_and_withdrawn_at_once_is_never_taken(rig_factory, ros_env):
    """The intruder publishes a 180° map transient local out of contact and destroys its publisher 50 ms later, so
    that no look at the topic's publishers finds it: the sample's own writer is judged, and refused."""
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), ABOVE
    bridge = start_bridge(ros_env)
    intruder = Intruder()
    try:
        rig.wait_until(lambda: (rig.loop_status() or {}).get("device_maps_taken") == "1", "the rig's map", bridge)
        foreign = intruder.publisher()
        foreign.publish(device_map_message(DeviceMap(HALF_TURN_X)))
        time.sleep(0.05)
        intruder.node.destroy_publisher(foreign)
        rig.spin_for(6.0)  # longer than a sample waits for its writer to be named
        rig.tool = INSIDE
        rig.wait_for_force(CONTACT, bridge)
        assert int(fresh_loop_status(rig, bridge)["device_maps_taken"]) == 1
    finally:
        stop(bridge)
        intruder.close()
    assert not any(float(f @ CONTACT) < 0.0 for f in rig.forces), "never turned against the surface"
    assert_safe(rig.forces)


def test_a_new_map_from_its_node_in_contact_applies_through_zero_with_a_soft_start(rig_factory, ros_env):
    """liver_tool restarted with another map while the hand rests on the tissue: the force ramps to zero, then the
    new map applies and the force rises again over the soft start; diagnostics count the map."""
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        before = len(rig.forces)
        rig.publish_map(HALF_TURN_X)  # from the map's own node, in contact
        rig.wait_for_force(-CONTACT, bridge)  # turned 180° about x: z flips
        assert int(fresh_loop_status(rig, bridge)["device_maps_taken"]) == 2
    finally:
        stop(bridge)
    forces, seconds = rig.forces[before:], [seconds_of(stamp) for stamp in rig.stamps[before:]]
    last_old = max(i for i, f in enumerate(forces) if float(f @ CONTACT) > 0.0)
    first_new = next(i for i, f in enumerate(forces) if float(f @ CONTACT) < 0.0)
    assert last_old < first_new and any(not f.any() for f in forces[last_old:first_new]), "through zero"
    full = next(i for i in range(first_new, len(forces)) if np.linalg.norm(forces[i]) > NEARLY_CONTACT_N)
    assert seconds[full] - seconds[first_new] >= 0.1, "soft start: 0.2 s from zero to full force"
    assert_safe(rig.forces)


def test_a_bad_map_from_its_node_zeroes_the_force_until_a_good_one(rig_factory, ros_env):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        rig._map.publish(not_a_map())
        rig.wait_for_force(np.zeros(3), bridge)
        rig.wait_until(lambda: "device map refused" in (rig.loop_level() or (0, ""))[1], "a diagnostic", bridge)
        assert rig.loop_level()[0] == 2
        rig.publish_map((0.0, 0.0, 0.0, 1.0))
        rig.wait_for_force(CONTACT, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_a_managed_bridges_envelope_is_the_one_its_process_started_with(rig_factory, ros_env):
    """deactivate → cleanup → loosen → configure → activate must not loosen anything: while unconfigured the
    parameters are checked against the envelope of the process's start, as a running bridge's are."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    def value(v):
        if isinstance(v, bool):
            return ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=v)
        if isinstance(v, str):
            return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=v)
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v)

    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env, [sys.executable, "-m", "liver_sim.nodes.bridge_node", "--managed"])
    change_state = rig.node.create_client(ChangeState, "/haptic_bridge/change_state")
    set_parameters = rig.node.create_client(SetParameters, "/haptic_bridge/set_parameters")

    def change(transition: int) -> None:
        assert rig.call(change_state, ChangeState.Request(transition=Transition(id=transition)), bridge).success

    def set_parameter(name, v):
        request = SetParameters.Request(parameters=[Parameter(name=name, value=value(v))])
        return rig.call(set_parameters, request, bridge).results[0]

    try:
        change(Transition.TRANSITION_CONFIGURE)
        change(Transition.TRANSITION_ACTIVATE)
        rig.wait_for_force(CONTACT, bridge)
        change(Transition.TRANSITION_DEACTIVATE)
        change(Transition.TRANSITION_CLEANUP)
        for name, looser in (("max_force_n", 3.3), ("stiffness_n_per_m", 1000.0), ("drives_device", False),
                             ("device_map_node", "/intruder"), ("device_damping_ns_per_m", 50.0)):
            result = set_parameter(name, looser)
            assert not result.successful, f"{name} loosened while unconfigured"
        assert set_parameter("max_force_n", 0.5).successful  # tightening is fine
        change(Transition.TRANSITION_CONFIGURE)
        change(Transition.TRANSITION_ACTIVATE)
        rig.wait_for_force(0.5 * CONTACT / np.linalg.norm(CONTACT), bridge)  # clamped at the tighter 0.5 N
        assert set_parameter("max_force_n", 2.0).successful  # back to the process's start, not beyond
        assert not set_parameter("max_force_n", 2.5).successful
        terminate_to_zero(rig, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_two_bridges_of_one_name_on_one_device_both_hold_zero(rig_factory, ros_env):
    """Two bridges started with the default name drive one device: each tells its own writers from the other's by
    their GIDs, names the other, and sends zero; when one stops the other drives again (soft start)."""
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    first = start_bridge(ros_env)
    second = None
    try:
        rig.wait_for_force(CONTACT, first)
        second = start_bridge(ros_env)
        rig.wait_for_force(np.zeros(3), first)
        rig.wait_until(lambda: sum("another publisher on /phantom/servo_cf (/haptic_bridge)" in
                                   status.message for array in rig.diagnostics[-10:] for status in array.status
                                   if status.name == LOOP) >= 2, "both bridges naming the other", first)
        second.send_signal(signal.SIGTERM)
        second.wait(timeout=WAIT_S)
        rig.wait_for_force(CONTACT, first)
    finally:
        stop(first)
        if second is not None:
            stop(second)
    assert_safe(rig.forces)
