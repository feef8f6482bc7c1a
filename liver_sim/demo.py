"""`liver-sim demo`: the closed loop of the four nodes (`run_demo`) and, with --offline, the scripted
press-and-release in one process without ROS (`run_offline_demo`; behaviours B1–B3 of docs/paper.md),
on the default liver or a user's mesh (--mesh PATH, its coordinates × --scale in metres).

Writes to the output folder: summary.json and summary.md (the figures), force.png (force and
displacement over time) and liver_press.png (the deformed liver at peak press).
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from liver_sim.mesh.io import load_mesh
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.model import LiverModel
from liver_sim.physics.params import ModelParams
from liver_sim.physics.pipeline import PARAMETERS as PHYSICS_PARAMETERS
from liver_sim.scenarios import offline_press_release, press_anchor, press_release, recovery_time_s
from liver_sim.tool_scripts import ScriptSettings

PLOTTED_FIGURES = ("force.png", "liver_press.png")


@dataclass(frozen=True)
class DemoMesh:
    """The liver a demo runs on: `path` None for the default liver, else a mesh file whose coordinates ×
    `scale` are metres, loaded as the physics node loads it (mesh_path, mesh_scale, target_tets)."""

    path: Path | None = None
    scale: float = 1.0

    @property
    def name(self) -> str:
        """What titles call it: "default liver" or the file's name."""
        return "default liver" if self.path is None else self.path.name

    @property
    def title(self) -> str:
        """`name` at the start of a title."""
        return self.name[:1].upper() + self.name[1:]

    def load(self) -> TetMesh:
        """The mesh in metres; MeshError (a ValueError naming the file) when refused."""
        if self.path is None:
            return default_liver()
        return load_mesh(self.path, PHYSICS_PARAMETERS["target_tets"].default, self.scale)

    def physics_parameters(self, mesh: TetMesh) -> dict:
        """The physics node's parameters that load this mesh (none for the default liver)."""
        if self.path is None:
            return {}
        return {"mesh_path": str(self.path.resolve()), "mesh_scale": self.scale}

    def device_parameters(self, mesh: TetMesh) -> dict:
        """The script anchor and device map that make the simulated hand press the top of `mesh` with the
        same device-frame moves as on the default liver (none for the default liver)."""
        if self.path is None:
            return {}
        anchor = press_anchor(mesh)
        shift = anchor - np.asarray(ScriptSettings().anchor_m)  # the device origin follows the press point
        return {"anchor_m": [round(float(v), 6) for v in anchor],
                "device_translation_m": [round(float(v), 6) for v in shift]}


def run_offline_demo(out_dir: Path, duration_s: float | None = None, progress=print,
                     liver: DemoMesh = DemoMesh()) -> dict:
    """Run the press-and-release on `liver`, write the summary and pictures into out_dir, return the summary."""
    mesh = liver.load()
    model = LiverModel(mesh, ModelParams())  # implicit: no stability bound, whatever the mesh's elements
    script = offline_press_release(mesh, model.tool.radius_m)
    if duration_s is not None:
        active = script.approach_s + script.press_s + script.hold_s + script.withdraw_s
        if duration_s <= active:
            raise ValueError(f"--duration must exceed {active:.2f} s (approach, press, hold, withdraw)")
        script = replace(script, rest_s=duration_s - active)
    progress(f"{liver.name}: {len(mesh.points)} nodes, {len(mesh.tets)} tets, {len(mesh.skin)} skin triangles, "
             f"{mesh.volume * 1e3:.2f} L; {model.springs.springs} springs; "
             f"{model.params.integrator}, dt {model.params.dt_s * 1e6:.0f} us ({model.params.substeps} step(s) at "
             f"{model.params.frame_rate_hz:g} Hz)")
    model.warm_up()
    start = time.perf_counter()
    trace = press_release(model, script, progress=lambda t, total: progress(f"  simulated {t:4.1f} / {total:.1f} s"))
    wall_s = time.perf_counter() - start
    data = trace.arrays()
    force = np.linalg.norm(data["tool_force_n"], axis=1)
    summary = {
        "mesh": {**mesh.summary(), "scale": liver.scale},
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
    (out_dir / "summary.md").write_text(_markdown(summary, liver.name))
    _plot_force(data, script, liver.name, out_dir / "force.png")
    peak = int(np.argmax(force))
    plot_liver(mesh.points, mesh.skin, trace.peak_positions_m, data["tool_position_m"][peak], model.tool.radius_m,
               f"{liver.title} at peak press ({force[peak]:.2f} N)", out_dir / "liver_press.png")
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
        f"- peak displacement: {summary['peak_displacement_m'] * 1e3:.1f} mm (B1, local deformation: see liver_press.png)",
        f"- half recovery after the tool left: {summary['half_recovery_s']:.2f} s; 90 % of the shape back after "
        f"{summary['shape_recovery_90pct_s']:.2f} s (B3, slow return)",
        f"- residual displacement at the end: {summary['final_displacement_m'] * 1e3:.3f} mm (B2, return to shape)",
        f"- divergences: {len(summary['divergences'])}",
        "",
    ])


def _plot_force(data: dict, script: ScriptSettings, name: str, path: Path) -> None:
    import matplotlib
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
    import matplotlib
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


@dataclass(frozen=True)
class Scenario:
    """A closed-loop demo: what it shows, the physics and simulated-hand overrides, its default length (s)."""

    title: str
    physics: dict = field(default_factory=dict)
    hand: dict = field(default_factory=dict)
    duration_s: float = 14.0


#: `liver-sim demo --scenario NAME`: press (the main job), tear (P13) and cut (P14, Fig. 9).
SCENARIOS = {
    "press": Scenario("Press, slide and release with the simulated PHANToM", hand={"rest_s": 6.0}),
    "tear": Scenario("Grasp and pull until the liver tears (P13)", physics={"tearing": True, "tool_mode": "grasp"},
                     hand={"script": "pull", "depth_m": 0.004, "pull_m": 0.08, "slide_s": 3.0, "rest_s": 4.0},
                     duration_s=12.0),
    "cut": Scenario("Cut along the tool path (P14, Fig. 9)", physics={"tool_mode": "cut", "cut_depth_m": 0.008},
                    hand={"script": "press_slide_release", "depth_m": 0.012, "slide_m": 0.06, "slide_s": 3.0,
                          "rest_s": 4.0}, duration_s=12.0),
}
#: What a topology scenario draws: the liver before and after (Fig. 9).
TOPOLOGY_FIGURES = ("force.png", "before.png", "after.png")


def run_demo(out_dir: Path, duration_s: float | None = None, progress=print, record_storage: str | None = None,
             scenario: str = "press", liver: DemoMesh = DemoMesh()) -> dict:
    """The main job: the four nodes in closed loop with the simulated PHANToM playing `scenario` on `liver`
    (the physics node loads the same file; the hand presses the top of it).

    Writes summary.json/.md, force.png, and liver_press.png (press) or before.png and after.png (tear,
    cut), and the nodes' logs in logs/. With `record_storage` (mcap or sqlite3), `liver-sim record`
    records the run into out_dir/session.
    """
    from liver_sim.analysis import largest_force_jump_n
    from liver_sim.machine_stalls import stall_summary
    from liver_sim.network import closed_loop_plan, run_network, wire_gaps, wire_rates
    from liver_sim.sessions.record import recorder_command

    if scenario not in SCENARIOS:
        raise ValueError(f"--scenario must be one of {', '.join(SCENARIOS)}, got {scenario!r}")
    spec = SCENARIOS[scenario]
    duration_s = spec.duration_s if duration_s is None else duration_s
    mesh = liver.load()  # refused here, before any node starts, if the physics node would refuse it
    device = liver.device_parameters(mesh)
    plan = closed_loop_plan(extra={"liver_physics": {**spec.physics, **liver.physics_parameters(mesh)},
                                   "phantom_sim": {**device, **spec.hand},
                                   "liver_tool": {k: v for k, v in device.items() if k != "anchor_m"}})
    if record_storage:
        plan.observers["recorder"] = recorder_command(out_dir / "session", record_storage)
    progress(f"{spec.title}: starting the node network (the same command lines work in four terminals):")
    snapshot = run_network(plan, duration_s, out_dir / "logs", progress)
    _, haptic_force = snapshot["forces"]["local_model"]
    wrench = snapshot["wrench_n"]
    peak_nodes = snapshot["peak_nodes"] if snapshot["peak_nodes"] is not None else mesh.points
    last_nodes = snapshot["last_nodes"] if snapshot["last_nodes"] is not None else mesh.points
    haptic_norm = np.linalg.norm(haptic_force, axis=1)
    summary = {
        "scenario": scenario,
        "mesh": {"source": mesh.source, "scale": liver.scale, "sha256": mesh.sha256},
        "duration_s": duration_s,
        **wire_rates(snapshot),
        "machine_stalls": stall_summary(snapshot["machine_stalls"]),
        "haptic_gaps_over_5ms": wire_gaps(snapshot, GAP_S),
        "peak_haptic_force_n": float(haptic_norm.max()) if haptic_norm.size else 0.0,
        "peak_physics_force_n": float(np.linalg.norm(wrench, axis=1).max()) if len(wrench) else 0.0,
        "largest_force_jump_n": largest_force_jump_n(haptic_force),
        "topology_changes": max(0, snapshot["surface_messages"] - 1),
        "nodes": [len(n) if n is not None else 0 for n in (snapshot["initial_nodes"], snapshot["last_nodes"])],
        "skin_triangles": [len(s[0]) if s is not None else 0
                           for s in (snapshot["initial_surface"], snapshot["surface"])],
        "surface_nodes": [len(s[1]) if s is not None else 0
                          for s in (snapshot["initial_surface"], snapshot["surface"])],
        "diagnostics": snapshot["diagnostics"],
    }
    if len(last_nodes) == len(mesh.points):
        summary["peak_displacement_m"] = float(np.linalg.norm(peak_nodes - mesh.points, axis=1).max())
        summary["final_displacement_m"] = float(np.linalg.norm(last_nodes - mesh.points, axis=1).max())
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    (out_dir / "summary.md").write_text(_network_markdown(summary, f"{spec.title} ({liver.name})"))
    _plot_network_forces(snapshot, f"{spec.title} ({liver.name})", out_dir / "force.png")
    if scenario == "press":
        figures = PLOTTED_FIGURES
        plot_liver(mesh.points, mesh.skin, peak_nodes, None, 0.0,
                   f"{liver.title} at peak press ({summary['peak_physics_force_n']:.2f} N)",
                   out_dir / "liver_press.png")
    else:
        figures = TOPOLOGY_FIGURES
        _plot_topology(snapshot, spec.title, mesh, out_dir)
    progress(f"physics {summary['physics']['rate_hz']:.1f} Hz, haptic {summary['haptic']['rate_hz']:.1f} Hz "
             f"(period error p99 {1e3 * (summary['haptic']['period_error_p99_s'] or 0):.2f} ms; {_gaps_line(summary)}), "
             f"peak force "
             f"{summary['peak_haptic_force_n']:.2f} N"
             + (f", residual displacement {summary['final_displacement_m'] * 1e3:.2f} mm"
                if "final_displacement_m" in summary else "")
             + (f"; {summary['topology_changes']} topology change(s): {summary['nodes'][0]} → "
                f"{summary['nodes'][1]} nodes" if scenario != "press" else ""))
    progress(f"wrote {out_dir}/summary.json, summary.md, {', '.join(figures)} and logs/"
             + (f"; the recorded session is {out_dir / 'session'} (liver-sim report {out_dir / 'session'})"
                if record_storage else ""))
    return summary


def _plot_topology(snapshot: dict, title: str, mesh, out_dir: Path) -> None:
    """before.png and after.png: the skin first received (else `mesh`'s) and the newest skin on the last
    nodes received."""
    first = snapshot["initial_surface"] or (mesh.skin, mesh.points)
    last = snapshot["surface"] or first
    for name, (skin, rest), nodes, when in (("before.png", first, snapshot["initial_nodes"], "before"),
                                            ("after.png", last, snapshot["last_nodes"], "after")):
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


#: Command gaps longer than this (s) are listed with the machine's share in them.
GAP_S = 0.005


def _gaps_line(summary: dict) -> str:
    """How many command gaps over GAP_S there were, how many held a stall of the machine itself, and those stalls."""
    gaps, stalls = summary["haptic_gaps_over_5ms"], summary["machine_stalls"]
    machine = sum(gap["machine_s"] > 0.0 for gap in gaps)
    return (f"{len(gaps)} command gap(s) over {GAP_S * 1e3:g} ms, {machine} of them during a stall of the machine "
            f"itself ({stalls['count']} stall(s), largest {stalls['largest_s'] * 1e3:.1f} ms)")


def _network_markdown(summary: dict, title: str) -> str:
    physics, haptic = summary["physics"], summary["haptic"]
    ms = lambda value: f"{value * 1e3:.2f} ms" if value is not None else "n/a"  # noqa: E731
    displacement = ([f"- peak displacement {summary['peak_displacement_m'] * 1e3:.1f} mm; residual at the end "
                     f"{summary['final_displacement_m'] * 1e3:.2f} mm"] if "final_displacement_m" in summary else [])
    return "\n".join([
        f"# Closed-loop demo: {title}",
        "",
        f"Rates as published on the wire over the {summary['duration_s']:g} s in which every node ran:",
        "",
        f"- physics: {physics['rate_hz']:.1f} Hz ({physics['samples']} frames), period error p99 "
        f"{ms(physics['period_error_p99_s'])}",
        f"- haptic commands: {haptic['rate_hz']:.1f} Hz ({haptic['samples']} commands), period error p50 "
        f"{ms(haptic['period_error_p50_s'])}, p99 {ms(haptic['period_error_p99_s'])}, largest gap "
        f"{ms(haptic['max_gap_s'])}",
        f"- {_gaps_line(summary)}: the machine stalls when it runs none of its threads that are due (a virtual "
        f"CPU its host did not run), measured by a sentinel per CPU at SCHED_FIFO 99 (liver_sim/machine_stalls.py)",
        f"- peak force sent to the device: {summary['peak_haptic_force_n']:.3f} N; physics contact force peak "
        f"{summary['peak_physics_force_n']:.3f} N",
        f"- largest force change between consecutive 1 ms commands in contact: "
        f"{summary['largest_force_jump_n']:.4f} N",
        *displacement,
        f"- topology changes: {summary['topology_changes']} (nodes {summary['nodes'][0]} → {summary['nodes'][1]}, "
        f"skin triangles {summary['skin_triangles'][0]} → {summary['skin_triangles'][1]})",
        "",
    ])


def _plot_network_forces(snapshot: dict, title: str, path: Path) -> None:
    """The report's force plot (sessions.report.plot_force: 1 kHz commands, 150 Hz physics force as markers,
    a zoom on contact where they meet at each update) of what the listener received, titled `title`."""
    from liver_sim.sessions.report import plot_force

    arrival, force = snapshot["forces"]["local_model"]
    origin = min([a[0] for a in (arrival, snapshot["wrench_arrival_s"]) if len(a)], default=0.0)
    plot_force({"forces": {"local_model": (arrival - origin, force)},
                "wrench": (snapshot["wrench_arrival_s"] - origin, snapshot["wrench_n"])}, path, title)
