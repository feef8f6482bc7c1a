"""`liver-sim demo`: the main job, the four nodes in closed loop with the simulated PHANToM playing a
scenario (press, tear, cut) on the default liver or a user's mesh.

Writes to the output folder: summary.json and summary.md (rates on the wire, command gaps, forces),
force.png, liver_press.png (press) or before.png and after.png (tear, cut), and the nodes' logs in logs/.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from liver_sim.base.emulated_link import LinkSettings
from liver_sim.base.process_settings import cli_command_line
from liver_sim.running.machine_stalls import stall_summary
from liver_sim.running.network import ROOT_LABEL, NetworkRun, closed_loop_plan, run_network, wire_gaps, wire_rates
from liver_sim.sessions.analysis import largest_force_jump_n
from liver_sim.sessions.record import recorder_command
from liver_sim.sessions.report import plot_force
from liver_sim.studies.demo_liver import DemoMesh
from liver_sim.studies.demo_offline import PLOTTED_FIGURES
from liver_sim.studies.plots import plot_liver, plot_topology


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
             scenario: str = "press", liver: DemoMesh = DemoMesh(), link: LinkSettings = LinkSettings(),
             view: list[str] | None = None, extra_load: int = 0, check_domain: bool = True) -> dict:
    """The main job: the four nodes in closed loop with the simulated PHANToM playing `scenario` on `liver`
    (the physics node loads the same file; the hand presses the top of it).

    Writes summary.json/.md, force.png, and liver_press.png (press) or before.png and after.png (tear,
    cut), and the nodes' logs in logs/. With `record_storage` (mcap or sqlite3), `liver-sim record`
    records the run into out_dir/session. `link` puts an emulated teleoperation link (delay, jitter, loss) between
    the operator's side (device, tool, bridge) and the physics, both ways. With `view` (the options of
    `liver-sim view`), the live view runs beside the nodes and draws out_dir/view.png at the end. `extra_load`
    core-bound processes run at normal priority beside the network once it is up, as a busy rig's would.
    `check_domain`: first refuse a domain where a product node or a device runs (network.run_network); a caller
    holding the domain for itself, as each test does, may skip it.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"--scenario must be one of {', '.join(SCENARIOS)}, got {scenario!r}")
    spec = SCENARIOS[scenario]
    duration_s = spec.duration_s if duration_s is None else duration_s
    mesh = liver.load()  # refused here, before any node starts, if the physics node would refuse it
    device = liver.device_parameters(mesh)
    over_link = link.parameters() if link.emulated else {}
    plan = closed_loop_plan(extra={"liver_physics": {**spec.physics, **liver.physics_parameters(mesh), **over_link},
                                   "haptic_bridge": over_link,
                                   "phantom_sim": {**device, **spec.hand},
                                   "liver_tool": {k: v for k, v in device.items() if k != "anchor_m"}})
    if record_storage:
        plan.observers["recorder"] = recorder_command(out_dir / "session", record_storage)
    if view is not None:
        plan.commands["view"] = cli_command_line("view", *view, "--picture", str(out_dir / "view.png"))
    progress(f"{spec.title}: starting the node network (the same command lines work in four terminals):")
    run = run_network(plan, duration_s, out_dir / "logs", progress, extra_load=extra_load, check_domain=check_domain)
    summary = {
        "scenario": scenario,
        "mesh": {"source": mesh.source, "scale": liver.scale, "sha256": mesh.sha256},
        "duration_s": duration_s,
        "link": {"delay_s": link.delay_s, "jitter_s": link.jitter_s, "loss_fraction": link.loss_fraction,
                 "seed": link.seed},
        "physics": wire_rates(run)["physics"],
        **device_summary(run, ROOT_LABEL),
        **network_summary(run, mesh),
    }
    peak_nodes = run.peak_nodes if run.peak_nodes is not None else mesh.points
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    (out_dir / "summary.md").write_text(_network_markdown(summary, f"{spec.title} ({liver.name})"))
    plot_network_forces(run, f"{spec.title} ({liver.name})", out_dir / "force.png")
    if scenario == "press":
        figures = PLOTTED_FIGURES
        plot_liver(mesh.points, mesh.skin, peak_nodes, None, 0.0,
                   f"{liver.title} at peak press ({summary['peak_physics_force_n']:.2f} N)",
                   out_dir / "liver_press.png")
    else:
        figures = TOPOLOGY_FIGURES
        plot_topology(run, spec.title, mesh, out_dir)
    progress(f"physics {summary['physics']['rate_hz']:.1f} Hz, haptic {summary['haptic']['rate_hz']:.1f} Hz "
             f"(period error p99 {1e3 * (summary['haptic']['period_error_p99_s'] or 0):.2f} ms; "
             f"{gaps_line(summary)}), "
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


#: Command gaps longer than this (s) are listed with the machine's share in them.
GAP_S = 0.005


def device_summary(run: NetworkRun, label: str) -> dict:
    """What one device side of a run did: its commands' rates on the wire (`haptic`), their gaps over GAP_S with
    the machine's share, the peak force commanded and the peak physics force on its tool (N), the largest change
    between consecutive commands in contact (N)."""
    _, command = run.forces[label]
    wrench = run.wrench_n[label]
    norm = np.linalg.norm(command, axis=1)
    return {"haptic": wire_rates(run, label)["haptic"], "haptic_gaps_over_5ms": wire_gaps(run, GAP_S, label),
            "peak_haptic_force_n": float(norm.max()) if norm.size else 0.0,
            "peak_physics_force_n": float(np.linalg.norm(wrench, axis=1).max()) if len(wrench) else 0.0,
            "largest_force_jump_n": largest_force_jump_n(command)}


def network_summary(run: NetworkRun, mesh) -> dict:
    """What the run did to the liver and the machine: its stalls, topology changes, nodes, skin triangles, the
    diagnostics, when the stop was asked, and (same node count) the peak and final displacement (m)."""
    summary = {
        "machine_stalls": stall_summary(run.machine_stalls),
        "topology_changes": max(0, run.surface_messages - 1),
        "nodes": [len(n) if n is not None else 0 for n in (run.initial_nodes, run.last_nodes)],
        "skin_triangles": [len(s[0]) if s is not None else 0 for s in (run.initial_surface, run.surface)],
        "surface_nodes": [len(s[1]) if s is not None else 0 for s in (run.initial_surface, run.surface)],
        "diagnostics": run.diagnostics,
        "stop_requested_unix_s": run.stop_requested_ns * 1e-9,
    }
    peak_nodes = run.peak_nodes if run.peak_nodes is not None else mesh.points
    last_nodes = run.last_nodes if run.last_nodes is not None else mesh.points
    if len(last_nodes) == len(mesh.points):
        summary["peak_displacement_m"] = float(np.linalg.norm(peak_nodes - mesh.points, axis=1).max())
        summary["final_displacement_m"] = float(np.linalg.norm(last_nodes - mesh.points, axis=1).max())
    return summary


def gaps_line(summary: dict, stalls: dict | None = None) -> str:
    """How many command gaps over GAP_S there were (a device summary), how many held a stall of the machine itself,
    and those stalls (`stalls`: the run's, default the summary's own)."""
    gaps, stalls = summary["haptic_gaps_over_5ms"], stalls or summary["machine_stalls"]
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
        f"- {gaps_line(summary)}: the machine stalls when it runs none of its threads that are due (a virtual "
        f"CPU its host did not run), measured by a sentinel per CPU at SCHED_FIFO 99 "
        f"(liver_sim/running/machine_stalls.py)",
        f"- peak force sent to the device: {summary['peak_haptic_force_n']:.3f} N; physics contact force peak "
        f"{summary['peak_physics_force_n']:.3f} N",
        f"- largest force change between consecutive 1 ms commands in contact: "
        f"{summary['largest_force_jump_n']:.4f} N",
        *displacement,
        f"- topology changes: {summary['topology_changes']} (nodes {summary['nodes'][0]} → {summary['nodes'][1]}, "
        f"skin triangles {summary['skin_triangles'][0]} → {summary['skin_triangles'][1]})",
        "",
    ])


def plot_network_forces(run: NetworkRun, title: str, path: Path) -> None:
    """The report's force plot (sessions.report.plot_force: 1 kHz commands, 150 Hz physics force as markers,
    a zoom on contact where they meet at each update) of what the listener received, titled `title`."""
    arrival, force = run.forces[ROOT_LABEL]
    wrench_arrival = run.wrench_arrival_s[ROOT_LABEL]
    origin = min([a[0] for a in (arrival, wrench_arrival) if len(a)], default=0.0)
    plot_force({"forces": {"local_model": (arrival - origin, force)},
                "wrench": (wrench_arrival - origin, run.wrench_n[ROOT_LABEL])}, path, title)
