"""The demos' pictures: the deformed liver (with the lips of what a tear or a cut opened), the offline
press-and-release. matplotlib loads in each function, for the commands that
draw (it is the heaviest import of the package and the rest never needs it)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from liver_sim.tool.scripts import ScriptSettings


def plot_press_release(data: dict, script: ScriptSettings, name: str, path: Path) -> None:
    """force.png of the offline demo: the force on the tool and the largest displacement over time, the press
    and hold shaded."""
    import matplotlib  # heavy, and only for the commands that draw
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.2), dpi=110)
    t = data["time_s"]
    ax.plot(t, np.linalg.norm(data["tool_force_n"], axis=1), color="tab:red", label="|force on tool| (N)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force (N)", color="tab:red")
    ax.axvspan(script.approach_s, script.approach_s + script.press_s + script.hold_s, color="0.92",
               label="press and hold")
    twin = ax.twinx()
    twin.plot(t, data["max_displacement_m"] * 1e3, color="tab:blue", label="largest node displacement (mm)")
    twin.set_ylabel("displacement (mm)", color="tab:blue")
    ax.set_title(f"Press and release on the {name}")
    lines = ax.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    ax.legend(lines, [line.get_label() for line in lines], loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_liver(rest_m: np.ndarray, skin: np.ndarray, positions_m: np.ndarray, tool_tip_m, tool_radius_m: float,
               title: str, path: Path, wounds: np.ndarray | None = None) -> None:
    """A 3D picture of the deformed skin coloured by displacement, with the tool sphere in red, and the lips
    of the skin triangles marked in `wounds` (opened by a tear or a cut) as red lines."""
    import matplotlib  # heavy, and only for the commands that draw
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    displacement = np.linalg.norm(positions_m - rest_m, axis=1)
    fig = plt.figure(figsize=(8, 5.5), dpi=110)
    ax = fig.add_subplot(projection="3d")
    colours = plt.get_cmap("viridis")(displacement[skin].mean(axis=1) / max(displacement.max(), 1e-9))
    ax.add_collection3d(Poly3DCollection(positions_m[skin], facecolors=colours, edgecolors="0.3", linewidths=0.2))
    if wounds is not None and wounds.any():
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        def edges(triangles):
            return {tuple(sorted(e)) for t in triangles.tolist() for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
        lips = np.array(sorted(edges(skin[wounds]) & edges(skin[~wounds]))).reshape(-1, 2)
        ax.computed_zorder = False  # the wound's lips are drawn over the skin, where a cut lies closed
        ax.add_collection3d(Line3DCollection(positions_m[lips], colors="red", linewidths=2.0, zorder=10))
    if tool_tip_m is not None:
        u, v = np.mgrid[0:2 * np.pi:16j, 0:np.pi:8j]
        tip, r = np.asarray(tool_tip_m), tool_radius_m
        ax.plot_wireframe(tip[0] + r * np.cos(u) * np.sin(v), tip[1] + r * np.sin(u) * np.sin(v),
                          tip[2] + r * np.cos(v), color="tab:red", linewidth=0.6)
    lower, upper = rest_m.min(axis=0), rest_m.max(axis=0)
    centre, half = (lower + upper) / 2, (upper - lower).max() / 2
    ax.set(xlim=(centre[0] - half, centre[0] + half), ylim=(centre[1] - half, centre[1] + half),
           zlim=(centre[2] - half, centre[2] + half), xlabel="x (m)", ylabel="y (m)", zlabel="z (m)")
    ax.view_init(elev=28, azim=-60)
    mappable = plt.cm.ScalarMappable(cmap="viridis", norm=plt.Normalize(0, displacement.max() * 1e3))
    fig.colorbar(mappable, ax=ax, shrink=0.6, label="displacement (mm)")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_topology(run, title: str, mesh, out_dir: Path) -> None:
    """before.png and after.png: the skin first received (else `mesh`'s) and the newest skin on the last
    nodes received."""
    first = run.initial_surface or (mesh.skin, mesh.points)
    last = run.surface or first
    for name, (skin, rest), nodes, when in (("before.png", first, run.initial_nodes, "before"),
                                            ("after.png", last, run.last_nodes, "after")):
        positions = nodes if nodes is not None and len(nodes) == len(rest) else rest
        wounds = opened_triangles(rest, skin)
        plot_liver(rest, skin, positions, None, 0.0, f"{title}: {when} ({len(rest)} nodes, {len(skin)} skin "
                   f"triangles, {int(wounds.sum())} opened: red lips)", out_dir / name, wounds)


def opened_triangles(rest_m: np.ndarray, skin: np.ndarray) -> np.ndarray:
    """Mask of the skin triangles opened by a tear or a cut: the two lips of an opening lie on each other at
    rest (a separation duplicates nodes in place), so such a triangle has a twin with the same rest corners."""
    corners = np.round(rest_m[skin] * 1e7).astype(np.int64)  # 0.1 µm
    keys = [tuple(sorted(map(tuple, c))) for c in corners]
    counts = {}
    for key in keys:
        counts[key] = counts.get(key, 0) + 1
    return np.array([counts[key] > 1 for key in keys], dtype=bool)
