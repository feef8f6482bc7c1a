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
    """What the bridge's status shows besides its loop's statistics and its supervisor's report: the input ages (s),
    each input's WriterGate (haptic_bridge.sources) by kind (the device map's too), the bad messages per input, the
    device map's problem (None once a map is in), the other publishers on the force topic (its resolved name) and the
    commands of other writers read back there since the last report (by writer), the last command's norm (N), whether a
    map offered by the executor waits for the loop."""

    ages_s: dict
    gates: dict
    bad: dict
    map_problem: str | None
    rivals: list
    bursts: dict
    last_force_n: float
    force_topic: str
    map_offered: bool


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
    if tick.map_waiting is not None or state.map_offered:
        problems.append("a new device map waits for the force to reach zero")
    if state.rivals:
        problems.append(f"another publisher on {state.force_topic} ({', '.join(state.rivals)}): not driving")
    if state.bursts:
        problems.append(f"commands of another writer on {state.force_topic} since the last report: "
                        + ", ".join(f"{count} from {name}" for name, count in sorted(state.bursts.items())))
    ambiguous = [gate.problem() for gate in state.gates.values() if gate.ambiguous]
    problems += ambiguous
    problems += [f"{kind} refused from {', '.join(gate.rivals())} (only {gate.source} may send it, parameter "
                 f"{gate.parameter})" for kind, gate in state.gates.items() if gate.rivals()]
    if not p.drives_device:
        problems += filter(None, [passivity_problem(p, tick.device_map.scale if tick.device_map else 1.0)])
    error = (report["error"] or (state.map_problem or "").startswith("device map refused") or bool(state.rivals)
             or bool(state.bursts) or bool(ambiguous))
    source_age = "tool_wrench_age_s" if p.local_model == "none" else "local_model_age_s"
    source_gate = state.gates["tool_wrench" if p.local_model == "none" else "local_model"]
    values = {"watchdog": watchdog, "local_model": p.local_model, "drives_device": p.drives_device,
              "bad_messages": sum(state.bad.values()), **{f"bad_{k}": v for k, v in state.bad.items()},
              "last_force_n": state.last_force_n, "max_force_n": p.max_force_n,
              "device_pose_age_s": state.ages_s["device_pose"], source_age: state.ages_s["source"],
              "device_node": state.gates["device_pose"].source, "model_node": source_gate.source,
              "refused_device_pose": state.gates["device_pose"].refused, "refused_source": source_gate.refused,
              "device_map_node": state.gates["device_map"].source,
              "refused_device_map": state.gates["device_map"].refused,
              "device_scale": tick.device_map.scale if tick.device_map is not None else math.nan,
              "device_maps_taken": tick.maps_taken, "device_map_waiting": tick.map_waiting is not None,
              "passive_model_update": tick.passive_update is not None,
              **tick.passivity.report(), **extra,
              **{k: v for k, v in report.items() if k not in ("events", "error", "max_gap_1s_at_s", "max_gap_at_s")},
              "max_gap_1s_at": wall_time(report["max_gap_1s_at_s"]), "max_gap_at": wall_time(report["max_gap_at_s"])}
    return diagnostic_status(name, stats, not problems, "; ".join(events + problems) or "ok", values,
                             error=error), events
