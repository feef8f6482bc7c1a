"""The test side of haptic_bridge as a real process (test_bridge_node, test_bridge_inputs, ...): it plays the physics,
the tool and the device, publishing the device map (latched, as liver_tool does), a local model (or a physics
wrench) and the device's stylus sample (placing the tool where asked, through its own device map) every 10 ms, and
listens to the force command and the diagnostics. Every wait is bounded."""
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from waiting import wait_for

from haptic_bridge.parameters import PARAMETERS as BRIDGE
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.geometry.rotations import quaternion_to_matrix
from liver_sim.base.local_model import LocalModel
from liver_sim.nodes.rcl_take import SerializedTake
from msg_defs.device_map import device_map_message
from msg_defs.forces import force_from_bytes, force_from_message, force_message_type, wrench_stamped
from msg_defs.local_model import local_model_marker
from msg_defs.poses import pose_stamped
from msg_defs.topics import TOPICS, device_command_qos

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config" / "haptic_bridge.yaml"
#: Deadline (s) of every wait: a bridge starting on a busy 2-core machine (a closed loop and a core-bound process
#: beside it) may take 15 s before its first command; a wait that passes ends as soon as its condition holds.
WAIT_S = 60.0
PUBLISH_PERIOD_S = 0.01
TOOL_RADIUS_M = 0.015
STIFFNESS_N_PER_M = 190.0
MAX_FORCE_N = 2.0
#: Device → liver rotation: a quarter turn about x (liver +z is device +y).
QUARTER_TURN_X = [math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)]
ROTATION = quaternion_to_matrix(QUARTER_TURN_X)
UP = np.array([0.0, 0.0, 1.0])
#: Tool tip heights (m) over the surface z = 0: 5 mm clear of it, 5 mm and 10 mm into it.
ABOVE = np.array([0.0, 0.0, TOOL_RADIUS_M + 0.005])
INSIDE = np.array([0.0, 0.0, TOOL_RADIUS_M - 0.005])
DEEP = np.array([0.0, 0.0, TOOL_RADIUS_M - 0.015])
EXPECTED_INSIDE = ROTATION.T @ (STIFFNESS_N_PER_M * 0.005 * UP)  # 0.95 N along the normal, in the device frame
LOOP = "haptic_bridge: loop"
#: The contact force of INSIDE with the identity device map (N).
CONTACT = STIFFNESS_N_PER_M * 0.005 * UP  # 0.95 N, identity device map
#: A soft start has (nearly) reached the contact force.
NEARLY_CONTACT_N = 0.95 * float(np.linalg.norm(CONTACT))
#: The bridge's soft start (s): its force rises from zero over it after every restart.
SOFT_START_S = BRIDGE["soft_start_s"].default
#: A device map turned half a turn about x.
HALF_TURN_X = (1.0, 0.0, 0.0, 0.0)


def local_model(kind: str) -> LocalModel:
    """The surface z = 0 with outward normal +z: a plane, or a sphere of radius 0.1 m under it."""
    origin = np.zeros(3)
    if kind == "plane":
        return LocalModel("plane", True, origin, UP, origin, 0.0, 0.0, True)
    return LocalModel("sphere", True, origin, UP, np.array([0.0, 0.0, -0.1]), 0.1, 0.0, True)


def start_bridge(env: dict, program: list[str] | None = None, **params) -> subprocess.Popen:
    args = (program or [sys.executable, "-m", "liver_sim.nodes.bridge_node"]) + ["--ros-args", "--params-file",
                                                                               str(CONFIG)]
    params = {"device_map_node": "/test_haptic_bridge", "model_node": "/test_haptic_bridge",
              "device_node": "/test_haptic_bridge", **params}  # the Rig publishes every input
    for name, v in params.items():
        text = ("[" + ",".join(repr(float(x)) for x in v) + "]" if isinstance(v, list)
                else str(v).lower() if isinstance(v, bool) else str(v))
        args += ["-p", f"{name}:={text}"]
    return subprocess.Popen(args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def stop(process: subprocess.Popen) -> str:
    """SIGINT the bridge if it still runs (SIGKILL after 2 s); its log (standard error)."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        return process.communicate(timeout=2.0)[1]
    except subprocess.TimeoutExpired:
        process.kill()
        return process.communicate()[1]


class Rig:
    """The test side: a node in its own context publishing the inputs every 10 ms and keeping the forces."""

    def __init__(self, force_output: str = "wrench_stamped", rotation_xyzw=(0.0, 0.0, 0.0, 1.0), input_qos=None,
                 names=None):
        """`input_qos`: the QoS of the tool pose, local model and wrench publishers (default: the contract's);
        `names`: other topic names for them (key of TOPICS → name)."""
        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("test_haptic_bridge", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.force_output = force_output
        self.forces, self.stamps, self.pose_stamps, self.diagnostics = [], [], set(), []
        self.tool = None      # tool tip (m, liver frame), published as the stylus sample that places it, or None
        self.nan_pose = False
        self.pose_lead_s = 0.0  # the stylus samples' stamps this far ahead of the clock (s)
        self.model = None     # a LocalModel published as the contact marker, or None
        self.zero_quaternion = False
        self.huge_marker = False  # a local model whose text makes the Marker 100 kB
        self.wrench = None    # a force (N) published as the physics wrench, or None
        self._publishers = {key: self.node.create_publisher(TOPICS[key].type, (names or {}).get(key, TOPICS[key].name),
                                                            TOPICS[key].qos if input_qos is None else input_qos)
                            for key in ("measured_cp", "contact_plane", "tool_wrench")}
        self.node.create_subscription(force_message_type(force_output), TOPICS["servo_cf"].name,
                                      self._on_force, TOPICS["servo_cf"].qos)
        self.node.create_subscription(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                      self.diagnostics.append, TOPICS["diagnostics"].qos)
        self.node.create_timer(PUBLISH_PERIOD_S, self._publish)
        self._map = self.node.create_publisher(TOPICS["device_map"].type, TOPICS["device_map"].name,
                                               TOPICS["device_map"].qos)
        self.publish_map(rotation_xyzw)

    def publish_map(self, rotation_xyzw, scale: float = 1.0) -> None:
        """Latch a device map of this rotation and scale (no translation) on the map topic; the stylus samples place
        the tool through it from now on."""
        self.device_map = DeviceMap(rotation_xyzw, scale=scale)
        self._map.publish(device_map_message(self.device_map))

    def _on_force(self, message) -> None:
        self.forces.append(force_from_message(self.force_output, message))
        if self.force_output == "wrench_stamped":
            self.stamps.append((message.header.stamp.sec, message.header.stamp.nanosec))

    def _publish(self) -> None:
        stamp = self.node.get_clock().now().to_msg()
        if self.tool is not None:
            pose_stamp = (self.node.get_clock().now() + Duration(seconds=self.pose_lead_s)).to_msg()
            pose = pose_stamped(self.device_map.liver_to_device(np.asarray(self.tool, dtype=float)),
                                (0.0, 0.0, 0.0, 1.0), pose_stamp, "phantom_base")
            if self.nan_pose:
                pose = PoseStamped(header=pose.header)
                pose.pose.position.z = math.nan
            self.pose_stamps.add((pose_stamp.sec, pose_stamp.nanosec))
            self._publishers["measured_cp"].publish(pose)
        if self.model is not None:
            marker = local_model_marker(self.model, stamp, "liver", 0.05)
            if self.zero_quaternion:
                marker.pose.orientation.w = 0.0
            if self.huge_marker:
                marker.text = "x " * 50000
            self._publishers["contact_plane"].publish(marker)
        if self.wrench is not None:
            self._publishers["tool_wrench"].publish(wrench_stamped(self.wrench, stamp, "liver"))

    def wait_until(self, condition, what: str, bridge: subprocess.Popen) -> None:
        """Spin (publishing and receiving) until `condition()`; fail if the bridge exits or WAIT_S passes."""
        wait_for(condition, WAIT_S, what,
                 seen=lambda: f"last force {self.forces[-1].tolist() if self.forces else None}, "
                              f"{len(self.forces)} received",
                 between=lambda: self.executor.spin_once(timeout_sec=0.005),
                 gone=lambda: None if bridge.poll() is None else
                 f"the bridge exited ({bridge.returncode}): {bridge.stderr.read()}")

    def wait_for_force(self, expected, bridge: subprocess.Popen, count: int = 20) -> None:
        """Wait until the last `count` force commands equal `expected` (N) within 1 mN."""
        self.wait_until(lambda: len(self.forces) >= count and all(
            np.allclose(f, expected, atol=1e-3, rtol=0.0) for f in self.forces[-count:]),
            f"force {np.round(expected, 4).tolist()} N", bridge)

    def wait_for_stale_zero(self, bridge: subprocess.Popen) -> None:
        """After the inputs stopped: wait for 50 exactly zero commands in a row (a local model sent just before
        the stop is fresh data, and may render for a tick or two after a first zero), then for the watchdog to
        say `stale` 200 commands later; every command from the first of those zeros on must be exactly zero."""
        self.wait_until(lambda: len(self.forces) > 50 and not any(f.any() for f in self.forces[-50:]),
                        "an exactly zero force", bridge)
        first_zero = len(self.forces) - 50
        del self.diagnostics[:]
        self.wait_until(lambda: (self.loop_status() or {}).get("watchdog") == "stale"
                        and len(self.forces) > first_zero + 200, "diagnostics: watchdog stale", bridge)
        assert all(not f.any() for f in self.forces[first_zero:]), "stays exactly zero until fresh data"

    def loop_status(self) -> dict | None:
        """The bridge's newest diagnostics key/values, or None."""
        for array in reversed(self.diagnostics):
            for status in array.status:
                if status.name == LOOP:
                    return {kv.key: kv.value for kv in status.values}
        return None

    def loop_level(self) -> tuple[int, str] | None:
        """(level, message) of the bridge's newest loop status, or None."""
        for array in reversed(self.diagnostics):
            for status in array.status:
                if status.name == LOOP:
                    return int.from_bytes(status.level, "little") if isinstance(status.level, bytes) \
                        else int(status.level), status.message
        return None

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.005)

    def drain(self, quiet_s: float = 0.5) -> None:
        """Spin until no force command has arrived for `quiet_s`: a test side starved of CPU reads the commands
        seconds after they were sent, and the newest one it has read is not yet the last one on the wire."""
        deadline = time.monotonic() + WAIT_S
        count, quiet_since = len(self.forces), time.monotonic()
        while time.monotonic() - quiet_since < quiet_s:
            assert time.monotonic() < deadline, f"force commands still arriving after {WAIT_S} s"
            self.executor.spin_once(timeout_sec=0.005)
            if len(self.forces) != count:
                count, quiet_since = len(self.forces), time.monotonic()

    def call(self, client, request, bridge: subprocess.Popen):
        """The response of a service of the bridge."""
        assert client.wait_for_service(timeout_sec=WAIT_S), f"no service {client.srv_name}"
        future = client.call_async(request)
        self.wait_until(future.done, f"the answer of {client.srv_name}", bridge)
        return future.result()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


class WriterLog:
    """The force commands as a device receives them (reliable, volatile), each with the GID of the writer that sent
    it (liver_sim.nodes.rcl_take): a node of the rig's context that no executor spins, read by :meth:`read`."""

    def __init__(self, rig: Rig):
        self._node = rclpy.create_node("test_device_writers", context=rig.context)
        subscription = self._node.create_subscription(force_message_type("wrench_stamped"), TOPICS["servo_cf"].name,
                                                      lambda _: None, device_command_qos(TOPICS["servo_cf"]),
                                                      raw=True)
        self._take = SerializedTake(subscription)
        self.received: list[tuple[bytes, np.ndarray]] = []  # (writer GID, force N), in order of reception

    def read(self) -> None:
        while (taken := self._take()) is not None:
            self.received.append((taken.gid, force_from_bytes("wrench_stamped", taken.data)))

    def last_by_writer(self) -> dict[bytes, np.ndarray]:
        return {gid: force for gid, force in self.received}

    def close(self) -> None:
        self._take.close()
        self._node.destroy_node()


def seconds_of(stamp) -> float:
    """Seconds of a command's (sec, nanosec) header stamp."""
    return stamp[0] + stamp[1] * 1e-9


def wait_for_exit(rig: Rig, bridge: subprocess.Popen) -> None:
    """Spin until the bridge has exited, then until every command it sent has been read."""
    deadline = time.monotonic() + WAIT_S
    while bridge.poll() is None:
        assert time.monotonic() < deadline, "the bridge did not exit"
        rig.executor.spin_once(timeout_sec=0.005)
    rig.drain()


def terminate_to_zero(rig: Rig, bridge: subprocess.Popen) -> None:
    """SIGTERM the bridge; its last command on the wire is zero."""
    bridge.send_signal(signal.SIGTERM)
    wait_for_exit(rig, bridge)
    assert bridge.returncode == 0 and not rig.forces[-1].any()


def fresh_loop_status(rig: Rig, bridge: subprocess.Popen) -> dict:
    """The bridge's next loop status published after this call."""
    del rig.diagnostics[:]
    rig.wait_until(lambda: rig.loop_status() is not None, "diagnostics", bridge)
    return rig.loop_status()


def assert_safe(forces: list, max_force: float = MAX_FORCE_N) -> None:
    """Every command finite and within the clamp."""
    assert forces, "no force command received"
    stacked = np.array(forces)
    assert np.isfinite(stacked).all()
    assert np.linalg.norm(stacked, axis=1).max() <= max_force + 1e-9
