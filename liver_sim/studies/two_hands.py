"""`liver-sim demo --tools 2`: two hands on the default liver, in closed loop with two simulated PHANToMs.

The left hand grasps the anterior edge of the liver and lifts it (the script `pull`: grasped at first contact,
raised LIFT_M), the right hand presses beside it, holds while the left lifts, then slides and leaves: a cut along
its stroke. Each hand is a device side of its own (bridge, tool node, simulated PHANToM) in its namespace, /left
and /right; one physics takes both tools (network.closed_loop_plan). Writes summary.json and summary.md (per device:
rates on the wire, command gaps, peak forces; how much the left lifted and what that did to the right's force),
force.png (both devices' commands and physics forces), liver_two_hands.png (the liver at the end, both tools on
it), the nodes' logs in logs/, and with `record_storage` the session in session/ with the command line that
re-simulates it.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from liver_sim.base.process_settings import cli_command_line, printable
from liver_sim.base.topic_names import tool_topic
from liver_sim.mesh.landmarks import upper_skin_point
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.running.network import DEVICE_START_DELAY_S, NetworkRun, closed_loop_plan, run_network, wire_rates
from liver_sim.sessions.record import recorder_command
from liver_sim.studies.demo import device_summary, gaps_line, network_summary
from liver_sim.view.picture import draw_scene
from liver_sim.view.scene import build_scene, lip_edges, scene_tool

#: How far (m) the left hand's script raises the grasped edge (the tissue rises less: the pull holds the stylus
#: back against the hand, and the tool first pushes the edge down a little as it closes on it).
LIFT_M = 0.018
#: The hands: where each works on the default liver (x, y m of the upper skin), its tool's use (the physics' NAME.
#: parameters) and its simulated hand's script (phantom_sim's parameters). After DEVICE_START_DELAY_S, the left
#: closes on the edge and lifts it from 2 s to 4 s; the right touches at 1 s, is 8 mm deep when the lift starts,
#: holds while the left lifts, slides 3 cm along +x from 5 s to 8 s and leaves at 8.3 s: the cut.
HANDS = {
    "left": {"xy": (-0.04, -0.055), "physics": {"tool_mode": "grasp"},
             "hand": {"script": "pull", "depth_m": 0.0, "clearance_m": 0.0, "pull_m": LIFT_M, "approach_s": 0.5,
                      "press_s": 1.0, "hold_s": 0.5, "slide_s": 2.0, "rest_s": 30.0,
                      # a firm grip: the stylus lags the hand by 3 mm under the clamped 2 N pull
                      "hand_stiffness_n_per_m": 600.0, "hand_damping_ns_per_m": 10.4}},
    "right": {"xy": (0.0, -0.035), "physics": {"tool_mode": "cut", "cut_depth_m": 0.008},
              # well clear of the raised tissue once it has left: up 2.5 cm, and back over its start
              "hand": {"script": "press_slide_release", "depth_m": 0.008, "slide_m": 0.03, "clearance_m": 0.025,
                       "approach_s": 1.0, "press_s": 1.0, "hold_s": 3.0, "slide_s": 3.0, "withdraw_s": 0.3,
                       "rest_s": 1.0, "start_delay_s": DEVICE_START_DELAY_S}},
}
#: The scene's length (s) from when every node runs: the right hand has left the surface (its cut) by then.
DURATION_S = 15.0
#: The left's lift runs from when its stylus has risen this share of its rise (from its lowest to its highest
#: within LIFT_WITHIN_S after that) to when it has risen all but this share.
LIFT_EDGE = 0.1
#: Where the stylus's highest is looked for (s after its lowest): the hand's hold and lift (2.5 s) and a second more,
#: well before the right's cut frees the tissue (8.3 s) and the held edge, pulling less, lets the stylus rise further.
LIFT_WITHIN_S = 3.5
#: What the right's force is taken over (s) before the lift starts and after it ends: its median.
FORCE_WINDOW_S = 0.2
#: The liver's edge the left lifts: the nodes at rest within this distance (m, in the xy plane) of the left's spot.
EDGE_REACH_M = 0.02


def hands_tools(mesh=None) -> dict:
    """The `tools` of network.closed_loop_plan for the scene: per hand, its tool's use, its script anchored on the
    upper skin at its spot, and a device map whose origin is that spot (each device works around its own), given
    alike to its tool node and its simulated PHANToM."""
    mesh = mesh or default_liver()
    tools = {}
    for name, hand in HANDS.items():
        anchor = [round(float(v), 6) for v in upper_skin_point(mesh, hand["xy"])]
        device_map = {"device_translation_m": anchor}
        tools[name] = {"liver_physics": hand["physics"], "liver_tool": device_map,
                       "phantom_sim": {"anchor_m": anchor, **device_map, **hand["hand"]}}
    return tools


def resimulate_command(bag: Path) -> list[str]:
    """`liver-sim resimulate BAG` with the scene's tools and their use (-p tools:=[left,right] -p left.…)."""
    overrides = [f"tools:=[{','.join(HANDS)}]"] + [f"{name}.{key}:={value}" for name, hand in HANDS.items()
                                                    for key, value in hand["physics"].items()]
    return cli_command_line("resimulate", str(bag), *[arg for o in overrides for arg in ("-p", o)])


def lift_window(arrival_s: np.ndarray, positions_m: np.ndarray) -> tuple[float, float, float] | None:
    """(start s, end s, rise m) of the left stylus's lift (device frame z, rise from its lowest to its highest within
    LIFT_WITHIN_S after that): from when it has risen LIFT_EDGE of the rise to when it has risen all but LIFT_EDGE;
    None without a rise."""
    if len(arrival_s) < 2:
        return None
    z = positions_m[:, 2]
    low = int(np.argmin(z))
    within = int(np.searchsorted(arrival_s, arrival_s[low] + LIFT_WITHIN_S, side="right"))
    high = low + int(np.argmax(z[low:within]))
    rise = float(z[high] - z[low])
    if rise <= 0.0:
        return None
    start = low + int(np.argmax(z[low:high + 1] > z[low] + LIFT_EDGE * rise))
    end = start + int(np.argmax(z[start:high + 1] >= z[high] - LIFT_EDGE * rise))
    return float(arrival_s[start]), float(arrival_s[end]), rise


def edge_rise(run: NetworkRun, mesh) -> float | None:
    """How high (m) the left holds the liver's edge at the end of the run: the largest rise from rest (z) of the
    nodes at rest within EDGE_REACH_M of the left's spot (a cut appends nodes: the first ones keep their index);
    None without nodes."""
    if run.last_nodes is None or len(run.last_nodes) < len(mesh.points):
        return None
    spot = upper_skin_point(mesh, HANDS["left"]["xy"])
    near = np.linalg.norm(mesh.points[:, :2] - spot[:2], axis=1) <= EDGE_REACH_M
    return float((run.last_nodes[:len(mesh.points)][near, 2] - mesh.points[near, 2]).max())


def coupling(run: NetworkRun, mesh) -> dict:
    """What the left's lift did: its start, end and rise (m, the stylus's), how high it holds the edge at the end
    (edge_rise), and the right's physics force (N, its norm's median over FORCE_WINDOW_S) before and after it."""
    window = lift_window(run.device_arrival_s["left"], run.device_position_m["left"])
    if window is None:
        return {"lift": None}
    start, end, rise = window
    arrival, wrench = run.wrench_arrival_s["right"], np.linalg.norm(run.wrench_n["right"], axis=1)

    def median(low, high):
        inside = (arrival >= low) & (arrival <= high)
        return float(np.median(wrench[inside])) if inside.any() else None

    return {"lift": {"duration_s": end - start, "rise_m": rise, "edge_rise_m": edge_rise(run, mesh)},
            "right_force_before_lift_n": median(start - FORCE_WINDOW_S, start),
            "right_force_after_lift_n": median(end, end + FORCE_WINDOW_S)}


def run_two_hands(out_dir: Path, duration_s: float | None = None, progress=print, record_storage: str | None = None,
                  view: list[str] | None = None, extra_load: int = 0, check_domain: bool = True) -> dict:
    """The scene (module docstring) for `duration_s` (default DURATION_S) from when every node runs; with
    `record_storage`, recorded into out_dir/session; with `view` (the options of `liver-sim view`), the live view of
    both tools beside it, drawing out_dir/view.png. Returns the summary."""
    duration_s = DURATION_S if duration_s is None else duration_s
    mesh = default_liver()
    plan = closed_loop_plan(tools=hands_tools(mesh))
    if record_storage:
        plan.observers["recorder"] = recorder_command(out_dir / "session", record_storage, tuple(HANDS))
    if view is not None:
        plan.commands["view"] = cli_command_line("view", *view, "--picture", str(out_dir / "view.png"),
                                                 "--tools", *HANDS)
    progress("Two hands: the left grasps and lifts the liver's edge, the right presses and cuts beside it "
             "(the same command lines work in separate terminals, each device side in its namespace):")
    run = run_network(plan, duration_s, out_dir / "logs", progress, extra_load=extra_load, check_domain=check_domain)
    summary = {"scenario": "two_hands", "mesh": {"source": mesh.source, "sha256": mesh.sha256},
               "duration_s": duration_s, "physics": wire_rates(run, "left")["physics"],
               "devices": {name: {"namespace": f"/{name}", "force_topic": f"/{name}/{tool_topic('servo_cf')}",
                                  **HANDS[name]["physics"], **device_summary(run, name)} for name in HANDS},
               "coupling": coupling(run, mesh), **network_summary(run, mesh)}
    if record_storage:
        summary["resimulate_command"] = printable(resimulate_command(out_dir / "session"))
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    (out_dir / "summary.md").write_text(_markdown(summary))
    plot_hands_forces(run, out_dir / "force.png")
    draw_hands(run, mesh, out_dir / "liver_two_hands.png")
    for name, device in summary["devices"].items():
        progress(f"{name}: haptic {device['haptic']['rate_hz']:.1f} Hz (period error p99 "
                 f"{1e3 * (device['haptic']['period_error_p99_s'] or 0):.2f} ms; "
                 f"{gaps_line(device, summary['machine_stalls'])}), peak force {device['peak_haptic_force_n']:.2f} N")
    progress(f"physics {summary['physics']['rate_hz']:.1f} Hz; {_coupling_line(summary['coupling'])}; "
             f"{summary['topology_changes']} topology change(s)")
    progress(f"wrote {out_dir}/summary.json, summary.md, force.png, liver_two_hands.png and logs/"
             + (f"; the recorded session is {out_dir / 'session'}: {summary['resimulate_command']}"
                if record_storage else ""))
    return summary


def _coupling_line(c: dict) -> str:
    if c["lift"] is None:
        return "the left did not lift"
    before, after = c["right_force_before_lift_n"], c["right_force_after_lift_n"]
    forces = (f"{before:.2f} N before it, {after:.2f} N after it" if before is not None and after is not None
              else "not measured")
    edge = c["lift"]["edge_rise_m"]
    held = f", and holds the edge {edge * 1e3:.1f} mm up at the end" if edge is not None else ""
    return (f"the left lifted its stylus {c['lift']['rise_m'] * 1e3:.1f} mm in {c['lift']['duration_s']:.2f} s{held}; "
            f"the physics force on the right tool: {forces}")


def _markdown(summary: dict) -> str:
    ms = lambda value: f"{value * 1e3:.2f} ms" if value is not None else "n/a"  # noqa: E731
    lines = ["# Closed-loop demo: two hands on the default liver", "",
             f"Rates as published on the wire over the {summary['duration_s']:g} s in which every node ran; "
             f"physics {summary['physics']['rate_hz']:.1f} Hz ({summary['physics']['samples']} frames).", ""]
    for name, device in summary["devices"].items():
        haptic = device["haptic"]
        lines += [f"## {name} ({device['namespace']}, tool_mode {device['tool_mode']})", "",
                  f"- haptic commands on {device['force_topic']}: {haptic['rate_hz']:.1f} Hz ({haptic['samples']} "
                  f"commands), period error p50 {ms(haptic['period_error_p50_s'])}, p99 "
                  f"{ms(haptic['period_error_p99_s'])}, largest gap {ms(haptic['max_gap_s'])}",
                  f"- {gaps_line(device, summary['machine_stalls'])}",
                  f"- peak force sent to the device {device['peak_haptic_force_n']:.3f} N; physics contact force peak "
                  f"{device['peak_physics_force_n']:.3f} N; largest change between consecutive 1 ms commands in "
                  f"contact {device['largest_force_jump_n']:.4f} N", ""]
    lines += ["## Through the tissue", "", f"- {_coupling_line(summary['coupling'])}",
              f"- topology changes: {summary['topology_changes']} (nodes {summary['nodes'][0]} → "
              f"{summary['nodes'][1]}, skin triangles {summary['skin_triangles'][0]} → "
              f"{summary['skin_triangles'][1]})", ""]
    if "resimulate_command" in summary:
        lines += ["Re-simulate the recorded session:", "", f"    {summary['resimulate_command']}", ""]
    return "\n".join(lines)


def plot_hands_forces(run: NetworkRun, path: Path) -> None:
    """force.png: per device, |force command| (1 kHz) and |physics force on its tool| (150 Hz markers) over time,
    the left's lift shaded on both."""
    import matplotlib  # heavy, and only for the commands that draw
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    origin = min((run.forces[name][0][0] for name in HANDS if len(run.forces[name][0])), default=0.0)
    window = lift_window(run.device_arrival_s["left"], run.device_position_m["left"])
    fig, axes = plt.subplots(len(HANDS), 1, figsize=(8, 6.5), dpi=110, sharex=True)
    for ax, name in zip(axes, HANDS):
        arrival, command = run.forces[name]
        ax.plot(arrival - origin, np.linalg.norm(command, axis=1), color="tab:red", linewidth=0.8,
                label="force command (1 kHz)")
        wrench_arrival, wrench = run.wrench_arrival_s[name], run.wrench_n[name]
        ax.plot(wrench_arrival - origin, np.linalg.norm(wrench, axis=1), "o", color="tab:blue", markersize=2,
                label="physics contact force (150 Hz)")
        if window is not None:
            ax.axvspan(window[0] - origin, window[1] - origin, color="0.9", label="the left lifts the edge")
        ax.set(ylabel="|force| (N)", title=f"{name}: {HANDS[name]['physics']['tool_mode']}")
        ax.legend(loc="upper left", fontsize=7)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle("Two hands: each device's force, coupled through the tissue", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def draw_hands(run: NetworkRun, mesh, path: Path) -> None:
    """liver_two_hands.png: the liver at the end of the run (the newest skin on the last nodes, the lips of the cut
    in red), each tool where its stylus was last (placed by its device map) with the force on it."""
    skin, rest = run.surface or (mesh.skin, mesh.points)
    nodes = run.last_nodes if run.last_nodes is not None and len(run.last_nodes) == len(rest) else rest
    tools = []
    for name, side in hands_tools(mesh).items():
        samples, wrenches = run.device_position_m[name], run.wrench_n[name]
        tip = samples[-1] + side["liver_tool"]["device_translation_m"] if len(samples) else None
        tools.append(scene_tool(tip, force_n=wrenches[-1] if len(wrenches) else None, name=name))
    draw_scene(build_scene(nodes, rest, skin, lip_edges(rest, skin), tools=tuple(tools)), path,
               "Two hands at the end: the edge held up by the left tool, the cut beside it (red)")
