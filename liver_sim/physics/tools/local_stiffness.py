"""K of the haptic local model: the stiffness the tool meets under its contact within one frame (paper §2.5, P11).

What the physics answers to the tool moving by Δ along its push over one frame T: the contact rows (each k·δ + c·δ̇,
Eq. 3, the tool's δ̇ = Δ/T: k + c/T) in series with the tissue under them, whose one-step compliance is
c_h = h²·bᵀ·A⁻¹·b, A = M − h·D − h²·K the step's own system (h = T, or 2T/3 in a BDF2 step) and b the rows' unit
load pattern
(implicit.ImplicitEuler.compliance with the horizon h: the tissue's inertia and Kelvin–Voigt viscosity stiffen it
within a frame), so 1/K = 1/Σ(k + c/h) + c_h.  The compliance changes slowly — with the tissue's strain and as the
touched patch moves — so it is solved every `refresh_frames` frames (warm-started from the last solution) and reused
in between, while the contact part follows the rows pushing at each frame.  Other tools on the liver hold the tissue
while this one presses: their pushing contact rows enter the compliance solve as the penalty springs they are, and
the nodes a tool grasps are held (contact_rows).
"""
from __future__ import annotations

import numpy as np

from liver_sim.physics.contact.kernels import ToolSweep
from liver_sim.physics.contact.rows import Contacts, row_forces_n
from liver_sim.physics.solver.implicit import ImplicitEuler
from liver_sim.physics.state import ToolState

#: Frames between two solves of the tissue's compliance under the tool (10: 15 Hz at 150 Hz; K then stays
#: within 10 % of a solve at every frame over the demo's press and slide, a test).
REFRESH_FRAMES = 10


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
    """K of the local model (N/m): the touching probes' penalties (in parallel, `probes` × the one-frame penalty)
    in series with the tissue under them (1/compliance): 1/K = 1/(probes·penalty) + compliance."""
    return 1.0 / (1.0 / (probes * penalty_n_per_m) + max(tissue_compliance_m_per_n, 0.0))


def row_stiffness(rows: Contacts, x: np.ndarray, v: np.ndarray, frame_s: float) -> tuple[float, np.ndarray]:
    """The one-frame stiffness (N/m) of the pushing `rows` along their total push d against a tool moving over the
    frame `frame_s` T, Σ (k + c/T)·(n·d)², and the unit load pattern (N, 3) of their answer to a move along d (each
    row's (k + c/T)·(n·d)·n spread by its weights); (0, zeros) when none pushes."""
    load = np.zeros_like(x)
    if not len(rows):
        return 0.0, load
    forces = np.maximum(row_forces_n(rows, x, v), 0.0)
    push = (forces[:, None] * rows.normal).sum(axis=0)
    total = float(np.linalg.norm(push))
    if total <= 0.0:
        return 0.0, load
    along = rows.normal @ (push / total)
    answer = np.where(forces > 0.0, (rows.stiffness_n_per_m + rows.damping_ns_per_m / frame_s) * along, 0.0)
    stiffness = float((answer * along).sum())
    pushes = answer[:, None] * rows.normal
    used = rows.nodes >= 0
    np.add.at(load, rows.nodes[used], (np.where(used, rows.weights, 0.0)[:, :, None]
                                       * (pushes / np.linalg.norm(pushes.sum(axis=0)))[:, None, :])[used])
    return stiffness, load


def stiffness_n_per_m(solver: ImplicitEuler, tool: ToolState, positions: np.ndarray, velocities: np.ndarray,
                      inv_mass: np.ndarray, penalty_n_per_m: float, environment_damping_per_s: float, frame_s: float,
                      step_s: float, own: Contacts | None = None, others: Contacts | None = None,
                      rotations: np.ndarray | None = None, refresh_frames: int = REFRESH_FRAMES) -> float:
    """K (N/m) for this frame's tool: the one-frame stiffness of its contact rows `own` pushing at the state against
    a tool moving over the frame `frame_s` (row_stiffness; where none pushes, the touching probes of its sweep, each
    with the one-frame `penalty_n_per_m` λ + μ/T) in series with the tissue's one-step compliance under their push,
    from the system of `solver` at `positions` with the step `step_s`, the held nodes (inv_mass 0) fixed and the
    other tools' pushing rows `others` holding the tissue (`rotations`: the state's StepHistory.rotations); the
    penalty alone when no probe is within reach. The compliance is solved every `refresh_frames` frames in which a
    probe is within reach, and at the first such frame after a reset or a topology change
    (ToolState.compliance_m_per_n None), warm-started from the last solution (ToolState.compliance_guess)."""
    probes = touching_probes(tool.sweep)
    contact, load = row_stiffness(own if own is not None else Contacts.none(), positions, velocities, frame_s)
    if probes == 0.0 and contact == 0.0:
        return penalty_n_per_m
    if contact == 0.0:
        contact, load = probes * penalty_n_per_m, contact_load(tool.sweep, len(positions))
    tool.frames_since_solve += 1
    if tool.compliance_m_per_n is None or tool.frames_since_solve >= refresh_frames:
        if tool.compliance_guess is None:
            tool.compliance_guess = np.zeros((len(positions), 3))
        tool.compliance_m_per_n = solver.compliance(positions, inv_mass, load, environment_damping_per_s,
                                                    tool.compliance_guess, others, rotations, step_s)
        tool.frames_since_solve = 0
    return local_stiffness(contact, 1.0, tool.compliance_m_per_n)
