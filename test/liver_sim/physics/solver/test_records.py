"""The implicit step's records (physics.solver.records): an operator allocated to be assembled, its springs and
elements in the groups of its parts, contact rows taken from contact.rows.Contacts field by field."""
import numpy as np

from liver_sim.mesh.liver_shape import build_liver
from liver_sim.physics.contact.rows import node_contacts
from liver_sim.physics.solver.partition import GROUPS, PARTS, item_groups
from liver_sim.physics.solver.records import ContactRows, Operator


def test_an_allocated_operator_has_a_block_per_spring_and_a_unit_shift_per_node():
    node_i, node_j = np.array([0, 1], np.uint32), np.array([1, 2], np.uint32)
    op = Operator.allocate(node_i, node_j, 4)
    np.testing.assert_array_equal(np.sort(op.spring_order), [0, 1])
    np.testing.assert_array_equal(op.node_i, node_i[op.spring_order])
    np.testing.assert_array_equal(op.node_j, node_j[op.spring_order])
    assert op.unit.shape == (2, 3) and op.iso.shape == op.axial.shape == (2,)
    assert not (op.unit.any() or op.iso.any() or op.axial.any() or op.diagonal.any())
    assert op.diagonal.shape == (4, 3, 3)
    np.testing.assert_array_equal(op.shift, np.ones(4))


def test_an_allocated_operator_keeps_each_group_of_springs_together_and_lists_its_parts_nodes_and_elements():
    mesh = build_liver(2_000)
    node_i, node_j = mesh.edges[:, 0].astype(np.uint32), mesh.edges[:, 1].astype(np.uint32)
    op = Operator.allocate(node_i, node_j, len(mesh.points), mesh.tets)
    part = np.empty(len(mesh.points), np.int64)
    for g in range(PARTS):
        part[op.part_nodes[op.part_start[g]:op.part_start[g + 1]]] = g
    np.testing.assert_array_equal(np.sort(op.part_nodes), np.arange(len(mesh.points)))
    springs = item_groups(part, np.stack([op.node_i, op.node_j], axis=1))
    elements = item_groups(part, mesh.tets[op.tet_order])
    for g in range(GROUPS):
        assert (springs[op.spring_start[g]:op.spring_start[g + 1]] == g).all()
        assert (elements[op.tet_start[g]:op.tet_start[g + 1]] == g).all()
    assert op.spring_start[-1] == len(node_i) and op.tet_start[-1] == len(mesh.tets)
    assert np.all(np.diff(op.spring_order[op.spring_start[0]:op.spring_start[1]]) > 0)  # a group keeps its order


def test_contact_rows_take_the_contacts_fields_and_the_coefficients():
    contacts = node_contacts(np.array([3, 5]), np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), np.array([0.1, 0.2]),
                             np.array([0.01, 0.02]), 300.0, 2.0)
    coefficient = np.array([0.5, 0.0])
    rows = ContactRows.of(contacts, coefficient)
    assert rows.nodes is contacts.nodes and rows.normal is contacts.normal and rows.coefficient is coefficient
    assert rows.offset is contacts.offset_m and rows.speed is contacts.normal_speed_m_s
    assert rows.stiffness is contacts.stiffness_n_per_m and rows.damping is contacts.damping_ns_per_m


def test_an_emptied_operator_shares_the_groups_and_owns_what_is_assembled():
    mesh = build_liver(2_000)
    node_i, node_j = mesh.edges[:, 0].astype(np.uint32), mesh.edges[:, 1].astype(np.uint32)
    op = Operator.allocate(node_i, node_j, len(mesh.points), mesh.tets)
    op.iso[:] = 1.0
    op.shift[:] = 2.0
    empty = op.emptied()
    for shared in ("node_i", "node_j", "spring_order", "spring_start", "part_nodes", "part_start", "tet_order",
                   "tet_start"):
        assert getattr(empty, shared) is getattr(op, shared)
    for own in ("unit", "iso", "axial", "shift", "diagonal"):
        assert not np.shares_memory(getattr(empty, own), getattr(op, own))
    assert not (empty.iso.any() or empty.unit.any() or empty.diagonal.any())
    np.testing.assert_array_equal(empty.shift, 1.0)
