"""The equal and opposite pair of a spring on its two nodes (physics.tissue.pairs.add_pair)."""
import numpy as np

from liver_sim.physics.tissue.pairs import add_pair


def test_add_pair_adds_to_the_first_node_and_takes_from_the_second():
    out = np.arange(9.0).reshape(3, 3)
    add_pair(out, 2, 0, 1.0, -2.0, 0.5)
    np.testing.assert_array_equal(out, [[-1.0, 3.0, 1.5], [3.0, 4.0, 5.0], [7.0, 5.0, 8.5]])
    add_pair(out, 1, 1, 4.0, 4.0, 4.0)  # a pair on one node cancels
    np.testing.assert_array_equal(out[1], [3.0, 4.0, 5.0])
