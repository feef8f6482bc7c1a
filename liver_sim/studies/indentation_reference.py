"""The reference of the indentation check: linear P1 elasticity at rest, pressed by an ideal frictionless sphere.

The textbook model the check's set-up must reproduce before the product is held to it: small-strain linear
elasticity on the block's own tetrahedra (the element stiffness K_ab = V·(λ·g_a⊗g_b + μ·(g_b⊗g_a + (g_a·g_b)·I)),
g the shape-function gradients of physics.tissue.fem_kernels.build_tets), the bottom bonded, solved statically; the
sphere an ideal rigid contact: every top-face node under it held on its surface in z (free to slide in x and y),
the set of held nodes found by the active-set rule — a node that would rise into the sphere is held, a held node
the sphere would pull is let go.  The force on the sphere is the sum of the held nodes' reactions.  No contact
stiffness, no sink, no time: what is left between it and Hertz is the mesh.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.tissue.fem_kernels import build_tets

#: The active set is final when no node enters or leaves it; at most this many solves per depth.
MAX_ACTIVE_SET_ROUNDS = 30


def stiffness_matrix(mesh: TetMesh, young_pa: float, poisson: float) -> scipy.sparse.csr_matrix:
    """The (3N, 3N) stiffness of linear P1 elasticity on `mesh` (N/m), DOF 3·node + axis."""
    law = build_tets(mesh.points, mesh.tets, young_pa, poisson, 0.0)
    g, volume = law.gradients, law.volume_m3
    lam, mu = law.lame_lambda_pa, law.lame_mu_pa
    # blocks[t, a, b] = V·(λ·g_a g_bᵀ + μ·g_b g_aᵀ + μ·(g_a·g_b)·I)
    outer = np.einsum("tai,tbj->tabij", g, g)
    blocks = lam * outer + mu * np.swapaxes(outer, 3, 4)
    blocks += mu * np.einsum("tai,tbi->tab", g, g)[..., None, None] * np.eye(3)
    blocks *= volume[:, None, None, None, None]
    dofs = 3 * law.tets[:, :, None] + np.arange(3)  # (T, 4, 3)
    rows = np.broadcast_to(dofs[:, :, None, :, None], blocks.shape)
    cols = np.broadcast_to(dofs[:, None, :, None, :], blocks.shape)
    size = 3 * len(mesh.points)
    return scipy.sparse.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(size, size))


def sphere_indentation(mesh: TetMesh, young_pa: float, poisson: float, radius_m: float, depths_m,
                       bonded_nodes) -> list[dict]:
    """Per depth δ (sphere centre at the middle of the top face, radius_m − δ above it): {depth_m, force_n (the
    sphere's push, N), held_nodes, rounds}; raises RuntimeError if the active set does not settle.

    The candidates are the top-face nodes under the sphere; with G the compliance among them (the z displacement
    of i under a unit z force at j, from one factorisation of the stiffness, a column per node ever held) and p ≥ 0
    the sphere's push on the held set H, G_HH·p = −t_H puts them on the sphere (t: the z displacement that does);
    a held node with p < 0 is let go, a free candidate with −G_iH·p > t_i is held, until neither happens. Where no
    node lies under the sphere, nothing is held and the force is 0 (the mesh cannot resolve that contact)."""
    stiffness = stiffness_matrix(mesh, young_pa, poisson)
    points = mesh.points
    bonded = np.asarray(bonded_nodes, dtype=np.int64)
    free = np.setdiff1d(np.arange(stiffness.shape[0]), (3 * bonded[:, None] + np.arange(3)).ravel())
    factor = scipy.sparse.linalg.splu(stiffness[free][:, free].tocsc())
    position = np.full(stiffness.shape[0], -1)
    position[free] = np.arange(len(free))
    top_z = float(points[:, 2].max())
    top = np.flatnonzero(points[:, 2] >= top_z - 1e-9)
    planar = np.hypot(points[top, 0], points[top, 1])
    candidates, planar = top[planar < radius_m], planar[planar < radius_m]
    rows_z = position[3 * candidates + 2]
    columns: dict[int, np.ndarray] = {}

    def compliance(held: np.ndarray) -> np.ndarray:
        """G[:, held]: the candidates' z displacement under a unit z force at each held candidate (m/N)."""
        for j in held:
            if j not in columns:
                unit = np.zeros(len(free))
                unit[rows_z[j]] = 1.0
                columns[j] = factor.solve(unit)[rows_z]
        return np.stack([columns[j] for j in held], axis=1) if len(held) else np.zeros((len(candidates), 0))

    rows = []
    for depth in depths_m:
        target = top_z + radius_m - depth - np.sqrt(radius_m ** 2 - planar ** 2) - points[candidates, 2]
        held = np.flatnonzero(target < 0.0)
        push = np.zeros(0)
        for rounds in range(1, MAX_ACTIVE_SET_ROUNDS + 1):
            g = compliance(held)
            push = np.linalg.solve(g[held], -target[held]) if len(held) else np.zeros(0)
            displacement = -g @ push
            entering = np.setdiff1d(np.flatnonzero(displacement > target + 1e-12), held)
            pulled = held[push < 0.0]
            if not len(entering) and not len(pulled):
                break
            held = np.union1d(np.setdiff1d(held, pulled), entering)
        else:
            raise RuntimeError(f"{mesh.source}: the sphere's contact set did not settle at {depth * 1e3:.1f} mm "
                               f"in {MAX_ACTIVE_SET_ROUNDS} solves")
        rows.append({"depth_m": float(depth), "force_n": float(push.sum()), "held_nodes": int(len(held)),
                     "rounds": rounds})
    return rows
