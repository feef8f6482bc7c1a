"""`liver-sim record` on loopback (each test in its own ROS domain): every message of a running publisher in the
bag, read back by the rosbags library; a stop by SIGINT or SIGTERM mid-stream; a recorder started mid-run."""
import json
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from waiting import wait_for

from liver_sim.base.process_settings import cli_command_line
from liver_sim.sessions.bag import bag_info
from liver_sim.sessions.record import READY

from network_clients import Tally, read_bag

PUBLISHER = Path(__file__).resolve().parents[2] / "support" / "session_publisher.py"
POSE = "geometry_msgs/msg/PoseStamped"
WRENCH = "geometry_msgs/msg/WrenchStamped"
NO_RATE_LOOPS = pytest.mark.no_rate_loops


def start_recorder(bag, ros_env, storage):
    process = subprocess.Popen(cli_command_line("record", "--out", str(bag), "--storage", storage),
                               env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    return process


def stop(process, sig):
    process.send_signal(sig)
    output, _ = process.communicate(timeout=30)
    return process.returncode, output


@NO_RATE_LOOPS
def test_recorded_bag_holds_every_published_message_read_back_by_rosbags(ros_env, tmp_path):
    bag = tmp_path / "session"
    recorder = start_recorder(bag, ros_env, "mcap")
    try:
        published = subprocess.run([sys.executable, str(PUBLISHER), "2000"], env=ros_env, capture_output=True,
                                   text=True, timeout=120, check=True)
    finally:
        status, output = stop(recorder, signal.SIGINT)
    assert status == 0, output
    sent = json.loads(published.stdout.splitlines()[-1])
    read = read_bag(bag)
    assert {topic: len(messages) for topic, messages in read.items()} == sent
    assert {read[t][0][0] for t in read} == {WRENCH, POSE, "sensor_msgs/msg/PointCloud2"}
    forces = [m.wrench.force.z for _, _, m in read["/phantom/servo_cf"]]
    np.testing.assert_allclose(forces, np.arange(2000) * 1e-4)  # every command, in order
    times = [t for _, t, _ in read["/tool/pose"]]
    assert times == sorted(times)  # logged at their reception
    assert read["/liver/nodes"][0][2].width == read["/liver/nodes"][-1][2].width > 100


@NO_RATE_LOOPS
def test_a_recording_stopped_mid_stream_by_sigterm_is_a_complete_sqlite3_bag(ros_env, tmp_path):
    bag = tmp_path / "session"
    recorder = start_recorder(bag, ros_env, "sqlite3")
    publisher = subprocess.Popen([sys.executable, str(PUBLISHER), "5000"], env=ros_env, stdout=subprocess.PIPE,
                                 text=True)
    tally = Tally(["/phantom/servo_cf"])
    try:
        assert publisher.stdout.readline().strip() == "publishing"  # it waits for the recorder's subscriptions
        wait_for(lambda: tally.count("/phantom/servo_cf") >= 500, 60.0, "500 commands published", tally.counts)
        status, output = stop(recorder, signal.SIGTERM)  # mid-stream: the publisher sends 5000
    finally:
        tally.close(linger_s=0.0)
        publisher.kill()
        publisher.wait()
    assert status == 0, output
    assert (bag / "metadata.yaml").is_file()
    read = read_bag(bag)
    written = {t: len(m) for t, m in read.items()}
    assert 0 < written["/phantom/servo_cf"] < 5000
    from rosbags.rosbag2 import Reader
    with Reader(bag) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == written  # metadata.yaml agrees


@NO_RATE_LOOPS
def test_recorder_follows_the_published_type_and_records_other_topics(ros_env, tmp_path):
    bag = tmp_path / "session"
    recorder = subprocess.Popen(cli_command_line("record", "--out", str(bag), "--topics", "/phantom/servo_cf",
                                                 "/custom/topic"),
                                env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        published = subprocess.run([sys.executable, str(PUBLISHER), "300", "other"], env=ros_env,
                                   capture_output=True, text=True, timeout=120, check=True)
    finally:
        status, output = stop(recorder, signal.SIGINT)
    assert status == 0, output
    read = read_bag(bag)
    assert {t: len(m) for t, m in read.items()} == json.loads(published.stdout.splitlines()[-1])
    assert read["/phantom/servo_cf"][0][0] == "geometry_msgs/msg/Vector3"  # a bridge with force_output: vector3
    assert [m.data for _, _, m in read["/custom/topic"]] == [str(k) for k in range(300)]


RUNNING_PUBLISHER = """
import sys, threading, time, rclpy
from rclpy.duration import Duration
from msg_defs.forces import wrench_stamped
from msg_defs.topics import TOPICS
rclpy.init()
node = rclpy.create_node("running_publisher")
publisher = node.create_publisher(TOPICS["tool_wrench"].type, TOPICS["tool_wrench"].name, TOPICS["tool_wrench"].qos)
halt = threading.Event()
threading.Thread(target=lambda: (sys.stdin.readline(), halt.set()), daemon=True).start()
published = matched = 0
while not halt.is_set():
    publisher.publish(wrench_stamped([0.0, 0.0, 0.1], time.time(), "liver"))
    published += 1
    if publisher.get_subscription_count() != matched:
        matched = publisher.get_subscription_count()
        print("matched", matched, flush=True)
    time.sleep(0.005)
acknowledged = publisher.wait_for_all_acked(Duration(seconds=float(sys.argv[1])))
print("published", published, "acknowledged", acknowledged, flush=True)
halt.wait(3600)
"""


@NO_RATE_LOOPS
def test_a_recorder_started_mid_run_counts_nothing_lost_of_a_running_publisher(ros_env, tmp_path):
    publisher = subprocess.Popen([sys.executable, "-c", RUNNING_PUBLISHER, "30"], env=ros_env,
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    tally = Tally(["/liver/tool_wrench"])
    try:
        published = lambda: max(tally.last().values(), default=0)  # noqa: E731
        # more messages published before the recorder starts than its history holds
        wait_for(lambda: published() >= 1000, 60.0, "1000 messages of the running publisher", tally.counts)
        recorder = subprocess.Popen(cli_command_line("record", "--out", str(tmp_path / "session"), "--topics",
                                                     "/liver/tool_wrench"),
                                    env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        # recording from `ready` on, and sent to by the writer (which discovers the recorder on its own)
        assert any(line.startswith(READY) for line in recorder.stdout), "the recorder ended before `ready`"
        lines = []
        threading.Thread(target=lambda: lines.extend(publisher.stdout), daemon=True).start()
        wait_for(lambda: "matched 2\n" in lines, 60.0, "the writer matching the recorder", lambda: lines)
        at_match = published()
        wait_for(lambda: published() >= at_match + 500, 60.0, "500 messages published while it records",
                 tally.counts)
        # the writer stops and waits until every reader it matched acknowledged all it published: a recorder
        # stopped then holds the last of them
        publisher.stdin.write("stop\n")
        publisher.stdin.flush()
        wait_for(lambda: lines[-1].startswith("published"), 60.0, "the publisher's count", lambda: lines)
        _, last, _, acknowledged = lines[-1].split()
        status, output = stop(recorder, signal.SIGINT)
    finally:
        tally.close(linger_s=0.0)
        publisher.kill()
        publisher.wait()
    assert acknowledged == "True", "the publisher's readers did not acknowledge all it published within 30 s"
    # what the running writer published before the recording began is not wanted, whether the graph showed
    # the writer by `ready` or its transient-local history reached the recorder later
    assert status == 0 and "lost: 0" in output, output
    (writer,) = json.loads(bag_info(tmp_path / "session").custom_data["writers"])
    assert writer["first"] > 1 and writer["before_match"] == 0 and writer["gaps"] == 0, writer
    assert writer["last"] == int(last) and writer["received"] == writer["last"] - writer["first"] + 1 > 300, writer
