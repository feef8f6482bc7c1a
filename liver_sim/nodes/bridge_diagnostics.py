"""The haptic bridge's `/diagnostics` status, built from what its shell knows (no state of its own)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from datetime import datetime, timezone

from haptic_bridge.tick import BridgeTick, passivity_problem
from liver_sim.nodes.diagnostics import diagnostic_status, on_rate


def wall_time(monotonic_s: float) -> str:
    """ISO-8601 UTC time (ms) of a monotonic time of this process."""
    if not math.isfinite(monotonic_s):
        return "-"
    wall = time.time() - (time.monotonic() - monotonic_s)
    return datetime.fromtimestamp(wall, tz=timezone.utc).isoformat(timespec="milliseconds")


@dataclass
class BridgeState:
    """What the bridge's status shows besides its loop's statistics and its supervisor's report: the input ages
    (s) and publishers, the bad messages per input, the device map's problem (None once a map is in), the other
    publishers on the force topic (its resolved name), the last command's norm (N)."""

    ages_s: dict
    publishers: dict
    bad: dict
    map_problem: str | None
    rivals: list
    last_force_n: float
    force_topic: str


def bridge_status(name: str, p: dict, tick: BridgeTick, stats: dict, report: dict, state: BridgeState,
                  extra: dict):
    """(the bridge loop's DiagnosticStatus, named `name`, the event lines for the log). The status is ERROR while the
    output is held at zero or after a stall, error or stop since the last report (each listed with its UTC time and
    cause),
    or while a map was refused from its source or another node publishes on the force topic; WARN below rate, on
    stale inputs, while a map waits or none is in; else OK. `extra`: more key/values (the emulated link's)."""
    events = [f"{e.kind} at {wall_time(e.start_s)}: {e.cause}"
              + (f" (zero held {(e.end_s - e.start_s) * 1e3:.1f} ms)" if e.end_s is not None else " (now)")
              for e in report["events"]]
    watchdog = tick.safety.state
    problems = [] if on_rate(stats, p.rate_hz) else ["below rate"]
    if stats["new_gaps"]:
        problems.append(stats["new_gaps"])
    if watchdog != "ok":
        problems.append(f"watchdog {watchdog}")
    if state.map_problem:
        problems.append(state.map_problem)
    if tick.map_waiting is not None:
        problems.append("a new device map waits for the force to reach zero")
    if state.rivals:
        problems.append(f"another publisher on {state.force_topic} ({', '.join(state.rivals)}): not driving")
    if not p.drives_device:
        problems += filter(None, [passivity_problem(p, tick.device_map.scale if tick.device_map else 1.0)])
    error = (report["error"] or (state.map_problem or "").startswith("device map refused") or bool(state.rivals))
    source_age = "tool_wrench_age_s" if p.local_model == "none" else "local_model_age_s"
    values = {"watchdog": watchdog, "local_model": p.local_model, "drives_device": p.drives_device,
              "bad_messages": sum(state.bad.values()), **{f"bad_{k}": v for k, v in state.bad.items()},
              "last_force_n": state.last_force_n, "max_force_n": p.max_force_n,
              "device_pose_age_s": state.ages_s["device_pose"], source_age: state.ages_s["source"],
              "device_pose_publishers": state.publishers["device_pose"],
              "source_publishers": state.publishers["source"],
              "device_scale": tick.device_map.scale if tick.device_map is not None else math.nan,
              "device_maps_taken": tick.maps_taken, "device_map_waiting": tick.map_waiting is not None,
              "passive_model_update": tick.passive_update is not None,
              **tick.passivity.report(), **extra,
              **{k: v for k, v in report.items() if k not in ("events", "error", "max_gap_1s_at_s", "max_gap_at_s")},
              "max_gap_1s_at": wall_time(report["max_gap_1s_at_s"]), "max_gap_at": wall_time(report["max_gap_at_s"])}
    return diagnostic_status(name, stats, not problems, "; ".join(events + problems) or "ok", values,
                             error=error), events
