"""haptic_bridge.rendering: passive model updates, the glide between local models, the penalty force, the passivity
bounds and the energy a contact stores."""
import math

import numpy as np
import pytest

from haptic_bridge.rendering import (
    ModelGlide,
    blend,
    capped,
    contact_force,
    contact_potential,
    depth_for_potential,
    max_passive_stiffness,
    passivity_damping_min,
    retreated,
)
from liver_sim.base.local_model import LocalModel, penetration

UP = np.array([0.0, 0.0, 1.0])


def test_a_passive_model_update_stores_no_more_than_the_hand_put_in():
    from haptic_bridge.rendering import PassiveModelUpdate, contact_potential

    tip = np.array([0.0, 0.0, 0.0])
    up = np.array([0.0, 0.0, 1.0])

    def plane(height):
        return LocalModel("plane", True, up * height, up, up * height, 0.0, 0.0, True, 100.0)

    def depth(model):
        return penetration(model, tip)[0]

    def admit(update, height, budget_j):
        return depth(update.admit(plane(height), depth, lambda m: 100.0, budget_j))

    update = PassiveModelUpdate(max_force_n=2.0)
    assert admit(update, 0.004, 0.0) == pytest.approx(0.0) and update.held_back  # first contact: up to touching
    assert admit(update, -0.001, 0.0) == 0.0 and not update.held_back            # away from the tool: at once
    update.shown = plane(0.002)                                                   # 2 mm deep, storing 0.2 mJ
    paid = contact_potential(0.003, 100.0, 2.0)                                   # the hand put in 0.45 mJ
    assert admit(update, 0.005, paid) == pytest.approx(0.003) and update.held_back  # 5 mm asked: 3 mm paid
    assert admit(update, 0.001, 0.0) == pytest.approx(0.001)                         # backing off: at once
    assert admit(update, 0.005, 1.0) == pytest.approx(0.005) and not update.held_back


# -- the penalty force: F = max(0, K·depth + B·depth_rate)·direction
def test_the_penalty_force_is_stiffness_times_depth_plus_damping_times_rate_along_the_direction():
    direction = np.array([0.0, 0.6, 0.8])
    np.testing.assert_allclose(contact_force(0.01, 0.5, direction, 100.0, 2.0), 2.0 * direction)  # 1 N + 1 N
    np.testing.assert_allclose(contact_force(0.01, 0.0, direction, 100.0, 2.0), 1.0 * direction)


def test_the_penalty_force_never_pulls_and_is_zero_out_of_contact():
    direction = UP
    # withdrawing fast: K·d + B·ḋ = 1 − 2 < 0, so the damping slows the push to zero but never pulls
    np.testing.assert_array_equal(contact_force(0.01, -1.0, direction, 100.0, 2.0), np.zeros(3))
    # just under the balance it still pushes, a little
    assert contact_force(0.01, -0.49, direction, 100.0, 2.0)[2] == pytest.approx(0.02)
    # out of contact (depth 0, or the tool above the surface), however fast it moves in
    for depth in (0.0, -0.01):
        np.testing.assert_array_equal(contact_force(depth, 5.0, direction, 100.0, 2.0), np.zeros(3))


# -- Colgate's bound b > K·T/2 + |B|, both ways
def test_the_smallest_passive_damping_is_half_k_t_plus_the_virtual_damping():
    assert passivity_damping_min(200.0, 0.005) == pytest.approx(0.5)
    assert passivity_damping_min(200.0, 0.005, virtual_damping=-0.25) == pytest.approx(0.75)  # |B| adds


def test_the_largest_passive_stiffness_is_the_inverse_and_zero_when_the_virtual_damping_eats_the_margin():
    assert max_passive_stiffness(0.5, 0.005) == pytest.approx(200.0)
    assert max_passive_stiffness(0.5, 0.005, virtual_damping=0.25) == pytest.approx(100.0)
    for stiffness, period, virtual in ((190.0, 0.001, 0.0), (37.0, 0.0066, 0.3), (1000.0, 0.0002, 1.5)):
        b = passivity_damping_min(stiffness, period, virtual)
        assert max_passive_stiffness(b, period, virtual) == pytest.approx(stiffness)
    assert max_passive_stiffness(0.5, 0.005, virtual_damping=0.5) == 0.0
    assert max_passive_stiffness(0.5, 0.005, virtual_damping=-0.7) == 0.0


@pytest.mark.parametrize("call, name", [
    (lambda: passivity_damping_min(-1.0, 0.001), "stiffness"),
    (lambda: passivity_damping_min(100.0, 0.0), "period"),
    (lambda: passivity_damping_min(100.0, 0.001, math.nan), "virtual_damping"),
    (lambda: max_passive_stiffness(-0.1, 0.001), "damping"),
    (lambda: max_passive_stiffness(0.5, -0.001), "period"),
])
def test_the_bounds_refuse_bad_arguments_by_name(call, name):
    with pytest.raises(ValueError, match=f"^{name} must be finite"):
        call()


# -- the energy a rendered contact stores
def test_the_contact_potential_is_the_integral_of_the_clamped_force():
    k, f_max = 100.0, 2.0  # the clamp is reached 20 mm deep
    assert contact_potential(0.01, k, f_max) == pytest.approx(0.5 * k * 0.01 ** 2)
    assert contact_potential(0.02, k, f_max) == pytest.approx(0.02)  # ½·K·d² at the clamp's depth
    assert contact_potential(0.03, k, f_max) == pytest.approx(0.02 + f_max * 0.01)  # then F_max per metre
    depths = np.linspace(0.0, 0.05, 5001)
    force = np.minimum(k * depths, f_max)
    integral = float(np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(depths)))  # trapezoids: exact here
    assert contact_potential(0.05, k, f_max) == pytest.approx(integral, rel=1e-9)
    assert contact_potential(0.0, k, f_max) == 0.0 and contact_potential(-0.01, k, f_max) == 0.0
    assert contact_potential(0.01, 0.0, f_max) == 0.0


@pytest.mark.parametrize("depth_m", [0.001, 0.0199, 0.0201, 0.05])
def test_the_depth_for_a_potential_inverts_it_on_both_sides_of_the_clamp(depth_m):
    energy = contact_potential(depth_m, 100.0, 2.0)
    assert depth_for_potential(energy, 100.0, 2.0) == pytest.approx(depth_m, rel=1e-12)
    assert depth_for_potential(0.0, 100.0, 2.0) == 0.0 and depth_for_potential(0.01, 0.0, 2.0) == 0.0


@pytest.mark.parametrize("model", [LocalModel.plane([0.0, 0.0, 0.01], [0.0, 1.0, 1.0]),
                                   LocalModel.sphere([0.0, 0.0, -0.05], 0.07)])
def test_a_retreated_model_just_touches_the_tool_that_was_that_deep_in_it(model):
    tip, radius = np.array([0.001, 0.0, 0.02]), 0.015
    depth = penetration(model, tip, radius)[0]
    assert depth > 0.005
    assert penetration(retreated(model, depth), tip, radius)[0] == pytest.approx(0.0, abs=1e-12)
    assert penetration(retreated(model, depth - 0.001), tip, radius)[0] == pytest.approx(0.001)


# -- blending two local models, and gliding from one to the next
def test_a_blend_interpolates_a_plane_and_renormalises_its_normal():
    start = LocalModel.plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], stiffness_n_per_m=100.0)
    target = LocalModel.plane([0.02, 0.0, 0.01], [1.0, 0.0, 0.0], stiffness_n_per_m=300.0)
    half = blend(start, target, 0.5)
    np.testing.assert_allclose(half.point, [0.01, 0.0, 0.005])
    np.testing.assert_allclose(half.normal, [math.sqrt(0.5), 0.0, math.sqrt(0.5)])
    assert half.stiffness_n_per_m == pytest.approx(200.0) and half.kind == "plane"
    np.testing.assert_allclose(blend(start, target, 0.25).point, [0.005, 0.0, 0.0025])
    assert blend(start, target, 1.0) is target and blend(start, target, 7.0) is target  # clipped to 1
    np.testing.assert_allclose(blend(start, target, -3.0).point, start.point)          # clipped to 0


def test_a_blend_interpolates_a_sphere_centre_and_radius():
    start, target = LocalModel.sphere([0.0, 0.0, 0.0], 0.05), LocalModel.sphere([0.0, 0.04, 0.0], 0.07)
    half = blend(start, target, 0.5)
    np.testing.assert_allclose(half.centre, [0.0, 0.02, 0.0])
    assert half.radius_m == pytest.approx(0.06) and half.stiffness_n_per_m is None


def test_a_blend_gives_the_target_where_no_way_between_exists():
    target = LocalModel.plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    assert blend(None, target, 0.5) is target
    assert blend(LocalModel.sphere([0.0, 0.0, 0.0], 0.05), target, 0.5) is target      # another kind
    assert blend(LocalModel.invalid(), target, 0.5) is target                          # no surface before
    assert blend(LocalModel.plane([0.0, 0.0, 0.0], [0.0, 0.0, -1.0]), target, 0.5) is target  # opposite normals


def test_a_glide_spreads_a_new_model_over_its_duration():
    glide = ModelGlide(0.01)
    first = LocalModel.plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    second = LocalModel.plane([0.0, 0.0, 0.004], [0.0, 0.0, 1.0])
    assert glide.update(first, 1.0) is first                      # nothing shown before: at once
    np.testing.assert_allclose(glide.update(second, 1.002).point, [0.0, 0.0, 0.0])  # the glide starts
    np.testing.assert_allclose(glide.update(second, 1.007).point, [0.0, 0.0, 0.002])  # halfway after 5 ms
    assert glide.update(second, 1.012) is second                  # there after 10 ms
    assert glide.update(None, 1.013) is None                      # no surface: at once


def test_a_glide_of_zero_renders_each_model_at_once_and_refuses_a_negative_duration():
    glide = ModelGlide(0.0)
    models = [LocalModel.plane([0.0, 0.0, z], [0.0, 0.0, 1.0]) for z in (0.0, 0.003)]
    assert [glide.update(m, t) for m, t in zip(models, (0.0, 0.001))] == models
    with pytest.raises(ValueError, match="^duration_s must be finite and >= 0"):
        ModelGlide(-0.001)


CAP = 190.0


def _physics_model(kind, stiffness, depth, tool_radius=0.003):
    """A model placed as the physics places it for a tool sphere (radius `tool_radius`) at the origin: the tool
    `depth` deep along the normal +x (sphere: radius 0.05, the liver inside it)."""
    normal = np.array([1.0, 0.0, 0.0])
    point = -(tool_radius - depth) * normal
    centre = point - 0.05 * normal if kind == "sphere" else point
    return LocalModel(kind, True, point, normal, centre, 0.05 if kind == "sphere" else 0.0, depth, True, stiffness)


@pytest.mark.parametrize("kind", ["plane", "sphere"])
def test_a_capped_model_renders_the_physics_force_at_the_physics_pose_and_the_cap_about_it(kind):
    model = _physics_model(kind, 350.0, 0.002)
    tip, radius = np.zeros(3), 0.003
    assert penetration(model, tip, radius)[0] == pytest.approx(0.002)  # the physics' placing: K·d = F = 0.7 N
    rendered = capped(model, CAP)
    assert rendered.stiffness_n_per_m == CAP and rendered.kind == kind
    depth, direction = penetration(rendered, tip, radius)
    assert CAP * depth == pytest.approx(350.0 * 0.002, rel=1e-12)  # the physics force, not (K_r/K)·F
    assert rendered.depth_m == pytest.approx(depth, rel=1e-12)     # and the depth it carries is that depth
    np.testing.assert_allclose(direction, [1.0, 0.0, 0.0], atol=1e-12)
    for step in (-0.001, 0.0005, 0.001):  # about the pose: a spring of the cap, the surface moved outward
        moved = penetration(rendered, tip - step * direction, radius)[0]
        assert CAP * (moved - depth) == pytest.approx(CAP * step, rel=1e-9)
    assert capped(rendered, CAP) is rendered


def test_a_capped_sphere_grows_and_a_capped_plane_moves_out_along_its_normal():
    plane, sphere = _physics_model("plane", 380.0, 0.001), _physics_model("sphere", 380.0, 0.001)
    shift = 0.001 * (380.0 / CAP - 1.0)  # = 1 mm
    np.testing.assert_allclose(capped(plane, CAP).point, plane.point + shift * plane.normal, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(capped(plane, CAP).centre, capped(plane, CAP).point)
    assert capped(sphere, CAP).radius_m == pytest.approx(sphere.radius_m + shift, rel=1e-12)
    np.testing.assert_array_equal(capped(sphere, CAP).centre, sphere.centre)


@pytest.mark.parametrize("model", [_physics_model("plane", 120.0, 0.002), _physics_model("sphere", CAP, 0.002),
                                   _physics_model("plane", None, 0.002), LocalModel.invalid(), None])
def test_a_model_within_the_cap_is_rendered_as_it_is(model):
    assert capped(model, CAP) is model


def test_a_model_above_the_cap_without_a_depth_only_takes_the_cap():
    plane = LocalModel.plane([0.0, 0.0, 0.01], [0.0, 0.0, 1.0], 1e4)  # no depth seen: an old Marker's
    rendered = capped(plane, CAP)
    assert rendered.stiffness_n_per_m == CAP and rendered.depth_m == 0.0
    np.testing.assert_array_equal(rendered.point, plane.point)
    assert capped(plane, 0.0) is plane  # a cap of 0: no force, min(K, 0) in the renderer


def test_the_glide_moves_between_the_capped_surfaces():
    """Capped before the glide: halfway through, the surface rendered is halfway between the two rendered ones."""
    first, second = _physics_model("plane", 350.0, 0.002), _physics_model("plane", 300.0, 0.003)
    glide = ModelGlide(0.01)
    start, target = capped(first, CAP), capped(second, CAP)
    glide.update(start, 0.0)
    glide.update(target, 0.001)
    halfway = glide.update(target, 0.006)
    np.testing.assert_allclose(halfway.point, (start.point + target.point) / 2.0, atol=1e-15)
    assert halfway.stiffness_n_per_m == CAP
