"""The liver's state: everything a frame changes, on one Structure (liver_sim.physics.structure).

Positions (m) and velocities (m/s) per node, the external loads (N) applied at every step, the nodes the tools hold,
the inverse masses the integrators use (0 for fixed and held nodes), the implicit integrator's warm start, BDF2
history and the elements' rotations (physics.solver.implicit.StepHistory), the set of faces whose tearing came to
nothing, the simulation clock, and per tool (`ToolState`) what its frames leave the next one.  Reset is
`rest_state(structure, ...)`; a tear or a cut carries the state onto the new structure (`carried_state`), the old
one left as it was.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from liver_sim.physics.contact.kernels import ToolSweep
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.solver.implicit import ComplianceSolve, ImplicitEuler, StepHistory
from liver_sim.physics.structure import Structure
from liver_sim.physics.topology.change import NodeState

NO_NODES = np.zeros(0, dtype=np.int64)


@dataclass(eq=False)
class ToolState:
    """What one tool's frames leave the next: its `previous_pose` (the frame's motion runs from it) and the last
    frame's `sweep` (its probes, candidate triangles and contact rows); its use's `in_contact` at the last frame,
    the `cut_path` (P, 3) m of a cutting stroke so far, the `held_nodes` it grasped and their `grasp_offsets` in
    the tool frame (m); and the tissue's compliance under it (physics.tools.local_stiffness): the last solve's
    `compliance_m_per_n` (None: none yet), its `compliance_guess` (N, 3), its PCG `compliance_iterations` and the
    frames since, the solve under way (`compliance_solve`, None: none) and the solver `compliance_workspace` the
    tool's solves run on (None: none yet; implicit.ImplicitEuler.workspace); with the surface
    contact, its augmented Lagrange multipliers `contact_multipliers_n` (N,) N per node (None: none yet;
    contact.tool_geometry.contact_rows)."""

    previous_pose: ToolPose | None = None
    sweep: ToolSweep | None = None
    in_contact: bool = False
    cut_path: list = field(default_factory=list)
    held_nodes: np.ndarray = field(default_factory=lambda: NO_NODES)
    grasp_offsets: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    compliance_m_per_n: float | None = None
    compliance_guess: np.ndarray | None = None
    frames_since_solve: int = 0
    compliance_iterations: int = 0
    compliance_solve: ComplianceSolve | None = None
    compliance_workspace: ImplicitEuler | None = None
    contact_multipliers_n: np.ndarray | None = None

    @property
    def holding(self) -> bool:
        """Whether the tool holds nodes."""
        return self.held_nodes.size > 0


@dataclass(eq=False)
class State:
    """The state of a liver on `structure`-sized arrays (N nodes): positions, velocities and external_forces_n
    (N, 3), held_nodes (H,) int64 (every tool's), inv_mass (N,) 1/kg, the integrator's `history`, `tools` (a
    ToolState per tool, in the model's order), `futile_tear_faces` (physics.topology.tearing.faces_to_tear) and
    time_s (s)."""

    positions: np.ndarray
    velocities: np.ndarray
    external_forces_n: np.ndarray
    held_nodes: np.ndarray
    inv_mass: np.ndarray
    history: StepHistory
    tools: tuple[ToolState, ...]
    futile_tear_faces: np.ndarray | None = None
    time_s: float = 0.0

    def hold(self, structure: Structure) -> None:
        """Let the tools move the nodes they hold instead of the integrator (their inverse mass 0, as the fixed
        nodes')."""
        held = [tool.held_nodes for tool in self.tools]
        self.held_nodes = held[0] if len(held) == 1 else np.concatenate(held)
        self.inv_mass = inverse_masses(structure, self.held_nodes)

    def displacement_m(self, structure: Structure) -> np.ndarray:
        """|x − x_rest| per node (m)."""
        return np.linalg.norm(self.positions - structure.mesh.points, axis=1)


def inverse_masses(structure: Structure, held_nodes: np.ndarray) -> np.ndarray:
    """1/m per node, 0 for the fixed and the held nodes."""
    inv_mass = 1.0 / structure.masses_kg
    inv_mass[structure.fixed_nodes] = 0.0
    inv_mass[held_nodes] = 0.0
    return inv_mass


def rest_state(structure: Structure, tools: int = 1, time_s: float = 0.0,
               external_forces_n: np.ndarray | None = None) -> State:
    """The structure at rest: positions its rest points, no velocity, nothing held, no step history, `tools` tools
    with no past, the clock at `time_s` and the loads `external_forces_n` (none by default)."""
    n = structure.node_count
    loads = np.zeros((n, 3)) if external_forces_n is None else external_forces_n
    return State(structure.mesh.points.copy(), np.zeros((n, 3)), loads, NO_NODES, inverse_masses(structure, NO_NODES),
                 structure.solver.new_history(), tuple(ToolState() for _ in range(tools)), time_s=time_s)


def carried_state(structure: Structure, state: State, nodes: NodeState) -> State:
    """`state` on the new `structure`, its node state carried over (`nodes`: physics.topology.change.carry_over):
    the same held nodes (a change keeps the numbers of the nodes it does not add) and clock, the tools' poses,
    sweeps, strokes and grasps, the implicit step from no history (backward Euler from the carried state) and the
    tissue's compliance and contact multipliers under each tool unknown (they are of the old network)."""
    tools = tuple(replace(tool, cut_path=list(tool.cut_path), compliance_m_per_n=None, compliance_guess=None,
                          frames_since_solve=0, compliance_iterations=0, compliance_solve=None,
                          compliance_workspace=None, contact_multipliers_n=None)
                  for tool in state.tools)
    return State(nodes.positions, nodes.velocities, nodes.external_forces_n, state.held_nodes,
                 inverse_masses(structure, state.held_nodes), structure.solver.new_history(), tools,
                 time_s=state.time_s)
