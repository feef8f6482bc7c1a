"""The implicit step's records (physics.solver.records): an operator allocated to be assembled, contact rows taken from
contact.rows.Contacts field by field."""
import numpy as np

from liver_sim.physics.contact.rows import node_contacts
from liver_sim.physics.solver.records import ContactRows, Operator


def test_an_allocated_operator_has_a_block_per_spring_and_a_unit_shift_per_node():
    node_i, node_j = np.array([0, 1], np.uint32), np.array([1, 2], np.uint32)
    op = Operator.allocate(node_i, node_j, 4)
    assert op.node_i is node_i and op.node_j is node_j
    assert op.unit.shape == (2, 3) and op.iso.shape == op.axial.shape == (2,)
    assert not (op.unit.any() or op.iso.any() or op.axial.any() or op.diagonal.any())
    assert op.diagonal.shape == (4, 3, 3)
    np.testing.assert_array_equal(op.shift, np.ones(4))


def test_contact_rows_take_the_contacts_fields_and_the_coefficients():
    contacts = node_contacts(np.array([3, 5]), np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), np.array([0.1, 0.2]),
                             np.array([0.01, 0.02]), 300.0, 2.0)
    coefficient = np.array([0.5, 0.0])
    rows = ContactRows.of(contacts, coefficient)
    assert rows.nodes is contacts.nodes and rows.normal is contacts.normal and rows.coefficient is coefficient
    assert rows.offset is contacts.offset_m and rows.speed is contacts.normal_speed_m_s
    assert rows.stiffness is contacts.stiffness_n_per_m and rows.damping is contacts.damping_ns_per_m
