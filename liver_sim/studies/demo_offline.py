"""`liver-sim demo --offline`: the scripted press-and-release in one process without ROS (behaviours B1–B3 of
docs/paper.md), on the default liver or a user's mesh (--mesh PATH, its coordinates × --scale in metres).

Writes to the output folder: summary.json and summary.md (the figures), force.png (force and
displacement over time) and liver_press.png (the deformed liver at peak press).
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from liver_sim.physics.model import LiverModel
from liver_sim.studies.demo_liver import DemoMesh
from liver_sim.studies.plots import plot_liver, plot_press_release
from liver_sim.studies.scenarios import offline_press_release, press_release, recovery_time_s

#: The pictures a press demo writes, offline or in closed loop.
PLOTTED_FIGURES = ("force.png", "liver_press.png")


def run_offline_demo(out_dir: Path, duration_s: float | None = None, progress=print,
                     liver: DemoMesh = DemoMesh()) -> dict:
    """Run the press-and-release on `liver`, write the summary and pictures into out_dir, return the summary."""
    mesh = liver.load()
    model = LiverModel(mesh, liver.model_params())  # implicit: no stability bound, whatever the mesh's elements
    script = offline_press_release(mesh, model.tool.shape.radius_m)
    if duration_s is not None:
        active = script.approach_s + script.press_s + script.hold_s + script.withdraw_s
        if duration_s <= active:
            raise ValueError(f"--duration must exceed {active:.2f} s (approach, press, hold, withdraw)")
        script = replace(script, rest_s=duration_s - active)
    params = model.structure.params
    progress(f"{liver.name}: {len(mesh.points)} nodes, {len(mesh.tets)} tets, {len(mesh.skin)} skin triangles, "
             f"{mesh.volume * 1e3:.2f} L; {model.structure.springs.springs} springs; "
             f"{params.integrator}, dt {params.dt_s * 1e6:.0f} us ({params.substeps} step(s) at "
             f"{params.frame_rate_hz:g} Hz)")
    model.warm_up()
    start = time.perf_counter()
    trace = press_release(model, script, progress=lambda t, total: progress(f"  simulated {t:4.1f} / {total:.1f} s"))
    wall_s = time.perf_counter() - start
    data = trace.arrays()
    force = np.linalg.norm(data["tool_force_n"], axis=1)
    summary = {
        "mesh": {**mesh.summary(), "scale": liver.scale},
        "parameters": {k: (asdict(v) if hasattr(v, "__dataclass_fields__") else v)
                       for k, v in vars(params).items()},
        "tool": asdict(model.tool.shape),
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
    (out_dir / "summary.md").write_text(_markdown(summary, liver.name))
    plot_press_release(data, script, liver.name, out_dir / "force.png")
    peak = int(np.argmax(force))
    plot_liver(mesh.points, mesh.skin, trace.peak_positions_m, data["tool_position_m"][peak],
               model.tool.shape.radius_m, f"{liver.title} at peak press ({force[peak]:.2f} N)",
               out_dir / "liver_press.png")
    progress(f"peak force {summary['peak_force_n']:.2f} N, peak displacement "
             f"{summary['peak_displacement_m'] * 1e3:.1f} mm, residual {summary['final_displacement_m'] * 1e3:.2f} mm "
             f"after {script.rest_s:.1f} s; {summary['realtime_factor']:.1f}x real time")
    progress(f"wrote {out_dir}/summary.json, summary.md, {', '.join(PLOTTED_FIGURES)}")
    return summary


def _markdown(summary: dict, name: str) -> str:
    mesh = summary["mesh"]
    return "\n".join([
        f"# Press-and-release on the {name}",
        "",
        f"- mesh: {mesh['nodes']} nodes, {mesh['tetrahedra']} tets, {mesh['skin_triangles']} skin triangles, "
        f"{mesh['volume_m3'] * 1e3:.2f} L, min dihedral {mesh['min_dihedral_deg']:.1f} deg",
        f"- simulated {summary['simulated_s']:.2f} s in {summary['wall_s']:.2f} s "
        f"({summary['realtime_factor']:.1f}x real time)",
        f"- peak force on the tool: {summary['peak_force_n']:.3f} N",
        f"- peak displacement: {summary['peak_displacement_m'] * 1e3:.1f} mm (B1, local deformation: see "
        f"liver_press.png)",
        f"- half recovery after the tool left: {summary['half_recovery_s']:.2f} s; 90 % of the shape back after "
        f"{summary['shape_recovery_90pct_s']:.2f} s (B3, slow return)",
        f"- residual displacement at the end: {summary['final_displacement_m'] * 1e3:.3f} mm (B2, return to shape)",
        f"- divergences: {len(summary['divergences'])}",
        "",
    ])
