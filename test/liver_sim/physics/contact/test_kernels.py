"""The contact kernels of Eq. 3 (physics.contact.kernels): a probe against one triangle by hand (closest point,
weights, normal, depth, the force spread over the nodes), the candidates near the tool, the rows linearised for the
implicit step; on the slab, the penalty force along the normal for each tool shape and its damping; on the liver, a
sphere sliding over the skin without a jump."""
import math

import numpy as np
import pytest
from contact_slab import DEPTH, STIFFNESS, one_step_model

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.physics.contact.kernels import add_contact_forces, contact_elements, near_triangles, probe_geometry
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape, probe_contacts, tool_sweep
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.tool import Tool

#: One skin triangle in the plane z = 0, facing +z (the liver below it).
TRIANGLE = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
SKIN = np.array([[0, 1, 2]])


def one_triangle_sweep(tip, radius=0.01, velocity=(0.0, 0.0, 0.0), stiffness=300.0, damping=2.0):
    """A sphere of `radius` at `tip` over TRIANGLE, moving at `velocity`: its sweep, the triangle its candidate."""
    params = ModelParams(contact_stiffness_n_per_m=stiffness, contact_damping_ns_per_m=damping)
    sweep = tool_sweep(ToolShape(radius_m=radius), ToolPose(np.array(tip)), None, params, 0.05, TRIANGLE, SKIN)
    return sweep._replace(velocity_m_s=np.array(velocity, dtype=float))


def test_a_probe_over_a_triangle_meets_its_closest_point_by_hand():
    sweep = one_triangle_sweep([0.02, 0.03, 0.006])
    assert list(sweep.triangles) == [0]
    probe_geometry(TRIANGLE, np.zeros((3, 3)), sweep, np.zeros(3), 0.0)
    np.testing.assert_allclose(sweep.point[0], [0.02, 0.03, 0.0], atol=1e-15)
    np.testing.assert_allclose(sweep.weights[0], [0.5, 0.2, 0.3], atol=1e-14)  # q = 0.2·b + 0.3·c
    np.testing.assert_allclose(sweep.normal[0], [0.0, 0.0, -1.0], atol=1e-14)  # from the probe to q: into the liver
    assert sweep.depth[0] == pytest.approx(0.004) and sweep.share[0] == 1.0 and sweep.surface_weight[0] == 1.0
    apart = one_triangle_sweep([0.02, 0.03, 0.016])
    probe_contacts(TRIANGLE, np.zeros((3, 3)), apart, np.zeros(3), 0.0)
    assert apart.depth[0] == pytest.approx(-0.006) and apart.share[0] == 0.0


def test_the_contact_force_is_the_penalty_and_damping_spread_by_the_weights():
    # δ = 4 mm, the probe moving in at 0.1 m/s, the nodes at rest: F = λ·δ + μ·δ̇ = 300·0.004 + 2·0.1 = 1.4 N
    sweep = one_triangle_sweep([0.02, 0.03, 0.006], velocity=(0.0, 0.0, -0.1))
    f = np.full((3, 3), 0.5)
    total = add_contact_forces(TRIANGLE, np.zeros((3, 3)), sweep, np.zeros(3), 0.0, f)
    np.testing.assert_allclose(total, [0.0, 0.0, -1.4], atol=1e-14)
    np.testing.assert_allclose(f[:, 2], 0.5 - 1.4 * np.array([0.5, 0.2, 0.3]), atol=1e-14)
    np.testing.assert_allclose(f[:, :2], 0.5, atol=1e-14)
    pulling_out = one_triangle_sweep([0.02, 0.03, 0.006], velocity=(0.0, 0.0, 1.0))  # 300·0.004 − 2·1 < 0
    assert not add_contact_forces(TRIANGLE, np.zeros((3, 3)), pulling_out, np.zeros(3), 0.0, np.zeros((3, 3))).any()


def test_contact_elements_keep_the_stiff_rows_with_the_offset_that_gives_back_their_depth():
    x = np.array([[0.0, 0.0, 0.01], [0.1, 0.0, 0.02], [0.0, 0.1, 0.03]])
    nodes = np.array([[0, 1, 2], [0, 1, 2]])
    weights = np.array([[0.5, 0.2, 0.3], [1.0, 0.0, 0.0]])
    normal = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    nodes_out, weights_out, normal_out, offset, speed, k, c = contact_elements(
        x, nodes, weights, normal, np.array([0.004, 0.001]), np.array([300.0, 0.0]), np.array([2.0, 5.0]),
        np.array([0.0, 0.0, -0.1]))
    assert len(offset) == 1 and k[0] == 300.0 and c[0] == 2.0  # the row without stiffness is left out
    np.testing.assert_array_equal(nodes_out[0], [0, 1, 2])
    along = normal_out[0] @ (weights_out[0] @ x)  # −(0.5·0.01 + 0.2·0.02 + 0.3·0.03) = −0.018
    assert offset[0] - along == pytest.approx(0.004) and along == pytest.approx(-0.018)
    assert speed[0] == pytest.approx(0.1)  # n·v_tool


def test_near_triangles_are_those_whose_centroid_is_within_reach_and_the_largest_circumradius(slab):
    skin = np.ascontiguousarray(slab.skin, dtype=np.int64)
    centre, reach = np.array([0.05, 0.05, 0.06]), 0.015
    corners = slab.points[skin]
    centroids = corners.mean(axis=1)
    spread = np.linalg.norm(corners - centroids[:, None], axis=2).max()
    expected = np.flatnonzero(np.linalg.norm(centroids - centre, axis=1) <= reach + spread)
    np.testing.assert_array_equal(near_triangles(slab.points, skin, centre, reach), expected)
    assert 0 < len(expected) < len(skin) / 4


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



def penalty_along(liver, steps_m):
    """Σ share·λ·δ·n of the sphere's probe (N) at tips along a line over the dome, 8 mm into the rest skin."""
    params = ModelParams()
    anchor, shape, skin = press_anchor(liver), ToolShape(), np.asarray(liver.skin, np.int64)
    totals = []
    for s in steps_m:
        tool = tool_sweep(shape, ToolPose(anchor + [s, 0.3 * s, shape.radius_m - 0.008]), None, params, 0.02,
                          liver.points, skin)
        probe_contacts(liver.points, np.zeros_like(liver.points), tool, np.zeros(3), 0.0)
        assert tool.share.sum() == pytest.approx(1.0) and (tool.depth > 0.0).any()
        np.testing.assert_allclose(tool.weights.sum(axis=1), 1.0)
        totals.append(params.contact_stiffness_n_per_m * ((tool.share * np.maximum(tool.depth, 0.0))[:, None]
                                                           * tool.normal).sum(axis=0))
    return np.linalg.norm(np.diff(totals, axis=0), axis=1)


def test_a_sphere_sliding_over_a_fixed_skin_meets_it_continuously(liver):
    """No jump, no double counting: across the edges and corners of 6 cm of skin, the largest change of
    the penalty between tips 0.1 mm apart shrinks ~5× when they are 0.02 mm apart (a jump would not shrink:
    a per-triangle count jumps at every edge) and stays below what the facets' turning explains."""
    coarse = penalty_along(liver, np.arange(-0.03, 0.03, 1e-4))
    worst = np.argmax(coarse)
    fine = penalty_along(liver, -0.03 + worst * 1e-4 + np.arange(0.0, 1e-4 + 1e-9, 2e-5))
    assert fine.max() < 0.35 * coarse.max()
    assert coarse.max() < 5.0 * ModelParams().contact_stiffness_n_per_m * 1e-4

