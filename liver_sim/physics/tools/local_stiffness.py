"""K of the haptic local model: the stiffness the tool meets under its contact (paper §2.5, P11).

The tool's penalty springs (λ per probe, paper Eq. 3) push on the tissue, which yields under them:
the two act in series, 1/K = 1/(probes·λ) + c, with c = bᵀ·K_t⁻¹·b the static compliance of the
spring network under the tool's unit load pattern b (implicit.ImplicitEuler.compliance).  The
compliance changes slowly — with the tissue's strain and as the touched patch moves — so it is solved
every `refresh_frames` frames (warm-started from the last solution) and reused in between, while the
penalty part follows the probes touching at each frame.  A solve is not made within one frame: it is assembled
SOLVE_FRAMES frames before the frame that takes its result and its PCG iterations are spread over the frames
between, so that no frame carries a whole solve; the frame that takes it is fixed, and the slices make the
iterations of one solve, so K is the same whatever the machine (implicit.ComplianceSolve).  Other tools on the
liver hold the tissue while this one presses: their pushing contact rows enter the compliance solve as the penalty
springs they are, and the nodes a tool grasps are held (contact_rows).
"""
from __future__ import annotations

import math

import numpy as np

from liver_sim.physics.contact.kernels import ToolSweep
from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.solver.implicit import ImplicitEuler
from liver_sim.physics.state import ToolState

#: Frames between two solves of the tissue's compliance under the tool, and frames over which a solve runs (its
#: assembly in the first, its result taken REFRESH_FRAMES after the last was): a K is at most their sum less one
#: frames old (9 frames, 60 ms at 150 Hz, as old as a whole solve every 10 frames left it), within which it stays
#: within 10 % of a solve at every frame over the demo's press and slide (a test).
REFRESH_FRAMES = 7
SOLVE_FRAMES = 3


def _rows(tool: ToolSweep) -> tuple[np.ndarray, np.ndarray]:
    """(rows within the candidates: finite depth, rows touching: penetrating with a share) of the tool's probes."""
    finite = np.isfinite(tool.depth)
    return finite, finite & (tool.depth > 0.0) & (tool.share > 0.0)


def contact_load(tool: ToolSweep, n_nodes: int) -> np.ndarray:
    """The pattern of the tool's push on the liver, scaled to a unit total, (N, 3): the touching rows'
    elastic pushes share·λ·δ·n spread by barycentric weights (as the last step left them); out of
    contact, a unit push at the nearest row's surface point (none within the candidates: zeros)."""
    load = np.zeros((n_nodes, 3))
    finite, touching = _rows(tool)
    if not finite.any():
        return load
    if touching.any():
        amount = np.where(touching, tool.share * tool.depth, 0.0)
    else:
        amount = (np.arange(len(tool.depth)) == np.argmax(np.where(finite, tool.depth, -np.inf))).astype(float)
    pushes = amount[:, None] * tool.normal
    total = float(np.linalg.norm(pushes.sum(axis=0)))
    if total > 0.0:
        np.add.at(load, tool.nodes.ravel(), (tool.weights[:, :, None] * pushes[:, None, :] / total).reshape(-1, 3))
    return load


def touching_probes(tool: ToolSweep) -> float:
    """How many probes' worth of penalty carry the tool's push: the sum of the touching rows' shares;
    1 when none touches but one is within the candidates (the first touch), 0 when none is."""
    finite, touching = _rows(tool)
    if not finite.any():
        return 0.0
    return float(tool.share[touching].sum()) if touching.any() else 1.0


def local_stiffness(penalty_n_per_m: float, probes: float, tissue_compliance_m_per_n: float) -> float:
    """K of the local model (N/m): the touching probes' penalties (in parallel, `probes` × λ) in series with
    the tissue under them (1/compliance): 1/K = 1/(probes·λ) + compliance."""
    return 1.0 / (1.0 / (probes * penalty_n_per_m) + max(tissue_compliance_m_per_n, 0.0))


def stiffness_n_per_m(solver: ImplicitEuler, tool: ToolState, positions: np.ndarray, inv_mass: np.ndarray,
                      penalty_n_per_m: float, environment_damping_per_s: float, others: Contacts | None = None,
                      rotations: np.ndarray | None = None, refresh_frames: int = REFRESH_FRAMES) -> float:
    """K (N/m) for this frame's tool (its sweep's contact geometry as the step left it): the penalty of the touching
    probes in series with the tissue's compliance under their push, from the tangent stiffness of `solver`'s
    network at `positions` with the held nodes (inv_mass 0) fixed and the other tools' pushing rows `others` holding
    the tissue (`rotations`: the state's StepHistory.rotations); the penalty alone when no probe is within reach.
    The compliance counts the frames in which a probe is within reach: solved at once at the first such frame after a
    reset or a topology change (ToolState.compliance_m_per_n None); then taken every `refresh_frames` of them from a
    solve (ToolState.compliance_solve, on the tool's ToolState.compliance_workspace) assembled min(SOLVE_FRAMES,
    refresh_frames − 1) frames before at the positions of that frame, its iterations spread over the frames
    between as the last solve's count divided among them, the rest made in the frame that takes it; warm-started
    from the last solution (ToolState.compliance_guess)."""
    probes = touching_probes(tool.sweep)
    if probes == 0.0:
        return penalty_n_per_m
    tool.frames_since_solve += 1
    if tool.compliance_m_per_n is None:
        _begin(solver, tool, positions, inv_mass, environment_damping_per_s, others, rotations)
        _take(tool)
    else:
        lead = min(SOLVE_FRAMES, refresh_frames - 1)
        if tool.compliance_solve is None and tool.frames_since_solve >= refresh_frames - lead:
            _begin(solver, tool, positions, inv_mass, environment_damping_per_s, others, rotations)
            tool.compliance_solve.advance(0)  # r = b − A·z0: the start of the solve
        elif tool.compliance_solve is not None and tool.frames_since_solve < refresh_frames:
            tool.compliance_solve.advance(math.ceil(tool.compliance_iterations / max(lead - 1, 1)))
        if tool.frames_since_solve >= refresh_frames:
            _take(tool)
    return local_stiffness(penalty_n_per_m, probes, tool.compliance_m_per_n)


def _begin(solver: ImplicitEuler, tool: ToolState, positions: np.ndarray, inv_mass: np.ndarray,
           environment_damping_per_s: float, others: Contacts | None, rotations: np.ndarray | None) -> None:
    """Assemble the tool's compliance solve at `positions` (ToolState.compliance_solve) on its workspace."""
    if tool.compliance_workspace is None:
        tool.compliance_workspace = solver.workspace()
    if tool.compliance_guess is None:
        tool.compliance_guess = np.zeros((len(positions), 3))
    tool.compliance_solve = solver.compliance_solve(tool.compliance_workspace, positions, inv_mass,
                                                    contact_load(tool.sweep, len(positions)),
                                                    environment_damping_per_s, tool.compliance_guess, others,
                                                    rotations)


def _take(tool: ToolState) -> None:
    """End the tool's compliance solve and take its result: ToolState.compliance_m_per_n, its iterations."""
    tool.compliance_m_per_n = tool.compliance_solve.finish()
    tool.compliance_iterations = tool.compliance_solve.iterations
    tool.compliance_solve = None
    tool.frames_since_solve = 0
