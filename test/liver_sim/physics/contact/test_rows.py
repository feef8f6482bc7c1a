"""Contact rows (physics.contact.rows): 1-node rows, the penalty of each row by hand, the force of the pushing rows
clipped at zero, the rows of several tools joined and split again, and those that push kept."""
import numpy as np
import pytest

from liver_sim.physics.contact.rows import (
    Contacts,
    contact_force_n,
    joined,
    node_contacts,
    pushing,
    row_forces_n,
    split,
)

X = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.01], [0.0, 0.0, 0.02], [1.0, 1.0, 1.0]])
V = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.1], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


def rows() -> Contacts:
    """Row 0: node 1 pressed 2 mm down (o = −0.008 along −z) at 0.1 m/s into it; row 1: nodes 0 and 2 half each,
    the tool 5 mm above them (o = −0.015), apart."""
    return Contacts(np.array([[1, -1, -1], [0, 2, -1]]), np.array([[1.0, 0.0, 0.0], [0.5, 0.5, 0.0]]),
                    np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]]), np.array([-0.008, -0.015]),
                    np.array([0.0, 0.0]), np.array([100.0, 100.0]), np.array([2.0, 2.0]))


def test_node_contacts_are_rows_of_one_node_of_weight_one():
    contacts = node_contacts(np.array([4, 7]), np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), [0.1, 0.2], [0.0, 0.3],
                             300.0, 2.0)
    np.testing.assert_array_equal(contacts.nodes, [[4, -1, -1], [7, -1, -1]])
    np.testing.assert_array_equal(contacts.weights, [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(contacts.stiffness_n_per_m, [300.0, 300.0])
    np.testing.assert_array_equal(contacts.damping_ns_per_m, [2.0, 2.0])
    assert len(contacts) == 2 and len(Contacts.none()) == 0


def test_row_forces_by_hand():
    # row 0: k·(o − n·x) + c·(s − n·v) = 100·(−0.008 + 0.01) + 2·(0 + 0.1) = 0.4 N
    # row 1: 100·(−0.015 + (0.5·0 + 0.5·0.02)) = −0.5 N (apart)
    np.testing.assert_allclose(row_forces_n(rows(), X, V), [0.4, -0.5])
    np.testing.assert_allclose(contact_force_n(rows(), X, V), [0.0, 0.0, -0.4])  # row 1 clipped to 0
    assert not contact_force_n(Contacts.none(), X, V).any()


def test_pushing_keeps_the_rows_that_push_and_joined_concatenates_in_order():
    kept = pushing(rows(), X, V)
    assert len(kept) == 1 and kept.nodes[0, 0] == 1
    both = joined([rows(), kept])
    assert len(both) == 3
    np.testing.assert_array_equal(both.nodes[:, 0], [1, 0, 1])
    np.testing.assert_allclose(row_forces_n(both, X, V), [0.4, -0.5, 0.4])
    assert joined([]).nodes.shape == (0, 3)
    single = rows()
    assert joined([single]) is single


@pytest.mark.parametrize("speed, expected", [(0.0, 0.4), (-0.2, 0.0)])
def test_the_tool_speed_along_the_normal_adds_damping(speed, expected):
    contacts = rows()
    contacts.normal_speed_m_s[0] = speed  # the tool withdrawing at 0.2 m/s: 0.4 − 2·0.2 = 0
    assert row_forces_n(contacts, X, V)[0] == pytest.approx(expected)


def test_split_undoes_joined_and_shares_its_arrays():
    first, second = rows(), node_contacts(np.array([3]), np.array([[1.0, 0.0, 0.0]]), [0.5], [0.0], 10.0, 0.0)
    together = joined([first, second])
    parts = split(together, [len(first), len(second)])
    for part, original in zip(parts, (first, second)):
        for name in Contacts.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(part, name), getattr(original, name))
    together.offset_m[2] = 0.7  # a step rebuilding the joined rows rebuilds each tool's
    assert parts[1].offset_m[0] == 0.7
    assert split(first, [len(first)])[0] is first
