"""The product's groups (physics.solver.partition): four parts of equal size whose cuts cross few edges, each item in
the smallest group holding its nodes, the items in group order, the same parts on every call."""
import numpy as np

from liver_sim.mesh.liver_shape import build_liver
from liver_sim.physics.solver.partition import GROUPS, PARTS, TET_EDGES, group_order, item_groups, node_parts


def test_the_parts_are_equal_and_their_cuts_cross_few_edges():
    mesh = build_liver(10_000)
    n = len(mesh.points)
    part = node_parts(n, mesh.edges[:, 0], mesh.edges[:, 1], mesh.tets)
    np.testing.assert_array_equal(part, node_parts(n, mesh.edges[:, 0], mesh.edges[:, 1], mesh.tets))
    sizes = np.bincount(part, minlength=PARTS)
    assert sizes.max() - sizes.min() <= 1
    edges = mesh.tets[:, TET_EDGES].reshape(-1, 2)
    crossing = part[edges[:, 0]] != part[edges[:, 1]]
    assert crossing.mean() < 0.25  # a cut by node index would cross about three quarters
    whole = part[edges[:, 0]] // 2 != part[edges[:, 1]] // 2
    assert whole.mean() < 0.1


def test_an_item_goes_to_its_part_its_halfs_cut_or_the_wholes_cut():
    part = np.array([0, 0, 1, 2, 3])
    items = np.array([[0, 1], [0, 2], [1, 2], [3, 4], [2, 4], [0, 3], [1, 4]])
    np.testing.assert_array_equal(item_groups(part, items), [0, 4, 4, 5, 6, 6, 6])


def test_the_order_lists_each_group_in_turn_keeping_the_items_order_within():
    groups = np.array([6, 0, 4, 0, 2, 6, 5])
    order, start = group_order(groups)
    np.testing.assert_array_equal(order, [1, 3, 4, 2, 6, 0, 5])
    np.testing.assert_array_equal(start, [0, 2, 2, 3, 3, 4, 5, 7])
    assert len(start) == GROUPS + 1


def test_fewer_nodes_than_parts_stay_in_the_first():
    np.testing.assert_array_equal(node_parts(3, np.array([0, 1]), np.array([1, 2]), np.zeros((0, 4), int)), 0)
