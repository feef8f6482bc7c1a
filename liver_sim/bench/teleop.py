"""`liver-sim bench teleop`: the closed loop over an emulated teleoperation link (liver_sim.base.emulated_link), each
delay rendered with the local model (the default: passive model updates over a link; with direct updates; with direct
updates and the passivity controller) and with direct force (`local_model: none`), as model-mediated teleoperation
is compared with direct force feedback. Passivity is judged by the simulated device's own measure of the energy it
gave the hand; the bridge's estimate of it is reported beside.

The operator's side is phantom_sim (a stylus held by a virtual hand playing `explore`), liver_tool and
haptic_bridge; the remote side is liver_physics. The link delays the tool pose into the physics and the local
model (or the physics wrench) into the bridge. Each run is one row (ROW_KEYS); the rows are compared with
reference runs with no delay, jitter or loss, at the same script time.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt

from haptic_bridge.passivity import GENERATED_LIMIT_J, WINDOW_S
from liver_sim.base.emulated_link import LinkSettings
from liver_sim.bench.machine import machine
from liver_sim.running.network import closed_loop_plan, run_network
from liver_sim.sessions.parameters import node_parameters

#: One-way delays (ms) run by default.
TELEOP_DELAYS_MS = (0.0, 10.0, 50.0, 100.0, 200.0)
#: Seconds of closed loop per run: two passes of `explore` (5.8 s each) after the hand starts.
TELEOP_RUN_S = 12.0
#: The variants a delay can run: name → the bridge's parameters. `local_model` is the default rendering (passive
#: model updates, as passive_model_update auto has them over an emulated link); the direct-force bridge is a
#: comparison bridge (drives_device false): its held physics force is not passive at 150 Hz, which a bridge driving a
#: real device refuses (haptic_bridge.tick.passivity_problem); phantom_sim obeys it all the same.
VARIANT_PARAMETERS = {
    "local_model": {"local_model": "plane"},
    "local_model_direct": {"local_model": "plane", "passive_model_update": "never"},
    "local_model_direct_pc": {"local_model": "plane", "passive_model_update": "never", "passivity_control": True},
    "none": {"local_model": "none", "drives_device": False}}
#: What runs at each delay by default.
VARIANTS = ("local_model", "local_model_direct", "none")
#: The default rendering must stay stable and passive (by the device's own measure) at every delay up to this (ms one
#: way), in runs with at least this jitter and loss.
TELEOP_TARGETS = {"default_stable_and_passive_up_to_delay_ms": 100.0, "with_jitter_ms": 10.0, "with_loss": 0.05}
#: Oscillation of the commands in a window of OSCILLATION_WINDOW_S (stepped by a quarter of it): the RMS of the
#: command vector (each component, so that a turning force at a constant norm shows too) in each band of
#: OSCILLATION_BANDS_HZ (Butterworth band-passes of OSCILLATION_ORDER, forward and back), together 0.5-100 Hz. A
#: window oscillates when that RMS exceeds the reference run's in the same band and window of script time by
#: OSCILLATION_RATIO and OSCILLATION_MARGIN_N (the hand's own script has content there, mostly in the lowest band);
#: the oscillation is sustained (the run unstable) when oscillating windows cover OSCILLATION_SUSTAINED_S.
OSCILLATION_WINDOW_S = 2.0
OSCILLATION_BANDS_HZ = ((0.5, 2.0), (2.0, 8.0), (8.0, 30.0), (30.0, 100.0))
OSCILLATION_ORDER = 2
OSCILLATION_RATIO = 1.3
OSCILLATION_MARGIN_N = 0.02
OSCILLATION_SUSTAINED_S = 2.0
#: The bridge's energy estimate agrees with the device's truth within this fraction of it (or ESTIMATE_FLOOR_J).
ESTIMATE_TOLERANCE = 0.1
ESTIMATE_FLOOR_J = 2e-5
#: A device sample that has moved this far (m) from the first one marks the start of the script (the hand's first
#: move).
SCRIPT_START_MOTION_M = 1e-4
ROW_KEYS = ("variant", "passive_model_update", "controller_on", "delay_ms", "jitter_ms", "loss", "stable", "passive",
            "energy_to_hand_j", "energy_generated_max_j", "bridge_energy_to_hand_j", "bridge_energy_generated_max_j",
            "estimate_agrees", "peak_force_n", "force_error_rms_n", "penetration_max_mm")


def run_teleop_bench(delays_ms=TELEOP_DELAYS_MS, jitter_ms: float = 0.0, loss: float = 0.0, out_dir=None,
                     progress=None, duration_s: float = TELEOP_RUN_S, seed: int = 0, variants=VARIANTS,
                     check_domain: bool = True) -> dict:
    """The benchmark's JSON object: `rows` (one per delay and variant of `variants`, VARIANTS by default: ROW_KEYS
    and the run's details), each variant's reference run (no delay, jitter or loss), each variant's first unstable
    or active delay, `met` against TELEOP_TARGETS, and the plots written to `out_dir` (force against script time
    per delay, energy against delay). Oscillation is judged against the variant's own reference (the oscillation
    the delay adds: direct force steps at every physics frame, delay or not), the force error against the default
    rendering's. `check_domain`: before the first run (network.run_network)."""
    out_dir = Path(out_dir or "out/bench_teleop")
    say = progress or (lambda line: None)
    references = {}
    for name in dict.fromkeys(("local_model", *variants)):
        say(f"reference of {name}: no delay, no jitter, no loss")
        references[name] = teleop_run(name, LinkSettings(), duration_s, out_dir / "logs" / f"{name}_reference",
                                      check_domain=check_domain and not references)
    rows, traces = [], {}
    for delay_ms in delays_ms:
        for name in variants:
            link = LinkSettings(delay_ms * 1e-3, jitter_ms * 1e-3, loss, seed)
            say(f"{name}: delay {delay_ms:g} ms, jitter {jitter_ms:g} ms, loss {loss:g}")
            run = teleop_run(name, link, duration_s, out_dir / "logs" / f"{name}_{delay_ms:g}ms")
            row = teleop_row(name, link, run, references[name], references["local_model"])
            rows.append(row)
            traces[name, delay_ms] = script_times(run)
            say(f"  stable {row['stable']}, passive {row['passive']}: "
                f"generated at most {row['energy_generated_max_j'] * 1e3:.3f} mJ in a window, "
                f"{row['energy_to_hand_j'] * 1e3:.2f} mJ to the hand (bridge's estimate "
                f"{row['bridge_energy_to_hand_j'] * 1e3:.2f}), peak force {row['peak_force_n']:.2f} N, "
                f"error {row['force_error_rms_n']:.3f} N, penetration {row['penetration_max_mm']:.1f} mm")
    first_unstable = {v: next((r["delay_ms"] for r in rows if r["variant"] == v and not r["stable"]), None)
                      for v in variants}
    first_active = {v: next((r["delay_ms"] for r in rows if r["variant"] == v and not r["passive"]), None)
                    for v in variants}
    return {"benchmark": "teleop", "machine": machine(), "run_s": duration_s, "script": "explore",
            "jitter_ms": jitter_ms, "loss": loss, "seed": seed, "definitions": DEFINITIONS,
            "references": {name: teleop_row(name, LinkSettings(), run, run, references["local_model"])
                           for name, run in references.items()},
            "rows": rows, "first_unstable_delay_ms": first_unstable, "first_active_delay_ms": first_active,
            "targets": TELEOP_TARGETS, "met": targets_met(rows, jitter_ms, loss),
            "plots": plot_teleop(traces, rows, out_dir)}


def targets_met(rows: list[dict], jitter_ms: float, loss: float) -> dict:
    """TELEOP_TARGETS against `rows`: the default rendering stable and passive at every delay up to the bound, in
    runs with at least the target's jitter and loss (False when the runs had less, or no row reaches the bound)."""
    bound = TELEOP_TARGETS["default_stable_and_passive_up_to_delay_ms"]
    covered = [r for r in rows if r["variant"] == "local_model" and r["delay_ms"] <= bound]
    conditions = jitter_ms >= TELEOP_TARGETS["with_jitter_ms"] and loss >= TELEOP_TARGETS["with_loss"]
    return {"default_stable_and_passive_up_to_delay_ms":
            conditions and bool(covered) and max(r["delay_ms"] for r in covered) >= bound
            and all(r["stable"] and r["passive"] for r in covered)}


DEFINITIONS = {
    "stable": "no sustained oscillation: the RMS of the command vector (each component: magnitude and direction) "
              f"band-passed in each of {[list(b) for b in OSCILLATION_BANDS_HZ]} Hz (Butterworth order "
              f"{OSCILLATION_ORDER}, forward and back) in {OSCILLATION_WINDOW_S:g} s windows exceeds the same "
              f"variant's reference run's (no delay, jitter or loss) in the same band and script time by "
              f"{OSCILLATION_RATIO:g}x + {OSCILLATION_MARGIN_N:g} N in windows covering less than "
              f"{OSCILLATION_SUSTAINED_S:g} s",
    "passive": f"judged by the device's own measure (phantom_sim: its applied force times its own motion): no "
               f"window of {WINDOW_S:g} s in which the rendering generated more than {GENERATED_LIMIT_J * 1e3:g} mJ, "
               "the generated energy between t1 and t2 being E(t2) - E(t1) - S(t1), E the energy given to the "
               "hand and S(t1) = max(0, E(t0) - E(t1)) what the contact may store at t1, bounded by what the hand "
               "put in since the contact began (t0: the last instant of zero force) "
               "(haptic_bridge.passivity.max_generated_energy)",
    "energy_to_hand_j": "the device's measure at the end of the run: the integral of its applied force times its "
                        "own motion (> 0: it gave the hand more than it took)",
    "energy_generated_max_j": "the largest generated energy in a window, by the device's measure (see passive)",
    "bridge_energy_to_hand_j": "the bridge's passivity observer's estimate of energy_to_hand_j, from the stylus "
                               "samples it received and the commands it sent, aligned by the measured latency",
    "estimate_agrees": f"the bridge's estimate within {ESTIMATE_TOLERANCE:.0%} of the device's measure (or "
                       f"{ESTIMATE_FLOOR_J * 1e6:g} uJ)",
    "passive_model_update": "whether the bridge rendered new local models through its energy tank "
                            "(haptic_bridge.rendering.PassiveModelUpdate)",
    "controller_on": "whether the bridge ran the passivity controller (passivity_control)",
    "force_error_rms_n": "RMS of the command minus the default rendering's reference run's at the same script "
                         "time (from the tool's first motion)",
    "penetration_max_mm": "largest physics contact force over the contact stiffness: how deep the remote tool went "
                          "into the tissue",
    "variants": {name: parameters for name, parameters in VARIANT_PARAMETERS.items()},
    "references": "each variant run with no delay, jitter or loss"}


def teleop_run(variant: str, link: LinkSettings, duration_s: float, log_dir: Path, check_domain: bool = False):
    """One closed-loop run of `variant` (VARIANT_PARAMETERS) over `link` (network.run_network's NetworkRun;
    `check_domain` for the bench's first run only)."""
    over_link = link.parameters() if link.emulated else {}
    plan = closed_loop_plan(extra={"liver_physics": over_link,
                                   "haptic_bridge": {**VARIANT_PARAMETERS[variant], **over_link},
                                   "phantom_sim": {"loop_script": True, "script": "explore"}})
    return run_network(plan, duration_s, log_dir, lambda line: None, check_domain=check_domain)


def script_times(run) -> tuple[np.ndarray, np.ndarray]:
    """(script time s, command (K, 3) N) of the commands published within the run's window, in order of their
    publication (DDS source times: unlike the listener's arrivals, which a burst delivers at one instant, no two
    are equal); script time counts from the arrival of the first device sample that moved (the hand's first move)."""
    published, force = run.force_published_s["local_model"], run.forces["local_model"][1]
    order = np.argsort(published, kind="stable")
    published, force = published[order], force[order]
    positions = run.device_position_m["local_model"]
    moved = np.linalg.norm(positions - positions[0], axis=1) > SCRIPT_START_MOTION_M if len(positions) else []
    start = (run.device_arrival_s["local_model"][np.argmax(moved)] if np.any(moved)
             else published[0] if len(published) else 0.0)
    keep = (published >= start) & (published <= run.window_s[1])
    return published[keep] - start, force[keep]


def oscillation_n(times_s: np.ndarray, force_n: np.ndarray, windows_s: np.ndarray) -> np.ndarray:
    """The oscillation (N) of the commands in each band (rows) and OSCILLATION_WINDOW_S window starting at
    `windows_s` (columns; module constants): the RMS of the band-passed command vector, resampled at 1 kHz."""
    rms = np.zeros((len(OSCILLATION_BANDS_HZ), len(windows_s)))
    if len(times_s) < 3 or times_s[-1] - times_s[0] < 0.1:
        return rms
    grid = np.arange(0.0, times_s[-1], 0.001)
    force = np.column_stack([np.interp(grid, times_s, force_n[:, i]) for i in range(3)])
    for b, band in enumerate(OSCILLATION_BANDS_HZ):
        sos = butter(OSCILLATION_ORDER, band, btype="bandpass", fs=1000.0, output="sos")
        power = np.sum(sosfiltfilt(sos, force, axis=0, padlen=min(len(grid) - 1, 3000)) ** 2, axis=1)
        for w, start in enumerate(windows_s):
            inside = power[(grid >= start) & (grid < start + OSCILLATION_WINDOW_S)]
            rms[b, w] = float(np.sqrt(np.mean(inside))) if inside.size else 0.0
    return rms


def oscillating_s(times: tuple, reference: tuple) -> float:
    """How long (s) the commands `times` = (script time s, commands N) oscillated beyond the `reference` run's in
    any band (module constants): the oscillating windows times the window step."""
    end = min(times[0][-1] if len(times[0]) else 0.0, reference[0][-1] if len(reference[0]) else 0.0)
    step = OSCILLATION_WINDOW_S / 4.0
    windows = np.arange(0.0, end - OSCILLATION_WINDOW_S + 1e-9, step)
    mine, theirs = oscillation_n(*times, windows), oscillation_n(*reference, windows)
    oscillating = (mine > OSCILLATION_RATIO * theirs + OSCILLATION_MARGIN_N).any(axis=0)
    return float(np.count_nonzero(oscillating) * step)


def estimate_agrees(estimate_j: float, truth_j: float) -> bool:
    """Whether the bridge's energy estimate is within ESTIMATE_TOLERANCE of the device's measure (or the floor)."""
    return abs(estimate_j - truth_j) <= max(ESTIMATE_TOLERANCE * abs(truth_j), ESTIMATE_FLOOR_J)


def teleop_row(variant: str, link: LinkSettings, run, reference, default_reference) -> dict:
    """One row of the benchmark (ROW_KEYS, then `oscillating_s` and details): oscillation against the variant's own
    `reference` run, the force error against the default rendering's."""
    times, force = script_times(run)
    ref_times, ref_force = script_times(default_reference)
    common = times <= (ref_times[-1] if len(ref_times) else -1.0)
    if common.any() and len(ref_times) > 1:
        expected = np.column_stack([np.interp(times[common], ref_times, ref_force[:, i]) for i in range(3)])
        error = float(np.sqrt(np.mean(np.sum((force[common] - expected) ** 2, axis=1))))
    else:
        error = float("nan")
    bridge = run.diagnostics.get("haptic_bridge: loop", {})
    device = run.diagnostics.get("phantom_sim: loop", {})
    truth, generated = float(device.get("energy_to_hand_j", "nan")), float(device.get("energy_generated_max_j", "nan"))
    estimate = float(bridge.get("energy_to_hand_j", "nan"))
    stiffness = node_parameters(())["liver_physics"].contact_stiffness_n_per_m
    wrenches = run.wrench_n["local_model"]
    wrench = np.linalg.norm(wrenches, axis=1) if len(wrenches) else np.zeros(1)
    oscillation = oscillating_s((times, force), script_times(reference))
    norm = np.linalg.norm(force, axis=1) if len(force) else np.zeros(1)
    return {"variant": variant, "passive_model_update": bridge.get("passive_model_update") == "True",
            "controller_on": bridge.get("passivity_control") == "True", "delay_ms": link.delay_s * 1e3,
            "jitter_ms": link.jitter_s * 1e3, "loss": link.loss_fraction,
            "stable": oscillation < OSCILLATION_SUSTAINED_S, "passive": generated <= GENERATED_LIMIT_J,
            "energy_to_hand_j": truth, "energy_generated_max_j": generated, "bridge_energy_to_hand_j": estimate,
            "bridge_energy_generated_max_j": float(bridge.get("energy_generated_max_j", "nan")),
            "estimate_agrees": estimate_agrees(estimate, truth), "peak_force_n": float(norm.max()),
            "force_error_rms_n": error, "penetration_max_mm": float(wrench.max() / stiffness * 1e3),
            "oscillating_s": oscillation, "commands": int(len(force)),
            "link_lost": {label.split(":")[0]: int(float(d["link_lost"])) for label, d in run.diagnostics.items()
                          if "link_lost" in d}}


#: How each variant is drawn: (colour, label).
STYLES = {"none": ("tab:red", "direct force"), "local_model": ("tab:blue", "local model, passive updates (default)"),
          "local_model_direct": ("tab:orange", "local model, direct updates"),
          "local_model_direct_pc": ("tab:green", "local model, direct updates, passivity controller")}


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
        mine = [r for r in rows if r["variant"] == name]
        axis.plot([r["delay_ms"] for r in mine], [r["energy_generated_max_j"] * 1e3 for r in mine], "o-",
                  color=colour, label=label)
    axis.axhline(GENERATED_LIMIT_J * 1e3, color="k", lw=0.5, ls="--")
    axis.set_xlabel("one-way delay (ms)")
    axis.set_ylabel(f"largest energy generated in {WINDOW_S:g} s (mJ)")
    axis.set_yscale("symlog", linthresh=0.1)
    axis.set_ylim(bottom=0.0)
    axis.legend(fontsize=8)
    figure.tight_layout()
    energy = out_dir / "teleop_energy.png"
    figure.savefig(energy, dpi=110)
    plt.close(figure)
    return [str(forces), str(energy)]
