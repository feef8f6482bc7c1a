"""The liver's state: what a frame changes, on one Structure (liver_sim.physics.structure).

Positions (m) and velocities (m/s) per node, the external loads (N) applied at every step, the nodes a tool holds,
the inverse masses the integrators use (0 for fixed and held nodes), the implicit integrator's warm start and BDF2
history (physics.solver.implicit.StepHistory) and the simulation clock.  A tear or a cut carries it onto the new
structure (`carried_state`); the old state is left as it was.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from liver_sim.physics.solver.implicit import StepHistory
from liver_sim.physics.structure import Structure
from liver_sim.physics.topology.change import NodeState


@dataclass(eq=False)
class State:
    """The state of a liver on `structure`-sized arrays (N nodes): positions, velocities and external_forces_n
    (N, 3), held_nodes (H,) int64, inv_mass (N,) 1/kg, the integrator's `history` and time_s (s)."""

    positions: np.ndarray
    velocities: np.ndarray
    external_forces_n: np.ndarray
    held_nodes: np.ndarray
    inv_mass: np.ndarray
    history: StepHistory
    time_s: float = 0.0

    def hold(self, structure: Structure, nodes: np.ndarray) -> None:
        """Let a tool move `nodes` instead of the integrator (their inverse mass 0, as the fixed nodes'); none:
        let go."""
        self.held_nodes = np.asarray(nodes, dtype=np.int64)
        self.inv_mass = inverse_masses(structure, self.held_nodes)

    def rest(self, structure: Structure) -> None:
        """Back to the rest shape, at rest, nothing held and no step history; the clock and loads stay."""
        self.positions = structure.mesh.points.copy()
        self.velocities = np.zeros_like(self.positions)
        self.history.reset()
        if self.held_nodes.size:
            self.hold(structure, np.zeros(0, dtype=np.int64))

    def displacement_m(self, structure: Structure) -> np.ndarray:
        """|x − x_rest| per node (m)."""
        return np.linalg.norm(self.positions - structure.mesh.points, axis=1)


def inverse_masses(structure: Structure, held_nodes: np.ndarray) -> np.ndarray:
    """1/m per node, 0 for the fixed and the held nodes."""
    inv_mass = 1.0 / structure.masses_kg
    inv_mass[structure.fixed_nodes] = 0.0
    inv_mass[held_nodes] = 0.0
    return inv_mass


def rest_state(structure: Structure) -> State:
    """The structure at rest: positions its rest points, no velocity, no load, nothing held, time 0."""
    n = structure.node_count
    nothing = np.zeros(0, dtype=np.int64)
    return State(structure.mesh.points.copy(), np.zeros((n, 3)), np.zeros((n, 3)), nothing,
                 inverse_masses(structure, nothing), StepHistory(n))


def carried_state(structure: Structure, state: State, nodes: NodeState) -> State:
    """`state` on the new `structure`, its node state carried over (`nodes`: physics.topology.change.carry_over): the
    same held nodes (a change keeps the numbers of the nodes it does not add) and clock, the implicit step from no
    history (backward Euler from the carried state)."""
    return State(nodes.positions, nodes.velocities, nodes.external_forces_n, state.held_nodes,
                 inverse_masses(structure, state.held_nodes), StepHistory(structure.node_count), state.time_s)
