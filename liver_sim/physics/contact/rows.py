"""Several tools in one implicit step: their contact rows (Contacts) joined, and each tool's share.

The tools' penalty contacts enter the same backward-Euler step as one set of rows (`joined`), so what one tool
does to the tissue — a grasp moving nodes, a press — acts on the others within the frame.  The step returns the
force of all the rows together; each tool's own is the force of its rows at the state the step ends in
(`contact_force_n`: the law of implicit_kernels.contact_forces), and the rows that push at that state
(`pushing`) hold the tissue under the other tools' local models (local_stiffness).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Contacts:
    """Penalty contact elements (see physics.solver.implicit_kernels), one row each.

    nodes (K, 3) int64 (−1 pads), weights (K, 3), normal (K, 3) unit vectors into the liver,
    offset_m (K,) o, normal_speed_m_s (K,) s (the tool surface's speed along n),
    stiffness_n_per_m (K,) k, damping_ns_per_m (K,) c.

    A row on the tool's true surface (a skin node against a ball swept along the segment `core_m` (K, 2, 3), of
    `radius_m` (K,) > 0, moving at `core_velocity_m_s` (K, 3)) is rebuilt at every iterate of the step
    (implicit_kernels.surface_rows): n = (x − c)/|x − c| with c the point of the core nearest the node,
    o = r + n·c + `bias_m`, s = n·v_core, so that its depth is r − |x − c| + bias (the bias: its node's augmented
    Lagrange multiplier over k, contact.tool_geometry.update_multipliers).  Rows of radius 0 keep the geometry they
    were given.
    """

    nodes: np.ndarray
    weights: np.ndarray
    normal: np.ndarray
    offset_m: np.ndarray
    normal_speed_m_s: np.ndarray
    stiffness_n_per_m: np.ndarray
    damping_ns_per_m: np.ndarray
    core_m: np.ndarray = None
    radius_m: np.ndarray = None
    core_velocity_m_s: np.ndarray = None
    bias_m: np.ndarray = None

    def __post_init__(self):
        count = len(self.offset_m)
        for name, shape in (("core_m", (count, 2, 3)), ("radius_m", (count,)), ("core_velocity_m_s", (count, 3)),
                            ("bias_m", (count,))):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(shape))

    @classmethod
    def none(cls) -> "Contacts":
        """No contact."""
        return cls(np.zeros((0, 3), np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0),
                   np.zeros(0), np.zeros(0))

    def __len__(self) -> int:
        return len(self.offset_m)


def node_contacts(nodes, normal, offset_m, normal_speed_m_s, stiffness_n_per_m, damping_ns_per_m) -> Contacts:
    """1-node contact elements (weight 1): Eq. 3 on skin nodes."""
    count = len(nodes)
    padded = np.full((count, 3), -1, dtype=np.int64)
    padded[:, 0] = nodes
    weights = np.zeros((count, 3))
    weights[:, 0] = 1.0
    return Contacts(padded, weights, np.ascontiguousarray(normal, dtype=np.float64),
                    np.asarray(offset_m, dtype=np.float64), np.asarray(normal_speed_m_s, dtype=np.float64),
                    np.broadcast_to(np.asarray(stiffness_n_per_m, dtype=np.float64), (count,)).copy(),
                    np.broadcast_to(np.asarray(damping_ns_per_m, dtype=np.float64), (count,)).copy())


def joined(rows: Sequence[Contacts]) -> Contacts:
    """The rows of every tool, in order, as one Contacts (none: no contact)."""
    if not rows:
        return Contacts.none()
    if len(rows) == 1:
        return rows[0]
    return Contacts(*(np.concatenate([getattr(r, name) for r in rows]) for name in Contacts.__dataclass_fields__))


def split(contacts: Contacts, counts: Sequence[int]) -> list[Contacts]:
    """`contacts` cut into consecutive parts of `counts` rows (the inverse of `joined`; the parts share its arrays)."""
    if len(counts) == 1:
        return [contacts]
    edges = np.cumsum([0, *counts])
    return [Contacts(*(getattr(contacts, name)[first:last] for name in Contacts.__dataclass_fields__))
            for first, last in zip(edges[:-1], edges[1:])]


def row_forces_n(contacts: Contacts, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(E,) the penalty of each row at (x, v), before clipping (N): F = k·(o − n·Σ w_a·x_a) + c·(s − n·Σ w_a·v_a),
    node −1 padding out."""
    used = contacts.nodes >= 0
    nodes = np.where(used, contacts.nodes, 0)
    weights = np.where(used, contacts.weights, 0.0)[:, :, None]
    along_x = np.einsum("ij,ij->i", contacts.normal, (weights * x[nodes]).sum(axis=1))
    along_v = np.einsum("ij,ij->i", contacts.normal, (weights * v[nodes]).sum(axis=1))
    return (contacts.stiffness_n_per_m * (contacts.offset_m - along_x)
            + contacts.damping_ns_per_m * (contacts.normal_speed_m_s - along_v))


def contact_force_n(contacts: Contacts, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The force of `contacts` on the liver at (x, v) (N, (3,)): Σ max(0, F)·n over the rows (row_forces_n)."""
    if not len(contacts):
        return np.zeros(3)
    return (np.maximum(row_forces_n(contacts, x, v), 0.0)[:, None] * contacts.normal).sum(axis=0)


def pushing(contacts: Contacts, x: np.ndarray, v: np.ndarray) -> Contacts:
    """The rows of `contacts` that push the liver at (x, v) (F > 0)."""
    if not len(contacts):
        return contacts
    keep = row_forces_n(contacts, x, v) > 0.0
    return Contacts(*(getattr(contacts, name)[keep] for name in Contacts.__dataclass_fields__))
