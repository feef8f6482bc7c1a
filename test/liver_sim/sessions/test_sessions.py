"""Sessions: what a recording becomes (each test with real processes in its own ROS domain), read back
by the rosbags library: replay, deterministic re-simulation, reports, refused bags."""
import json
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from rclpy.serialization import serialize_message
from waiting import wait_for

from liver_sim.base.local_model import LocalModel
from liver_sim.base.process_settings import cli_command_line
from liver_sim.cli.main import main
from liver_sim.sessions.analysis import largest_force_jump_n
from liver_sim.sessions.bag import BagWriter, QosSpec, bag_info, read_messages
from liver_sim.sessions.parameters import node_parameters
from liver_sim.sessions.report import write_report
from liver_sim.sessions.resimulate import resimulate
from liver_sim.tool.scripts import ScriptSettings, make_script
from msg_defs.forces import wrench_stamped
from msg_defs.local_model import local_model_marker
from msg_defs.poses import pose_stamped

from network_clients import read_bag

POSE = "geometry_msgs/msg/PoseStamped"
WRENCH = "geometry_msgs/msg/WrenchStamped"
PNG = b"\x89PNG\r\n\x1a\n"
#: A recorder, a replay, a test publisher and clients, at normal priority: nothing that keeps a rate in real time
#: (conftest: such a test may run beside the closed loops).
NO_RATE_LOOPS = pytest.mark.no_rate_loops


def pose_bag(path, duration_s=1.6, depth_m=0.01, storage="mcap", script_name="press_release", slide_m=0.03):
    """A bag of /tool/pose at 1 kHz pressing the default liver (press and release)."""
    script = make_script(script_name, ScriptSettings(depth_m=depth_m, approach_s=0.3, press_s=0.5, hold_s=0.3,
                                                      withdraw_s=0.2, rest_s=0.2, slide_m=slide_m, slide_s=2.0))
    with BagWriter(path, storage) as writer:
        for k in range(int(duration_s * 1000)):
            t = 50.0 + k * 1e-3
            message = pose_stamped(script.position_at(k * 1e-3), (0, 0, 0, 1), t, "liver")
            writer.write("/tool/pose", POSE, round(t * 1e9), serialize_message(message), QosSpec(False, False, 1))
    return path


def messages(path):
    return [(m.topic, m.msgtype, m.timestamp_ns, m.data) for m in read_messages(path)]


def test_resimulation_is_deterministic_and_follows_changed_parameters(tmp_path):
    source = pose_bag(tmp_path / "poses")
    first = resimulate(source, tmp_path / "a", progress=lambda line: None, compare=True)
    second = resimulate(source, tmp_path / "b", storage="sqlite3", progress=lambda line: None, compare=True)
    stiffer = resimulate(source, tmp_path / "c", ["contact_stiffness_n_per_m:=900"], progress=lambda line: None)
    assert messages(tmp_path / "a") == messages(tmp_path / "b")  # byte-identical, whatever the storage
    read = read_bag(tmp_path / "a")
    assert {t: read[t][0][0] for t in read} == {
        "/tool/pose": POSE, "/phantom/servo_cf": WRENCH, "/liver/tool_wrench": WRENCH,
        "/liver/nodes": "sensor_msgs/msg/PointCloud2", "/liver/contact_plane": "visualization_msgs/msg/Marker",
        "/liver/marker": "visualization_msgs/msg/Marker", "/liver/surface": "shape_msgs/msg/Mesh",
        "/phantom/servo_cf_without_local_model": WRENCH}
    assert len(read["/tool/pose"]) == len(read["/phantom/servo_cf"]) == first["commands"] == 1600
    assert len(read["/phantom/servo_cf_without_local_model"]) == 1600
    held = max(m.wrench.force.z for _, _, m in read["/phantom/servo_cf_without_local_model"])
    assert held == pytest.approx(max(m.wrench.force.z for _, _, m in read["/liver/tool_wrench"]), abs=0.02)
    assert first["frames"] == 240 and first["divergences"] == 0
    assert first["peak_command_n"] == second["peak_command_n"] > 0.1  # the press is felt
    physics = lambda result: [m.wrench.force.z for _, _, m in read_bag(result)["/liver/tool_wrench"]]  # noqa
    assert max(physics(tmp_path / "c")) > max(physics(tmp_path / "a"))  # a stiffer contact pushes back harder
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, _, m in read["/liver/tool_wrench"]]
    np.testing.assert_allclose(np.diff(stamps), 1 / 150, atol=1e-8)  # simulation time at the frame rate
    assert stiffer["overrides"] == ["contact_stiffness_n_per_m:=900"]


def test_resimulation_cuts_in_cut_mode_and_records_the_new_surface(tmp_path):
    source = pose_bag(tmp_path / "poses", duration_s=4.0, depth_m=0.012, script_name="press_slide_release",
                      slide_m=0.06)
    resimulate(source, tmp_path / "cut", ["tool_mode:=cut", "cut_depth_m:=0.008"], progress=lambda line: None)
    read = read_bag(tmp_path / "cut")
    surfaces = [m for _, _, m in read["/liver/surface"]]
    assert len(surfaces) == 2 and len(surfaces[1].vertices) > len(surfaces[0].vertices)
    widths = [m.width for _, _, m in read["/liver/nodes"]]
    assert widths[0] == len(surfaces[0].vertices) and widths[-1] == len(surfaces[1].vertices)


def test_parameter_overrides_are_checked_as_the_nodes_check_them():
    both = node_parameters(["tool_radius_m:=0.01"])
    assert both["liver_physics"].tool_radius_m == both["haptic_bridge"].tool_radius_m == 0.01
    one = node_parameters(["haptic_bridge.rate_hz:=500"])
    assert one["haptic_bridge"].rate_hz == 500.0 and one["liver_physics"].rate_hz == 150.0
    for override, named in (("contact_stiffness_n_per_m:=-1", "contact_stiffness_n_per_m"),
                            ("integrator:=rk4", "integrator"), ("substeps:=many", "substeps"),
                            ("no_such_parameter:=1", "no_such_parameter"), ("rate_hz", "name:=value"),
                            ("phantom.rate_hz:=1", "phantom")):
        with pytest.raises(ValueError, match=named):
            node_parameters([override])


def test_the_physics_topic_parameters_default_to_the_topics_table():
    """In the root namespace; a tool's topics are relative names (README, "Two hands")."""
    from liver_sim.base.topic_names import in_namespace
    from liver_sim.physics.parameters import PARAMETERS
    from msg_defs.topics import TOPICS

    for key in ("nodes", "surface", "marker", "contact_plane", "tool_wrench", "tool_pose"):
        assert in_namespace(PARAMETERS[f"{key}_topic"].default, "/") == TOPICS[key].name


@NO_RATE_LOOPS
def test_replay_republishes_the_recorded_messages_in_order(ros_env, tmp_path, ros_domain_id):
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import QoSProfile

    bag = tmp_path / "wrenches"
    sent = []
    with BagWriter(bag) as writer:
        for k in range(300):
            data = serialize_message(wrench_stamped([0.0, 0.0, 0.01 * k], 10.0 + k / 150, "liver"))
            writer.write("/liver/tool_wrench", WRENCH, round((10.0 + k / 150) * 1e9), data)
            sent.append(data)
        writer.write("/tool/pose", POSE, round(20e9), serialize_message(
            pose_stamped([0, 0, 0], (0, 0, 0, 1), 20.0, "liver")))
    context = rclpy.Context()
    rclpy.init(context=context)
    received = []
    try:
        node = rclpy.create_node("replay_listener", context=context)
        node.create_subscription(WrenchStamped, "/liver/tool_wrench", received.append, QoSProfile(depth=1000),
                                 raw=True)
        replay = subprocess.Popen(cli_command_line("replay", str(bag), "--rate", "4", "--delay", "3",
                                                   "--topics", "/liver/tool_wrench"),
                                  env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + 60
        while replay.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        for _ in range(20):
            executor.spin_once(timeout_sec=0.05)
        output = replay.communicate(timeout=10)[0]
    finally:
        context.try_shutdown()
    assert replay.returncode == 0, output
    assert received == sent
    assert "/liver/tool_wrench 300" in output


def test_report_plots_the_session_and_the_fig8_comparison(tmp_path):
    bag = tmp_path / "session"
    t = np.arange(3000) * 1e-3
    smooth = np.clip(np.sin(np.pi * t / 3.0), 0, None)[:, None] * [0.0, 0.0, 1.0]     # rendered at 1 kHz
    held = smooth[(np.floor(t * 150) / 150 * 1000).astype(int)]                       # held between 150 Hz frames
    plane = local_model_marker(LocalModel.plane(np.zeros(3), [0.0, 0.0, 1.0]), 0.0, "liver", 0.05)
    with BagWriter(bag) as writer:
        writer.write("/liver/contact_plane", "visualization_msgs/msg/Marker", 1, serialize_message(plane))
        for k, tk in enumerate(t):
            ns = round((1.0 + tk) * 1e9)
            tip = [0.0, 0.0, 0.015 - 0.004 * smooth[k, 2]]
            writer.write("/tool/pose", POSE, ns, serialize_message(pose_stamped(tip, (0, 0, 0, 1), tk,
                                                                                  "liver")))
            writer.write("/phantom/servo_cf", WRENCH, ns, serialize_message(wrench_stamped(
                smooth[k], tk, "phantom_base")))
            writer.write("/phantom/servo_cf_without_local_model", WRENCH, ns, serialize_message(
                wrench_stamped(held[k], tk, "phantom_base")))
    summary = write_report(bag, tmp_path / "report", progress=lambda line: None)
    for name in ("force.png", "penetration.png", "tool_path.png", "loop_rates.png", "fig8.png"):
        assert (tmp_path / "report" / name).read_bytes()[:8] == PNG
    fig8 = summary["fig8"]
    assert fig8["largest_jump_with_local_model_n"] == pytest.approx(largest_force_jump_n(smooth, onsets=True))
    assert fig8["largest_jump_without_local_model_n"] == pytest.approx(largest_force_jump_n(held, onsets=True))
    assert fig8["smoothness_ratio"] > 5.0
    assert summary["penetration_max_m"] == pytest.approx(0.004, abs=1e-5)
    assert summary["topics"]["/phantom/servo_cf"]["messages"] == 3000
    assert json.loads((tmp_path / "report" / "summary.json").read_text())["fig8"] == fig8
    markdown = (tmp_path / "report" / "summary.md").read_text()
    assert "Fig. 8" in markdown and "- lost: not counted" in markdown  # not written by `liver-sim record`


def damage(kind, bag):
    if kind == "missing":
        shutil.rmtree(bag)
    elif kind == "no metadata":
        (bag / "metadata.yaml").unlink()
    elif kind == "truncated storage":
        data = next(bag.glob("*.mcap"))
        data.write_bytes(data.read_bytes()[:data.stat().st_size // 2])
    elif kind == "garbage storage":
        data = next(bag.glob("*.mcap"))
        raw = bytearray(data.read_bytes())
        raw[len(raw) // 3:len(raw) // 3 + 4000] = b"\xa5" * 4000
        data.write_bytes(bytes(raw))
    elif kind == "metadata promises more":
        meta = bag / "metadata.yaml"
        meta.write_text(meta.read_text().replace("message_count: 1600", "message_count: 1700"))
    elif kind == "not a bag":
        shutil.rmtree(bag)
        bag.write_text("hello")


@NO_RATE_LOOPS
@pytest.mark.parametrize("kind, says", [("missing", "does not exist"), ("no metadata", "no metadata.yaml"),
                                        ("truncated storage", "unreadable"), ("garbage storage", ""),
                                        ("metadata promises more", "truncated"), ("not a bag", "not a bag folder")])
@pytest.mark.parametrize("command", ["report", "resimulate", "replay"])
def test_a_damaged_bag_is_refused_with_a_clear_error(tmp_path, capsys, kind, says, command):
    bag = pose_bag(tmp_path / "poses")
    damage(kind, bag)
    status = main([command, str(bag), "--out", str(tmp_path / "out")] if command != "replay" else [command, str(bag)])
    error = capsys.readouterr().err
    assert status == 2
    assert error.startswith(f"liver-sim: error: {bag}: ") and says in error
    assert not (tmp_path / "out").exists() or command == "report"


def test_demo_records_its_run_and_the_report_reads_it(recorded_demo, tmp_path):
    summary = recorded_demo.summary
    bag = recorded_demo.out / "session"
    read = recorded_demo.bag
    assert {"/liver/nodes", "/liver/surface", "/liver/contact_plane", "/liver/tool_wrench", "/tool/pose",
            "/phantom/measured_cp", "/phantom/servo_cf", "/diagnostics"} <= set(read)
    assert "/liver/marker" not in read  # only with --marker
    # the recorder starts before the nodes and stops after them: it holds every frame the demo saw
    writers = json.loads(bag_info(bag).custom_data["writers"])
    assert all(w["before_match"] + w["gaps"] == 0 for w in writers if w["topic"] == "/liver/nodes"), writers
    assert len(read["/liver/nodes"]) >= summary["physics"]["samples"]
    domain_line, recording_line = (recorded_demo.out / "logs" / "recorder.log").read_text().splitlines()[:2]
    assert domain_line.startswith("liver-sim: ROS_DOMAIN_ID=") and recording_line.startswith("recording to")
    report = write_report(bag, tmp_path / "report", progress=lambda line: None)
    assert report["topics"]["/liver/nodes"]["messages"] == len(read["/liver/nodes"])
    assert f"- lost: {bag_info(bag).custom_data['lost_messages']}" in (tmp_path / "report" / "summary.md").read_text()
    assert {"force.png", "tool_path.png", "loop_rates.png"} <= set(report["figures"])
    assert report["diagnostics_last"]["haptic_bridge: loop"]["rate_hz"]


def test_replay_leaves_out_device_commands_unless_remapped():
    from liver_sim.sessions.replay import output_topics

    recorded = ["/liver/tool_wrench", "/phantom/servo_cf", "/phantom/servo_cf_without_local_model"]
    said = []
    assert output_topics(recorded, None, said.append) == {"/liver/tool_wrench": "/liver/tool_wrench"}
    assert "left out the device commands" in said[0]
    assert output_topics(recorded, "/replayed/servo_cf") == {
        "/liver/tool_wrench": "/liver/tool_wrench", "/phantom/servo_cf": "/replayed/servo_cf",
        "/phantom/servo_cf_without_local_model": "/replayed/servo_cf_without_local_model"}
    with pytest.raises(ValueError, match="never replayed"):
        output_topics(["/phantom/servo_cf"], None)
    with pytest.raises(ValueError, match="no device"):
        output_topics(recorded, "/phantom/servo_cf")


@NO_RATE_LOOPS
def test_replay_puts_nothing_on_the_device_topic(ros_env, tmp_path, ros_domain_id):
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import DurabilityPolicy, QoSProfile

    bag = tmp_path / "commands"
    with BagWriter(bag) as writer:
        for k in range(100):
            t = 10.0 + k / 100
            data = serialize_message(wrench_stamped([0.0, 0.0, 1.0], t, "phantom_base"))
            writer.write("/phantom/servo_cf", WRENCH, round(t * 1e9), data)
            writer.write("/liver/tool_wrench", WRENCH, round(t * 1e9), data)
    context = rclpy.Context()
    rclpy.init(context=context)
    heard = {"/phantom/servo_cf": [], "/liver/tool_wrench": [], "/replayed/servo_cf": []}
    outputs = []
    try:
        node = rclpy.create_node("replay_device_listener", context=context)
        for topic, messages in heard.items():
            # transient local, as a recorder subscribes: what the replay published before this client matched it
            # (discovery can outlast --delay when the machine is busy) still arrives, and so would any device command
            node.create_subscription(WrenchStamped, topic, messages.append,
                                     QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL), raw=True)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        for extra in ([], ["--remap-device-commands", "/replayed/servo_cf"]):
            replay = subprocess.Popen(cli_command_line("replay", str(bag), "--rate", "4", "--delay", "3", *extra),
                                      env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            deadline = time.monotonic() + 60
            while replay.poll() is None and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            for _ in range(20):
                executor.spin_once(timeout_sec=0.05)
            outputs.append(replay.communicate(timeout=10)[0])
            assert replay.returncode == 0, outputs[-1]
    finally:
        context.try_shutdown()
    assert heard["/phantom/servo_cf"] == [], "a replay drove the device topic"
    assert len(heard["/liver/tool_wrench"]) == 200 and len(heard["/replayed/servo_cf"]) == 100
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST" in outputs[0] and "ROS_DOMAIN_ID=" in outputs[0]
    assert "left out the device commands /phantom/servo_cf" in outputs[0]


def test_ros_commands_keep_dds_on_this_machine_unless_told():
    from liver_sim.base.process_settings import keep_dds_local

    env = {}
    assert "LOCALHOST (liver-sim default)" in keep_dds_local(None, env) and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == \
        "LOCALHOST"
    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_DOMAIN_ID": "42"}
    assert keep_dds_local(None, env) == "ROS_DOMAIN_ID=42, ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET (environment)"
    assert "SUBNET (--discovery-range)" in keep_dds_local("SUBNET", {})


def test_fig8_offline_on_the_exploration_is_five_times_smoother_with_the_local_model(tmp_path):
    """The whole explore script offline: the held physics force steps when a frame arrives, and its largest
    change between 1 ms commands in contact (touching and leaving included) is at least 5× the local model's."""
    from liver_sim.studies.fig8 import exploration_fig8

    figures = exploration_fig8(tmp_path)
    assert figures["largest_jump_without_local_model_n"] > 0.0 and figures["largest_jump_with_local_model_n"] > 0.0
    assert figures["smoothness_ratio"] >= 5.0, figures
    assert figures["smoothness_ratio_steady"] > 3.0, figures
    steps = figures["baseline_steps"]
    assert all(steps["at_physics_update"]), steps  # the held physics force steps when a frame arrives
    assert steps["jump_n"][0] >= figures["largest_jump_without_local_model_n"]
    for name in ("fig8.png", "force.png"):
        assert (tmp_path / name).read_bytes().startswith(PNG)
    assert json.loads((tmp_path / "fig8.json").read_text())["smoothness_ratio"] == figures["smoothness_ratio"]


DEVICE_DRIVER = """
import time, rclpy
from geometry_msgs.msg import PoseStamped
rclpy.init()
node = rclpy.create_node("omni_driver")
node.create_publisher(PoseStamped, "/phantom/measured_cp", 1)
print("up", flush=True)
deadline = time.monotonic() + 120.0
while rclpy.ok() and time.monotonic() < deadline:  # until SIGINT (rclpy's handler shuts the context down)
    time.sleep(0.05)
"""


@pytest.mark.parametrize("occupant", ["haptic_bridge", "device"])
def test_demo_and_replay_refuse_a_domain_where_a_bridge_or_a_device_runs(ros_env, tmp_path, occupant):
    args = ([sys.executable, "-m", "liver_sim.nodes.bridge_node"] if occupant == "haptic_bridge"
            else [sys.executable, "-c", DEVICE_DRIVER])
    log = open(tmp_path / "running.log", "w")
    running = subprocess.Popen(args, env=ros_env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    found = "node /haptic_bridge" if occupant == "haptic_bridge" else "publishing /phantom/measured_cp"
    bag = pose_bag(tmp_path / "poses")
    context = rclpy.Context()
    rclpy.init(context=context)
    probe = rclpy.create_node("refusal_probe", context=context)  # the test's own view of the graph

    def seen() -> bool:
        if occupant == "haptic_bridge":
            return ("haptic_bridge", "/") in probe.get_node_names_and_namespaces()
        return bool(probe.get_publishers_info_by_topic("/phantom/measured_cp"))
    try:
        wait_for(seen, 60.0, f"the {occupant} in the graph", lambda: (tmp_path / "running.log").read_text())
        for command in (["demo", "--duration", "5", "--out", str(tmp_path / "demo")],
                        ["replay", str(bag), "--delay", "0"]):
            result = subprocess.run(cli_command_line(*command), env=ros_env, capture_output=True, text=True,
                                    timeout=120)
            assert result.returncode == 2, result.stdout + result.stderr
            assert "already has" in result.stderr and found in result.stderr, result.stderr
            assert "ROS_DOMAIN_ID of its own" in result.stderr
        assert running.poll() is None, "what ran on the domain was left alone"
    finally:
        running.send_signal(signal.SIGINT)
        running.wait(timeout=60)
        log.close()
        probe.destroy_node()
        context.try_shutdown()


def test_a_resimulation_names_the_solver_the_bag_was_made_with(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from liver_sim.physics.solver.implicit import SOLVER_VERSION
    from liver_sim.sessions.resimulate import recorded_solver

    lines = []
    fresh = resimulate(pose_bag(tmp_path / "poses", duration_s=0.3), tmp_path / "a", progress=lines.append)
    assert fresh["recorded_solver"] is None and fresh["physics_solver"] == f"pcg block-jacobi; solver {SOLVER_VERSION}"
    again = resimulate(tmp_path / "a", tmp_path / "b", progress=lines.append)  # a re-simulated bag names its own
    assert again["recorded_solver"] == again["physics_solver"] and not any("made with" in line for line in lines)

    older = pose_bag(tmp_path / "older", duration_s=0.3)  # a bag recorded live names its solver in /diagnostics
    status = DiagnosticStatus(name="liver_physics: loop", values=[KeyValue(key="solver", value="pcg block-jacobi")])
    with BagWriter(tmp_path / "recorded", "mcap") as writer:
        for m in read_messages(older):
            writer.write(m.topic, m.msgtype, m.timestamp_ns, m.data, QosSpec(False, False, 1))
        writer.write("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", 50_100_000_000,
                     serialize_message(DiagnosticArray(status=[status])), QosSpec(True, True, 1))
    assert recorded_solver(tmp_path / "recorded") == "pcg block-jacobi"
    redone = resimulate(tmp_path / "recorded", tmp_path / "c", progress=lines.append)
    assert redone["recorded_solver"] == "pcg block-jacobi"
    assert any("made with the solver 'pcg block-jacobi'" in line for line in lines)

    lines.clear()  # from solver 3 on, a bag made on two threads re-simulates to the bit on one: no line
    two_threads = f"pcg block-jacobi, 2 threads; solver {SOLVER_VERSION}"
    with BagWriter(tmp_path / "threads", "mcap") as writer:
        for m in read_messages(tmp_path / "recorded"):
            writer.write(m.topic, m.msgtype, m.timestamp_ns, m.data, QosSpec(False, False, 1))
        writer.set_custom_data("physics_solver", two_threads)
    assert resimulate(tmp_path / "threads", tmp_path / "d", progress=lines.append)["recorded_solver"] == two_threads
    assert not any("made with" in line for line in lines)
