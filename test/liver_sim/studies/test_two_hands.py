"""Two hands on one liver as real processes: one physics, and per device a bridge, a tool node and a simulated
PHANToM in the device's namespace (the shared `demo --tools 2` run, and a network of its own to stop one side), each
in its own ROS_DOMAIN_ID; no timing thresholds. The scene's pieces without ROS come first."""
import time

import numpy as np
import pytest
import rclpy

from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.bench.loop import HAND_SPOTS_XY
from liver_sim.mesh.landmarks import upper_skin_point
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.running.network import closed_loop_plan, side_label
from liver_sim.sessions.bag import read_messages
from liver_sim.sessions.resimulate import resimulate
from liver_sim.studies.two_hands import HANDS, hands_tools, lift_window, resimulate_command
from msg_defs.device_map import device_map_message
from msg_defs.forces import force_message_type
from msg_defs.topics import TOPICS

from network_clients import Network

MAX_FORCE_N = 2.0


def test_each_hand_has_its_spot_its_use_and_a_device_map_of_its_own():
    tools = hands_tools()
    assert list(tools) == ["left", "right"]
    left, right = tools["left"], tools["right"]
    assert left["liver_physics"] == {"tool_mode": "grasp"} and right["liver_physics"]["tool_mode"] == "cut"
    for side in (left, right):  # the tool node and the simulated device map the device alike, around its spot
        assert side["liver_tool"]["device_translation_m"] == side["phantom_sim"]["device_translation_m"]
        assert side["phantom_sim"]["anchor_m"] == side["liver_tool"]["device_translation_m"]
    assert left["phantom_sim"]["anchor_m"] != right["phantom_sim"]["anchor_m"]
    command = resimulate_command("session")
    assert command[command.index("session") + 1:] == ["-p", "tools:=[left,right]", "-p", "left.tool_mode:=grasp",
                                                       "-p", "right.tool_mode:=cut", "-p", "right.cut_depth_m:=0.008"]


def test_the_lift_runs_from_the_first_tenth_of_the_rise_to_the_last():
    t = np.arange(0.0, 9.0, 0.01)
    # down onto the edge, then up; once the other hand's cut frees the tissue (8 s), the stylus rises further
    z = np.interp(t, [0.0, 1.0, 2.0, 4.0, 8.0, 8.5], [0.0, -0.002, -0.002, 0.018, 0.018, 0.021])
    start, end, rise = lift_window(t, np.column_stack([np.zeros_like(t), np.zeros_like(t), z]))
    assert rise == pytest.approx(0.020)
    assert start == pytest.approx(2.2, abs=0.011) and end == pytest.approx(3.8, abs=0.011)
    assert lift_window(t[:1], np.zeros((1, 3))) is None
    assert lift_window(t, np.zeros((len(t), 3))) is None  # never rose


def test_two_bridges_drive_two_devices_each_in_its_namespace(two_hands_demo):
    summary, out = two_hands_demo.summary, two_hands_demo.out
    assert summary["physics"]["samples"] > 100
    for name in HANDS:
        device = summary["devices"][name]
        assert device["force_topic"] == f"/{name}/phantom/servo_cf"
        assert device["haptic"]["samples"] > 1000
        assert 0.1 < device["peak_haptic_force_n"] <= MAX_FORCE_N  # felt, and clamped, on each device
        assert {f"{name}/haptic_bridge: loop", f"{name}/liver_tool: loop", f"{name}/phantom_sim: loop"} <= set(
            summary["diagnostics"])
        assert {f"{side_label(executable, name)}.log" for executable in ("haptic_bridge", "liver_tool",
                                                                          "phantom_sim")} <= {
            path.name for path in (out / "logs").iterdir()}
    assert "liver_physics: loop" in summary["diagnostics"]
    for name in ("summary.json", "summary.md", "force.png", "liver_two_hands.png", "view.png"):
        assert (out / name).stat().st_size > 0
    messages = {}
    for message in read_messages(out / "session"):
        messages[message.topic] = messages.get(message.topic, 0) + 1
    for name in HANDS:  # the recorder took both sides' topics, each in its namespace
        for topic in ("phantom/servo_cf", "phantom/measured_cp", "tool/pose", "liver/contact_plane",
                      "liver/tool_wrench", "tool/device_map"):
            assert messages.get(f"/{name}/{topic}", 0) > 0, f"/{name}/{topic}"
    assert "/phantom/servo_cf" not in messages and "/tool/pose" not in messages  # no tool in the root namespace


def test_the_left_lift_changes_the_force_the_right_feels_and_the_right_cuts(two_hands_demo):
    coupling = two_hands_demo.summary["coupling"]
    assert coupling["lift"] is not None, "the left did not lift"
    assert coupling["lift"]["rise_m"] > 0.01                        # the hand lifted the stylus
    assert 0.008 < coupling["lift"]["edge_rise_m"] < 0.022          # and the grasped edge with it, 1-2 cm
    # the right presses beside the edge the whole time: raising the tissue under it pushes it up harder
    assert coupling["right_force_after_lift_n"] > coupling["right_force_before_lift_n"] + 0.1
    summary = two_hands_demo.summary
    assert summary["topology_changes"] >= 1 and summary["nodes"][1] > summary["nodes"][0]  # the right's cut


def test_a_two_hand_session_is_resimulated_byte_for_byte_with_both_force_streams(two_hands_demo, tmp_path):
    bag = two_hands_demo.out / "session"
    command = resimulate_command(bag)
    overrides = [command[k + 1] for k, arg in enumerate(command) if arg == "-p"]
    runs = [resimulate(bag, tmp_path / f"out{k}", overrides, progress=lambda line: None) for k in (1, 2)]
    first, second = (list(read_messages(tmp_path / f"out{k}")) for k in (1, 2))
    assert [(m.topic, m.timestamp_ns, m.data) for m in first] == [(m.topic, m.timestamp_ns, m.data) for m in second]
    for name in HANDS:
        assert runs[0]["tools"][name]["commands"] > 1000
        assert runs[0]["tools"][name]["peak_command_n"] > 0.1
        assert any(m.topic == f"/{name}/phantom/servo_cf" for m in first)


@pytest.mark.two_hands
def test_each_bridge_keeps_to_its_device_its_map_and_its_zero(ros_domain_id, tmp_path):
    """Both hands press and hold. No node but a side's own bridge publishes on its device's topic; a map for the left
    from a node named liver_tool outside /left (not the left's tool node) is refused and turns nothing; a rival on the
    left's force topic holds the left at zero, not the right; the left's bridge is stopped: its last command is zero,
    and the right's device goes on feeling the liver."""
    mesh = default_liver()
    plan = closed_loop_plan(tools={name: {"phantom_sim": {
        "script": "press", "approach_s": 0.2, "press_s": 0.3,
        "anchor_m": [round(float(v), 6) for v in upper_skin_point(mesh, xy)]}} for name, xy in HAND_SPOTS_XY.items()})
    network = Network(tmp_path, plan.force_topics, plan.namespaces)

    def forces(name, since=0.0):
        return np.linalg.norm(network.forces_since(since, name), axis=1)

    try:
        for label, args in plan.commands.items():
            network.processes.start(label, args)
        network.wait_for(lambda: all(forces(name).max(initial=0.0) > 0.1 for name in HAND_SPOTS_XY), 90.0,
                         "both devices pressing")
        for name in HAND_SPOTS_XY:  # each device's commands come from its own side's bridge only
            publishers = network.listener.get_publishers_info_by_topic(f"/{name}/phantom/servo_cf")
            assert publishers and {info.node_namespace for info in publishers} == {f"/{name}"}
        intruder = rclpy.create_node("liver_tool", context=network.context)  # in the root namespace
        try:
            maps = intruder.create_publisher(TOPICS["device_map"].type, "/left/tool/device_map",
                                             TOPICS["device_map"].qos)
            published = time.monotonic()
            maps.publish(device_map_message(DeviceMap((1.0, 0.0, 0.0, 0.0))))  # would turn the left's force 180°
            network.wait_for(lambda: int(network.listener.diagnostics.get("left/haptic_bridge: loop", {}).get(
                "bad_device_map", 0)) >= 1, 15.0, "the foreign map refused")
            assert network.forces_since(published, "left")[:, 2].min() >= 0.0  # never turned against the press
            # a rival on the left's device (another bridge, a driver's echo): the left holds zero, the right goes on
            rival = intruder.create_publisher(force_message_type("wrench_stamped"), "/left/phantom/servo_cf",
                                              TOPICS["servo_cf"].qos)
            rivalled = time.monotonic()
            network.wait_for(lambda: len(left := forces("left", rivalled)) > 20 and not left[-20:].any(), 15.0,
                             "the left at zero beside its rival")
            assert forces("right", rivalled).max() > 0.1
            intruder.destroy_publisher(rival)
            gone = time.monotonic()
            network.wait_for(lambda: forces("left", gone).max(initial=0.0) > 0.1, 15.0, "the left driving again")
        finally:
            intruder.destroy_node()
        assert network.processes.stop(side_label("haptic_bridge", "left")) == {"haptic_bridge_left": 0}
        stopped = time.monotonic()
        network.wait_for(lambda: len(forces("right", stopped + 0.5)) > 200, 10.0, "the right's commands after the stop")
        assert forces("left")[-1] == 0.0                                  # the left's last command: zero
        assert len(forces("left", stopped + 0.5)) == 0                    # and nothing drives it after
        assert forces("right", stopped + 0.5).min() > 0.1                 # the right still presses, and feels it
        assert network.processes.failed() == {"haptic_bridge_left": 0}  # every other process runs on
    finally:
        network.close()
