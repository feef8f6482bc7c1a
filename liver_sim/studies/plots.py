"""The demos' pictures: the deformed liver as the live view draws it (liver_sim.view.picture: the skin coloured by
displacement, the tool, the lips of what a tear or a cut opened), the offline press-and-release. matplotlib loads
in each function, for the commands that draw (it is the heaviest import of the package and the rest never needs
it)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from liver_sim.tool.scripts import ScriptSettings
from liver_sim.view.picture import draw_scene
from liver_sim.view.scene import build_scene, lip_edges


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
               title: str, path: Path) -> None:
    """The picture of the live view (liver_sim.view.picture) of the deformed skin over `rest_m`: coloured by
    displacement, with the tool sphere (`tool_tip_m` None: none) and the lips of what a tear or a cut opened
    (view.scene.lip_edges)."""
    draw_scene(build_scene(positions_m, rest_m, skin, lip_edges(rest_m, skin), tool_tip_m, tool_radius_m), path,
               title)


def plot_topology(run, title: str, mesh, out_dir: Path) -> None:
    """before.png and after.png: the skin first received (else `mesh`'s) and the newest skin on the last
    nodes received."""
    first = run.initial_surface or (mesh.skin, mesh.points)
    last = run.surface or first
    for name, (skin, rest), nodes, when in (("before.png", first, run.initial_nodes, "before"),
                                            ("after.png", last, run.last_nodes, "after")):
        positions = nodes if nodes is not None and len(nodes) == len(rest) else rest
        lips = lip_edges(rest, skin)
        plot_liver(rest, skin, positions, None, 0.0, f"{title}: {when} ({len(rest)} nodes, {len(skin)} skin "
                   f"triangles, {len(lips)} lip edges: red)", out_dir / name)
