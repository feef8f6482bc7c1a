"""`liver-sim report`: plots and a summary of a recorded (or re-simulated) session.

Writes force.png (force command and physics contact force over time), penetration.png (depth of the
tool sphere below the local model, the bridge's penetration()), tool_path.png, loop_rates.png
(on-wire rates per second, and the nodes' own loop rate and jitter from /diagnostics when recorded),
fig8.png when the bag holds the force with and without local model (Fig. 8), and summary.json/.md, of one
tool: the one in the root namespace, or tool NAME of a session with several (`--tool NAME`: its topics under
/NAME). Times are the bag's log times, from its first message.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from rclpy.serialization import deserialize_message

from liver_sim.base.local_model import penetration
from liver_sim.base.topic_names import BASELINE_FORCE_TOPIC, in_namespace, tool_namespace
from liver_sim.sessions.analysis import (
    CONTACT_FORCE_N,
    contact_fraction,
    fig8_figures,
    fig8_line,
    largest_force_jump_n,
    rate_figures,
)
from liver_sim.sessions.bag import BagError, bag_info, read_messages
from liver_sim.sessions.parameters import node_parameters
from liver_sim.sessions.record import message_class, type_name
from msg_defs.device_map import device_map_from_message
from msg_defs.forces import FORCE_OUTPUT_FORMATS, force_from_message, force_message_type
from msg_defs.local_model import marker_to_local_model
from msg_defs.poses import pose_to_arrays
from msg_defs.topics import TOPICS


def _force_format(msgtype: str) -> str | None:
    """The force_output format whose message type is `msgtype`, or None."""

    for fmt in FORCE_OUTPUT_FORMATS:
        try:
            if type_name(force_message_type(fmt)) == msgtype:
                return fmt
        except ValueError:  # omni_feedback without omni_msgs
            continue
    return None


def tool_topics(physics, bridge, tool: str = "") -> dict:
    """{what: topic} of tool `tool` ('': the root namespace's) in a session: its force commands (with and without
    local model), physics wrench, tool pose, local model, device samples and device map."""
    namespace = tool_namespace(tool)
    return {key: in_namespace(name, namespace) for key, name in (
        ("force", bridge.force_topic), ("baseline", BASELINE_FORCE_TOPIC.lstrip("/")),
        ("tool_wrench", physics.tool_wrench_topic), ("tool_pose", physics.tool_pose_topic),
        ("contact_plane", physics.contact_plane_topic), ("measured_cp", bridge.measured_cp_topic),
        ("device_map", bridge.device_map_topic))}


def session_arrays(bag: Path, physics: dict, bridge: dict, tool: str = "") -> dict:
    """One pass over the bag: log times of every topic, tool `tool`'s forces, wrench, tool tips and local models
    (tool_topics), diagnostics. The tool tips are the device's samples placed in the liver frame by the recorded
    device map (1 kHz, what the bridge rendered), or, in a bag without them, the tool poses."""

    names = tool_topics(physics, bridge, tool)
    force_topics = {"local_model": names["force"], "without_local_model": names["baseline"]}
    decoded = {*names.values(), TOPICS["diagnostics"].name}
    times: dict[str, list] = {}
    values: dict[str, list] = {}
    diagnostics: list = []
    classes = {}
    for m in read_messages(bag):
        t = m.timestamp_ns * 1e-9
        times.setdefault(m.topic, []).append(t)
        if m.topic not in decoded:
            continue
        if m.msgtype not in classes:
            classes[m.msgtype] = message_class(m.msgtype)
        try:
            message = deserialize_message(m.data, classes[m.msgtype])
            if m.topic in force_topics.values():
                fmt = _force_format(m.msgtype)
                if fmt is None:
                    raise ValueError(f"{m.msgtype} is not a force command type")
                value = force_from_message(fmt, message)
            elif m.topic == names["tool_wrench"]:
                value = force_from_message("wrench_stamped", message)
            elif m.topic in (names["tool_pose"], names["measured_cp"]):
                value = pose_to_arrays(message.pose)[0]
            elif m.topic == names["device_map"]:
                value = device_map_from_message(message)
            elif m.topic == names["contact_plane"]:
                value = marker_to_local_model(message)[0]
            else:
                for status in message.status:
                    diagnostics.append((t, status.name, {kv.key: kv.value for kv in status.values}))
                continue
        except Exception as exc:  # a message that does not decode: the bag is not a session of this product
            raise BagError(bag, f"a {m.topic} message ({m.msgtype}) does not decode: {exc}") from None
        values.setdefault(m.topic, []).append((t, value))
    origin = min((ts[0] for ts in times.values()), default=0.0)

    def series(topic):
        pairs = values.get(topic, [])
        return np.array([p[0] - origin for p in pairs]), [p[1] for p in pairs]

    forces = {}
    for label, topic in force_topics.items():
        t, f = series(topic)
        if len(t):
            forces[label] = (t, np.array(f).reshape(-1, 3))
    wrench_t, wrench = series(names["tool_wrench"])
    sample_t, samples = series(names["measured_cp"])
    device_maps = series(names["device_map"])[1]
    if len(sample_t) and device_maps:
        pose_t, tips = sample_t, [device_maps[0].device_to_liver(sample) for sample in samples]
    else:
        pose_t, tips = series(names["tool_pose"])
    plane_t, models = series(names["contact_plane"])
    return {"origin_s": origin, "times": {k: np.array(v) - origin for k, v in times.items()},
            "forces": forces, "wrench": (wrench_t, np.array(wrench).reshape(-1, 3)),
            "tool": (pose_t, np.array(tips).reshape(-1, 3)), "local_models": (plane_t, models),
            "diagnostics": [(t - origin, name, kv) for t, name, kv in diagnostics]}


def penetration_series(tool_t, tips, model_t, models, tool_radius_m: float) -> np.ndarray:
    """Depth (m) of the tool sphere at each tip below the newest local model logged before it (0 without one)."""

    index = np.searchsorted(model_t, tool_t, side="right") - 1
    depth = np.zeros(len(tool_t))
    for k, (i, tip) in enumerate(zip(index, tips)):
        if i >= 0 and models[i] is not None:
            depth[k] = penetration(models[i], tip, tool_radius_m)[0]
    return depth


def windowed_rate(t: np.ndarray, window_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Messages per second in the consecutive full windows from the first message: (window centres s, rate Hz)."""
    windows = int((t[-1] - t[0]) // window_s) if len(t) >= 2 else 0
    if windows < 1:
        return np.array([]), np.array([])
    edges = t[0] + window_s * np.arange(windows + 1)
    counts, _ = np.histogram(t, edges)
    return edges[:-1] + window_s / 2, counts / window_s


def _plots():
    import matplotlib  # heavy, and only for the commands that draw
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path, plt) -> None:
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _zoom(ax, centre_s: float, half_width_s: float, series) -> None:
    """Limit `ax` to centre_s ± half_width_s (s) and to the range of the (t, y) `series` inside it."""
    inside = [y[(t >= centre_s - half_width_s) & (t <= centre_s + half_width_s)] for t, y in series]
    values = np.concatenate(inside) if inside else np.zeros(0)
    ax.set_xlim(centre_s - half_width_s, centre_s + half_width_s)
    if values.size:
        margin = 0.1 * max(float(np.ptp(values)), 0.01)
        ax.set_ylim(float(values.min()) - margin, float(values.max()) + margin)


def plot_force(data: dict, path: Path, title: str = "Force over time") -> None:
    """|force| over time: the 1 kHz commands and the 150 Hz physics contact force (markers); a second panel
    zooms on 0.1 s of contact, where the command meets the physics force at every update."""

    plt = _plots()
    fig, axes = plt.subplots(2, 1, figsize=(8, 7), dpi=110)
    colours = {"local_model": "tab:red", "without_local_model": "tab:orange"}
    wt, w = data["wrench"]
    physics = np.linalg.norm(np.reshape(w, (-1, 3)), axis=1)
    series = [(t, np.linalg.norm(f, axis=1)) for t, f in data["forces"].values()] + [(wt, physics)]
    for ax in axes:
        for label, (t, norm) in zip(data["forces"], series):
            ax.plot(t, norm, color=colours[label], linewidth=0.8, label=f"force command, {label.replace('_', ' ')}")
        if len(wt):
            ax.plot(wt, physics, "o", color="tab:blue", markersize=2.5, label="physics contact force (150 Hz)")
        ax.set(xlabel="time (s)", ylabel="|force| (N)")
    axes[0].set_title(title)
    axes[0].legend(loc="upper right", fontsize=8)
    if len(wt) and physics.max() > CONTACT_FORCE_N:
        _zoom(axes[1], float(wt[np.argmax(physics)]), 0.05, series)  # around the peak physics force
        axes[1].set_title("0.1 s in contact: the 1 kHz command and the physics force at each update")
    _save(fig, path, plt)


def _plot_penetration(t, depth_m, path: Path) -> None:
    plt = _plots()
    fig, ax = plt.subplots(figsize=(8, 3.6), dpi=110)
    ax.plot(t, depth_m * 1e3, color="tab:purple", linewidth=0.8)
    ax.set(xlabel="time (s)", ylabel="penetration (mm)", title="Tool penetration below the local model")
    _save(fig, path, plt)


def _plot_tool_path(t, tips, path: Path) -> None:
    plt = _plots()
    fig, axes = plt.subplots(1, 2, figsize=(9, 4.2), dpi=110)
    for ax, (i, j), name in zip(axes, ((0, 2), (0, 1)), ("side (x-z)", "top (x-y)")):
        points = ax.scatter(tips[:, i] * 1e3, tips[:, j] * 1e3, c=t, s=2, cmap="viridis")
        ax.set(xlabel=f"{'xyz'[i]} (mm)", ylabel=f"{'xyz'[j]} (mm)", title=f"Tool path, {name}")
        ax.set_aspect("equal", adjustable="datalim")
    fig.colorbar(points, ax=axes, label="time (s)", shrink=0.8)
    fig.savefig(path)
    plt.close(fig)


def _plot_rates(data: dict, topics: list[str], path: Path) -> None:
    plt = _plots()
    nodes = sorted({name for _, name, _ in data["diagnostics"]})
    fig, axes = plt.subplots(3 if nodes else 1, 1, figsize=(8, 7.5 if nodes else 3.6), dpi=110, squeeze=False)
    axes = axes[:, 0]
    for topic in topics:
        centres, rate = windowed_rate(data["times"][topic])
        axes[0].plot(centres, rate, marker=".", label=topic)
    axes[0].set(xlabel="time (s)", ylabel="messages/s", title="Rates on the wire (1 s windows)")
    axes[0].legend(fontsize=7)
    for name in nodes:
        rows = [(t, kv) for t, n, kv in data["diagnostics"] if n == name and "rate_hz" in kv]
        t = [r[0] for r in rows]
        axes[1].plot(t, [float(r[1]["rate_hz"]) for r in rows], marker=".", label=name)
        axes[2].plot(t, [float(r[1].get("jitter_p99_s", "nan")) * 1e3 for r in rows], marker=".", label=name)
    if nodes:
        axes[1].set(xlabel="time (s)", ylabel="loop rate (Hz)", title="Loop rates (diagnostics)", yscale="log")
        axes[2].set(xlabel="time (s)", ylabel="period error p99 (ms)", title="Loop jitter (diagnostics)")
        axes[1].legend(fontsize=7)
    _save(fig, path, plt)


def plot_fig8(data: dict, path: Path) -> None:
    """Fig. 8: |command| with and without the local model; a second panel zooms on 0.1 s around the baseline's
    largest step in contact."""

    plt = _plots()
    (t1, f1), (t0, f0) = data["forces"]["local_model"], data["forces"]["without_local_model"]
    n1, n0 = np.linalg.norm(f1, axis=1), np.linalg.norm(f0, axis=1)
    steps = np.abs(np.diff(n0)) * ((n0[1:] > CONTACT_FORCE_N) & (n0[:-1] > CONTACT_FORCE_N))
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), dpi=110)
    for ax in axes:
        ax.plot(t0, n0, color="tab:orange", linewidth=0.8, label="without local model (physics force held)")
        ax.plot(t1, n1, color="tab:red", linewidth=0.8, label="with local model")
        ax.set(xlabel="time (s)", ylabel="|force| (N)")
    axes[0].set_title("Fig. 8: force sent to the device with and without the local model")
    if steps.size and steps.max() > 0.0:
        _zoom(axes[1], float(t0[np.argmax(steps) + 1]), 0.05, [(t0, n0), (t1, n1)])
        axes[1].set_title("0.1 s around the largest step of the held physics force in contact")
    axes[0].legend(loc="upper right", fontsize=8)
    _save(fig, path, plt)


def write_report(bag: Path, out: Path, progress=print, tool: str = "") -> dict:
    """Read the bag, write the PNGs and summary.json/.md of tool `tool` ('': the root namespace's) into `out`;
    return the summary."""

    info = bag_info(bag)
    params = node_parameters()
    physics, bridge = params["liver_physics"], params["haptic_bridge"]
    progress(f"reading {bag}: {info.message_count} messages on {len(info.topics)} topics")
    data = session_arrays(bag, physics, bridge, tool)
    topic = tool_topics(physics, bridge, tool)
    out.mkdir(parents=True, exist_ok=True)
    figures = []
    summary = {"bag": str(bag), "tool": tool, "storage": info.storage, "duration_s": info.duration_ns * 1e-9,
               "topics": {t: {"type": kind, "messages": n} for t, (kind, n) in sorted(info.topics.items())},
               "recorder": info.custom_data}
    nominal = {topic["tool_pose"]: physics.rate_hz, topic["force"]: bridge.rate_hz,
               topic["measured_cp"]: bridge.rate_hz, physics.nodes_topic: physics.rate_hz,
               topic["contact_plane"]: physics.rate_hz, topic["tool_wrench"]: physics.rate_hz}
    rate_topics = [t for t in nominal if t in data["times"]]
    summary["rates_received"] = {t: rate_figures(data["times"][t], nominal[t]) for t in rate_topics}
    latest = {}
    for _, name, kv in data["diagnostics"]:
        latest[name] = kv
    summary["diagnostics_last"] = latest
    if data["forces"] or len(data["wrench"][0]):
        plot_force(data, out / "force.png")
        figures.append("force.png")
    summary["forces"] = {label: {"commands": len(f), "peak_n": float(np.linalg.norm(f, axis=1).max()),
                                 "contact_fraction": contact_fraction(f),
                                 "largest_jump_in_contact_n": largest_force_jump_n(f)}
                         for label, (_, f) in data["forces"].items()}
    wt, w = data["wrench"]
    summary["physics_force_peak_n"] = float(np.linalg.norm(w, axis=1).max()) if len(wt) else None
    tool_t, tips = data["tool"]
    if len(tool_t):
        model_t, models = data["local_models"]
        depth = penetration_series(tool_t, tips, model_t, models, bridge.tool_radius_m)
        summary["penetration_max_m"] = float(depth.max())
        summary["tool_path"] = {"samples": len(tips), "length_m": float(np.linalg.norm(np.diff(tips, axis=0),
                                                                                        axis=1).sum()),
                                "lower_m": tips.min(axis=0).tolist(), "upper_m": tips.max(axis=0).tolist()}
        if len(model_t):
            _plot_penetration(tool_t, depth, out / "penetration.png")
            figures.append("penetration.png")
        _plot_tool_path(tool_t, tips, out / "tool_path.png")
        figures.append("tool_path.png")
    if rate_topics or data["diagnostics"]:
        _plot_rates(data, rate_topics, out / "loop_rates.png")
        figures.append("loop_rates.png")
    if {"local_model", "without_local_model"} <= set(data["forces"]):
        summary["fig8"] = fig8_figures(data["forces"]["local_model"][1], data["forces"]["without_local_model"][1])
        plot_fig8(data, out / "fig8.png")
        figures.append("fig8.png")
    else:
        summary["fig8"] = None
    summary["figures"] = figures
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    (out / "summary.md").write_text(_markdown(summary))
    progress(f"wrote {out}/summary.json, summary.md, {', '.join(figures)}")
    return summary


def _lost_line(custom_data: dict) -> str:
    """'lost: N' of a bag's recorder (metadata custom_data, liver_sim.sessions.gaps), by topic where any."""
    if "lost_messages" not in custom_data:
        return "- lost: not counted (the bag was not written by `liver-sim record`)"
    by_topic = {t: n for t, n in json.loads(custom_data.get("lost_messages_by_topic", "{}")).items() if n}
    return (f"- lost: {custom_data['lost_messages']}" + "".join(f", `{t}` {n}" for t, n in sorted(by_topic.items()))
            + " (publication sequence numbers of every writer after `ready`; per writer: metadata.yaml `writers`)")


def _markdown(s: dict) -> str:
    ms = lambda v: f"{v * 1e3:.2f} ms" if v is not None else "n/a"  # noqa: E731
    lines = [f"# Session {s['bag']}", "", f"- {s['storage']} bag, {s['duration_s']:.2f} s, "
             f"{sum(t['messages'] for t in s['topics'].values())} messages", "", "| topic | type | messages |",
             "|---|---|---|"]
    lines += [f"| `{t}` | `{v['type']}` | {v['messages']} |" for t, v in s["topics"].items()]
    lines += ["", "## Forces", ""]
    for label, f in s["forces"].items():
        lines.append(f"- command ({label.replace('_', ' ')}): {f['commands']} commands, peak {f['peak_n']:.3f} N, "
                     f"in contact {100 * f['contact_fraction']:.0f} %, largest change between consecutive commands "
                     f"in contact {f['largest_jump_in_contact_n']:.4f} N")
    if s["physics_force_peak_n"] is not None:
        lines.append(f"- physics contact force peak: {s['physics_force_peak_n']:.3f} N")
    if "penetration_max_m" in s:
        lines.append(f"- deepest penetration below the local model: {s['penetration_max_m'] * 1e3:.2f} mm; "
                     f"tool path {s['tool_path']['length_m'] * 1e3:.0f} mm long")
    if s["fig8"]:
        f8 = s["fig8"]
        lines += ["", "## Fig. 8: with and without the local model", "", "- " + fig8_line(f8)]
    lines += ["", "## Recording", "", _lost_line(s["recorder"])]
    lines += ["", "## Rates", "", "As the recorder received the messages (its log times, start-up and shutdown "
              "included: batched deliveries read as bursts; `liver-sim bench loop` gives the rates as published):", "",
              "| topic | rate | period error p50 | p99 | largest gap |", "|---|---|---|---|---|"]
    for t, r in s["rates_received"].items():
        lines.append(f"| `{t}` | {r['rate_hz']:.1f} Hz | {ms(r['period_error_p50_s'])} | "
                     f"{ms(r['period_error_p99_s'])} | {ms(r['max_gap_s'])} |")
    if s["diagnostics_last"]:
        lines += ["", "Loops as the nodes measured them (last /diagnostics):", ""]
        for name, kv in sorted(s["diagnostics_last"].items()):
            lines.append(f"- {name}: {kv.get('rate_hz', '?')} Hz, period error p99 {kv.get('jitter_p99_s', '?')} s, "
                         f"overruns {kv.get('overruns', '?')}")
    lines += ["", "Figures: " + ", ".join(s["figures"]), ""]
    return "\n".join(lines)
