"""`liver-sim fig8`: the paper's Fig. 8 reproduced offline on the `explore` tool script (taps and strokes at
hand speed): the 1 kHz command with the local model against a bridge holding the 150 Hz physics force
(local_model none), both from the same resimulate session (resimulate.play_script), no ROS graph."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from liver_sim.sessions.analysis import fig8_figures
from liver_sim.sessions.report import plot_fig8, plot_force
from liver_sim.sessions.resimulate import play_script
from liver_sim.tool.scripts import ScriptSettings, make_script

#: Wait (s) before the exploration offline: both bridges' soft start (soft_start_s, 0.2 s) is over at the first tap.
EXPLORE_DELAY_S = 0.5


def baseline_step_ticks(command_s: np.ndarray, baseline_n: np.ndarray, wrench_s: np.ndarray, count: int = 5) -> dict:
    """Where the held physics force's `count` largest changes between consecutive commands occur: their tick
    times (s) and whether each is the first tick at or after a physics update (`wrench_s`, s)."""
    jumps = np.linalg.norm(np.diff(baseline_n, axis=0), axis=1)
    largest = np.argsort(jumps)[::-1][:count] + 1
    first_after = np.unique(np.searchsorted(command_s, wrench_s, side="left"))
    return {"tick_s": command_s[largest].tolist(), "jump_n": jumps[largest - 1].tolist(),
            "at_physics_update": np.isin(largest, first_after).tolist()}


def exploration_fig8(out: Path | None = None, overrides=(), duration_s: float | None = None,
                     progress=lambda line: None) -> dict:
    """Fig. 8's figures (analysis.fig8_figures) of the explore script, played for `duration_s` (default: once)
    after EXPLORE_DELAY_S, with parameter `overrides`, and where the baseline steps (:func:`baseline_step_ticks`);
    with `out`, writes fig8.png, force.png and fig8.json there."""

    script = make_script("explore", ScriptSettings(start_delay_s=EXPLORE_DELAY_S))
    duration_s = script.duration_s if duration_s is None else duration_s
    progress(f"playing the explore script for {duration_s:.2f} s offline, with and without the local model")
    run = play_script(script, duration_s, overrides, progress)
    figures = {"script": "explore", "duration_s": duration_s, "overrides": list(overrides),
               **fig8_figures(run["command_n"], run["baseline_n"]),
               "baseline_steps": baseline_step_ticks(run["command_s"], run["baseline_n"], run["wrench_s"])}
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        forces = {"local_model": (run["command_s"], run["command_n"]),
                  "without_local_model": (run["command_s"], run["baseline_n"])}
        plot_fig8({"forces": forces}, out / "fig8.png")
        plot_force({"forces": forces, "wrench": (run["wrench_s"], run["wrench_n"])}, out / "force.png")
        (out / "fig8.json").write_text(json.dumps(figures, indent=2) + "\n")
        progress(f"wrote {out}/fig8.png, force.png, fig8.json")
    return figures
