"""haptic_bridge as a real process, talked to over DDS on loopback in a domain of its own.

The test side plays the physics and the tool: it publishes the device map (latched, as liver_tool
does), refreshes a local model (or a physics wrench) and the tool pose every 10 ms, and listens to the
force command. Every wait is bounded; nothing asserts on timing. The bridge is stopped (SIGINT, then
SIGKILL) in `finally`.
"""
import signal
import sys
import time
from datetime import datetime

import numpy as np
import pytest

from haptic_bridge.parameters import PARAMETERS as BRIDGE
from liver_sim.base.local_model import LocalModel
from liver_sim.nodes.bridge_shell import ZERO_NOT_ACKED
from msg_defs.forces import force_message_type
from msg_defs.topics import TOPICS

from bridge_rig import (
    ABOVE,
    CONTACT,
    DEEP,
    EXPECTED_INSIDE,
    INSIDE,
    LOOP,
    MAX_FORCE_N,
    NEARLY_CONTACT_N,
    QUARTER_TURN_X,
    ROTATION,
    SOFT_START_S,
    STIFFNESS_N_PER_M,
    UP,
    WAIT_S,
    Rig,
    WriterLog,
    assert_safe,
    local_model,
    seconds_of,
    start_bridge,
    stop,
    terminate_to_zero,
    wait_for_exit,
)


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
        np.testing.assert_allclose(EXPECTED_INSIDE, [0.0, 0.95, 0.0], atol=1e-12)  # the map is not the identity
        assert set(rig.stamps[-20:]) <= rig.pose_stamps, "stamped with the tool pose it was computed from"
        rig.tool = DEEP  # 2.85 N asked for: clamped to max_force_n along the same direction
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
        rig.wait_for_stale_zero(bridge)
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


@pytest.mark.parametrize("bad_input, counter", [("nan_pose", "bad_device_pose"),
                                                ("zero_quaternion", "bad_local_model"),
                                                ("huge_marker", "bad_local_model")])
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


def assert_soft_start(rig: Rig, start_s: float) -> None:
    """The force rose from zero over the soft start, which began at `start_s` (s, the commands' clock) or later.
    Read by the commands' stamps, since a starved test side reads late and may miss some. A command is stamped with
    the tool pose it was computed from, at most the pose lifetime (and 10 ms of transit) older than its tick: every
    command stamped within SOFT_START_S of `start_s` stays under the ramp from zero at `start_s` shifted by that,
    and one in its first half was read (a force back at once, without the ramp, is well above it)."""
    pose_age_s = BRIDGE["lifetime_s"].default + 0.01
    ramp = [(seconds_of(stamp) - start_s, float(np.linalg.norm(force)))
            for force, stamp in zip(rig.forces, rig.stamps) if 0.0 < seconds_of(stamp) - start_s < SOFT_START_S]
    assert any(t < SOFT_START_S / 2 for t, _ in ramp), "no command read in the first half of the soft start"
    full = float(np.linalg.norm(CONTACT))
    over = [(t, norm) for t, norm in ramp if norm > full * (t + pose_age_s) / SOFT_START_S + 0.05]
    assert not over, f"soft start: above the ramp from zero {over[:3]}"


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP, signal.SIGQUIT, signal.SIGPIPE])
def test_a_signal_in_contact_leaves_zero_as_the_last_command_after_a_soft_start(rig_factory, ros_env, sig):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_until(lambda: rig.forces and rig.forces[-1].any(), "the first force", bridge)
        first = len(rig.forces) - 1
        rig.wait_for_force(CONTACT, bridge)
        reached = next(i for i in range(first, len(rig.forces)) if np.linalg.norm(rig.forces[i]) > NEARLY_CONTACT_N)
        # by the commands' stamps (the tool poses they were computed from, 10 ms apart), not by when this busy test
        # side got to read them
        seconds = [seconds_of(stamp) for stamp in rig.stamps]
        assert seconds[reached] - seconds[first] >= 0.1, "soft start: 0.2 s from zero to full force"
        in_contact = len(rig.forces)
        bridge.send_signal(sig)
        wait_for_exit(rig, bridge)
    finally:
        log = stop(bridge)
    assert bridge.returncode == 0
    assert ZERO_NOT_ACKED not in log, "this test side acknowledges every command it reads"
    assert np.linalg.norm(rig.forces[in_contact - 1]) > 0.9, "in contact when the signal came"
    assert not rig.forces[-1].any(), f"last command on the wire {rig.forces[-1].tolist()} N, not zero"
    assert_safe(rig.forces)


def test_ctrl_z_is_ignored_and_a_stop_and_continue_resumes_with_a_soft_start(rig_factory, ros_env):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        bridge.send_signal(signal.SIGTSTP)  # Ctrl-Z: ignored, the loop goes on
        count = len(rig.forces)
        rig.wait_until(lambda: len(rig.forces) > count + 200, "commands after SIGTSTP", bridge)
        assert bridge.poll() is None
        rig.wait_for_force(CONTACT, bridge)
        bridge.send_signal(signal.SIGSTOP)  # cannot be caught: the process freezes whole
        time.sleep(0.3)
        continued_s = seconds_of(rig.node.get_clock().now().seconds_nanoseconds())  # before: it cannot tick sooner
        bridge.send_signal(signal.SIGCONT)
        rig.wait_until(lambda: rig.stamps and seconds_of(rig.stamps[-1]) > continued_s + SOFT_START_S,
                       "commands after SIGCONT", bridge)
        rig.wait_for_force(CONTACT, bridge)
        assert_soft_start(rig, continued_s)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def fault_start_s(rig: Rig, kind: str, cause: str, since_s: float) -> float:
    """System-clock time (s) at which the first `kind` event naming `cause` began, at or after `since_s`, in the
    bridge's loop statuses ("<kind> at <ISO time, ms>: <cause> (zero held …)", events joined by "; ")."""
    starts = [datetime.fromisoformat(event[len(kind) + 4:].split(": ", 1)[0]).timestamp()
              for array in rig.diagnostics for status in array.status if status.name == LOOP
              for event in status.message.split("; ") if event.startswith(f"{kind} at ") and cause in event]
    starts = [start for start in starts if start >= since_s - 0.001]
    assert starts, f"no {kind} event naming {cause!r} since the fault was set"
    return min(starts)


@pytest.mark.parametrize("fault, kind, cause", [("raise RuntimeError('injected fault')", "error", "injected fault"),
                                                ("time.sleep(0.05)", "stall", "no tick")])
def test_a_loop_that_raises_or_stalls_yields_zero_and_an_error_diagnostic(rig_factory, ros_env, fault, kind, cause):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env, [sys.executable, "-c", FAULTY_BRIDGE.replace("FAULT", fault)])
    try:
        rig.wait_for_force(CONTACT, bridge)
        del rig.diagnostics[:]
        deep_s = time.time()
        rig.tool = DEEP  # from now on every tick raises, or sleeps 50 ms (10× the stall bound)
        rig.wait_until(lambda: rig.forces and not rig.forces[-1].any(), "zero from the supervisor", bridge)
        rig.wait_until(lambda: (rig.loop_level() or (0, ""))[0] == 2, "an ERROR diagnostic", bridge)
        level, message = rig.loop_level()
        assert kind in message and cause in message and "T" in message.split(" at ")[1][:11], message
        rig.spin_for(0.3)
        # every command stamped after the fault began is zero (its time is in ms: 1 ms more). Read by stamp: a
        # starved test side may read, after a watchdog zero, commands sent before the fault.
        fault_s = fault_start_s(rig, kind, cause, deep_s)
        after = [(seconds_of(stamp) - fault_s, force) for force, stamp in zip(rig.forces, rig.stamps)
                 if seconds_of(stamp) >= fault_s + 0.001]
        assert not any(force.any() for _, force in after), \
            ("held at zero while the loop fails", [(t, force) for t, force in after if force.any()][:3])
        rig.tool = INSIDE  # the loop is back: a soft start to the contact force
        rig.wait_for_force(CONTACT, bridge)
        assert int(rig.loop_status()[f"{kind}s"]) > 0
        terminate_to_zero(rig, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_the_parameter_service_lowers_the_clamp_and_never_loosens_the_envelope(rig_factory, ros_env):
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
        answered = rig.node.get_clock().now().seconds_nanoseconds()
        assert result.successful, result.reason
        # the commands computed from tool poses published after the answer: the bridge received those poses after
        # it had taken the change (by their stamps, not by when this busy test side got to read the commands)
        rig.wait_until(lambda: sum(stamp > answered for stamp in rig.stamps[-30:]) > 20, "commands after", bridge)
        after = [f for f, stamp in zip(rig.forces, rig.stamps) if stamp > answered]
        assert max(np.linalg.norm(after, axis=1)) <= 0.05 + 1e-9
        refused = rig.call(client, request("rate_hz", 500.0), bridge).results[0]
        assert not refused.successful and "restart" in refused.reason
        for name, looser in (("stiffness_n_per_m", 10000.0), ("lifetime_s", 10.0), ("max_force_n", 3.0)):
            loosened = rig.call(client, request(name, looser), bridge).results[0]
            assert not loosened.successful and "would loosen the safety envelope" in loosened.reason, name
        for name, looser in (("model_glide_s", 0.1), ("soft_start_s", 0.1)):  # more lag, a faster rise
            loosened = rig.call(client, request(name, looser), bridge).results[0]
            assert not loosened.successful and "would loosen the safety envelope" in loosened.reason, name
        for name, value in (("device_damping_ns_per_m", 100.0), ("depth_rate_cutoff_hz", 1.0)):
            fixed = rig.call(client, request(name, value), bridge).results[0]
            assert not fixed.successful and "read at start only" in fixed.reason, name
        restored = rig.call(client, request("max_force_n", 2.0), bridge).results[0]  # back to the start's clamp
        assert restored.successful, restored.reason
        rig.wait_for_force(CONTACT, bridge)
    finally:
        stop(bridge)
    assert_safe(rig.forces)


def test_another_publisher_on_the_force_topic_holds_the_bridge_at_zero(rig_factory, ros_env):
    rig = rig_factory()
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        rival = rig.node.create_publisher(force_message_type("wrench_stamped"), TOPICS["servo_cf"].name,
                                          TOPICS["servo_cf"].qos)  # a second bridge or driver on the device
        rig.wait_for_force(np.zeros(3), bridge)
        rig.wait_until(lambda: "another publisher" in (rig.loop_level() or (0, ""))[1], "a diagnostic", bridge)
        assert rig.loop_level()[0] == 2 and "test_haptic_bridge" in rig.loop_level()[1]
        rig.node.destroy_publisher(rival)
        rig.wait_for_force(CONTACT, bridge)  # driving again once it has gone
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
        rig.drain()
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


def test_a_managed_bridges_force_writer_is_a_lifecycle_publisher_sending_only_while_active(ros_domain_id):
    """As the ros2/demos lifecycle talker: the writer is made in on_configure, enabled by activate and disabled by
    deactivate (after the loop's last zero), so an inactive bridge cannot send a command whatever its threads do."""
    import rclpy
    from rclpy.lifecycle import LifecyclePublisher, TransitionCallbackReturn

    from liver_sim.nodes.bridge_node import ManagedHapticBridge

    rclpy.init()
    bridge = ManagedHapticBridge()
    try:
        assert bridge.trigger_configure() == TransitionCallbackReturn.SUCCESS
        writer = bridge.shell.output.publisher
        assert isinstance(writer, LifecyclePublisher) and not writer.is_activated
        assert bridge.trigger_activate() == TransitionCallbackReturn.SUCCESS
        assert writer.is_activated and bridge.shell.loop.is_alive()
        assert bridge.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
        assert not writer.is_activated and bridge.shell.supervisor.closed
        assert bridge.trigger_cleanup() == TransitionCallbackReturn.SUCCESS  # the writer destroyed with the shell
        assert writer not in bridge._managed_entities
    finally:
        bridge.close()
        bridge.destroy_node()
        rclpy.shutdown()


def test_after_a_stop_the_bridges_one_writer_ends_on_zero(rig_factory, ros_env):
    """DDS keeps order within one writer only: the loop's commands and the supervisor's zeros go on one writer, so
    no retransmitted command can arrive after the last zero (a driver that holds the last command would keep
    pushing)."""
    rig = rig_factory()
    writers = WriterLog(rig)
    rig.model, rig.tool = local_model("plane"), INSIDE
    bridge = start_bridge(ros_env)
    try:
        rig.wait_for_force(CONTACT, bridge)
        writers.read()
        bridge.send_signal(signal.SIGTERM)
        wait_for_exit(rig, bridge)
        writers.read()
    finally:
        stop(bridge)
        writers.close()
    last = writers.last_by_writer()
    assert len(last) == 1, "one writer for the loop's commands and the supervisor's zeros"
    assert all(not force.any() for force in last.values()), {gid.hex(): f.tolist() for gid, f in last.items()}
    assert any(force.any() for _, force in writers.received), "in contact before the stop"
