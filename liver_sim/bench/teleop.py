"""`liver-sim bench teleop`: the closed loop over an emulated teleoperation link (liver_sim.base.link), each delay
rendered once with the local model and once with direct force (`local_model: none`), as model-mediated
teleoperation is compared with direct force feedback.

The operator's side is phantom_sim (a stylus held by a virtual hand playing `explore`), liver_tool and
haptic_bridge; the remote side is liver_physics. The link delays the tool pose into the physics and the local
model (or the physics wrench) into the bridge. Each run is one row (ROW_KEYS); the rows are compared with a
reference run, the local model with no delay, jitter or loss, at the same script time.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from liver_sim.base.link import LinkSettings
from liver_sim.bench.machine import machine
from liver_sim.running.network import closed_loop_plan, run_network
from liver_sim.sessions.parameters import node_parameters

#: One-way delays (ms) run by default.
TELEOP_DELAYS_MS = (0.0, 10.0, 50.0, 100.0, 200.0)
#: Seconds of closed loop per run: two passes of `explore` (5.8 s each) after the hand starts.
TELEOP_RUN_S = 12.0
#: The bridge's local_model parameter of each rendering.
RENDERINGS = {"local_model": "plane", "none": "none"}
#: What runs at each delay: (rendering, passivity controller on).
VARIANTS = (("local_model", False), ("local_model", True), ("none", False))
#: The local model with the passivity controller must stay stable and passive at every delay up to this (ms one
#: way), with 10 ms of jitter and 5 % loss included (run with --jitter 10 --loss 0.05).
TELEOP_TARGETS = {"local_model_stable_and_passive_up_to_delay_ms": 100.0}
#: Passive: the energy the device gave the hand beyond what it took never exceeded this (J): a 1 N force over
#: 1 mm. A passivity controller acts on the tick after the observer sees energy appear, so it leaves a little.
PASSIVE_TOLERANCE_J = 0.001
#: Oscillation of the commands in a window of OSCILLATION_WINDOW_S (stepped by half of it): the RMS of the command
#: norm band-passed by the difference of its moving means over OSCILLATION_FAST_S and OSCILLATION_SLOW_S (about
#: 2-20 Hz: above the hand's script, below the loop's noise). A window oscillates when that RMS exceeds the
#: reference run's in the same window of script time by OSCILLATION_RATIO and OSCILLATION_MARGIN_N; the
#: oscillation is sustained (the run unstable) when oscillating windows cover OSCILLATION_SUSTAINED_S.
OSCILLATION_WINDOW_S = 1.0
OSCILLATION_FAST_S = 0.025
OSCILLATION_SLOW_S = 0.25
OSCILLATION_RATIO = 1.3
OSCILLATION_MARGIN_N = 0.02
OSCILLATION_SUSTAINED_S = 2.0
#: A tool pose that has moved this far (m) from the first one marks the start of the script (the hand's first move).
SCRIPT_START_MOTION_M = 1e-4
ROW_KEYS = ("rendering", "passivity_control", "delay_ms", "jitter_ms", "loss", "stable", "energy_generated_j",
            "peak_force_n", "force_error_rms_n", "penetration_max_mm")


def run_teleop_bench(delays_ms=TELEOP_DELAYS_MS, jitter_ms: float = 0.0, loss: float = 0.0, out_dir=None,
                     progress=None, duration_s: float = TELEOP_RUN_S, seed: int = 0, variants=VARIANTS,
                     check_domain: bool = True) -> dict:
    """The benchmark's JSON object: `rows` (one per delay and variant of `variants`, VARIANTS by default: ROW_KEYS
    and the run's details), the reference run, each variant's first unstable or active delay, `met` against
    TELEOP_TARGETS, and the plots written to `out_dir` (force against script time per delay, energy against
    delay). `check_domain`: before the reference run (network.run_network)."""
    out_dir = Path(out_dir or "out/bench_teleop")
    say = progress or (lambda line: None)
    say("reference: local model, no delay, no jitter, no loss")
    reference = teleop_run("local_model", LinkSettings(), duration_s, out_dir / "logs" / "reference",
                           check_domain=check_domain)
    rows, traces = [], {}
    for delay_ms in delays_ms:
        for rendering, control in variants:
            link = LinkSettings(delay_ms * 1e-3, jitter_ms * 1e-3, loss, seed)
            name = variant_name(rendering, control)
            say(f"{name}: delay {delay_ms:g} ms, jitter {jitter_ms:g} ms, loss {loss:g}")
            run = teleop_run(rendering, link, duration_s, out_dir / "logs" / f"{name}_{delay_ms:g}ms", control)
            row = teleop_row(rendering, control, link, run, reference)
            rows.append(row)
            traces[name, delay_ms] = script_times(run)
            say(f"  stable {row['stable']}, passive {row['passive']}, energy {row['energy_generated_j'] * 1e3:.2f} "
                f"mJ (peak {row['energy_generated_peak_j'] * 1e3:.2f}), peak force {row['peak_force_n']:.2f} N, "
                f"error {row['force_error_rms_n']:.3f} N, penetration {row['penetration_max_mm']:.1f} mm")
    first_unstable = {variant_name(*v): next((r["delay_ms"] for r in rows if (r["rendering"], r["passivity_control"])
                                              == v and not r["stable"]), None) for v in variants}
    first_active = {variant_name(*v): next((r["delay_ms"] for r in rows if (r["rendering"], r["passivity_control"])
                                            == v and not r["passive"]), None) for v in variants}
    bound = TELEOP_TARGETS["local_model_stable_and_passive_up_to_delay_ms"]
    covered = [r for r in rows if r["rendering"] == "local_model" and r["passivity_control"] and r["delay_ms"] <= bound]
    met = {"local_model_stable_and_passive_up_to_delay_ms":
           bool(covered) and max(r["delay_ms"] for r in covered) >= bound
           and all(r["stable"] and r["passive"] for r in covered)}
    plots = plot_teleop(traces, rows, out_dir)
    return {"benchmark": "teleop", "machine": machine(), "run_s": duration_s, "script": "explore",
            "jitter_ms": jitter_ms, "loss": loss, "seed": seed,
            "definitions": {
                "stable": f"no sustained oscillation: the command norm's RMS between about 2 and 20 Hz (moving means "
                          f"over {OSCILLATION_FAST_S * 1e3:g} ms minus {OSCILLATION_SLOW_S * 1e3:g} ms) in "
                          f"{OSCILLATION_WINDOW_S:g} s windows exceeds the reference run's at the same script time "
                          f"by {OSCILLATION_RATIO:g}x + {OSCILLATION_MARGIN_N:g} N in windows covering less than "
                          f"{OSCILLATION_SUSTAINED_S:g} s",
                "energy_generated_j": "the bridge's passivity observer at the end of the run: Σ F_k·Δx_(k+1), the "
                                      "energy the commands gave the hand beyond what they took (< 0: absorbed)",
                "passive": f"that energy never above {PASSIVE_TOLERANCE_J:g} J during the run "
                           "(energy_generated_peak_j)",
                "force_error_rms_n": "RMS of the command minus the reference run's at the same script time (from "
                                     "the tool's first motion)",
                "penetration_max_mm": "largest physics contact force over the contact stiffness: how deep the "
                                      "remote tool went into the tissue",
                "reference": "the local model without passivity controller, no delay, jitter or loss"},
            "reference": teleop_row("local_model", False, LinkSettings(), reference, reference),
            "rows": rows, "first_unstable_delay_ms": first_unstable, "first_active_delay_ms": first_active,
            "targets": TELEOP_TARGETS, "met": met, "plots": plots}


def variant_name(rendering: str, passivity_control: bool) -> str:
    """'local_model', 'local_model+pc' (with the passivity controller), 'none'."""
    return rendering + ("+pc" if passivity_control else "")


def teleop_run(rendering: str, link: LinkSettings, duration_s: float, log_dir: Path, passivity_control: bool = False,
               check_domain: bool = False):
    """One closed-loop run with `rendering` over `link` (network.run_network's NetworkRun; `check_domain` for the
    bench's first run only). The direct-force bridge is a comparison bridge (drives_device false): its held physics
    force is not passive at 150 Hz, which a bridge driving a real device refuses
    (haptic_bridge.tick.passivity_problem); phantom_sim obeys it all the same."""
    over_link = link.parameters() if link.emulated else {}
    bridge = {"local_model": RENDERINGS[rendering], **over_link}
    if passivity_control:
        bridge["passivity_control"] = True
    if rendering == "none":
        bridge["drives_device"] = False
    plan = closed_loop_plan(extra={"liver_physics": over_link, "haptic_bridge": bridge,
                                   "phantom_sim": {"loop_script": True, "script": "explore"}})
    return run_network(plan, duration_s, log_dir, lambda line: None, check_domain=check_domain)


def script_times(run) -> tuple[np.ndarray, np.ndarray]:
    """(script time s, command (K, 3) N) of the commands published within the run's window, in order of their
    publication (DDS source times: unlike the listener's arrivals, which a burst delivers at one instant, no two
    are equal); script time counts from the arrival of the first tool pose that moved (the hand's first move)."""
    published, force = run.force_published_s["local_model"], run.forces["local_model"][1]
    order = np.argsort(published, kind="stable")
    published, force = published[order], force[order]
    positions = run.tool_position_m
    moved = np.linalg.norm(positions - positions[0], axis=1) > SCRIPT_START_MOTION_M if len(positions) else []
    start = run.tool_arrival_s[np.argmax(moved)] if np.any(moved) else published[0] if len(published) else 0.0
    keep = (published >= start) & (published <= run.window_s[1])
    return published[keep] - start, force[keep]


def oscillation_n(times_s: np.ndarray, force_n: np.ndarray, windows_s: np.ndarray) -> np.ndarray:
    """The oscillation (N) of the commands in each OSCILLATION_WINDOW_S window starting at `windows_s` (module
    constants): RMS of the band-passed command norm, sampled at 1 kHz."""
    if len(times_s) < 3:
        return np.zeros(len(windows_s))
    grid = np.arange(0.0, times_s[-1], 0.001)
    norm = np.interp(grid, times_s, np.linalg.norm(force_n, axis=1))

    def mean(width_s: float) -> np.ndarray:
        width = max(1, int(round(width_s / 0.001)))
        return np.convolve(norm, np.ones(width) / width, mode="same")

    band = mean(OSCILLATION_FAST_S) - mean(OSCILLATION_SLOW_S)
    rms = []
    for start in windows_s:
        inside = band[(grid >= start) & (grid < start + OSCILLATION_WINDOW_S)]
        rms.append(float(np.sqrt(np.mean(inside ** 2))) if inside.size else 0.0)
    return np.array(rms)


def oscillating_s(times: tuple, reference: tuple) -> float:
    """How long (s) the commands `times` = (script time s, commands N) oscillated beyond the `reference` run's
    (module constants): the oscillating windows times the window step."""
    end = min(times[0][-1] if len(times[0]) else 0.0, reference[0][-1] if len(reference[0]) else 0.0)
    step = OSCILLATION_WINDOW_S / 2.0
    windows = np.arange(0.0, end - OSCILLATION_WINDOW_S, step)
    mine, theirs = oscillation_n(*times, windows), oscillation_n(*reference, windows)
    return float(np.count_nonzero(mine > OSCILLATION_RATIO * theirs + OSCILLATION_MARGIN_N) * step)


def teleop_row(rendering: str, passivity_control: bool, link: LinkSettings, run, reference) -> dict:
    """One row of the benchmark (ROW_KEYS, then `passive`, `energy_generated_peak_j`, `oscillating_s`, details)."""
    times, force = script_times(run)
    ref_times, ref_force = script_times(reference)
    common = times <= (ref_times[-1] if len(ref_times) else -1.0)
    if common.any() and len(ref_times) > 1:
        expected = np.column_stack([np.interp(times[common], ref_times, ref_force[:, i]) for i in range(3)])
        error = float(np.sqrt(np.mean(np.sum((force[common] - expected) ** 2, axis=1))))
    else:
        error = float("nan")
    bridge = run.diagnostics.get("haptic_bridge: loop", {})
    energy = float(bridge.get("energy_to_hand_j", "nan"))
    peak_energy = float(bridge.get("energy_to_hand_peak_j", "nan"))
    stiffness = node_parameters(())["liver_physics"].contact_stiffness_n_per_m
    wrench = np.linalg.norm(run.wrench_n, axis=1) if len(run.wrench_n) else np.zeros(1)
    oscillation = oscillating_s((times, force), (ref_times, ref_force))
    norm = np.linalg.norm(force, axis=1) if len(force) else np.zeros(1)
    return {"rendering": rendering, "passivity_control": passivity_control, "delay_ms": link.delay_s * 1e3,
            "jitter_ms": link.jitter_s * 1e3, "loss": link.loss_fraction,
            "stable": oscillation < OSCILLATION_SUSTAINED_S, "energy_generated_j": energy,
            "peak_force_n": float(norm.max()), "force_error_rms_n": error,
            "penetration_max_mm": float(wrench.max() / stiffness * 1e3),
            "passive": peak_energy <= PASSIVE_TOLERANCE_J, "energy_generated_peak_j": peak_energy,
            "oscillating_s": oscillation, "commands": int(len(force)),
            "link_lost": {label.split(":")[0]: int(float(d["link_lost"])) for label, d in run.diagnostics.items()
                          if "link_lost" in d}}


#: How each variant is drawn: (colour, label).
STYLES = {"none": ("tab:red", "direct force"), "local_model": ("tab:blue", "local model"),
          "local_model+pc": ("tab:green", "local model + passivity controller")}


def plot_teleop(traces: dict, rows: list[dict], out_dir: Path) -> list[str]:
    """teleop_forces.png (the command norm against script time, a panel per delay, every variant) and
    teleop_energy.png (energy given to the hand against delay); their paths. `traces`: (variant, delay ms) ->
    (script time s, commands N)."""
    import matplotlib  # heavy, and only for the commands that draw

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    delays = sorted({delay for _, delay in traces})
    figure, axes = plt.subplots(len(delays), 1, figsize=(9, 2.0 * len(delays) + 1), sharex=True, squeeze=False)
    for axis, delay in zip(axes[:, 0], delays):
        for name, (colour, label) in STYLES.items():
            if (name, delay) in traces:
                times, force = traces[name, delay]
                axis.plot(times, np.linalg.norm(force, axis=1), colour, lw=0.7, label=label)
        axis.set_ylabel("|F| (N)")
        axis.set_title(f"{delay:g} ms one way", fontsize=9)
        axis.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("script time (s)")
    figure.tight_layout()
    forces = out_dir / "teleop_forces.png"
    figure.savefig(forces, dpi=110)
    plt.close(figure)
    figure, axis = plt.subplots(figsize=(6, 3.5))
    for name, (colour, label) in STYLES.items():
        mine = [r for r in rows if variant_name(r["rendering"], r["passivity_control"]) == name]
        axis.plot([r["delay_ms"] for r in mine], [r["energy_generated_peak_j"] * 1e3 for r in mine], "o-",
                  color=colour, label=label)
    axis.axhline(PASSIVE_TOLERANCE_J * 1e3, color="k", lw=0.5, ls="--")
    axis.set_xlabel("one-way delay (ms)")
    axis.set_ylabel("largest energy given to the hand (mJ)")
    axis.set_yscale("symlog", linthresh=0.1)
    axis.set_ylim(bottom=0.0)
    axis.legend(fontsize=8)
    figure.tight_layout()
    energy = out_dir / "teleop_energy.png"
    figure.savefig(energy, dpi=110)
    plt.close(figure)
    return [str(forces), str(energy)]
