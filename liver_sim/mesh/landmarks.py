"""Places on a mesh at rest where scripts and benchmarks put the tool: the top of the dome, a point or a path on
the upper skin."""
from __future__ import annotations

import numpy as np

from liver_sim.mesh.tetmesh import TetMesh


def press_anchor(mesh: TetMesh) -> np.ndarray:
    """The topmost skin node (m): the diaphragmatic dome, where the scripts press."""
    nodes = mesh.skin_nodes
    return mesh.points[nodes[np.argmax(mesh.points[nodes, 2])]].copy()


def upper_skin_point(mesh: TetMesh, xy) -> np.ndarray:
    """(3,) m: the upper skin of `mesh` at rest above `xy` (m, in the xy plane; upper_skin_path); ValueError when
    the mesh is not under it."""
    return upper_skin_path(mesh, xy, xy, 1)[0]


def upper_skin_path(mesh: TetMesh, start_xy, end_xy, points: int = 11) -> np.ndarray:
    """(points, 3) m: a straight line from `start_xy` to `end_xy` (m, in the xy plane) dropped onto the
    upper skin of `mesh` at rest (vertical rays, highest hit): a blade path along the surface.
    ValueError when a ray misses the mesh."""
    skin = mesh.points[mesh.skin]
    a, b, c = skin[:, 0, :2], skin[:, 1, :2], skin[:, 2, :2]
    det = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    upward = np.abs(det) > 0.0
    path = []
    for q in np.linspace(np.asarray(start_xy, float), np.asarray(end_xy, float), points):
        u = ((q - a)[:, 0] * (c - a)[:, 1] - (q - a)[:, 1] * (c - a)[:, 0]) / np.where(upward, det, 1.0)
        v = ((b - a)[:, 0] * (q - a)[:, 1] - (b - a)[:, 1] * (q - a)[:, 0]) / np.where(upward, det, 1.0)
        hit = upward & (u >= 0) & (v >= 0) & (u + v <= 1)
        if not hit.any():
            raise ValueError(f"the path point {q.tolist()} (m) is not above the mesh")
        z = ((1 - u - v) * skin[:, 0, 2] + u * skin[:, 1, 2] + v * skin[:, 2, 2])[hit]
        path.append([q[0], q[1], z.max()])
    return np.array(path)
