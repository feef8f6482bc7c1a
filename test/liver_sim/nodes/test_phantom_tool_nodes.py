"""phantom_sim and liver_tool as real processes, talked to over DDS on loopback in a domain of their own.

Every wait is bounded; nothing asserts on timing. Processes are stopped (SIGINT, then SIGKILL) in `finally`.
"""
import math
import subprocess

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from node_processes import WAIT_S, Ros, command, start, statuses, stop

from msg_defs.device_map import device_map_from_message
from msg_defs.forces import force_message, force_message_type
from msg_defs.poses import pose_to_arrays
from msg_defs.stamps import seconds_from_stamp, stamp_from_seconds
from msg_defs.topics import TOPICS

#: A short script anchored at the origin: up at z = 0.025, contact at 0.015, deep at 0.005 (m).
SHORT_SCRIPT = {"anchor_m": [0.0, 0.0, 0.0], "tool_radius_m": 0.015, "depth_m": 0.01, "clearance_m": 0.01,
                "approach_s": 0.2, "press_s": 0.3, "hold_s": 0.3, "withdraw_s": 0.2, "rest_s": 0.3,
                "script": "press_release", "loop_script": True}
UP_Z, DEEP_Z = 0.025, 0.005
QUARTER_TURN_Z = [0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]


@pytest.fixture
def ros(ros_domain_id):
    session = Ros("test_phantom_tool")
    try:
        yield session
    finally:
        session.close()


def positions(messages) -> np.ndarray:
    return np.array([pose_to_arrays(m.pose)[0] for m in messages]).reshape(-1, 3)


def test_phantom_sim_plays_its_script(ros, ros_env):
    poses = ros.collect("measured_cp")
    process = start("phantom_sim", SHORT_SCRIPT, ros_env)
    try:
        ros.wait_until(lambda: len(poses) > 10, "the first stylus poses", process)
        del poses[:]
        ros.wait_until(lambda: len(poses) > 1 and seconds_from_stamp(poses[-1].header.stamp)
                       - seconds_from_stamp(poses[0].header.stamp) > 2.5, "two script cycles", process)
    finally:
        stop(process)
    z = positions(poses)[:, 2]
    assert z.max() == pytest.approx(UP_Z, abs=1.5e-3)
    assert z.min() == pytest.approx(DEEP_Z, abs=1.5e-3)
    assert {m.header.frame_id for m in poses} == {"phantom_base"}
    stamps = [seconds_from_stamp(m.header.stamp) for m in poses]
    assert np.all(np.diff(stamps) > 0.0), "stamps are the sample times, increasing"


@pytest.mark.parametrize("force_output", ["wrench_stamped", "wrench", "vector3", "float64_array"])
def test_phantom_sim_feels_the_commanded_force(ros, ros_env, force_output):
    poses = ros.collect("measured_cp")
    diagnostics = ros.collect("diagnostics")
    command_type = force_message_type(force_output)
    commands = ros.node.create_publisher(command_type, TOPICS["servo_cf"].name, TOPICS["servo_cf"].qos)
    pushing = [False]

    def send():
        force = [0.0, 0.0, 2.0] if pushing[0] else [0.0, 0.0, 0.0]
        commands.publish(force_message(force_output, force, 0.0, "phantom_base"))

    ros.node.create_timer(0.01, send)
    params = dict(SHORT_SCRIPT, script="hold", loop_script=False, force_output=force_output,
                  command_timeout_s=0.5)
    process = start("phantom_sim", params, ros_env)
    try:
        ros.wait_until(lambda: len(poses) > 10, "the first stylus poses", process)
        rest = positions(poses[-1:])[0]
        assert rest[2] == pytest.approx(UP_Z, abs=1e-6)
        pushing[0] = True
        shift = 2.0 / 200.0  # N / (N/m): the hand spring's new equilibrium
        ros.wait_until(lambda: positions(poses[-1:])[0, 2] > UP_Z + 0.9 * shift, "the push to move the stylus",
                       process)
        ros.wait_until(lambda: any(float(s["commanded_force_n"]) == pytest.approx(2.0)
                                   for s in statuses(diagnostics, "phantom_sim: loop")),
                       "diagnostics with the commanded force", process)
        pushing[0] = False
        ros.wait_until(lambda: abs(positions(poses[-1:])[0, 2] - UP_Z) < 1e-4, "the stylus to come back", process)
    finally:
        stop(process)
    status = statuses(diagnostics, "phantom_sim: loop")[-1]
    assert {"rate_hz", "jitter_p50_s", "jitter_p99_s", "jitter_max_s", "overruns", "command_age_s"} <= set(status)
    assert positions(poses)[:, 2].max() < UP_Z + shift + 1e-3, "no more than the spring's equilibrium (+overshoot)"


def test_liver_tool_maps_device_samples_into_the_liver_frame(ros, ros_env):
    tool_poses = ros.collect("tool_pose")
    diagnostics = ros.collect("diagnostics")
    device = ros.node.create_publisher(PoseStamped, TOPICS["measured_cp"].name, TOPICS["measured_cp"].qos)
    sample = {"position": [0.01, 0.02, 0.03], "stamp": 12.5}

    def send():
        message = PoseStamped()
        message.header.stamp = stamp_from_seconds(sample["stamp"])
        message.header.frame_id = "phantom_base"
        (message.pose.position.x, message.pose.position.y, message.pose.position.z) = sample["position"]
        message.pose.orientation.w = 1.0
        device.publish(message)

    ros.node.create_timer(0.01, send)
    params = {"source": "device", "device_rotation_xyzw": QUARTER_TURN_Z, "device_translation_m": [0.1, -0.2, 0.05],
              "device_scale": 2.0, "workspace_radius_m": 0.5}
    process = start("liver_tool", params, ros_env)
    try:
        ros.wait_until(lambda: len(tool_poses) > 0, "a mapped tool pose", process)
        first = tool_poses[-1]
        rejected = 0
        for bad, stamp in (([math.nan, 0.0, 0.0], 20.0), ([5.0, 0.0, 0.0], 21.0)):
            sample.update(position=bad, stamp=stamp)
            diagnostics.clear()

            def counted_now() -> int:
                """The most rejected samples any status read since the clear reports (this side may read late)."""
                return max((int(st["rejected_samples"]) for st in statuses(diagnostics, "liver_tool: loop")),
                           default=rejected)
            ros.wait_until(lambda: counted_now() > rejected, f"diagnostics counting the bad sample {bad}", process)
            counted = counted_now()
            assert counted > rejected, f"bad sample {bad} counted"
            rejected = counted
        sample.update(position=[0.0, 0.0, 0.01], stamp=30.0)
        ros.wait_until(lambda: seconds_from_stamp(tool_poses[-1].header.stamp) == 30.0,
                       "a good sample after the bad ones", process)
        assert process.poll() is None, "bad samples do not stop the node"
    finally:
        stop(process)
    position, orientation = pose_to_arrays(first.pose)
    # p_liver = 2·Rz(90°)·(0.01, 0.02, 0.03) + (0.1, −0.2, 0.05)
    np.testing.assert_allclose(position, [0.1 - 0.04, -0.2 + 0.02, 0.05 + 0.06], atol=1e-9)
    np.testing.assert_allclose(orientation, QUARTER_TURN_Z, atol=1e-9)
    assert first.header.frame_id == "liver"
    assert seconds_from_stamp(first.header.stamp) == 12.5
    forwarded = {seconds_from_stamp(m.header.stamp) for m in tool_poses}
    assert not forwarded & {20.0, 21.0}, "bad samples are not forwarded"
    np.testing.assert_allclose(positions(tool_poses[-1:])[0], [0.1, -0.2, 0.07], atol=1e-9)


def test_liver_tool_publishes_the_newest_device_sample_at_its_own_rate_once(ros, ros_env):
    """The device sends at 1 kHz; the tool publishes, at its rate (the physics'), the newest sample it polled, each
    at most once: it relays no sample per sample (the bridge takes the device's samples itself)."""
    tool_poses = ros.collect("tool_pose")
    diagnostics = ros.collect("diagnostics")
    device = ros.node.create_publisher(PoseStamped, TOPICS["measured_cp"].name, TOPICS["measured_cp"].qos)
    sent = []

    def send():
        message = PoseStamped()
        message.header.stamp = stamp_from_seconds(100.0 + 0.001 * len(sent))
        message.pose.position.z = 0.01
        message.pose.orientation.w = 1.0
        device.publish(message)
        sent.append(seconds_from_stamp(message.header.stamp))

    ros.node.create_timer(0.001, send)
    process = start("liver_tool", {"source": "device", "rate_hz": 100.0}, ros_env)
    try:
        ros.wait_until(lambda: len(tool_poses) >= 100, "100 tool poses", process)
        ros.wait_until(lambda: statuses(diagnostics, "liver_tool: loop"), "the tool's diagnostics", process)
    finally:
        stop(process)
    stamps = [seconds_from_stamp(m.header.stamp) for m in tool_poses]
    assert len(stamps) == len(set(stamps)), "each device sample is published once, never repeated"
    assert set(stamps) <= set(sent), "a pose is published only for a device sample"
    first, last = sent.index(stamps[0]), sent.index(stamps[-1])
    assert len(stamps) < 0.5 * (last - first + 1), "the newest sample at the tool's rate, not every sample"
    status = statuses(diagnostics, "liver_tool: loop")[-1]
    assert int(status["published"]) <= len(sent)
    # the collector is frozen after start-up and runs no automatic full collection
    assert int(status["gc_frozen_objects"]) > 0 and status["gc_automatic_full_collection"] == "False"


def test_liver_tool_plays_a_script(ros, ros_env):
    tool_poses = ros.collect("tool_pose")
    process = start("liver_tool", dict(SHORT_SCRIPT, source="script", anchor_m=[0.02, -0.01, 0.0]), ros_env)
    try:
        ros.wait_until(lambda: len(tool_poses) > 1 and seconds_from_stamp(tool_poses[-1].header.stamp)
                       - seconds_from_stamp(tool_poses[0].header.stamp) > 1.5, "a script cycle", process)
    finally:
        stop(process)
    points = positions(tool_poses)
    assert points[:, 2].max() == pytest.approx(UP_Z, abs=1e-4)
    assert points[:, 2].min() == pytest.approx(DEEP_Z, abs=1e-4)
    np.testing.assert_allclose(points[:, :2], np.tile([0.02, -0.01], (len(points), 1)))
    assert {m.header.frame_id for m in tool_poses} == {"liver"}


def test_liver_tool_holds_a_static_pose(ros, ros_env):
    tool_poses = ros.collect("tool_pose")
    params = {"source": "static", "static_position_m": [0.01, 0.02, 0.1], "static_orientation_xyzw": QUARTER_TURN_Z}
    process = start("liver_tool", params, ros_env)
    try:
        ros.wait_until(lambda: len(tool_poses) > 5, "static poses", process)
    finally:
        stop(process)
    for message in tool_poses:
        position, orientation = pose_to_arrays(message.pose)
        np.testing.assert_allclose(position, [0.01, 0.02, 0.1])
        np.testing.assert_allclose(orientation, QUARTER_TURN_Z, atol=1e-12)


@pytest.mark.parametrize("executable, params, named", [
    ("phantom_sim", {"rate_hz": 0.0}, "rate_hz"),
    ("phantom_sim", {"max_force_n": 5.0}, "max_force_n"),
    ("phantom_sim", {"force_output": "omni_feedback"}, "force_output"),
    ("phantom_sim", {"script": "poke"}, "script"),
    ("phantom_sim", {"script": "press", "loop_script": True}, "loop_script"),
    ("liver_tool", {"rate_hz": 0.0}, "rate_hz"),
    ("liver_tool", {"source": "bogus"}, "source"),
    ("liver_tool", {"anchor_m": [0.0, 1.0]}, "anchor_m"),
    ("liver_tool", {"device_rotation_xyzw": [0.0, 0.0, 0.0, 0.0]}, "device_rotation_xyzw"),
])
def test_bad_parameters_end_the_node_with_status_2(ros_env, executable, params, named):
    result = subprocess.run(command(executable, params), env=ros_env, capture_output=True, text=True, timeout=30)
    assert result.returncode == 2, result.stderr
    assert named in result.stderr


def set_parameter(ros: Ros, node: str, name: str, v, process: subprocess.Popen):
    """The SetParametersResult of setting `name` on `node` through its parameter service."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    client = ros.node.create_client(SetParameters, f"/{node}/set_parameters")
    assert client.wait_for_service(timeout_sec=WAIT_S)
    future = client.call_async(SetParameters.Request(parameters=[Parameter(name, value=v).to_parameter_msg()]))
    ros.wait_until(future.done, f"{node} answering set_parameters {name}", process)
    return future.result().results[0]


def test_liver_tool_publishes_its_device_map_latched_and_refuses_to_change_it(ros, ros_env):
    params = {"source": "static", "device_rotation_xyzw": QUARTER_TURN_Z, "device_translation_m": [0.1, -0.2, 0.05],
              "device_scale": 2.0}
    process = start("liver_tool", params, ros_env)
    try:
        poses = ros.collect("tool_pose")
        ros.wait_until(lambda: len(poses) > 10, "the tool running", process)
        maps = ros.collect("device_map")  # subscribed late: the latched map still arrives
        ros.wait_until(lambda: len(maps) > 0, "the latched device map", process)
        device_map = device_map_from_message(maps[-1])
        np.testing.assert_allclose(device_map.device_to_liver(np.array([0.01, 0.0, 0.0])), [0.1, -0.18, 0.05],
                                   atol=1e-12)
        assert device_map.scale == 2.0
        refused = set_parameter(ros, "liver_tool", "device_scale", 1.0, process)
        assert not refused.successful and "restart liver_tool" in refused.reason
        applied = set_parameter(ros, "liver_tool", "workspace_radius_m", 0.3, process)
        assert applied.successful
        out_of_range = set_parameter(ros, "liver_tool", "workspace_radius_m", 50.0, process)
        assert not out_of_range.successful and out_of_range.reason
    finally:
        stop(process)


def test_phantom_sim_changes_its_timeout_and_refuses_the_rest_with_a_reason(ros, ros_env):
    process = start("phantom_sim", {**SHORT_SCRIPT, "realtime_priority": 0}, ros_env)
    try:
        assert set_parameter(ros, "phantom_sim", "command_timeout_s", 0.02, process).successful
        refused = set_parameter(ros, "phantom_sim", "max_force_n", 1.0, process)
        assert not refused.successful and "restart phantom_sim" in refused.reason
    finally:
        stop(process)
