"""`liver-sim demo`: the scripted press-and-release on the default liver, headless (B1–B3).

Writes to the output folder: summary.json and summary.md (the figures), force.png (force and
displacement over time) and liver_press.png (the deformed liver at peak press).
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.model import LiverModel
from liver_sim.scenarios import PressRelease, Trace, press_release, press_target, recovery_time_s

PLOTTED_FIGURES = ("force.png", "liver_press.png")


def run_demo(out_dir: Path, duration_s: float | None = None, progress=print) -> dict:
    """Run the press-and-release, write the summary and pictures into out_dir, return the summary."""
    script = PressRelease()
    if duration_s is not None:
        active = script.duration_s - script.rest_s
        if duration_s <= active:
            raise ValueError(f"--duration must exceed {active:.2f} s (approach, press, hold, withdraw)")
        script = replace(script, rest_s=duration_s - active)
    mesh = default_liver()
    model = LiverModel(mesh)
    progress(f"liver: {len(mesh.points)} nodes, {len(mesh.tets)} tets, {len(mesh.skin)} skin triangles, "
             f"{mesh.volume * 1e3:.2f} L; {model.springs.springs} springs; "
             f"dt {model.params.dt_s * 1e6:.0f} us ({model.params.substeps} substeps at "
             f"{model.params.frame_rate_hz:g} Hz), stable below {model.stable_dt_s * 1e6:.0f} us")
    model.warm_up()
    start = time.perf_counter()
    trace = press_release(model, script, progress=lambda t, total: progress(f"  simulated {t:4.1f} / {total:.1f} s"))
    wall_s = time.perf_counter() - start
    data = trace.arrays()
    force = np.linalg.norm(data["tool_force_n"], axis=1)
    summary = {
        "mesh": mesh.summary(),
        "parameters": {k: (asdict(v) if hasattr(v, "__dataclass_fields__") else v)
                       for k, v in vars(model.params).items()},
        "tool": asdict(model.tool),
        "script": asdict(script),
        "simulated_s": float(data["time_s"][-1]),
        "wall_s": wall_s,
        "realtime_factor": float(data["time_s"][-1] / wall_s),
        "peak_force_n": float(force.max()),
        "peak_displacement_m": float(data["max_displacement_m"].max()),
        "final_displacement_m": float(data["max_displacement_m"][-1]),
        "half_recovery_s": recovery_time_s(trace, 0.5, "max_displacement_m"),
        "shape_recovery_90pct_s": recovery_time_s(trace, 0.1),
        "divergences": trace.divergences,
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    (out_dir / "summary.md").write_text(_markdown(summary))
    _plot_force(data, script, out_dir / "force.png")
    _plot_liver(model, trace, out_dir / "liver_press.png")
    progress(f"peak force {summary['peak_force_n']:.2f} N, peak displacement "
             f"{summary['peak_displacement_m'] * 1e3:.1f} mm, residual {summary['final_displacement_m'] * 1e3:.2f} mm "
             f"after {script.rest_s:.1f} s; {summary['realtime_factor']:.1f}x real time")
    progress(f"wrote {out_dir}/summary.json, summary.md, {', '.join(PLOTTED_FIGURES)}")
    return summary


def _markdown(summary: dict) -> str:
    mesh = summary["mesh"]
    return "\n".join([
        "# Press-and-release on the default liver",
        "",
        f"- mesh: {mesh['nodes']} nodes, {mesh['tetrahedra']} tets, {mesh['skin_triangles']} skin triangles, "
        f"{mesh['volume_m3'] * 1e3:.2f} L, min dihedral {mesh['min_dihedral_deg']:.1f} deg",
        f"- simulated {summary['simulated_s']:.2f} s in {summary['wall_s']:.2f} s "
        f"({summary['realtime_factor']:.1f}x real time)",
        f"- peak force on the tool: {summary['peak_force_n']:.3f} N",
        f"- peak displacement: {summary['peak_displacement_m'] * 1e3:.1f} mm (B1: see liver_press.png)",
        f"- half recovery after the tool left: {summary['half_recovery_s']:.2f} s; 90 % of the shape back after "
        f"{summary['shape_recovery_90pct_s']:.2f} s (B3)",
        f"- residual displacement at the end: {summary['final_displacement_m'] * 1e3:.3f} mm (B2)",
        f"- divergences: {len(summary['divergences'])}",
        "",
    ])


def _plot_force(data: dict, script: PressRelease, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.2), dpi=110)
    t = data["time_s"]
    ax.plot(t, np.linalg.norm(data["tool_force_n"], axis=1), color="tab:red", label="|force on tool| (N)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force (N)", color="tab:red")
    ax.axvspan(script.approach_s, script.release_time_s, color="0.92", label="press and hold")
    twin = ax.twinx()
    twin.plot(t, data["max_displacement_m"] * 1e3, color="tab:blue", label="largest node displacement (mm)")
    twin.set_ylabel("displacement (mm)", color="tab:blue")
    ax.set_title("Press and release on the default liver")
    lines = ax.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    ax.legend(lines, [line.get_label() for line in lines], loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _plot_liver(model: LiverModel, trace: Trace, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    positions = trace.peak_positions_m if trace.peak_positions_m is not None else model.positions
    displacement = np.linalg.norm(positions - model.mesh.points, axis=1)
    skin = model.mesh.skin
    fig = plt.figure(figsize=(8, 5.5), dpi=110)
    ax = fig.add_subplot(projection="3d")
    colours = plt.get_cmap("viridis")(displacement[skin].mean(axis=1) / max(displacement.max(), 1e-9))
    ax.add_collection3d(Poly3DCollection(positions[skin], facecolors=colours, edgecolors="0.3", linewidths=0.2))
    target, _ = press_target(model)
    peak = int(np.argmax(np.linalg.norm(trace.arrays()["tool_force_n"], axis=1)))
    tip = trace.arrays()["tool_position_m"][peak]
    u, v = np.mgrid[0:2 * np.pi:16j, 0:np.pi:8j]
    r = model.tool.radius_m
    ax.plot_wireframe(tip[0] + r * np.cos(u) * np.sin(v), tip[1] + r * np.sin(u) * np.sin(v),
                      tip[2] + r * np.cos(v), color="tab:red", linewidth=0.6)
    lower, upper = model.mesh.bounds
    centre, half = (lower + upper) / 2, (upper - lower).max() / 2
    ax.set(xlim=(centre[0] - half, centre[0] + half), ylim=(centre[1] - half, centre[1] + half),
           zlim=(centre[2] - half, centre[2] + half), xlabel="x (m)", ylabel="y (m)", zlabel="z (m)")
    ax.view_init(elev=28, azim=-60)
    mappable = plt.cm.ScalarMappable(cmap="viridis", norm=plt.Normalize(0, displacement.max() * 1e3))
    fig.colorbar(mappable, ax=ax, shrink=0.6, label="displacement (mm)")
    ax.set_title(f"Default liver at peak press ({np.linalg.norm(trace.tool_force_n[peak]):.2f} N)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
