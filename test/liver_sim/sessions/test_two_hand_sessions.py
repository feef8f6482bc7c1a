"""Sessions of two hands (no ROS graph): the tools' parameters offline, what a recorder takes of two tools, what a
replay leaves out, and a two-tool bag re-simulated byte for byte with both force streams."""
import numpy as np
import pytest
from rclpy.serialization import serialize_message

from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.mesh.landmarks import upper_skin_point
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.sessions.bag import BagError, BagWriter, read_messages
from liver_sim.sessions.parameters import node_parameters
from liver_sim.sessions.record import default_topics, known_topic
from liver_sim.sessions.replay import output_topics
from liver_sim.sessions.resimulate import resimulate
from liver_sim.tool.scripts import ScriptSettings, make_script
from msg_defs.device_map import device_map_message
from msg_defs.poses import pose_stamped

POSE = "geometry_msgs/msg/PoseStamped"
TWO = ["-p", "tools:=[left,right]"]
HANDS = ("tools:=[left,right]", "left.tool_mode:=grasp", "right.cut_depth_m:=0.008", "right.tool_mode:=cut")


def test_each_tool_takes_parameters_of_its_own_offline_as_the_node_does():
    params = node_parameters(HANDS)
    left, right = params["tools"]
    assert (left.name, left.settings.tool_mode, right.settings.tool_mode) == ("left", "grasp", "cut")
    assert right.settings.cut_depth_m == 0.008 and left.settings.cut_depth_m == params["liver_physics"].cut_depth_m
    assert right.topic("tool_pose_topic") == "/right/tool/pose"
    assert left.topic("contact_plane_topic") == "/left/liver/contact_plane"
    (tool,) = node_parameters()["tools"]  # by default one tool, in the root namespace, today's names
    assert tool.name == "" and tool.topic("tool_wrench_topic") == "/liver/tool_wrench"
    with pytest.raises(ValueError, match="left.tool_mode"):
        node_parameters(["left.tool_mode:=grasp"])  # no tool named left
    with pytest.raises(ValueError, match=r"parameter right\.tool_mode='scalpel'"):
        node_parameters(["tools:=[left,right]", "right.tool_mode:=scalpel"])
    with pytest.raises(ValueError, match="is already"):  # two tools on one absolute topic
        node_parameters(["tools:=[left,right]", "contact_plane_topic:=/liver/contact_plane"])
    with pytest.raises(ValueError, match="tools"):
        node_parameters(["tools:=[left,left]"])


def test_a_recorder_takes_each_tools_topics_in_its_namespace():
    one, two = default_topics(), default_topics(tools=("left", "right"))
    assert "/phantom/servo_cf" in one and "/phantom/servo_cf" not in two
    for name in ("/left/phantom/servo_cf", "/right/phantom/measured_cp", "/left/tool/device_map",
                 "/right/liver/contact_plane", "/left/phantom/servo_cf_without_local_model"):
        assert name in two and known_topic(name) is not None
    assert {"/liver/nodes", "/liver/surface", "/diagnostics"} <= set(two)
    assert known_topic("/left/phantom/servo_cf") == known_topic("/phantom/servo_cf")
    assert known_topic("/left/something") is None


def test_a_replay_never_republishes_a_device_command_of_any_namespace():
    recorded = ["/left/phantom/servo_cf", "/right/phantom/servo_cf_without_local_model", "/liver/nodes"]
    said = []
    assert output_topics(recorded, None, said.append) == {"/liver/nodes": "/liver/nodes"}
    assert "/left/phantom/servo_cf" in said[0]
    assert output_topics(recorded, "/replayed/cf", said.append) == {
        "/left/phantom/servo_cf": "/left/replayed/cf",
        "/right/phantom/servo_cf_without_local_model": "/right/replayed/cf_without_local_model",
        "/liver/nodes": "/liver/nodes"}
    with pytest.raises(ValueError, match="remap"):
        output_topics(recorded, "/phantom/servo_cf")  # would put /left's commands on /left/phantom/servo_cf


def two_hand_bag(path):
    """A bag of two devices, each with its device map (origin at its spot) and 1.2 s of 1 kHz samples: the left
    closes on the liver's edge and lifts it, the right presses beside it."""
    liver = default_liver()
    spots = {"left": upper_skin_point(liver, (-0.04, -0.055)), "right": upper_skin_point(liver, (0.0, -0.035))}
    scripts = {"left": make_script("pull", ScriptSettings(anchor_m=tuple(spots["left"]), depth_m=0.0, clearance_m=0.0,
                                                          approach_s=0.1, press_s=0.1, hold_s=0.1, slide_s=0.6,
                                                          pull_m=0.01)),
               "right": make_script("press", ScriptSettings(anchor_m=tuple(spots["right"]), depth_m=0.006,
                                                            approach_s=0.2, press_s=0.3))}
    with BagWriter(path) as writer:
        for name, spot in spots.items():
            writer.write(f"/{name}/tool/device_map", "std_msgs/msg/Float64MultiArray", 0,
                         serialize_message(device_map_message(DeviceMap(translation=spot))))
        for k in range(1200):
            t = k * 1e-3
            for name, spot in spots.items():
                writer.write(f"/{name}/phantom/measured_cp", POSE, round((1.0 + t) * 1e9), serialize_message(
                    pose_stamped(scripts[name].position_at(t) - spot, (0, 0, 0, 1), 1.0 + t, "phantom_base")))


def test_a_two_hand_bag_is_resimulated_byte_for_byte_with_both_force_streams(tmp_path):
    two_hand_bag(tmp_path / "hands")
    runs = [resimulate(tmp_path / "hands", tmp_path / f"out{k}", HANDS, progress=lambda line: None)
            for k in (1, 2)]
    assert runs[0]["tools"]["left"]["commands"] == runs[0]["tools"]["right"]["commands"] == 1200
    first, second = (list(read_messages(tmp_path / f"out{k}")) for k in (1, 2))
    assert [(m.topic, m.timestamp_ns, m.data) for m in first] == [(m.topic, m.timestamp_ns, m.data) for m in second]
    topics = {m.topic for m in first}
    assert {"/left/phantom/servo_cf", "/right/phantom/servo_cf", "/left/liver/tool_wrench",
            "/right/liver/contact_plane"} <= topics
    assert runs[0]["tools"]["left"]["peak_command_n"] > 0.1 and runs[0]["tools"]["right"]["peak_command_n"] > 0.1
    with pytest.raises(BagError, match=r"/left/phantom/measured_cp, /right/phantom/measured_cp: name its tools"):
        resimulate(tmp_path / "hands", tmp_path / "one", (), progress=lambda line: None)
    assert np.isfinite(runs[0]["peak_command_n"])
