"""Tool shapes against the skin: Eq. 3 force direction and magnitude, candidates, and the local model."""
import math

import numpy as np
import pytest

from liver_sim.base.local_model import penetration
from liver_sim.physics.contact.tool_geometry import (
    ToolPose,
    ToolShape,
    candidate_nodes,
    candidate_triangles,
    fit_sphere,
)
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.tool import Tool

from meshes import box_mesh

STIFFNESS = 250.0
DEPTH = 0.002
SPACING = 0.02


@pytest.fixture(scope="module")
def slab():
    """A 10 × 10 × 4 cm slab; its top face is z = 0.04 m, with a grid vertex at (0.04, 0.04)."""
    return box_mesh(5, 5, 2, SPACING)


def one_step_model(mesh, tool):
    """One 10 µs explicit step per frame: forces are read before the nodes have moved noticeably (the
    implicit step's contacts, evaluated at the end of its step: test_implicit.py)."""
    params = ModelParams(integrator="symplectic_euler", substeps=1, frame_rate_hz=1e5,
                         contact_stiffness_n_per_m=STIFFNESS,
                         contact_damping_ns_per_m=0.0)
    return LiverModel(mesh, params, Tool(tool))


Y_TO_X = (0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4))  # tool +z along liver +x


@pytest.mark.parametrize("tool, tip, probes", [
    (ToolShape("sphere", radius_m=0.01), (0.04, 0.04, 0.04 + 0.01 - DEPTH), 1),
    (ToolShape("capsule", radius_m=0.01, length_m=0.05), (0.04, 0.04, 0.04 + 0.01 - DEPTH), 1),
    (ToolShape("sphere", radius_m=0.01), (0.047, 0.043, 0.04 + 0.01 - DEPTH), 1),  # between nodes
    # the box's bottom face: its 3 × 3 probes (corners, edge midpoints, centre) all touch
    (ToolShape("box", half_extents_m=(0.005, 0.005, 0.01)), (0.04, 0.04, 0.04 + 0.01 - DEPTH), 9),
])
def test_pressing_a_vertex_gives_the_penalty_force_along_the_normal(slab, tool, tip, probes):
    result = one_step_model(slab, tool).step_frame(ToolPose(np.array(tip)))
    # Eq. 3 with μ = 0: |F| = λ·δ per touching probe, pushing the tool out along the surface normal (+z)
    np.testing.assert_allclose(result.tool_force_n, [0.0, 0.0, probes * STIFFNESS * DEPTH], atol=1e-9)


def test_liver_nodes_feel_the_opposite_of_the_tool_force(slab):
    model = one_step_model(slab, ToolShape("sphere", radius_m=0.01))
    result = model.step_frame(ToolPose(np.array([0.042, 0.041, 0.04 + 0.01 - DEPTH])))
    momentum = (model.structure.masses_kg[:, None] * model.state.velocities).sum(axis=0)
    impulse_on_liver = -result.tool_force_n * model.structure.params.dt_s
    # the fixed nodes absorb only spring forces, which are zero at rest
    np.testing.assert_allclose(momentum, impulse_on_liver, atol=1e-12)
    assert result.tool_force_n[2] > 0


def test_horizontal_capsule_touches_along_its_length(slab):
    vertical = one_step_model(slab, ToolShape("capsule", radius_m=0.01, length_m=0.06))
    tip = np.array([0.02, 0.04, 0.04 + 0.01 - DEPTH])
    upright = vertical.step_frame(ToolPose(tip)).tool_force_n
    lying = one_step_model(slab, ToolShape("capsule", radius_m=0.01, length_m=0.06)).step_frame(
        ToolPose(tip, Y_TO_X)).tool_force_n
    assert lying[2] > 2.5 * upright[2]
    assert abs(lying[0]) < 1e-6 * lying[2] + 1e-12 or abs(lying[0]) < 0.05 * lying[2]


def test_no_force_out_of_contact(slab):
    for tool in (ToolShape("sphere"), ToolShape("capsule"), ToolShape("box")):
        lowest = tool.half_extents_m[2] if tool.kind == "box" else tool.radius_m  # below the tip
        result = one_step_model(slab, tool).step_frame(ToolPose(np.array([0.05, 0.05, 0.04 + lowest + 0.001])))
        np.testing.assert_array_equal(result.tool_force_n, 0.0)


def test_penalty_damping_resists_approach(slab):
    params = ModelParams(integrator="symplectic_euler", substeps=1, frame_rate_hz=1e5,
                         contact_stiffness_n_per_m=STIFFNESS, contact_damping_ns_per_m=5.0)
    model = LiverModel(slab, params, Tool(ToolShape("sphere", radius_m=0.01)))
    z0 = 0.04 + 0.01 - DEPTH
    model.step_frame(ToolPose(np.array([0.04, 0.04, z0 + 1e-6])))
    moving = model.step_frame(ToolPose(np.array([0.04, 0.04, z0]))).tool_force_n[2]
    # pressing in at 0.1 m/s: δ̇ ≈ 0.1 m/s adds μ·δ̇ ≈ 0.5 N to λ·δ = 0.5 N
    assert moving == pytest.approx(STIFFNESS * DEPTH + 5.0 * 0.1, rel=0.05)


def test_candidates_are_the_elements_near_the_tool(slab):
    tool = ToolShape("sphere", radius_m=0.01)
    near, far = ToolPose(np.array([0.05, 0.05, 0.05])), ToolPose(np.array([0.05, 0.05, 0.5]))
    triangles = candidate_triangles(slab.points, slab.skin, tool, near, 0.0)
    assert 0 < len(triangles) < len(slab.skin) / 4
    assert len(candidate_triangles(slab.points, slab.skin, tool, far, 0.0)) == 0
    centroids = slab.points[slab.skin[triangles]].mean(axis=1)
    assert (np.linalg.norm(centroids - near.position, axis=1) < 0.01 + 0.03).all()
    nodes = candidate_nodes(slab.points, slab.skin_nodes, tool, near, 0.005)
    np.testing.assert_array_equal(
        nodes, [n for n in slab.skin_nodes if np.linalg.norm(slab.points[n] - near.position) <= 0.015])


def test_local_model_in_contact_is_the_touched_plane(slab):
    """The touched plane, sunk so that its stiffness K times the tool's penetration is the contact force
    (K: the penalty in series with the slab under the tool, so ≤ λ, and the plane at or below the skin)."""
    model = one_step_model(slab, ToolShape("sphere", radius_m=0.01))
    tip = np.array([0.04, 0.04, 0.04 + 0.01 - DEPTH])
    result = model.step_frame(ToolPose(tip))
    local = result.local_model
    assert local.valid and local.in_contact and local.kind == "plane"
    np.testing.assert_allclose(local.normal, [0, 0, 1], atol=1e-9)
    assert 0.0 < local.stiffness_n_per_m < STIFFNESS
    assert local.stiffness_n_per_m * local.depth_m == pytest.approx(np.linalg.norm(result.tool_force_n), rel=1e-9)
    assert penetration(local, tip, 0.01)[0] == pytest.approx(local.depth_m, rel=1e-9) and local.depth_m >= DEPTH
    np.testing.assert_allclose(local.point[:2], [0.04, 0.04], atol=1e-6)


def test_local_model_near_but_not_touching_and_out_of_reach(slab):
    model = LiverModel(slab, tool=Tool(ToolShape("sphere", radius_m=0.01), local_model_reach_m=0.02))
    near = model.step_frame(ToolPose(np.array([0.05, 0.05, 0.04 + 0.01 + 0.005]))).local_model
    assert near.valid and not near.in_contact and near.depth_m == 0.0
    np.testing.assert_allclose(near.normal, [0, 0, 1], atol=1e-6)
    assert near.point[2] == pytest.approx(0.04, abs=1e-6)
    far = model.step_frame(ToolPose(np.array([0.05, 0.05, 0.04 + 0.01 + 0.05]))).local_model
    assert not far.valid


def test_fit_sphere_recovers_a_sphere_and_flags_a_plane():
    rng = np.random.default_rng(3)
    directions = rng.normal(size=(40, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    centre, radius = fit_sphere(np.array([0.1, -0.2, 0.3]) + 0.07 * directions)
    np.testing.assert_allclose(centre, [0.1, -0.2, 0.3], atol=1e-9)
    assert radius == pytest.approx(0.07)
    flat = np.column_stack([rng.uniform(size=(20, 2)), np.zeros(20)])
    assert fit_sphere(flat)[1] == math.inf


@pytest.mark.parametrize("kwargs, name", [
    (dict(kind="scalpel"), "tool.kind"), (dict(radius_m=0.0), "tool.radius_m"),
    (dict(length_m=-1.0), "tool.length_m"), (dict(half_extents_m=(0.01, 0.0, 0.01)), "tool.half_extents_m"),
])
def test_bad_tool_shapes_are_refused_by_name(kwargs, name):
    with pytest.raises(ValueError, match=name.replace(".", r"\.")):
        ToolShape(**kwargs)


def test_the_local_stiffness_refreshed_every_few_frames_stays_near_a_fresh_solve():
    """K is solved every REFRESH_FRAMES frames and reused in between: over a press and slide on the
    default liver it stays within 10 % of K solved afresh at each frame (a twin model)."""
    from liver_sim.mesh.landmarks import press_anchor
    from liver_sim.mesh.liver_shape import default_liver
    from liver_sim.physics.tools.local_stiffness import REFRESH_FRAMES
    from liver_sim.tool.scripts import ScriptSettings, make_script

    mesh = default_liver()
    cached = LiverModel(mesh, ModelParams())
    fresh = LiverModel(mesh, ModelParams(), Tool(stiffness_refresh_frames=1))
    script = make_script("press_slide_release", ScriptSettings(anchor_m=tuple(press_anchor(mesh)), rest_s=0.1))
    penalty = cached.structure.params.contact_stiffness_n_per_m
    compared = 0
    for k in range(int(script.duration_s * 150)):
        pose = ToolPose(script.position_at(k / 150.0))
        reused, solved = cached.step_frame(pose).local_model, fresh.step_frame(pose).local_model
        np.testing.assert_array_equal(cached.state.positions, fresh.state.positions)  # K does not touch the physics
        if not solved.in_contact:
            continue
        assert reused.stiffness_n_per_m == pytest.approx(solved.stiffness_n_per_m, rel=0.10), k
        assert solved.stiffness_n_per_m < penalty
        compared += 1
    assert REFRESH_FRAMES > 1 and compared > 50
