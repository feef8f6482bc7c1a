"""haptic_bridge as a real process, talked to over DDS on loopback in a domain of its own.

The test side plays the physics and the tool: it publishes the device map (latched, as liver_tool
does), refreshes a local model (or a physics wrench) and the tool pose every 10 ms, and listens to the
force command. Every wait is bounded; nothing asserts on timing. The bridge is stopped (SIGINT, then
SIGKILL) in `finally`.
"""
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.geometry.rotations import quaternion_to_matrix
from liver_sim.base.local_model import LocalModel
from msg_defs.device_map import device_map_message
from msg_defs.forces import force_from_message, force_message_type, wrench_stamped
from msg_defs.local_model import local_model_marker
from msg_defs.poses import pose_stamped
from msg_defs.topics import TOPICS

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "config" / "haptic_bridge.yaml"
WAIT_S = 15.0
PUBLISH_PERIOD_S = 0.01
TOOL_RADIUS_M = 0.015
STIFFNESS_N_PER_M = 300.0
MAX_FORCE_N = 2.0
#: Device → liver rotation: a quarter turn about x (liver +z is device +y).
QUARTER_TURN_X = [math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)]
ROTATION = quaternion_to_matrix(QUARTER_TURN_X)
UP = np.array([0.0, 0.0, 1.0])
#: Tool tip heights (m) over the surface z = 0: 5 mm clear of it, 5 mm and 10 mm into it.
ABOVE = np.array([0.0, 0.0, TOOL_RADIUS_M + 0.005])
INSIDE = np.array([0.0, 0.0, TOOL_RADIUS_M - 0.005])
DEEP = np.array([0.0, 0.0, TOOL_RADIUS_M - 0.010])
EXPECTED_INSIDE = ROTATION.T @ (STIFFNESS_N_PER_M * 0.005 * UP)  # 1.5 N along the normal, in the device frame
LOOP = "haptic_bridge: loop"


def local_model(kind: str) -> LocalModel:
    """The surface z = 0 with outward normal +z: a plane, or a sphere of radius 0.1 m under it."""
    origin = np.zeros(3)
    if kind == "plane":
        return LocalModel("plane", True, origin, UP, origin, 0.0, 0.0, True)
    return LocalModel("sphere", True, origin, UP, np.array([0.0, 0.0, -0.1]), 0.1, 0.0, True)


def start_bridge(env: dict, program: list[str] | None = None, **params) -> subprocess.Popen:
    args = (program or [sys.executable, "-m", "liver_sim.nodes.bridge_node"]) + ["--ros-args", "--params-file",
                                                                               str(CONFIG)]
    for name, v in params.items():
        text = ("[" + ",".join(repr(float(x)) for x in v) + "]" if isinstance(v, list)
                else str(v).lower() if isinstance(v, bool) else str(v))
        args += ["-p", f"{name}:={text}"]
    return subprocess.Popen(args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        process.communicate(timeout=2.0)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()


class Rig:
    """The test side: a node in its own context publishing the inputs every 10 ms and keeping the forces."""

    def __init__(self, force_output: str = "wrench_stamped", rotation_xyzw=(0.0, 0.0, 0.0, 1.0)):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("test_haptic_bridge", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.force_output = force_output
        self.forces, self.stamps, self.pose_stamps, self.diagnostics = [], [], set(), []
        self.arrivals = []    # monotonic s at which each force command arrived
        self.tool = None      # tip position (m) published as the tool pose, or None
        self.nan_pose = False
        self.model = None     # a LocalModel published as the contact marker, or None
        self.zero_quaternion = False
        self.wrench = None    # a force (N) published as the physics wrench, or None
        self._publishers = {key: self.node.create_publisher(TOPICS[key].type, TOPICS[key].name, TOPICS[key].qos)
                            for key in ("tool_pose", "contact_plane", "tool_wrench")}
        self.node.create_subscription(force_message_type(force_output), TOPICS["servo_cf"].name,
                                      self._on_force, TOPICS["servo_cf"].qos)
        self.node.create_subscription(TOPICS["diagnostics"].type, TOPICS["diagnostics"].name,
                                      self.diagnostics.append, TOPICS["diagnostics"].qos)
        self.node.create_timer(PUBLISH_PERIOD_S, self._publish)
        self._map = self.node.create_publisher(TOPICS["device_map"].type, TOPICS["device_map"].name,
                                               TOPICS["device_map"].qos)
        self._map.publish(device_map_message(DeviceMap(rotation_xyzw)))

    def _on_force(self, message) -> None:
        self.arrivals.append(time.monotonic())
        self.forces.append(force_from_message(self.force_output, message))
        if self.force_output == "wrench_stamped":
            self.stamps.append((message.header.stamp.sec, message.header.stamp.nanosec))

    def _publish(self) -> None:
        stamp = self.node.get_clock().now().to_msg()
        if self.tool is not None:
            pose = pose_stamped(self.tool, (0.0, 0.0, 0.0, 1.0), stamp, "liver")
            if self.nan_pose:
                pose = PoseStamped(header=pose.header)
                pose.pose.position.z = math.nan
            self.pose_stamps.add((stamp.sec, stamp.nanosec))
            self._publishers["tool_pose"].publish(pose)
        if self.model is not None:
            marker = local_model_marker(self.model, stamp, "liver", 0.05)
            if self.zero_quaternion:
                marker.pose.orientation.w = 0.0
            self._publishers["contact_plane"].publish(marker)
        if self.wrench is not None:
            self._publishers["tool_wrench"].publish(wrench_stamped(self.wrench, stamp, "liver"))

    def wait_until(self, condition, what: str, bridge: subprocess.Popen) -> None:
        """Spin (publishing and receiving) until `condition()`; fail if the bridge exits or WAIT_S passes."""
        deadline = time.monotonic() + WAIT_S
        while not condition():
            if bridge.poll() is not None:
                pytest.fail(f"the bridge exited ({bridge.returncode}) while waiting for {what}: "
                            f"{bridge.stderr.read()}")
            if time.monotonic() > deadline:
                last = self.forces[-1].tolist() if self.forces else None
                pytest.fail(f"timed out waiting for {what} (last force {last}, {len(self.forces)} received)")
            self.executor.spin_once(timeout_sec=0.005)

    def wait_for_force(self, expected, bridge: subprocess.Popen, count: int = 20) -> None:
        """Wait until the last `count` force commands equal `expected` (N) within 1 mN."""
        self.wait_until(lambda: len(self.forces) >= count and all(
            np.allclose(f, expected, atol=1e-3, rtol=0.0) for f in self.forces[-count:]),
            f"force {np.round(expected, 4).tolist()} N", bridge)

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


@pytest.fixture
def rig_factory(ros_domain_id):
    rigs = []

    def make(**kwargs) -> Rig:
        rigs.append(Rig(**kwargs))
        return rigs[-1]
    try:
        yield make
    finally:
        for rig in rigs:
            rig.close()


def assert_safe(forces: list, max_force: float = MAX_FORCE_N) -> None:
    """Every command finite and within the clamp."""
    assert forces, "no force command received"
    stacked = np.array(forces)
    assert np.isfinite(stacked).all()
    assert np.linalg.norm(stacked, axis=1).max() <= max_force + 1e-9


@pytest.mark.parametrize("kind", ["plane", "sphere"])
def test_local_model_force_in_the_device_frame(rig_factory, ros_env, kind):
    rig = rig_factory(rotation_xyzw=QUARTER_TURN_X)
    rig.model, rig.tool = local_model(kind), ABOVE
    bridge = start_bridge(ros_env, local_model=kind)
    try:
        rig.wait_until(lambda: len(rig.pose_stamps) > 10 and len(rig.forces) > 100, "force commands", bridge)
        rig.wait_for_force(np.zeros(3), bridge)
        assert all(not f.any() for f in rig.forces[-20:]), "exactly zero out of contact"
        rig.tool = INSIDE
        rig.wait_for_force(EXPECTED_INSIDE, bridge)
        np.testing.assert_allclose(EXPECTED_INSIDE, [0.0, 1.5, 0.0], atol=1e-12)  # the map is not the identity
        assert set(rig.stamps[-20:]) <= rig.pose_stamps, "stamped with the tool pose it was computed from"
        rig.tool = DEEP  # 3 N asked for: clamped to max_force_n along the same direction
        rig.wait_for_force(MAX_FORCE_N * EXPECTED_INSIDE / np.linalg.norm(EXPECTED_INSIDE), bridge)
        assert bridge.poll() is None
    finally:
        stop(bridge)
    assert_safe(rig.forces)


@pytest.mark.parametrize("force_output", ["wrench_stamped", "wrench", "vector3", "float64_array"])
def test_every_force_output_carries_the_same_force(rig_factory, ros_env, force_output):
    rig = rig_factory(force_output=force_output, rotation_xyzw=QUARTER_TURN_X)
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env, force_output=force_output)
    try:
        rig.wait_for_force(EXPECTED_INSIDE, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_omni_feedback_without_omni_msgs_is_refused(ros_env):
    try:
        import omni_msgs  # noqa: F401
        pytest.skip("omni_msgs is installed here")
    except ImportError:
        pass
    bridge = start_bridge(ros_env, force_output="omni_feedback")
    try:
        _, err = bridge.communicate(timeout=WAIT_S)
    finally:
        stop(bridge)
    assert bridge.returncode == 2
    assert "omni_feedback" in err and "omni_msgs" in err


def test_watchdog_zeroes_the_force_on_a_stale_model_and_recovers(rig_factory, ros_env):
    rig = rig_factory(rotation_xyzw=QUARTER_TURN_X)
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(EXPECTED_INSIDE, bridge)
        rig.wait_until(lambda: (rig.loop_status() or {}).get("watchdog") == "ok", "diagnostics: watchdog ok",
                       bridge)
        rig.model = None  # the physics stops refreshing the local model
        # 50 zero commands in a row: a local model the rig sent just before it stopped is fresh data, and may
        # still render for a tick or two after a first zero
        rig.wait_until(lambda: len(rig.forces) > 50 and not any(f.any() for f in rig.forces[-50:]),
                       "an exactly zero force", bridge)
        first_zero = len(rig.forces) - 50
        del rig.diagnostics[:]
        rig.wait_until(lambda: (rig.loop_status() or {}).get("watchdog") == "stale"
                       and len(rig.forces) > first_zero + 200, "diagnostics: watchdog stale", bridge)
        assert all(not f.any() for f in rig.forces[first_zero:]), "stays exactly zero until fresh data"
        status = rig.loop_status()
        assert float(status["last_force_n"]) == 0.0 and float(status["rate_hz"]) > 0.0
        rig.model = local_model("plane")
        rig.wait_for_force(EXPECTED_INSIDE, bridge)
        rig.model = LocalModel.invalid()  # DELETE markers: fresh news of no surface near the tool
        rig.wait_for_force(np.zeros(3), bridge)
        # fresh news keeps the watchdog from going stale: it is ok, once a soft start after a loop gap (the
        # machine's own stalls restart the output) has ramped up
        del rig.diagnostics[:]
        rig.wait_until(lambda: (rig.loop_status() or {}).get("watchdog") == "ok", "diagnostics: watchdog ok", bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


@pytest.mark.parametrize("bad_input, counter", [("nan_pose", "bad_tool_pose"),
                                                ("zero_quaternion", "bad_local_model")])
def test_bad_input_is_counted_and_ignored(rig_factory, ros_env, bad_input, counter):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(STIFFNESS_N_PER_M * 0.005 * UP, bridge)
        setattr(rig, bad_input, True)  # only bad messages from now on: the last good one goes stale
        rig.wait_until(lambda: rig.forces and not rig.forces[-1].any(), "the watchdog's zero force", bridge)
        del rig.diagnostics[:]
        rig.wait_until(lambda: int((rig.loop_status() or {}).get(counter, 0)) > 0, f"diagnostics: {counter}",
                       bridge)
        assert int(rig.loop_status()["bad_messages"]) >= int(rig.loop_status()[counter])
        setattr(rig, bad_input, False)
        rig.wait_for_force(STIFFNESS_N_PER_M * 0.005 * UP, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


@pytest.mark.parametrize("params, named", [({"max_force_n": 5.0}, "max_force_n"),
                                           ({"stiffness_n_per_m": 2000.0}, "stiffness_n_per_m"),
                                           ({"local_model": "cube"}, "local_model"),
                                           ({"local_model": "none"}, "contact_stiffness_n_per_m"),
                                           ({"soft_start_s": 0.01}, "soft_start_s")])
def test_refused_parameters_end_the_process_naming_them(ros_env, params, named):
    bridge = start_bridge(ros_env, **params)
    try:
        _, err = bridge.communicate(timeout=WAIT_S)
    finally:
        stop(bridge)
    assert bridge.returncode == 2
    assert named in err


def test_without_local_model_the_physics_wrench_is_held(rig_factory, ros_env):
    rig = rig_factory(rotation_xyzw=QUARTER_TURN_X)
    wrench = np.array([0.3, -0.4, 1.2])  # N on the tool, liver frame
    rig.wrench, rig.tool = wrench, ABOVE
    rig.model = local_model("plane")  # ignored in this mode
    bridge = start_bridge(ros_env, local_model="none", device_damping_ns_per_m=2.5)  # passive: b > K·T/2 + B = 2
    try:
        rig.wait_for_force(ROTATION.T @ wrench, bridge)
        rig.wrench = None  # the physics stops: the held wrench goes stale
        rig.wait_until(lambda: rig.forces and not rig.forces[-1].any(), "the watchdog's zero force", bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


# ---------------------------------------------------------------- zero on every exit (issue 13)

CONTACT = STIFFNESS_N_PER_M * 0.005 * UP  # 1.5 N, identity device map
#: A bridge process whose tick misbehaves while the tool is DEEP (z below 7.5 mm): FAULT runs first.
FAULTY_BRIDGE = """
import sys, time
import haptic_bridge.tick as tick
step = tick.BridgeTick.step
def faulty(self, now_s, tip, *rest):
    if tip is not None and tip[2] < 0.0075:
        FAULT
    return step(self, now_s, tip, *rest)
tick.BridgeTick.step = faulty
from liver_sim.nodes.bridge_node import main
sys.exit(main())
"""


def wait_for_exit(rig: Rig, bridge: subprocess.Popen) -> None:
    """Spin until the bridge has exited, then half a second more for anything still in flight."""
    deadline = time.monotonic() + WAIT_S
    while bridge.poll() is None:
        assert time.monotonic() < deadline, "the bridge did not exit"
        rig.executor.spin_once(timeout_sec=0.005)
    rig.spin_for(0.5)


def terminate_to_zero(rig: Rig, bridge: subprocess.Popen) -> None:
    """SIGTERM the bridge; its last command on the wire is zero."""
    bridge.send_signal(signal.SIGTERM)
    wait_for_exit(rig, bridge)
    assert bridge.returncode == 0 and not rig.forces[-1].any()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_in_contact_leaves_zero_as_the_last_command_after_a_soft_start(rig_factory, ros_env, sig):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_until(lambda: rig.forces and rig.forces[-1].any(), "the first force", bridge)
        first = len(rig.forces) - 1
        rig.wait_for_force(CONTACT, bridge)
        reached = next(i for i in range(first, len(rig.forces)) if np.linalg.norm(rig.forces[i]) > 0.95 * 1.5)
        assert rig.arrivals[reached] - rig.arrivals[first] >= 0.1, "soft start: 0.2 s from zero to full force"
        in_contact = len(rig.forces)
        bridge.send_signal(sig)
        wait_for_exit(rig, bridge)
    finally:
        stop(bridge)
    assert bridge.returncode == 0
    assert np.linalg.norm(rig.forces[in_contact - 1]) > 1.4, "in contact when the signal came"
    assert not rig.forces[-1].any(), f"last command on the wire {rig.forces[-1].tolist()} N, not zero"
    assert_safe(rig.forces)


@pytest.mark.parametrize("fault, kind, cause", [("raise RuntimeError('injected fault')", "error", "injected fault"),
                                                ("time.sleep(0.05)", "stall", "no tick")])
def test_a_loop_that_raises_or_stalls_yields_zero_and_an_error_diagnostic(rig_factory, ros_env, fault, kind, cause):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env, [sys.executable, "-c", FAULTY_BRIDGE.replace("FAULT", fault)])
    try:
        rig.wait_for_force(CONTACT, bridge)
        rig.tool = DEEP  # from now on every tick raises, or sleeps 50 ms (10× the stall bound)
        rig.wait_until(lambda: rig.forces and not rig.forces[-1].any(), "zero from the supervisor", bridge)
        first_zero = len(rig.forces) - 1
        del rig.diagnostics[:]
        rig.wait_until(lambda: (rig.loop_level() or (0, ""))[0] == 2, "an ERROR diagnostic", bridge)
        level, message = rig.loop_level()
        assert kind in message and cause in message and "T" in message.split(" at ")[1][:11], message
        rig.spin_for(0.3)
        assert all(not f.any() for f in rig.forces[first_zero:]), "held at zero while the loop fails"
        rig.tool = INSIDE  # the loop is back: a soft start to the contact force
        rig.wait_for_force(CONTACT, bridge)
        assert int(rig.loop_status()[f"{kind}s"]) > 0
        terminate_to_zero(rig, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_a_lowered_clamp_through_the_parameter_service_is_obeyed(rig_factory, ros_env):
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    def request(name, value):
        return SetParameters.Request(parameters=[Parameter(name=name, value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=value))])

    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    client = rig.node.create_client(SetParameters, "/haptic_bridge/set_parameters")
    try:
        rig.wait_for_force(CONTACT, bridge)
        result = rig.call(client, request("max_force_n", 0.05), bridge).results[0]
        answered = time.monotonic()
        assert result.successful, result.reason
        rig.spin_for(0.5)
        after = [f for f, t in zip(rig.forces, rig.arrivals) if t > answered + 0.01]
        assert len(after) > 20 and max(np.linalg.norm(after, axis=1)) <= 0.05 + 1e-9
        refused = rig.call(client, request("rate_hz", 500.0), bridge).results[0]
        assert not refused.successful and "restart" in refused.reason
        unsafe = rig.call(client, request("stiffness_n_per_m", 5000.0), bridge).results[0]
        assert not unsafe.successful and "passive" in unsafe.reason
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_no_device_map_no_force(rig_factory, ros_env):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    rig.node.destroy_publisher(rig._map)  # nobody publishes the map
    bridge = start_bridge(ros_env, device_map_topic="/tool/device_map_of_nobody")
    try:
        rig.wait_until(lambda: len(rig.forces) > 100 and rig.loop_status() is not None, "commands", bridge)
        assert all(not f.any() for f in rig.forces)
        assert "waiting for the device map" in rig.loop_level()[1]
    finally:
        stop(bridge)


def test_a_managed_bridge_zeroes_the_force_on_deactivate(rig_factory, ros_env):
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env, [sys.executable, "-m", "liver_sim.nodes.bridge_node", "--managed"])
    client = rig.node.create_client(ChangeState, "/haptic_bridge/change_state")

    def change(transition: int) -> None:
        assert rig.call(client, ChangeState.Request(transition=Transition(id=transition)), bridge).success

    try:
        change(Transition.TRANSITION_CONFIGURE)
        rig.spin_for(0.3)
        assert not rig.forces, "no command before activate"
        change(Transition.TRANSITION_ACTIVATE)
        rig.wait_for_force(CONTACT, bridge)
        change(Transition.TRANSITION_DEACTIVATE)
        rig.spin_for(0.5)
        assert not rig.forces[-1].any(), "deactivate leaves zero on the wire"
        count = len(rig.forces)
        rig.spin_for(0.3)
        assert len(rig.forces) == count, "nothing after the zero while inactive"
        change(Transition.TRANSITION_ACTIVATE)
        rig.wait_for_force(CONTACT, bridge)
        terminate_to_zero(rig, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)
