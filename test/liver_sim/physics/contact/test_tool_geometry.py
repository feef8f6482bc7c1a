"""The tool's geometry (physics.contact.tool_geometry): its shapes and probes, its sweep over a frame, its candidate
skin nodes and triangles, the implicit step's contact rows, and the local models of a press and of a pull."""
import math

import numpy as np
import pytest
from contact_slab import DEPTH, STIFFNESS, one_step_model

from liver_sim.base.local_model import penetration
from liver_sim.physics.contact.kernels import ToolSweep
from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.contact.tool_geometry import (
    BOX_PROBE_SPACING_M,
    SURFACE_MARGIN_M,
    TOOL_JUMP_M,
    ToolPose,
    ToolShape,
    candidate_nodes,
    candidate_triangles,
    contact_rows,
    fit_sphere,
    pull_local_model,
    surface_depths,
    tool_probes,
    tool_sweep,
    update_multipliers,
)
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.tool import Tool

#: A quarter turn about y: the tool's +z along the liver's +x.
Y_TO_X = (0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4))


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



def test_the_probes_are_a_spheres_centre_a_capsules_shaft_and_a_boxs_faces():
    tip = np.array([0.1, 0.2, 0.3])
    probes, radius = tool_probes(ToolShape(radius_m=0.01), ToolPose(tip))
    np.testing.assert_array_equal(probes, [tip])
    assert radius == 0.01
    probes, radius = tool_probes(ToolShape("capsule", radius_m=0.01, length_m=0.05), ToolPose(tip, Y_TO_X))
    assert radius == 0.01 and len(probes) == 11  # 5 cm at most 5 mm apart: ⌈0.05/0.005⌉ + 1
    np.testing.assert_allclose(probes[-1], tip + [0.05, 0.0, 0.0], atol=1e-15)  # the shaft along the liver's +x
    assert np.linalg.norm(np.diff(probes, axis=0), axis=1).max() <= 0.005 + 1e-15
    half = np.array([0.01, 0.02, 0.005])
    probes, radius = tool_probes(ToolShape("box", half_extents_m=tuple(half)), ToolPose(tip))
    local = probes - tip
    assert radius == 0.0 and (np.abs(local) <= half + 1e-15).all()
    assert np.isclose(np.abs(local), half).any(axis=1).all()  # every probe on a face
    assert len(local) == 3 * 5 * 3 - 1 * 3 * 1  # a 3 × 5 × 3 grid (spacing ≤ 1 cm) less its interior
    assert BOX_PROBE_SPACING_M == 0.01


def test_a_sweep_moves_the_probes_from_the_last_pose_unless_the_tool_jumped(slab):
    params = ModelParams()
    skin = np.ascontiguousarray(slab.skin, dtype=np.int64)
    start, end = ToolPose(np.array([0.05, 0.05, 0.05])), ToolPose(np.array([0.05, 0.052, 0.05]))
    sweep = tool_sweep(ToolShape(), end, start, params, 0.02, slab.points, skin)
    np.testing.assert_allclose(sweep.velocity_m_s, [0.0, 0.002 * params.frame_rate_hz, 0.0])
    np.testing.assert_array_equal(sweep.probes, [start.position])  # where the frame starts
    assert sweep.stiffness_n_per_m == params.contact_stiffness_n_per_m
    assert len(sweep.depth) == len(sweep.triangles) > 0 and (sweep.depth == -np.inf).all()
    jumped = ToolPose(end.position + [TOOL_JUMP_M, 0.0, 0.0])
    replaced = tool_sweep(ToolShape(), jumped, start, params, 0.02, slab.points, skin)
    assert not replaced.velocity_m_s.any()
    np.testing.assert_array_equal(replaced.probes, [jumped.position])
    away = tool_sweep(ToolShape(), None, start, params, 0.02, slab.points, skin)
    assert away.kind == 0 and len(away.probes) == 0 and len(away.triangles) == 0


def test_probe_contact_rows_carry_each_rows_share_of_the_penalty(slab):
    params = ModelParams(contact_stiffness_n_per_m=STIFFNESS, contact_damping_ns_per_m=2.0)
    skin = np.ascontiguousarray(slab.skin, dtype=np.int64)
    pose = ToolPose(np.array([0.047, 0.043, 0.04 + 0.01 - DEPTH]))  # between nodes, 2 mm deep
    sweep = tool_sweep(ToolShape(radius_m=0.01), pose, None, params, 0.02, slab.points, skin)
    rows = contact_rows(slab.points, np.zeros_like(slab.points), sweep, np.zeros(3), 1e-3)
    assert len(rows) > 0
    assert rows.stiffness_n_per_m.sum() == pytest.approx(STIFFNESS)  # shares of one probe sum to 1
    np.testing.assert_allclose(rows.damping_ns_per_m, rows.stiffness_n_per_m * 2.0 / STIFFNESS)
    depth = rows.offset_m - np.einsum("ij,ij->i", rows.normal, (rows.weights[:, :, None]
                                                                 * slab.points[rows.nodes]).sum(axis=1))
    touching = rows.stiffness_n_per_m > 0
    np.testing.assert_allclose(depth[touching], DEPTH, atol=1e-12)  # a flat top: every touching row 2 mm deep


def test_the_pull_local_model_is_the_plane_the_tool_sinks_into_by_pull_over_stiffness():
    pose = ToolPose(np.array([0.0, 0.0, 0.1]))
    local = pull_local_model(pose, np.array([0.0, 0.0, -3.0]), 300.0, 0.015)
    assert local.valid and local.in_contact and local.kind == "plane"
    np.testing.assert_allclose(local.normal, [0.0, 0.0, -1.0])
    assert local.depth_m == pytest.approx(0.01)
    np.testing.assert_allclose(local.point, [0.0, 0.0, 0.1 + 0.015 - 0.01])  # tip − (r − depth)·n
    assert penetration(local, pose.position, 0.015)[0] == pytest.approx(0.01)
    assert not pull_local_model(pose, np.zeros(3), 300.0, 0.015).valid


def test_surface_contact_rows_sit_on_the_balls_true_surface(slab):
    """contact_model 'surface': a row per skin node within the margin, its depth r − |x − c| from the ball's centre,
    its normal radial, stiffness k_A·A, its bias the node's multiplier over k; no face row where the nodes reach the
    ball (the slab's 2 cm faces are larger than this 1 cm ball at 2 mm, so faces with no node inside push)."""
    params = ModelParams(contact_stiffness_n_per_m=STIFFNESS, contact_damping_ns_per_m=2.0)
    skin = np.ascontiguousarray(slab.skin, dtype=np.int64)
    centre = np.array([0.04, 0.04, 0.04 + 0.01 - DEPTH])  # over a grid vertex: it is inside the ball
    sweep = tool_sweep(ToolShape(radius_m=0.01), ToolPose(centre), None, params, 0.02, slab.points, skin)
    areas = np.full(len(slab.points), 1e-4)
    multipliers = np.zeros(len(slab.points))
    vertex = int(np.argmin(np.linalg.norm(slab.points - [0.04, 0.04, 0.04], axis=1)))
    multipliers[vertex] = 0.3
    rows = contact_rows(slab.points, np.zeros_like(slab.points), sweep, np.zeros(3), 1e-3, areas, 3e7, multipliers)
    surface = rows.radius_m > 0.0
    nodes = rows.nodes[surface, 0]
    distance = np.linalg.norm(slab.points[nodes] - centre, axis=1)
    assert (distance < 0.01 + SURFACE_MARGIN_M).all() and vertex in nodes
    depth = rows.offset_m[surface] - np.einsum("ij,ij->i", rows.normal[surface], slab.points[nodes])
    bias = np.where(nodes == vertex, 0.3 / (3e7 * 1e-4), 0.0)
    np.testing.assert_allclose(depth, 0.01 - distance + bias, atol=1e-12)
    np.testing.assert_allclose(rows.normal[surface], (slab.points[nodes] - centre) / distance[:, None], atol=1e-12)
    np.testing.assert_allclose(rows.stiffness_n_per_m[surface], 3e7 * 1e-4)
    np.testing.assert_allclose(rows.core_m[surface], np.broadcast_to([centre, centre], (surface.sum(), 2, 3)))
    np.testing.assert_array_equal(np.sort(nodes), np.unique(nodes))  # one row per node: its multiplier's
    assert (rows.nodes[surface, 1:] == -1).all() and (rows.bias_m[~surface] == 0.0).all()
    faces = ~surface
    for row in np.flatnonzero(faces & (rows.stiffness_n_per_m > 0.0)):
        assert vertex not in rows.nodes[row]  # the faces round the vertex inside the ball are the node's


def test_the_multipliers_take_each_surface_rows_elastic_force():
    x = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.01], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    rows = Contacts(np.array([[0, -1, -1], [1, -1, -1], [2, -1, -1], [0, 3, -1]]),
                    np.array([[1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [0.5, 0.5, 0]]),
                    np.tile([0.0, 0.0, 1.0], (4, 1)), np.array([0.001, 0.005, 0.5, 0.007]), np.zeros(4),
                    np.full(4, 100.0), np.zeros(4), radius_m=np.array([0.01, 0.01, 0.0, 0.0]))
    multipliers = np.full(4, 9.0)
    update_multipliers(rows, x, multipliers)
    # node 0 pushed 1 mm: 0.1 N; node 1 pulled apart: 0; node 2's row and the face row are not on the tool's surface
    np.testing.assert_allclose(multipliers, [0.1, 0.0, 0.0, 0.0])


def test_surface_depths_measure_from_a_capsules_shaft():
    x = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.004], [0.05, 0.0, 0.0], [0.01, 0.003, 0.0]])
    sweep = ToolSweep(2, np.array([[0.0, 0.0, 0.005], [0.03, 0.0, 0.005]]), 0.004, np.zeros(3), 1.0, 0.0,
                      np.array([[0, 1, 2], [0, 2, 3]]), np.array([0, 1]), *([np.zeros(0)] * 7))
    nodes, normal, depth = surface_depths(x, sweep, sweep.probes)
    np.testing.assert_array_equal(nodes, [0, 1, 2, 3])
    expected = [0.004 - 0.005, 0.004 - 0.001, 0.004 - math.hypot(0.02, 0.005), 0.004 - math.hypot(0.003, 0.005)]
    np.testing.assert_allclose(depth, expected, atol=1e-12)
    np.testing.assert_allclose(normal[1], [0.0, 0.0, -1.0], atol=1e-12)
