"""How the liver is held (physics.tissue.organ_support): the ties' force and Jacobian in both integrators, their
stiffness from the regions and the capsule's areas, the default liver held by them, the paper's scene without."""
import numpy as np
import pytest

from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver import implicit_kernels, reference
from liver_sim.physics.solver.records import Operator
from liver_sim.physics.structure import default_fixed_nodes
from liver_sim.physics.tissue.organ_support import (
    SupportArrays,
    build_support,
    node_areas_m2,
    region_stiffness_n_per_m3,
    support_forces,
)

from meshes import box_mesh


def random_support(count=6, nodes=20, seed=0):
    rng = np.random.default_rng(seed)
    x, v = rng.normal(size=(nodes, 3)), rng.normal(size=(nodes, 3))
    support = SupportArrays(rng.choice(nodes, count, replace=False).astype(np.int64), rng.normal(size=(count, 3)),
                            rng.uniform(10, 100, count), rng.uniform(0.1, 1, count))
    return x, v, support


def test_support_force_and_jacobian_in_both_integrators():
    x, v, support = random_support()
    expected = reference.support_forces(x, v, support)
    f = np.zeros_like(x)
    support_forces(x, v, *support, f)
    np.testing.assert_allclose(f, expected, rtol=1e-12)
    inv_mass = np.ones(len(x))
    inv_mass[support.nodes[0]] = 0.0  # a held node: no force, no matrix entry

    def implicit_terms(xs, vs, y, h=0.01):
        f, ky = np.zeros_like(xs), np.zeros_like(xs)
        none = np.zeros(0, np.uint32)
        op = Operator.allocate(none, none, len(xs))
        implicit_kernels.support_terms(xs, vs, y, inv_mass, h, support, f, ky, op, True)
        return f, ky, op.shift, op.diagonal

    direction = np.random.default_rng(1).normal(size=x.shape)
    f, ky, shift, diagonal = implicit_terms(x, v, direction)
    free = inv_mass > 0.0
    np.testing.assert_allclose(f[free], expected[free], rtol=1e-12)
    eps = 1e-6
    dfdx = (implicit_terms(x + eps * direction, v, direction)[0] - implicit_terms(x - eps * direction, v,
                                                                                  direction)[0]) / (2 * eps)
    np.testing.assert_allclose(ky, dfdx, atol=1e-6)
    k, c = np.zeros(len(x)), np.zeros(len(x))
    k[support.nodes], c[support.nodes] = support.stiffness_n_per_m, support.damping_ns_per_m
    np.testing.assert_allclose(shift, np.where(free, 1.0 + 0.01 * c + 1e-4 * k, 1.0))
    assert shift[support.nodes[0]] == 1.0 and not f[support.nodes[0]].any()


def test_the_organ_support_holds_the_default_liver_and_the_paper_scene_stays_selectable():
    liver = default_liver()
    organ, paper = LiverModel(liver), LiverModel(liver, ModelParams(support="paper"))
    support = organ.structure.support
    assert organ.structure.fixed_nodes.size == 0 and len(support.nodes) >= 20
    assert np.isin(support.nodes, liver.skin_nodes).all() and (support.stiffness_n_per_m > 0).all()
    # the bare area and the vena cava are posterior: most of the tie stiffness holds the posterior face
    posterior = liver.points[support.nodes, 1] > 0.02
    assert support.stiffness_n_per_m[posterior].sum() > 0.8 * support.stiffness_n_per_m.sum()
    assert np.array_equal(paper.structure.fixed_nodes, default_fixed_nodes(liver))
    assert len(paper.structure.support.nodes) == 0
    # regions that hold no skin node of a mesh: the paper's scene
    far = ModelParams(support_regions=((1.0, 1.0, 1.0, 0.01, 1e6),))
    assert len(build_support(liver, liver.skin, far).nodes) == 0
    assert np.array_equal(LiverModel(liver, far).structure.fixed_nodes, default_fixed_nodes(liver))



def test_each_node_gets_a_third_of_the_area_of_its_triangles():
    points = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0], [2.0, 3.0, 0.0], [9.0, 9.0, 9.0]])
    areas = node_areas_m2(points, np.array([[0, 1, 2], [1, 3, 2]]))  # two triangles of 3 m² each
    np.testing.assert_allclose(areas, [1.0, 2.0, 2.0, 1.0, 0.0])


def test_overlapping_regions_add_their_stiffness():
    points = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [2.0, 0.0, 0.0]])
    regions = ((0.0, 0.0, 0.0, 1.0, 10.0), (1.0, 0.0, 0.0, 0.6, 5.0))
    np.testing.assert_allclose(region_stiffness_n_per_m3(points, regions), [10.0, 15.0, 0.0])


def test_the_ties_are_the_capsule_nodes_in_the_regions_with_k_a_times_their_area():
    box = box_mesh(2, 2, 2, 0.01)  # 2 × 2 × 2 cm: its corner (0, 0, 0) carries a third of three right triangles
    params = ModelParams(support_regions=((0.0, 0.0, 0.0, 0.001, 2.0e5),), support_damping_s=0.05)
    support = build_support(box, box.skin, params)
    np.testing.assert_array_equal(support.nodes, [0])
    area = node_areas_m2(box.points, box.skin)[0]
    assert support.stiffness_n_per_m[0] == pytest.approx(2.0e5 * area)
    assert support.damping_ns_per_m[0] == pytest.approx(0.05 * 2.0e5 * area)
    np.testing.assert_array_equal(support.rest_m, box.points[[0]])
    assert len(build_support(box, box.skin, params.with_changes(support="paper")).nodes) == 0
    assert len(build_support(box, np.zeros((0, 3), np.int64), params).nodes) == 0  # no capsule: nothing held


def test_the_support_kernel_ties_its_nodes_to_their_rest():
    # node 1 at 2 cm from its rest, moving at 0.5 m/s: −k·Δx − c·v = −100·(0.02, 0, 0) − 2·(0, 0.5, 0)
    x = np.array([[0.0, 0.0, 0.0], [0.12, 0.0, 0.0]])
    v = np.array([[1.0, 1.0, 1.0], [0.0, 0.5, 0.0]])
    f = np.zeros((2, 3))
    support_forces(x, v, np.array([1]), np.array([[0.1, 0.0, 0.0]]), np.array([100.0]), np.array([2.0]), f)
    np.testing.assert_allclose(f, [[0.0, 0.0, 0.0], [-2.0, -1.0, 0.0]])
