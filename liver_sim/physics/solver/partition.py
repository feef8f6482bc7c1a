"""The fixed groups the implicit step's product A·p runs in (physics.solver.pcg), so that its sums are the same
whatever the threads.

The nodes are cut in two halves and each half in two again: PARTS = 4 parts, each cut at the median breadth-first
distance, over the springs and the elements' edges, from a far node of the set it cuts (a level-set bisection: the cut
runs across the organ and crosses few edges).  A spring or an element belongs to the smallest group holding all its
nodes: a part (groups 0–3), the cut of a half (4, 5) or the cut of the whole (6).  The product adds a node's terms
group by group, parts, then halves, then the whole, each group's items in order: the groups of one level touch
disjoint nodes, so they may run on any thread and every node's sum comes out in the same order.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse
from scipy.sparse.csgraph import shortest_path

#: The parts the nodes are cut into (two levels of halving).
PARTS = 4
#: The groups of items: the parts, the halves' cuts, the whole's cut.
GROUPS = 7
#: The groups of each level, run one level after the other: (first, last + 1).
LEVELS = ((0, 4), (4, 6), (6, 7))
#: The tetrahedron's six edges, as pairs of its corners.
TET_EDGES = [0, 1, 0, 2, 0, 3, 1, 2, 1, 3, 2, 3]


def _halves(graph: scipy.sparse.csr_matrix, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`nodes` (sorted) cut in two at the median breadth-first distance from a far node of their subgraph: the node
    farthest from the first (the lowest index among equals); unreachable nodes last, ties by index."""
    sub = graph[nodes][:, nodes]
    far = shortest_path(sub, unweighted=True, indices=0)
    far[~np.isfinite(far)] = -1.0
    start = int(np.argmax(far))
    distance = shortest_path(sub, unweighted=True, indices=start)
    distance[~np.isfinite(distance)] = np.inf
    order = np.lexsort((nodes, distance))
    half = len(nodes) // 2
    return np.sort(nodes[order[:half]]), np.sort(nodes[order[half:]])


def node_parts(n_nodes: int, node_i: np.ndarray, node_j: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Each node's part (N,) int64, 0..PARTS − 1, from the graph of the springs `node_i`–`node_j` and the edges of
    the elements `tets` (M, 4)."""
    pairs = np.concatenate([np.stack([node_i, node_j], axis=1).astype(np.int64),
                            np.asarray(tets, np.int64)[:, TET_EDGES].reshape(-1, 2)])
    graph = scipy.sparse.coo_matrix((np.ones(2 * len(pairs)), (np.concatenate([pairs[:, 0], pairs[:, 1]]),
                                                               np.concatenate([pairs[:, 1], pairs[:, 0]]))),
                                    shape=(n_nodes, n_nodes)).tocsr()
    part = np.zeros(n_nodes, np.int64)
    if n_nodes < PARTS:
        return part
    left, right = _halves(graph, np.arange(n_nodes))
    for first, half in ((0, left), (2, right)):
        a, b = _halves(graph, half)
        part[a], part[b] = first, first + 1
    return part


def item_groups(part: np.ndarray, item_nodes: np.ndarray) -> np.ndarray:
    """The group (M,) of each item of nodes `item_nodes` (M, k): its part if all its nodes share one, else its half's
    cut (4 + half) if they share a half, else the whole's cut (6)."""
    parts = part[np.asarray(item_nodes, np.int64)]
    low, high = parts.min(axis=1), parts.max(axis=1)
    return np.where(low == high, low, np.where(low // 2 == high // 2, PARTS + low // 2, GROUPS - 1))


def group_order(groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(order (M,) int64, start (GROUPS + 1,) int64): the items by group, in their own order within one, group g's
    being order[start[g]:start[g + 1]]."""
    order = np.argsort(groups, kind="stable")
    start = np.zeros(GROUPS + 1, np.int64)
    np.cumsum(np.bincount(groups, minlength=GROUPS), out=start[1:])
    return order, start
