"""A node's diagnostics: its loops' statistics and the collector's as DiagnosticStatus key/value pairs."""
from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from liver_sim.realtime.garbage import garbage_fields

#: A loop is on rate while it achieves at least this fraction of its rate (diagnostics).
ON_RATE_FRACTION = 0.98


def diagnostic_status(name: str, stats: dict, level_ok: bool, message: str,
                      extra: dict | None = None, error: bool = False) -> DiagnosticStatus:
    """One DiagnosticStatus with the loop statistics (and `extra`) as key/value pairs: OK, WARN when not
    `level_ok`, ERROR when `error`."""
    level = DiagnosticStatus.ERROR if error else DiagnosticStatus.OK if level_ok else DiagnosticStatus.WARN
    status = DiagnosticStatus(name=name, hardware_id="liver_sim", message=message, level=level)
    fields = dict(stats)
    fields.update(extra or {})
    fields.update(garbage_fields())
    status.values = [KeyValue(key=key, value=f"{value:.6g}" if isinstance(value, float) else str(value))
                     for key, value in fields.items()]
    return status


def loop_status_name(node) -> str:
    """The name of a node's loop status: '<node>: loop', after the node's namespace when it has one
    ('left/haptic_bridge: loop' for /left/haptic_bridge)."""
    return f"{node.get_fully_qualified_name().lstrip('/')}: loop"


def on_rate(stats: dict, rate_hz: float) -> bool:
    """Whether a loop with LoopStats.summary() `stats` achieves ON_RATE_FRACTION of `rate_hz` (Hz)."""
    return stats["rate_hz"] >= ON_RATE_FRACTION * rate_hz


def loop_status(name: str, stats: dict, rate_hz: float, extra: dict) -> DiagnosticStatus:
    """A node loop's DiagnosticStatus: OK while it is on rate (:func:`on_rate`) and had no gap over GAP_CAUSE_S
    since the last report (`new_gaps` of RateLoop.report(), named with their causes in the message)."""
    ok = on_rate(stats, rate_hz)
    problems = ([] if ok else [f"below {rate_hz:g} Hz"]) + ([stats["new_gaps"]] if stats.get("new_gaps") else [])
    return diagnostic_status(name, stats, not problems, "; ".join(problems) or "ok", extra)


def publish_diagnostics(node, publisher, statuses: list[DiagnosticStatus]) -> None:
    """Publish the node's statuses stamped now."""
    message = DiagnosticArray(status=statuses)
    message.header.stamp = node.get_clock().now().to_msg()
    publisher.publish(message)
