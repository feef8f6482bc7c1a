"""A still picture of a Scene (liver_sim.view.scene) with matplotlib: what the live view shows, for the README
and for machines without the Foxglove app."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from liver_sim.view.scene import FORCE_COLOUR, LIPS_COLOUR, MODEL_COLOUR, TOOL_COLOUR, Scene, force_arrow, plane_patch

#: Half the side (m) of the close-up around the tool.
CLOSE_UP_HALF_M = 0.04


def _draw(axis, scene: Scene, centre: np.ndarray, half: float, skin_alpha: float) -> None:
    # matplotlib loads only when a picture is drawn (the live view itself never needs it)
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    faces = scene.colours[scene.skin].mean(axis=1)
    faces[:, 3] = skin_alpha
    axis.add_collection3d(Poly3DCollection(scene.triangles, facecolors=faces, edgecolors=(0.3, 0.15, 0.1, 0.2),
                                           linewidths=0.2))
    for tool in scene.tools:
        if tool.local_model is not None and tool.local_model.kind == "plane":
            axis.add_collection3d(Poly3DCollection(plane_patch(tool.local_model), facecolors=MODEL_COLOUR,
                                                   edgecolors=MODEL_COLOUR[:3]))
        if tool.tool_tip_m is not None:
            u, v = np.mgrid[0:2 * np.pi:16j, 0:np.pi:8j]
            r, tip = tool.tool_radius_m, tool.tool_tip_m
            axis.plot_surface(tip[0] + r * np.cos(u) * np.sin(v), tip[1] + r * np.sin(u) * np.sin(v),
                              tip[2] + r * np.cos(v), color=TOOL_COLOUR, linewidth=0, alpha=0.6)
            if tool.name:
                axis.text(tip[0], tip[1], tip[2] + 1.5 * r, tool.name, fontsize=8)
        arrow = force_arrow(tool)
        if arrow is not None:
            start, end = arrow
            axis.quiver(*start, *(end - start), color=FORCE_COLOUR, linewidth=2.5, arrow_length_ratio=0.25)
    if len(scene.lips):
        axis.add_collection3d(Line3DCollection(scene.lips, colors=LIPS_COLOUR, linewidths=1.5))
    for setter, c in zip((axis.set_xlim, axis.set_ylim, axis.set_zlim), centre):
        setter(c - half, c + half)
    axis.set_box_aspect((1, 1, 1))
    axis.view_init(elev=25, azim=-60)
    axis.set_xlabel("x (m)", fontsize=8)
    axis.set_ylabel("y (m)", fontsize=8)
    axis.set_zlabel("z (m)", fontsize=8)
    axis.tick_params(labelsize=7)


def draw_scene(scene: Scene, path: Path, title: str = "") -> Path:
    """Draw `scene` into the PNG `path`: the whole liver (skin coloured by displacement, each tool with its local
    model and force arrow, lips) and, with a tool, a close-up around the tools with the skin made see-through."""
    import matplotlib  # heavy, and only for the commands that draw

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    corners = scene.triangles.reshape(-1, 3)
    low, high = corners.min(axis=0), corners.max(axis=0)
    tips = np.array([tool.tool_tip_m for tool in scene.tools if tool.tool_tip_m is not None]).reshape(-1, 3)
    close_up = len(tips) > 0
    figure = plt.figure(figsize=(11 if close_up else 7, 5))
    whole = figure.add_subplot(1, 2 if close_up else 1, 1, projection="3d")
    _draw(whole, scene, (low + high) / 2.0, (high - low).max() / 2.0, 1.0)
    whole.set_title("the liver", fontsize=9)
    if close_up:
        near = figure.add_subplot(1, 2, 2, projection="3d")
        middle = (tips.min(axis=0) + tips.max(axis=0)) / 2.0
        _draw(near, scene, middle, max(CLOSE_UP_HALF_M, float(np.ptp(tips, axis=0).max()) / 2.0 + 0.025), 0.35)
        shown = [what for what, present in (
            ("local model (blue)", any(tool.local_model is not None for tool in scene.tools)),
            ("contact force (green)", any(force_arrow(tool) is not None for tool in scene.tools))) if present]
        near.set_title(("at the tools" if len(tips) > 1 else "at the tool") + (": " + ", ".join(shown) if shown
                                                                                else ""), fontsize=9)
    figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
