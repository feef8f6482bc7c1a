"""The records the implicit step's kernels take (numba passes named tuples of arrays as one argument).

`Operator` is the step's matrix-free system A that `implicit_kernels.assemble` fills and `pcg` multiplies by,
`ContactRows` the contacts' penalty rows (contact.rows.Contacts) with each row's coefficient in A, `Loads` what acts
on every node besides the tissue, `Tissue` the laws a step sums, `SolveSettings` when the CG and Newton iterations
stop, `Scratch` a solver's work arrays.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from liver_sim.physics.solver.partition import PARTS, group_order, item_groups, node_parts
from liver_sim.physics.tissue.fem_kernels import TetArrays
from liver_sim.physics.tissue.organ_support import SupportArrays
from liver_sim.physics.tissue.spring_law import SpringArrays


class Operator(NamedTuple):
    """The step's system A = M − h·D − h²·K without contacts and tetrahedra: per spring its nodes (E,) uint32, unit
    axis `unit` (E, 3) and block B = iso·I + axial·uuᵀ (`iso`, `axial` (E,)); per node `shift` (N,), m·(1 + h·c_env)
    plus the support's h·c + h²·k (1 on held nodes), and the 3×3 `diagonal` blocks (N, 3, 3).  The groups of the
    product (physics.solver.partition): the springs are the network's in the order `spring_order` (E,) int64, group
    g's spring_start[g]..spring_start[g + 1] − 1; part g's nodes `part_nodes`[part_start[g]:part_start[g + 1]]
    (uint32); group g's elements `tet_order`[tet_start[g]:tet_start[g + 1]] (uint32); the starts uint64."""

    node_i: np.ndarray
    node_j: np.ndarray
    unit: np.ndarray
    iso: np.ndarray
    axial: np.ndarray
    shift: np.ndarray
    diagonal: np.ndarray
    spring_order: np.ndarray
    spring_start: np.ndarray
    part_nodes: np.ndarray
    part_start: np.ndarray
    tet_order: np.ndarray
    tet_start: np.ndarray

    @classmethod
    def allocate(cls, node_i: np.ndarray, node_j: np.ndarray, n_nodes: int,
                 tets: np.ndarray | None = None) -> "Operator":
        """The operator of springs `node_i`→`node_j` and elements `tets` (M, 4; none by default) on `n_nodes` nodes,
        to be assembled (blocks 0, shift 1), its springs in group order: the spring law's arrays must be taken in
        `spring_order` too (spring_law.SpringArrays.taken)."""
        tets = np.zeros((0, 4), np.int64) if tets is None else tets
        part = node_parts(n_nodes, node_i, node_j, tets)
        spring_order, spring_start = group_order(item_groups(part, np.stack([node_i, node_j], axis=1)))
        part_nodes = np.argsort(part, kind="stable").astype(np.uint32)
        part_start = np.zeros(PARTS + 1, np.uint64)
        np.cumsum(np.bincount(part, minlength=PARTS), out=part_start[1:])
        tet_order, tet_start = group_order(item_groups(part, tets))
        edges = len(node_i)
        # unsigned ranges spare numba's negative-index wraparound in the loops they bound
        return cls(np.ascontiguousarray(node_i[spring_order]), np.ascontiguousarray(node_j[spring_order]),
                   np.zeros((edges, 3)), np.zeros(edges), np.zeros(edges), np.ones(n_nodes),
                   np.zeros((n_nodes, 3, 3)), spring_order, spring_start.astype(np.uint64), part_nodes, part_start,
                   tet_order.astype(np.uint32), tet_start.astype(np.uint64))

    def emptied(self) -> "Operator":
        """An operator of the same springs, elements and groups (shared, never written) with blocks, shifts and
        diagonal blocks of its own, to be assembled (blocks 0, shift 1)."""
        edges, n_nodes = len(self.node_i), len(self.shift)
        return self._replace(unit=np.zeros((edges, 3)), iso=np.zeros(edges), axial=np.zeros(edges),
                             shift=np.ones(n_nodes), diagonal=np.zeros((n_nodes, 3, 3)))


class ContactRows(NamedTuple):
    """The penalty rows of contact.rows.Contacts for the kernels (`nodes` (K, 3) int64 with −1 pads, `weights`,
    `normal` (K, 3), `offset` o, `speed` s, `stiffness` k, `damping` c (K,); the tool's surface of the rows rebuilt
    at each iterate, `core` (K, 2, 3), `radius` (K,), `core_velocity` (K, 3), `bias` (K,)) and each row's
    `coefficient` (K,) in A, h·c + h²·k while active, else 0 (written by implicit_kernels.contact_forces)."""

    nodes: np.ndarray
    weights: np.ndarray
    normal: np.ndarray
    offset: np.ndarray
    speed: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    core: np.ndarray
    radius: np.ndarray
    core_velocity: np.ndarray
    bias: np.ndarray
    coefficient: np.ndarray

    @classmethod
    def of(cls, contacts, coefficient: np.ndarray) -> "ContactRows":
        """The rows of `contacts` (contact.rows.Contacts) with each row's `coefficient` in the system (its arrays
        shared: the step rebuilds the surface rows' geometry in them)."""
        return cls(contacts.nodes, contacts.weights, contacts.normal, contacts.offset_m, contacts.normal_speed_m_s,
                   contacts.stiffness_n_per_m, contacts.damping_ns_per_m, contacts.core_m, contacts.radius_m,
                   contacts.core_velocity_m_s, contacts.bias_m, coefficient)


class Loads(NamedTuple):
    """`external` forces (N, 3) N, `gravity` (3,) m/s² and the environment's damping `c_env` 1/s."""

    external: np.ndarray
    gravity: np.ndarray
    c_env: float


class Tissue(NamedTuple):
    """The laws a step sums: the `springs` (spring_law.SpringArrays), the organ's `support`
    (organ_support.SupportArrays) and the tetrahedra of the 'fem' or 'neo_hookean' law (`tets`,
    fem_kernels.TetArrays; none with the springs' law)."""

    springs: SpringArrays
    support: SupportArrays
    tets: TetArrays


class SolveSettings(NamedTuple):
    """PCG stops at ‖r‖ ≤ max(`cg_tolerance`·‖b‖, `cg_floor_ns`) or `max_cg_iterations`; Newton's iterations at a
    residual of `newton_tolerance_n` N on every node or `max_newton`."""

    cg_tolerance: float
    max_cg_iterations: int
    newton_tolerance_n: float
    max_newton: int
    cg_floor_ns: float = 0.0


class Scratch(NamedTuple):
    """A solver's work arrays: `work` (10, N, 3) and the block-Jacobi `preconditioner` (N, 3, 3); and whether the
    step's assembly and solve run on the threads (`parallel`; the same bits either way)."""

    work: np.ndarray
    preconditioner: np.ndarray
    parallel: bool
