"""What haptic_bridge takes its inputs from, as a real process: publishers with ROS's default QoS (reliable,
volatile) are rendered like the product's own, and a publisher's transient-local history is never taken as a
fresh input when the bridge (re)matches it; remapped inputs reach the loop."""
import sys

import numpy as np

from bridge_rig import ABOVE, EXPECTED_INSIDE, INSIDE, QUARTER_TURN_X, assert_safe, local_model, start_bridge, stop

#: ROS's default QoS for a publisher created with a depth only: reliable, volatile, keep last 10.
DEFAULT_QOS = 10


def test_a_local_model_and_pose_from_default_qos_publishers_are_rendered(rig_factory, ros_env):
    rig = rig_factory(rotation_xyzw=QUARTER_TURN_X, input_qos=DEFAULT_QOS)
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(EXPECTED_INSIDE, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_an_old_local_model_kept_by_its_publisher_is_not_rendered_when_the_bridge_matches(rig_factory, ros_env):
    """The physics' publisher keeps 5 s of local models, transient local, for a recorder; a bridge that matches it
    after the physics went quiet must render nothing from them (received now, they would look fresh)."""
    rig = rig_factory(rotation_xyzw=QUARTER_TURN_X)  # the contract's QoS: reliable, transient local
    rig.model, rig.tool = local_model("plane"), ABOVE
    rig.spin_for(0.3)       # local models in contact... with the tool out of contact: kept in the history
    rig.model = None        # the physics goes quiet; its history stays
    rig.tool = INSIDE       # the tool now inside the surface those models describe
    bridge = start_bridge(ros_env)
    try:
        rig.wait_until(lambda: len(rig.forces) > 1000, "a second of force commands", bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)
    assert not np.array(rig.forces).any(), "a force was rendered from a local model sent before the bridge ran"


def test_remapped_inputs_reach_the_loop(rig_factory, ros_env):
    rig = rig_factory(rotation_xyzw=QUARTER_TURN_X,
                      names={"measured_cp": "/rig/measured_cp", "contact_plane": "/rig/contact_plane"})
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env, [sys.executable, "-m", "liver_sim.nodes.bridge_node", "--ros-args",
                                    "-r", "/phantom/measured_cp:=/rig/measured_cp",
                                    "-r", "/liver/contact_plane:=/rig/contact_plane", "--"])
    try:
        rig.wait_for_force(EXPECTED_INSIDE, bridge)  # the loop's own subscriptions took the remaps
    finally:
        stop(bridge)
    assert_safe(rig.forces)
