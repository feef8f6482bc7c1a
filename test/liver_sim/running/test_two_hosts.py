"""Two hosts with the product's own DDS profile: the physics, the tool and the simulated PHANToM on host A, the
bridge and a client on host B, as two network namespaces joined by a virtual link (veth), discovery range
SUBNET. The addresses are TEST-NET-1 (RFC 5737) and exist only inside the namespaces this test makes: no
traffic leaves the machine. Where namespaces cannot be made (not root, no iproute2), the test is skipped."""
import json
import os
import shutil
import subprocess
import sys

import pytest

from liver_sim.base.process_settings import DDS_PROFILE_VARIABLE, command_line, config_dir

HOSTS = {"a": "192.0.2.1", "b": "192.0.2.2"}
#: How long (s) the control on host B, which must hear nothing, listens (once the client there has heard host A):
#: host A's participants answer a new one's first announcement at once; with UDP on every interface, a control
#: heard 548 frames in it.
LISTEN_S = 5.0
#: Deadline (s) for host B to hear host A, whose nodes start on a busy machine (the client stops once it has).
HEAR_DEADLINE_S = 90.0
#: What the client on host B must hear of host A: physics frames, and a rendered press (N).
FRAMES, PRESS_N = 150, 0.1

#: A client on host B: counts /liver/nodes frames and the largest force command it receives until it has heard
#: FRAMES frames and a PRESS_N force (argv[2] "until"), or for argv[1] s; prints them as JSON.
CLIENT = r"""
import json, sys, time
from liver_sim.base.process_settings import use_dds_profile
use_dds_profile()
import numpy as np, rclpy
from msg_defs.topics import TOPICS
FRAMES, PRESS_N = %d, %r
rclpy.init()
node = rclpy.create_node("host_b_client")
seen = {"nodes": 0, "max_force_n": 0.0}
def on_nodes(message):
    seen["nodes"] += 1
def on_force(message):
    f = message.wrench.force
    seen["max_force_n"] = max(seen["max_force_n"], float(np.linalg.norm([f.x, f.y, f.z])))
node.create_subscription(TOPICS["nodes"].type, TOPICS["nodes"].name, on_nodes, 10)
node.create_subscription(TOPICS["tool_wrench"].type, TOPICS["servo_cf"].name, on_force, 10)
end = time.monotonic() + float(sys.argv[1])
heard = lambda: seen["nodes"] > FRAMES and seen["max_force_n"] > PRESS_N
while time.monotonic() < end and not (sys.argv[2:] == ["until"] and heard()):
    rclpy.spin_once(node, timeout_sec=0.05)
print(json.dumps(seen), flush=True)
"""


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=30)


@pytest.fixture
def two_hosts():
    """{"a": namespace, "b": namespace} joined by a veth pair, each with loopback up and a multicast route."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("two hosts need network namespaces: root and iproute2 (ip)")
    names = {host: f"liver_sim_{host}{os.getpid()}" for host in HOSTS}
    try:
        for name in names.values():
            ip("netns", "add", name)
        ip("link", "add", f"ls_a{os.getpid()}", "netns", names["a"], "type", "veth",
           "peer", "name", f"ls_b{os.getpid()}", "netns", names["b"])
        for host, name in names.items():
            device = f"ls_{host}{os.getpid()}"
            for command in (["addr", "add", f"{HOSTS[host]}/24", "dev", device], ["link", "set", device, "up"],
                            ["link", "set", "lo", "up"], ["route", "add", "224.0.0.0/4", "dev", device]):
                ip("-n", name, *command)
    except (subprocess.CalledProcessError, OSError) as exc:
        for name in names.values():
            subprocess.run(["ip", "netns", "del", name], capture_output=True)
        pytest.skip(f"network namespaces cannot be made here: {getattr(exc, 'stderr', exc)}")
    try:
        yield names
    finally:
        for name in names.values():
            subprocess.run(["ip", "netns", "del", name], capture_output=True)


def test_the_bridge_on_another_host_renders_the_physics_with_the_products_profile(two_hosts, ros_env, tmp_path):
    env = {**ros_env, "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    env.pop(DDS_PROFILE_VARIABLE)  # each process picks the product's profile for its range
    loopback_only = {**env, DDS_PROFILE_VARIABLE: str(config_dir() / "fastdds.xml")}  # the control
    started = []

    def start(host, args, environ=env, label=None):
        log = open(tmp_path / f"{label or args[0].rsplit('/', 1)[-1]}.log", "w")
        started.append(subprocess.Popen(["ip", "netns", "exec", two_hosts[host], *args], env=environ,
                                        stdout=log, stderr=subprocess.STDOUT, text=True))
        return started[-1]

    try:
        start("a", command_line("liver_physics"))
        start("a", command_line("liver_tool", {"source": "device"}))
        start("a", command_line("phantom_sim", {"loop_script": True}))
        start("b", command_line("haptic_bridge"))
        client = start("b", [sys.executable, "-c", CLIENT % (FRAMES, PRESS_N), str(HEAR_DEADLINE_S), "until"],
                       label="client")
        client.wait(timeout=HEAR_DEADLINE_S + 60)
        # once host B hears host A: a loopback-only client there hears nothing of it
        control = start("b", [sys.executable, "-c", CLIENT % (FRAMES, PRESS_N), str(LISTEN_S)], loopback_only,
                        label="control")
        control.wait(timeout=LISTEN_S + 60)
    finally:
        for process in started:
            if process.poll() is None:
                process.terminate()
        for process in started:
            try:
                process.wait(timeout=15)
            except subprocess.TimeoutExpired:
                process.kill()
    heard = json.loads((tmp_path / "client.log").read_text().splitlines()[-1])
    unheard = json.loads((tmp_path / "control.log").read_text().splitlines()[-1])
    assert heard["nodes"] > FRAMES, heard                # host A's physics frames reach host B
    assert heard["max_force_n"] > PRESS_N, heard          # and the bridge there renders the press of host A's hand
    assert unheard["nodes"] == 0, unheard             # with UDP on loopback only, host B hears nothing of host A
