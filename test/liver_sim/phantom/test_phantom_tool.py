"""Scripted tool trajectories and the simulated PHANToM stylus (pure cores, no ROS)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.geometry.rotations import matrix_to_quaternion, quaternion_to_matrix
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.phantom.device import PhantomSim, StylusParams
from liver_sim.tool.scripts import SCRIPT_NAMES, ScriptSettings, make_script

SETTINGS = ScriptSettings(anchor_m=(0.01, -0.02, 0.05), tool_radius_m=0.015, depth_m=0.012, clearance_m=0.008,
                          slide_m=0.03, approach_s=0.4, press_s=0.6, hold_s=0.3, slide_s=0.5, withdraw_s=0.2,
                          rest_s=0.7)
CONTACT_Z = 0.05 + 0.015
UP_Z = CONTACT_Z + 0.008
DEEP_Z = CONTACT_Z - 0.012


def sampled(trajectory, dt=0.001):
    times = np.arange(0.0, trajectory.duration_s + 0.5, dt)
    return times, np.array([trajectory.position_at(t) for t in times])


def test_default_anchor_is_the_default_livers_dome():
    mesh = default_liver()
    skin = mesh.points[mesh.skin_nodes]
    np.testing.assert_allclose(ScriptSettings().anchor_m, skin[np.argmax(skin[:, 2])], atol=1e-6)


@pytest.mark.parametrize("name", ["press", "press_release", "slide", "press_slide_release", "pull"])
def test_pressing_scripts_start_above_contact_and_reach_depth(name):
    times, points = sampled(make_script(name, SETTINGS))
    np.testing.assert_allclose(points[0], [0.01, -0.02, UP_Z])
    assert points[:, 2].min() == pytest.approx(DEEP_Z)
    np.testing.assert_allclose(points[:, 1], -0.02)
    assert np.all(np.abs(np.diff(points, axis=0)) < 1e-3), "the tip moves smoothly, without jumps"


@pytest.mark.parametrize("name", ["press_release", "slide", "press_slide_release", "withdraw"])
def test_releasing_scripts_return_to_clearance(name):
    trajectory = make_script(name, SETTINGS)
    assert trajectory.position_at(trajectory.duration_s)[2] == pytest.approx(UP_Z)
    assert trajectory.position_at(trajectory.duration_s + 10.0)[2] == pytest.approx(UP_Z)


def test_press_holds_at_depth_and_withdraw_starts_there():
    press = make_script("press", SETTINGS)
    assert press.position_at(press.duration_s + 5.0)[2] == pytest.approx(DEEP_Z)
    assert make_script("withdraw", SETTINGS).position_at(0.0)[2] == pytest.approx(DEEP_Z)


def test_waypoints_are_reached_with_cosine_easing():
    trajectory = make_script("press", SETTINGS)
    assert trajectory.position_at(0.4)[2] == pytest.approx(CONTACT_Z)
    assert trajectory.position_at(0.2)[2] == pytest.approx((UP_Z + CONTACT_Z) / 2)
    eased = 0.5 - 0.5 * math.cos(math.pi * 0.25)
    assert trajectory.position_at(0.1)[2] == pytest.approx(UP_Z + eased * (CONTACT_Z - UP_Z))


@pytest.mark.parametrize("name", ["slide", "press_slide_release"])
def test_slides_reach_slide_m_along_x_at_depth(name):
    times, points = sampled(make_script(name, SETTINGS))
    farthest = np.argmax(points[:, 0])
    assert points[farthest, 0] == pytest.approx(0.01 + 0.03)
    assert points[farthest, 2] == pytest.approx(DEEP_Z)
    assert points[-1, 0] == pytest.approx(0.01), "back above the start at the end"


def test_hold_stays_above_contact():
    trajectory = make_script("hold", SETTINGS)
    assert trajectory.duration_s == 0.0
    np.testing.assert_allclose(trajectory.position_at(3.0), [0.01, -0.02, UP_Z])


def test_start_delay_waits_at_the_start_point():
    delayed = make_script("press", replace(SETTINGS, start_delay_s=2.0))
    plain = make_script("press", SETTINGS)
    assert delayed.duration_s == pytest.approx(plain.duration_s + 2.0)
    np.testing.assert_allclose(delayed.position_at(1.9), plain.position_at(0.0))
    np.testing.assert_allclose(delayed.position_at(2.5), plain.position_at(0.5))


def test_looping_repeats_the_script():
    trajectory = make_script("press_release", replace(SETTINGS, loop=True))
    for t in (0.1, 0.5, 1.3, 2.0):
        np.testing.assert_allclose(trajectory.position_at(t + 3 * trajectory.duration_s),
                                   trajectory.position_at(t), atol=1e-12)


def test_unknown_script_is_refused_by_parameter_name():
    with pytest.raises(ValueError, match="script"):
        make_script("poke", SETTINGS)


def test_pull_presses_then_pulls_back_along_z_and_stays():
    settings = replace(SETTINGS, pull_m=0.04)
    trajectory = make_script("pull", settings)
    times, points = sampled(trajectory)
    pulled = DEEP_Z + 0.04
    assert points[:, 2].max() == pytest.approx(pulled)
    assert times[np.argmax(points[:, 2])] > times[np.argmin(points[:, 2])], "the pull follows the press"
    assert trajectory.position_at(trajectory.duration_s + 5.0)[2] == pytest.approx(pulled)
    np.testing.assert_allclose(points[:, :2], [[0.01, -0.02]] * len(points))


@pytest.mark.parametrize("name", ["press", "withdraw", "pull"])
def test_scripts_that_do_not_end_at_their_start_refuse_to_loop(name):
    with pytest.raises(ValueError, match="loop_script"):
        make_script(name, replace(SETTINGS, loop=True))


@pytest.mark.parametrize("field, value", [("depth_m", -0.01), ("press_s", math.nan), ("anchor_m", (0.0, 1.0))])
def test_bad_settings_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        make_script("press", replace(SETTINGS, **{field: value}))


def hold_sim(**params):
    return PhantomSim(make_script("hold", SETTINGS), params=StylusParams(**params))


def settle(sim, force, seconds=2.0, dt=0.001):
    for _ in range(round(seconds / dt)):
        sim.step(dt, force)
    return sim.position


def test_free_stylus_converges_to_the_hand_target():
    sim = hold_sim()
    target = sim.hand_target(0.0)
    sim.position = target + [0.02, -0.01, 0.03]
    np.testing.assert_allclose(settle(sim, np.zeros(3)), target, atol=1e-6)
    np.testing.assert_allclose(sim.velocity, 0.0, atol=1e-5)


def test_free_stylus_follows_the_script():
    sim = PhantomSim(make_script("press_release", SETTINGS))
    trajectory = sim.trajectory
    errors = [np.linalg.norm(sim.step(0.001, np.zeros(3)) - trajectory.position_at(sim.time_s))
              for _ in range(round(trajectory.duration_s / 0.001))]
    assert max(errors) < 2e-3
    np.testing.assert_allclose(sim.position, trajectory.position_at(trajectory.duration_s), atol=1e-4)


def test_constant_force_shifts_the_equilibrium_by_force_over_stiffness():
    sim = hold_sim(hand_stiffness_n_per_m=250.0)
    target = sim.hand_target(0.0)
    np.testing.assert_allclose(settle(sim, [0.0, 0.0, 1.0]), target + [0.0, 0.0, 1.0 / 250.0], atol=1e-7)


def test_commanded_force_is_clamped_to_the_phantom_limit():
    sim = hold_sim()
    target = sim.hand_target(0.0)
    np.testing.assert_allclose(settle(sim, [10.0, 0.0, 0.0]), target + [3.3 / 200.0, 0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(sim.force, [3.3, 0.0, 0.0])


def test_max_force_above_the_phantom_limit_is_refused():
    with pytest.raises(ValueError, match="max_force_n"):
        hold_sim(max_force_n=4.0)


@pytest.mark.parametrize("force", [[math.nan, 0.0, 1.0], [0.0, math.inf, 0.0]])
def test_non_finite_command_counts_as_zero(force):
    sim = hold_sim()
    target = sim.hand_target(0.0)
    np.testing.assert_allclose(settle(sim, force), target, atol=1e-9)
    assert np.isfinite(sim.position).all()
    np.testing.assert_allclose(sim.force, 0.0)


def test_stylus_stays_in_the_workspace_box():
    sim = hold_sim(workspace_half_m=0.05)
    position = settle(sim, [0.0, 0.0, 3.3])
    assert position[2] == pytest.approx(0.05)
    assert np.all(np.abs(position) <= 0.05)
    assert sim.velocity[2] == 0.0


def test_hand_target_uses_the_inverse_device_map():
    device_map = DeviceMap([0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)], [0.1, 0.0, -0.05], 2.0)
    sim = PhantomSim(make_script("press_release", SETTINGS), device_map)
    for t in (0.0, 0.7, 1.2):
        np.testing.assert_allclose(device_map.device_to_liver(sim.hand_target(t)),
                                   sim.trajectory.position_at(t), atol=1e-12)


def test_advance_to_steps_until_the_given_time_and_skips_long_stalls():
    sim = hold_sim()
    assert sim.advance_to(0.0105, np.zeros(3), 0.001) == 10
    assert sim.time_s == pytest.approx(0.010)
    assert sim.advance_to(0.0104, np.zeros(3), 0.001) == 0
    assert sim.advance_to(60.0, np.zeros(3), 0.001) == 100
    assert sim.time_s == pytest.approx(60.0)


def test_device_samples_are_mapped_into_the_liver_frame():
    rotation = [0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]  # 90° about z
    mapping = DeviceMap(rotation, [0.1, 0.2, 0.3], 2.0, workspace_radius_m=0.3)
    position, orientation = mapping.pose([0.01, 0.02, 0.03], [0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(position, [0.1 - 0.04, 0.2 + 0.02, 0.3 + 0.06])
    np.testing.assert_allclose(orientation, rotation, atol=1e-12)
    with pytest.raises(ValueError, match="workspace_radius_m"):
        mapping.pose([0.4, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="not finite"):
        mapping.pose([math.nan, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="quaternion"):
        mapping.pose([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0])


RANDOM_QUATERNIONS = [q / np.linalg.norm(q) for q in np.random.default_rng(7).normal(size=(5, 4))]


@pytest.mark.parametrize("q", [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
                               [0.6, 0.0, 0.0, 0.8], [0.0, 0.6, 0.0, 0.8]] + RANDOM_QUATERNIONS)
def test_matrix_to_quaternion_inverts_quaternion_to_matrix(q):
    q = np.asarray(q) if q[3] >= 0 else -np.asarray(q)
    np.testing.assert_allclose(matrix_to_quaternion(quaternion_to_matrix(q)), q, atol=1e-12)


def test_all_script_names_build():
    for name in SCRIPT_NAMES:
        assert make_script(name, SETTINGS).name == name


def test_explore_taps_and_strokes_the_surface_at_hand_speed():
    trajectory = make_script("explore", SETTINGS)
    assert trajectory.cyclic
    times, points = sampled(trajectory)
    starts, ends = trajectory.times_s[:-1], trajectory.times_s[1:]
    middles = ((starts + ends) / 2)[ends - starts > 1e-3]  # an eased move is fastest half-way
    peaks = np.array([np.linalg.norm(trajectory.position_at(t + 5e-4) - trajectory.position_at(t - 5e-4)) / 1e-3
                      for t in middles])
    moving = peaks[peaks > 1e-6]
    assert len(moving) >= 20 and np.all((moving >= 0.05) & (moving <= 0.2)), moving  # every move at hand speed
    deep = points[:, 2] <= DEEP_Z + 1e-9
    tapped = {tuple(np.round(p[:2], 4)) for p in points[deep]}
    assert len(tapped) > 5 and points[:, 2].min() == pytest.approx(DEEP_Z)  # presses depth_m at several places
    stroke = np.flatnonzero(deep)
    in_contact_travel = np.linalg.norm(np.diff(points[stroke, :2], axis=0), axis=1)
    assert in_contact_travel[np.diff(stroke) == 1].sum() > 2 * SETTINGS.slide_m  # strokes along the surface at depth
    with pytest.raises(ValueError, match="hand_speed_m_s"):
        make_script("explore", replace(SETTINGS, hand_speed_m_s=0.0))


def test_a_device_samples_liver_orientation_is_the_map_rotation_times_its_own(rng):
    for _ in range(200):
        device_map = DeviceMap(rng.normal(size=4), rng.normal(size=3) * 0.1, float(rng.uniform(0.5, 2.0)))
        orientation = rng.normal(size=4) * 10.0 ** rng.uniform(-3, 3)
        _, liver = device_map.pose(rng.normal(size=3) * 0.05, orientation)
        expected = matrix_to_quaternion(device_map.rotation @ quaternion_to_matrix(orientation))
        np.testing.assert_allclose(liver, expected, atol=1e-12)
        assert liver[3] >= 0.0 and math.isclose(np.linalg.norm(liver), 1.0)
    with pytest.raises(ValueError, match="quaternion must be a finite, non-zero"):
        DeviceMap().pose(np.zeros(3), [0.0, 0.0, 0.0, 0.0])
