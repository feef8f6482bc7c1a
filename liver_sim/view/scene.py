"""What the live view shows, without ROS or Foxglove: the deformed skin coloured by displacement, the tool, the
local model, the contact force, and the lips of what a tear or a cut opened (liver frame, metres).

`liver-sim view` (liver_sim.view.server) turns a Scene into a foxglove.SceneUpdate; `liver-sim view --picture`
draws the same Scene with matplotlib (liver_sim.view.picture), so the picture in the README is the view's.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from liver_sim.base.local_model import LocalModel

#: Displacement (m) at which the skin's colour saturates: a 1 cm press is the scale of the demo.
DISPLACEMENT_SCALE_M = 0.01
#: Side of the square patch (m) that shows a plane local model.
PLANE_PATCH_M = 0.04
#: Length (m) of the force arrow per newton.
ARROW_M_PER_N = 0.03
#: Colours (r, g, b, a): rest skin, fully displaced skin, tool, local model, force, lips.
REST_COLOUR = np.array([0.75, 0.45, 0.40, 1.0])
DISPLACED_COLOUR = np.array([0.95, 0.85, 0.25, 1.0])
TOOL_COLOUR = (0.6, 0.6, 0.65, 1.0)
MODEL_COLOUR = (0.2, 0.6, 1.0, 0.45)
FORCE_COLOUR = (0.1, 0.8, 0.2, 1.0)
LIPS_COLOUR = (0.9, 0.1, 0.1, 1.0)


@dataclass(frozen=True)
class Scene:
    """One frame of the view: skin triangles as (T, 3, 3) corner positions with (T, 3, 4) corner colours, the tool
    tip (m) and radius, the local model (or None), the contact force on the tool (N, liver frame) and the lips
    of opened skin as (L, 2, 3) segments."""

    triangles: np.ndarray
    colours: np.ndarray
    tool_tip_m: np.ndarray | None = None
    tool_radius_m: float = 0.015
    local_model: LocalModel | None = None
    force_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    lips: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))

    @property
    def triangle_count(self) -> int:
        return len(self.triangles)


def displacement_colours(displacement_m: np.ndarray) -> np.ndarray:
    """(N, 4) RGBA per node: REST_COLOUR at rest to DISPLACED_COLOUR at DISPLACEMENT_SCALE_M and beyond."""
    share = np.clip(np.asarray(displacement_m, dtype=np.float64) / DISPLACEMENT_SCALE_M, 0.0, 1.0)[:, None]
    return (1.0 - share) * REST_COLOUR + share * DISPLACED_COLOUR


def lips(skin: np.ndarray, initial_skin: np.ndarray | None, positions: np.ndarray) -> np.ndarray:
    """(L, 2, 3) segments: the boundary edges of the skin triangles a tear or a cut added (edges used by one
    new triangle only, so the rim of what opened), at `positions`; none before any topology change."""
    if initial_skin is None or len(skin) == len(initial_skin) and np.array_equal(skin, initial_skin):
        return np.zeros((0, 2, 3))
    known = {tuple(sorted(row)) for row in np.asarray(initial_skin).tolist()}
    added = np.array([row for row in np.asarray(skin).tolist() if tuple(sorted(row)) not in known], dtype=np.int64)
    if added.size == 0:
        return np.zeros((0, 2, 3))
    edges = np.sort(np.concatenate([added[:, [0, 1]], added[:, [1, 2]], added[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    rim = unique[counts == 1]
    return positions[rim]


def build_scene(positions: np.ndarray, rest_positions: np.ndarray, skin: np.ndarray,
                initial_skin: np.ndarray | None = None, tool_tip_m: np.ndarray | None = None,
                tool_radius_m: float = 0.015, local_model: LocalModel | None = None,
                force_n: np.ndarray | None = None) -> Scene:
    """The Scene of node `positions` (N, 3) m over `rest_positions` (the first ones of this node count), the
    `skin` (K, 3) and the rest of the state; colours by each node's displacement from rest."""
    positions = np.asarray(positions, dtype=np.float64)
    skin = np.asarray(skin, dtype=np.int64)
    if len(rest_positions) == len(positions):
        displacement = np.linalg.norm(positions - rest_positions, axis=1)
    else:
        displacement = np.zeros(len(positions))
    colours = displacement_colours(displacement)
    return Scene(positions[skin], colours[skin], None if tool_tip_m is None else np.asarray(tool_tip_m, float),
                 tool_radius_m, local_model if local_model is not None and local_model.valid else None,
                 np.zeros(3) if force_n is None else np.asarray(force_n, dtype=np.float64),
                 lips(skin, initial_skin, positions))


def plane_patch(model: LocalModel, side_m: float = PLANE_PATCH_M) -> np.ndarray:
    """(2, 3, 3): two triangles of a square of `side_m` (m) in the model's plane, centred on its point."""
    normal = model.normal
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    h = side_m / 2.0
    c = model.point
    corners = [c - h * u - h * v, c + h * u - h * v, c + h * u + h * v, c - h * u + h * v]
    return np.array([[corners[0], corners[1], corners[2]], [corners[0], corners[2], corners[3]]])


def force_arrow(scene: Scene) -> tuple[np.ndarray, np.ndarray] | None:
    """(start, end) of the force arrow (m): from the tool tip along the force, ARROW_M_PER_N per newton; None
    without a tool or a force."""
    if scene.tool_tip_m is None or not np.any(scene.force_n):
        return None
    return scene.tool_tip_m, scene.tool_tip_m + ARROW_M_PER_N * scene.force_n
