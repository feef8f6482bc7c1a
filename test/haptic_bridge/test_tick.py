"""haptic_bridge.tick: one tick of the haptic loop without ROS: passivity in every mode at the longest hold, run-time
limits within the envelope fixed at start, the no-latch depth rate, the device map, the lifetime cap, passive model
updates and the energy the bridge counts."""
import itertools
import math

import numpy as np
import pytest

from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.passivity import GENERATED_LIMIT_J, GenerationMonitor
from haptic_bridge.tick import (
    BridgeTick,
    DepthRate,
    check_passivity,
    checked_change,
    hold_time_s,
    passive_model_update_on,
    passivity_problem,
)
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.local_model import LocalModel

DEFAULTS = BridgeParameters.defaults()
TICKS = itertools.count(0.0, 0.001)
#: The tick period (s) at the default rate_hz: 1 ms.
T = 1.0 / DEFAULTS.rate_hz


def test_passivity_is_checked_at_the_longest_hold_not_the_nominal_period():
    p = BridgeParameters.defaults()
    assert hold_time_s(p) == p.stall_bound_s == 0.005  # ticks 1 ms apart, but up to 5 ms before a zero
    assert passivity_problem(p) is None  # K 190 < 2·0.5/0.005 = 200 N/m
    slow = p.replace(rate_hz=250.0, stall_bound_s=0.002, stiffness_n_per_m=240.0)
    assert hold_time_s(slow) == 0.004 and passivity_problem(slow) is None  # then T is the period: 240 < 250 N/m
    problem = passivity_problem(p.replace(stall_bound_s=0.008))  # 2·0.5/0.008 = 125 N/m
    assert "T=8 ms" in problem and "stall_bound_s" in problem and "< 125 N/m" in problem


def test_depth_rate_drops_a_bad_sample_and_never_latches():
    rate = DepthRate(0.001, 50.0)
    rate.update(0.001)
    rate.update(1e308)        # huge but finite: the difference overflows
    rate.update(float("nan"))  # not finite: dropped
    rate.update(float("inf"))
    rate.update(0.002)
    assert math.isfinite(rate.update(0.0021))


def test_a_huge_input_then_a_good_one_renders_again():
    tick = BridgeTick(DEFAULTS)
    plane = (LocalModel.plane(np.zeros(3), [0.0, 0.0, 1.0]), 0.05)
    for _ in range(300):
        tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    tick.step(next(TICKS), np.array([0.0, 0.0, -1e300]), 0.0, plane, 0.0)
    for _ in range(300):
        out = tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    np.testing.assert_allclose(out, [0.0, 0.0, 0.95], atol=1e-6)


def test_passivity_is_checked_for_every_mode():
    assert passivity_problem(DEFAULTS) is None
    none = DEFAULTS.replace(local_model="none")
    problem = passivity_problem(none)  # 300 N/m held for 1/150 s with 1 N·s/m: needs b > 2 N·s/m
    assert "contact_stiffness_n_per_m" in problem and "T=6.66667 ms" in problem
    check_passivity(none.replace(device_damping_ns_per_m=2.5))
    with pytest.raises(ValueError, match="stiffness_n_per_m"):
        check_passivity(DEFAULTS.replace(stiffness_n_per_m=700.0), scale=2.0)  # felt as 1400 N/m
    BridgeTick(none)  # an offline baseline drives no device: not refused by the tick


@pytest.mark.parametrize("name, looser", [("max_force_n", 2.5), ("max_force_rate_n_per_s", 500.0), ("lifetime_s", 10.0),
                                          ("ramp_time_s", 0.02), ("stiffness_n_per_m", 350.0),
                                          ("damping_ns_per_m", 0.1), ("contact_stiffness_n_per_m", 400.0),
                                          ("contact_damping_ns_per_m", 2.0), ("soft_start_s", 0.15)])
def test_run_time_changes_never_loosen_the_envelope_fixed_at_start(name, looser):
    with pytest.raises(ValueError, match=f"{name}=.* would loosen the safety envelope"):
        checked_change(DEFAULTS, {name: looser})
    tighter = {"soft_start_s": 0.5}.get(name, getattr(DEFAULTS, name) * 0.5)
    tightened = checked_change(DEFAULTS, {name: tighter})
    assert getattr(tightened, name) == tighter
    with pytest.raises(ValueError, match="would loosen"):  # the envelope is the start's, not the current value's
        checked_change(tightened, {name: looser}, start=DEFAULTS)
    start = getattr(DEFAULTS, name)
    assert getattr(checked_change(tightened, {name: start}, start=DEFAULTS), name) == start


def test_the_device_damping_is_read_at_start_only():
    with pytest.raises(ValueError, match="device_damping_ns_per_m: read at start only"):
        checked_change(DEFAULTS, {"device_damping_ns_per_m": 100.0})


def test_run_time_changes_are_checked_or_refused_with_a_reason():
    lowered = checked_change(DEFAULTS, {"max_force_n": 0.05, "stiffness_n_per_m": 100.0})
    assert lowered.max_force_n == 0.05 and DEFAULTS.max_force_n == 2.0
    with pytest.raises(ValueError, match="not passive"):  # within the envelope, not with a device map's scale 4
        checked_change(DEFAULTS, {"max_force_n": 1.0}, scale=4.0)
    with pytest.raises(ValueError, match="restart haptic_bridge"):
        checked_change(DEFAULTS, {"rate_hz": 500.0})
    with pytest.raises(ValueError, match="max_force_rate_n_per_s"):
        checked_change(DEFAULTS, {"max_force_rate_n_per_s": 100.0})
    tick = BridgeTick(DEFAULTS)
    tick.configure(lowered)
    plane = (LocalModel.plane(np.zeros(3), [0.0, 0.0, 1.0]), 0.05)
    for _ in range(300):
        out = tick.step(next(TICKS), np.array([0.0, 0.0, 0.0]), 0.0, plane, 0.0)
    assert np.linalg.norm(out) <= 0.05


def test_no_device_map_renders_zero_and_a_new_map_soft_starts():
    tick = BridgeTick(DEFAULTS, device_map=None)
    plane = (LocalModel.plane(np.zeros(3), [0.0, 0.0, 1.0]), 0.05)
    for _ in range(300):
        assert not tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0).any()
    tick.set_device_map(DeviceMap([math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)]))
    first = tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    assert np.linalg.norm(first) < 0.02
    for _ in range(300):
        out = tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    np.testing.assert_allclose(out, [0.0, 0.95, 0.0], atol=1e-6)


def test_the_marker_lifetime_is_capped_by_lifetime_s():
    tick = BridgeTick(DEFAULTS)
    plane = (LocalModel.plane(np.zeros(3), [0.0, 0.0, 1.0]), 10.0)  # a marker claiming 10 s
    for _ in range(300):
        tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.0)
    for _ in range(20):
        out = tick.step(next(TICKS), np.array([0.0, 0.0, 0.01]), 0.0, plane, 0.2)  # 200 ms old
    assert not out.any()


def test_passive_model_updates_are_on_by_default_exactly_when_a_link_is_emulated():
    p = BridgeParameters.defaults()
    assert not passive_model_update_on(p)
    assert passive_model_update_on(p.replace(link_delay_s=0.05))
    assert passive_model_update_on(p.replace(link_loss_fraction=0.1))
    assert not passive_model_update_on(p.replace(link_delay_s=0.05, passive_model_update="never"))
    assert passive_model_update_on(p.replace(passive_model_update="always"))


def _plane_tick(control: bool) -> BridgeTick:
    p = BridgeParameters.defaults().replace(passivity_control=control, soft_start_s=0.1,
                                            max_force_rate_n_per_s=100000.0)
    return BridgeTick(p)


def test_the_bridge_counts_the_energy_of_what_it_sent_in_the_device_frame():
    """A tip pressed into a fixed plane and drawn back along the same path: the observer's energy is the sum of
    the commands times the motion (samples without latency), and a plane that jumps outward while in contact (a
    model update) gives the hand energy, which the controller then takes back out."""
    plane = LocalModel("plane", True, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.0, 0.0, True, None)
    raised = LocalModel("plane", True, np.array([0.0, 0.0, 0.005]), np.array([0.0, 0.0, 1.0]),
                        np.array([0.0, 0.0, 0.005]), 0.0, 0.0, True, None)
    depths = np.concatenate([np.linspace(0.0, 0.01, 400), np.full(200, 0.01), np.linspace(0.01, 0.0, 400)])
    results = {}
    for control in (False, True):
        tick = _plane_tick(control)
        sent, positions = [], []
        for k, depth in enumerate(depths):
            tip = np.array([0.0, 0.0, 0.015 - depth])
            model = raised if 450 <= k else plane
            tick.sample(k * T, k * T, tip)
            sent.append(tick.step(k * T, tip, 0.0, (model, 1.0), 0.0))
            positions.append(tip)
        expected = sum(float(f @ (x1 - x0)) for f, x0, x1 in zip(sent, positions, positions[1:]))
        assert tick.passivity.energy_j == pytest.approx(expected)
        results[control] = tick.passivity
    assert results[False].energy_j > 0.0             # the raised plane pushed the hand out with more than it took
    assert results[True].energy_j < results[False].energy_j


def test_the_observer_takes_the_stylus_motion_through_the_device_map():
    """With a turned and scaled map the energy is the command (device frame) times the stylus's motion (device frame),
    and the sample places the tool tip through the map."""
    from liver_sim.base.geometry.device_map import DeviceMap

    device_map = DeviceMap([0.0, 0.0, np.sin(np.pi / 8), np.cos(np.pi / 8)], [0.1, 0.0, 0.0], 2.0)
    p = BridgeParameters.defaults()
    tick = BridgeTick(p.replace(stiffness_n_per_m=90.0), device_map)  # passive at this map's scale 2
    tips = [np.array([0.01, 0.02, 0.03]), np.array([0.012, 0.017, 0.034]), np.array([0.011, 0.02, 0.031])]
    forces = [np.array([0.3, -0.2, 0.5]), np.array([-0.1, 0.4, 0.2])]
    assert tick.sample(0.0, 0.0, device_map.liver_to_device(tips[0])) == pytest.approx(tips[0])  # placed by it
    for k, (force, tip) in enumerate(zip(forces, tips[1:])):
        tick.passivity.commanded(k * T + 0.0005, force)
        tick.sample((k + 1) * T, (k + 1) * T, device_map.liver_to_device(tip))
    expected = sum(float(f @ (device_map.liver_to_device(b) - device_map.liver_to_device(a)))
                   for f, a, b in zip(forces, tips, tips[1:]))
    assert tick.passivity.energy_j == pytest.approx(expected, rel=1e-12)


def _pumped_energy(update: str) -> float:
    """A hand resting its stylus on a surface whose delayed model rises and falls 3 mm at 2 Hz (updates at 150 Hz):
    the largest energy generated in a window, by the simulated device's own measure."""
    from liver_sim.phantom.device import PhantomSim
    from liver_sim.tool.scripts import ScriptedTrajectory

    p = BridgeParameters.defaults()
    tick = BridgeTick(p.replace(passive_model_update=update, soft_start_s=0.1))
    rest = np.array([0.0, 0.0, 0.015 - 0.002])  # the hand holds the tip 2 mm into the mean surface
    device = PhantomSim(ScriptedTrajectory("rest", np.zeros(1), rest[np.newaxis]))
    monitor = GenerationMonitor(T)
    model = None
    for k in range(3000):
        now = k * T
        if k % 7 == 0:  # a physics frame
            height = 0.003 * np.sin(2 * np.pi * 2.0 * now)
            point = np.array([0.0, 0.0, height])
            model = LocalModel("plane", True, point, np.array([0.0, 0.0, 1.0]), point, 0.0, 0.0, True, 190.0)
        tick.sample(now, now, device.position.copy())  # the stylus sample of this tick, no latency
        command = tick.step(now, device.position.copy(), 0.0, (model, 1.0), 0.0)
        device.step(T, command)
        monitor.record(now, device.energy_to_hand_j, bool(device.force.any()))
    return monitor.update()


def test_a_passive_model_update_keeps_a_moving_surface_from_pumping_energy_into_the_hand():
    assert _pumped_energy("never") > GENERATED_LIMIT_J
    assert _pumped_energy("always") <= 0.1 * GENERATED_LIMIT_J


def test_after_a_restart_in_contact_a_passive_update_builds_the_contact_again_from_touching():
    """A stall while the hand rests 5 mm deep: a soft start back to the full force would store energy the hand never
    put in. With passive updates the surface comes back touching the tool, and the force with the hand's push."""
    p = BridgeParameters.defaults()
    tick = BridgeTick(p.replace(passive_model_update="always", soft_start_s=0.1))
    plane = LocalModel("plane", True, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.0, 0.0, True, 190.0)
    depths = np.concatenate([np.linspace(-0.005, 0.005, 500), np.full(300, 0.005)])
    forces = []
    for k, depth in enumerate(depths):
        tip = np.array([0.0, 0.0, 0.015 - depth])
        tick.sample(k * T, k * T, tip)
        forces.append(float(np.linalg.norm(tick.step(k * T, tip, 0.0, (plane, 1.0), 0.0))))
        if k == 600:
            tick.restart()  # a stall of the loop, 5 mm deep
    assert forces[599] == pytest.approx(0.95, abs=0.02), "pressed in by the hand: the full force"
    assert max(forces[601:]) < 0.01, "after the restart: no force the hand did not build"


def test_a_comparison_bridge_that_drives_no_device_is_not_refused_for_passivity_at_run_time():
    comparison = DEFAULTS.replace(drives_device=False)
    assert checked_change(comparison, {"max_force_n": 1.0}, scale=4.0).max_force_n == 1.0  # felt as 760 N/m
    with pytest.raises(ValueError, match="not passive"):
        checked_change(DEFAULTS, {"max_force_n": 1.0}, scale=4.0)
    with pytest.raises(ValueError, match="would loosen"):  # the envelope holds all the same
        checked_change(comparison, {"max_force_n": 2.5}, scale=4.0)


def test_a_comparison_bridge_starts_with_a_rendering_it_reports_as_not_passive():
    stiff = DEFAULTS.replace(stiffness_n_per_m=700.0)
    with pytest.raises(ValueError, match="stiffness_n_per_m"):
        BridgeTick(stiff)  # on a device: refused
    comparison = BridgeTick(stiff.replace(drives_device=False))  # no device: it starts
    assert "stiffness_n_per_m" in passivity_problem(comparison.p)  # and the problem stays reportable


def test_the_longest_hold_with_local_model_none_is_the_physics_period_or_the_stall_bound():
    none = DEFAULTS.replace(local_model="none")
    assert hold_time_s(none) == pytest.approx(1.0 / 150.0)               # 6.7 ms > stall_bound_s 5 ms
    assert hold_time_s(none.replace(physics_rate_hz=1000.0)) == 0.005    # then the stall bound is longer
    assert hold_time_s(none.replace(physics_rate_hz=1000.0, stall_bound_s=0.002)) == pytest.approx(0.002)


def _stiff_plane(depth_m: float, stiffness: float = 350.0) -> LocalModel:
    """A plane z = h placed as the physics places it for the tip at the origin: the tool sphere `depth_m` into it,
    K·depth_m the physics force (0.7 N at 2 mm and 350 N/m), K above the bridge's cap of 190 N/m."""
    point = np.array([0.0, 0.0, -(DEFAULTS.tool_radius_m - depth_m)])
    return LocalModel("plane", True, point, np.array([0.0, 0.0, 1.0]), point, 0.0, depth_m, True, stiffness)


def test_a_model_stiffer_than_the_cap_renders_the_physics_force_at_the_physics_pose_and_the_cap_about_it():
    tick = BridgeTick(DEFAULTS.replace(damping_ns_per_m=0.0))
    model, at_pose, deeper = _stiff_plane(0.002), np.zeros(3), np.array([0.0, 0.0, -0.001])
    for k in range(300):  # past the soft start, the tip held at the physics pose
        out = tick.step(k * T, at_pose, 0.0, (model, 0.05), 0.0)
    np.testing.assert_allclose(out, [0.0, 0.0, 350.0 * 0.002], atol=1e-9)  # F, not (190/350)·F
    for k in range(300, 350):  # 1 mm deeper: a spring of the cap
        out = tick.step(k * T, deeper, 0.0, (model, 0.05), 0.0)
    np.testing.assert_allclose(out, [0.0, 0.0, 350.0 * 0.002 + DEFAULTS.stiffness_n_per_m * 0.001], atol=1e-9)


def test_the_glide_and_the_passive_update_take_the_capped_model_the_force_is_rendered_from():
    tick = BridgeTick(DEFAULTS.replace(passive_model_update="always"))
    model, cap = _stiff_plane(0.002), DEFAULTS.stiffness_n_per_m
    rendered = tick.rendered_model(model)
    assert rendered.stiffness_n_per_m == cap and rendered.depth_m == pytest.approx(350.0 * 0.002 / cap)
    tip = np.array([0.0, 0.0, 0.01])
    for k in range(20):  # out of contact: nothing holds the model back
        tick.step(k * T, tip, 0.0, (model, 0.05), 0.0)
    assert tick.rendered_model(model) is rendered  # one capped model per arrival: the glide sees it once
    assert tick.glide.update(rendered, 20 * T) is rendered and tick.passive_update.shown is rendered
    within = LocalModel("plane", True, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.0, 0.002, True, 120.0)
    assert tick.rendered_model(within) is within  # at or below the cap: rendered exactly as it came


def test_a_cap_lowered_at_run_time_still_renders_the_physics_force_at_the_physics_pose():
    tick = BridgeTick(DEFAULTS.replace(damping_ns_per_m=0.0))
    model = _stiff_plane(0.002)
    for k in range(300):
        tick.step(k * T, np.zeros(3), 0.0, (model, 0.05), 0.0)
    tick.configure(checked_change(tick.p, {"stiffness_n_per_m": 120.0}))
    assert tick.rendered_model(model).stiffness_n_per_m == 120.0
    for k in range(300, 330):  # the glide to the surface of the new cap
        out = tick.step(k * T, np.zeros(3), 0.0, (model, 0.05), 0.0)
    np.testing.assert_allclose(out, [0.0, 0.0, 350.0 * 0.002], atol=1e-9)
