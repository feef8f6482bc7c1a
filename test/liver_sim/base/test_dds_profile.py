"""The product's Fast DDS profiles (config/fastdds.xml, config/fastdds_network.xml;
liver_sim.base.process_settings.use_dds_profile): every process loads the one of its discovery range unless the
environment names another, and under it a participant's shared-memory ports make an opener's health check wait at
most 33 ms instead of Fast DDS's 333 ms (the check holds the opener's send lock)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from liver_sim.base.process_settings import DDS_PROFILE_VARIABLE, config_dir, use_dds_profile

#: A participant that reports, for each shared-memory port it listens on in its domain's port range, the
#: health-check timeout and the listener's wait period that Fast DDS 2.14 stored in the port
#: (SharedMemGlobal::PortNode: port_id, num_listeners, healthy_check_timeout_ms, port_wait_timeout_ms).
PROBE = r"""
import json, os, struct, sys
from liver_sim.base.process_settings import use_dds_profile
use_dds_profile()
import rclpy
rclpy.init()
node = rclpy.create_node("dds_profile_probe")
domain = int(os.environ["ROS_DOMAIN_ID"])
first = 7400 + 250 * domain
found = {}
for task in os.listdir("/proc/self/task"):
    name = open(f"/proc/self/task/{task}/comm").read().strip()
    if name.startswith("dds.shm.") and name[8:].isdigit() and first <= int(name[8:]) < first + 250:
        port = int(name[8:])
        data = open(f"/dev/shm/fastrtps_port{port}", "rb").read(16384)
        for offset in range(0, len(data) - 16, 4):
            port_id, listeners, timeout_ms, wait_ms = struct.unpack_from("<IIII", data, offset)
            if port_id == port and 0 < listeners < 64 and timeout_ms > 0 and wait_ms == timeout_ms // 3:
                found[port] = [timeout_ms, wait_ms]
                break
print(json.dumps({"profile": os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE"), "ports": found}))
node.destroy_node()
rclpy.shutdown()
"""


def _forget_ports(domain: int) -> None:
    """Remove the shared-memory port files of `domain`'s port range that earlier participants left in /dev/shm: a
    port keeps the health-check timeout of its creator, so a probe reusing one would read that creator's profile.
    The test holds the domain's lock (conftest), so no live participant of another test uses them."""
    first = 7400 + 250 * domain
    for path in Path("/dev/shm").glob("fastrtps_port*"):
        digits = "".join(c for c in path.name[len("fastrtps_port"):] if c.isdigit())
        if digits and first <= int(digits) < first + 250:
            path.unlink(missing_ok=True)


def _probe(env: dict) -> dict:
    _forget_ports(int(env["ROS_DOMAIN_ID"]))
    done = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_every_process_loads_the_product_profile_unless_the_environment_names_one():
    for discovery_range, profile in (("LOCALHOST", "fastdds.xml"), ("OFF", "fastdds.xml"),
                                     ("SUBNET", "fastdds_network.xml"), ("SYSTEM_DEFAULT", "fastdds_network.xml"),
                                     ("", "fastdds_network.xml")):  # unset: ROS's default, SUBNET
        env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": discovery_range}
        line = use_dds_profile(env)
        assert Path(env[DDS_PROFILE_VARIABLE]) == config_dir() / profile and Path(env[DDS_PROFILE_VARIABLE]).is_file()
        assert line.endswith("(liver-sim default)")
    env = {DDS_PROFILE_VARIABLE: "/etc/rig/dds.xml"}
    assert use_dds_profile(env) == f"{DDS_PROFILE_VARIABLE}=/etc/rig/dds.xml (environment)"
    assert env[DDS_PROFILE_VARIABLE] == "/etc/rig/dds.xml"


@pytest.mark.no_rate_loops  # a participant in a process of its own or this one: no loop keeps a rate
def test_shared_memory_ports_under_the_profile_hold_an_opener_33_ms_not_333(ros_env, tmp_path):
    """A participant's ports, read back from /dev/shm: 100/33 ms under the product profile; the same probe under
    Fast DDS's own defaults (a profile file without transports) finds 1000/333 ms, so the reading can fail."""
    ros_env.pop(DDS_PROFILE_VARIABLE, None)
    product = _probe(ros_env)
    assert product["profile"] == str(config_dir() / "fastdds.xml")
    assert product["ports"] and all(ports == [100, 33] for ports in product["ports"].values()), product

    defaults = tmp_path / "defaults.xml"
    defaults.write_text('<?xml version="1.0" encoding="UTF-8" ?>\n'
                        '<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"/>\n')
    fast_dds = _probe({**ros_env, DDS_PROFILE_VARIABLE: str(defaults)})
    assert fast_dds["ports"] and all(ports == [1000, 333] for ports in fast_dds["ports"].values()), fast_dds
    assert os.environ.get(DDS_PROFILE_VARIABLE) == str(config_dir() / "fastdds.xml")  # conftest's, for the suite
