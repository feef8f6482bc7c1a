"""What the live view shows, without ROS or Foxglove: the deformed skin coloured by displacement, each tool with its
local model and contact force, and the lips of what a tear or a cut opened (liver frame, metres).

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
class SceneTool:
    """One tool of a scene: its `name` ('' for the tool in the root namespace, the only one by default), its tip
    (m; None: not seen) and radius, its local model (or None) and the contact force on it (N, liver frame)."""

    name: str = ""
    tool_tip_m: np.ndarray | None = None
    tool_radius_m: float = 0.015
    local_model: LocalModel | None = None
    force_n: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class Scene:
    """One frame of the view: the deformed node `points` (N, 3) m with their `colours` (N, 4) RGBA, the `skin`
    triangles (K, 3) over them, the `tools` and the lips of opened skin as (L, 2, 3) segments."""

    points: np.ndarray
    colours: np.ndarray
    skin: np.ndarray
    tools: tuple[SceneTool, ...] = ()
    lips: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))

    @property
    def largest_force_n(self) -> float:
        """The largest contact force on a tool (N, its norm)."""
        return max((float(np.linalg.norm(tool.force_n)) for tool in self.tools), default=0.0)

    @property
    def triangles(self) -> np.ndarray:
        """(K, 3, 3) corner positions of the skin triangles (m)."""
        return self.points[self.skin]

    @property
    def triangle_count(self) -> int:
        return len(self.skin)


def displacement_colours(displacement_m: np.ndarray) -> np.ndarray:
    """(N, 4) RGBA per node: REST_COLOUR at rest to DISPLACED_COLOUR at DISPLACEMENT_SCALE_M and beyond."""
    share = np.clip(np.asarray(displacement_m, dtype=np.float64) / DISPLACEMENT_SCALE_M, 0.0, 1.0)[:, None]
    return (1.0 - share) * REST_COLOUR + share * DISPLACED_COLOUR


#: Rest positions closer than this (m) are one point when lips are looked for (opened_triangles).
TWIN_TOLERANCE_M = 1e-7


def opened_triangles(rest_m: np.ndarray, skin: np.ndarray) -> np.ndarray:
    """Mask of the skin triangles a tear or a cut opened: the two lips of an opening lie on each other at rest (a
    separation duplicates nodes in place, physics.topology.change), so such a triangle has a twin with the same rest
    corners (to TWIN_TOLERANCE_M); the skin of the original surface has none."""
    skin = np.asarray(skin, dtype=np.int64).reshape(-1, 3)
    if not len(skin):
        return np.zeros(0, dtype=bool)
    corners = np.round(np.asarray(rest_m, dtype=np.float64)[skin] / TWIN_TOLERANCE_M).astype(np.int64)
    point = np.dtype([("x", np.int64), ("y", np.int64), ("z", np.int64)])
    ordered = np.sort(np.ascontiguousarray(corners).view(point).reshape(len(skin), 3), axis=1)
    _, inverse, counts = np.unique(ordered.view(np.int64).reshape(len(skin), 9), axis=0, return_inverse=True,
                                   return_counts=True)
    return counts[inverse.ravel()] > 1


def lip_edges(rest_m: np.ndarray, skin: np.ndarray) -> np.ndarray:
    """(L, 2) node pairs: the rims of what opened, the skin edges shared by an opened triangle and one of the
    original surface (opened_triangles); none before any tear or cut."""
    skin = np.asarray(skin, dtype=np.int64).reshape(-1, 3)
    opened = opened_triangles(rest_m, skin)
    if not opened.any():
        return np.zeros((0, 2), dtype=np.int64)

    def edges(triangles: np.ndarray) -> np.ndarray:
        return np.unique(np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)

    both = np.concatenate([edges(skin[opened]), edges(skin[~opened])])
    unique, counts = np.unique(both, axis=0, return_counts=True)
    return unique[counts > 1]


def scene_tool(tool_tip_m: np.ndarray | None = None, tool_radius_m: float = 0.015,
               local_model: LocalModel | None = None, force_n: np.ndarray | None = None, name: str = "") -> SceneTool:
    """The SceneTool of a tool's state: its tip, radius, local model (an invalid one: none) and force."""
    return SceneTool(name, None if tool_tip_m is None else np.asarray(tool_tip_m, float), tool_radius_m,
                     local_model if local_model is not None and local_model.valid else None,
                     np.zeros(3) if force_n is None else np.asarray(force_n, dtype=np.float64))


def build_scene(positions: np.ndarray, rest_positions: np.ndarray, skin: np.ndarray, lips: np.ndarray | None = None,
                tool_tip_m: np.ndarray | None = None, tool_radius_m: float = 0.015,
                local_model: LocalModel | None = None, force_n: np.ndarray | None = None,
                tools: tuple[SceneTool, ...] | None = None) -> Scene:
    """The Scene of node `positions` (N, 3) m over `rest_positions` (the first ones of this node count), the
    `skin` (K, 3), its `lips` (L, 2) node pairs (lip_edges), and the tool's state (scene_tool), or `tools`, the
    SceneTools of several; colours by each node's displacement from rest."""
    positions = np.asarray(positions, dtype=np.float64)
    if len(rest_positions) == len(positions):
        displacement = np.linalg.norm(positions - rest_positions, axis=1)
    else:
        displacement = np.zeros(len(positions))
    lips = np.zeros((0, 2), dtype=np.int64) if lips is None else np.asarray(lips, dtype=np.int64).reshape(-1, 2)
    if tools is None:
        tools = (scene_tool(tool_tip_m, tool_radius_m, local_model, force_n),)
    return Scene(positions, displacement_colours(displacement), np.asarray(skin, dtype=np.int64), tuple(tools),
                 positions[lips])


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


def force_arrow(tool: SceneTool) -> tuple[np.ndarray, np.ndarray] | None:
    """(start, end) of the force arrow of a tool (m): from the tool tip along the force,
    ARROW_M_PER_N per newton; None without a tip or a force."""
    if tool.tool_tip_m is None or not np.any(tool.force_n):
        return None
    return tool.tool_tip_m, tool.tool_tip_m + ARROW_M_PER_N * tool.force_n
