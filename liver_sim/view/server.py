"""`liver-sim view`: the running network served to the Foxglove app over the Foxglove SDK's WebSocket server, by a
LiveView (liver_sim.view.live_view) in its own rclpy context, until an ending signal or a duration; at exit, what it
served as a summary (scenes, seconds, scenes per second, refused messages, failed ticks), and the picture of the
scene with the largest contact force when asked."""
from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.signals import SignalHandlerOptions

from liver_sim.base.stop_request import stop_on_signals
from liver_sim.nodes.run import spin
from liver_sim.view.defaults import DEFAULT_HOST, DEFAULT_PORT, VIEW_RATE_HZ
from liver_sim.view.live_view import LiveView, check_host
from liver_sim.view.picture import draw_scene
from liver_sim.view.scene import Scene


def serve(host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, rate_hz: float = VIEW_RATE_HZ,
          allow_remote: bool = False, picture: Path | None = None, duration_s: float | None = None,
          progress=print, summary: Path | None = None, tools=("",)) -> dict:
    """`liver-sim view`: a LiveView of `tools` until an ending signal (or `duration_s`); with `picture`, the scene
    with the largest contact force on a tool (the last one if none) drawn into that PNG at exit. Returns what it
    served, {scenes, seconds, scenes_per_s, refused_messages, tick_errors}, also written as JSON into `summary` when
    given."""
    check_host(host, allow_remote)
    kept = {}

    def keep(scene: Scene, stamp_ns: int) -> None:
        if "scene" not in kept or scene.largest_force_n >= kept["scene"].largest_force_n:
            kept["scene"] = scene

    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    view = None
    started = time.monotonic()
    try:
        with stop_on_signals() as stop:
            view = LiveView(host, port, rate_hz, allow_remote, keep if picture else None, context=context,
                            tools=tools)
            executor = EventsExecutor(context=context)
            executor.add_node(view)
            progress(f"serving the live view on ws://{host}:{view.port} (Foxglove: Open connection → Foxglove "
                     f"WebSocket); {rate_hz:g} scenes/s; Ctrl-C stops")
            spinner = threading.Thread(target=spin, args=(executor, context, stop), daemon=True)
            spinner.start()
            stop.wait(duration_s)
            stop.set()
            spinner.join(timeout=2.0)
    finally:
        if view is not None:
            view.close()
            view.destroy_node()
        context.try_shutdown()
    elapsed = time.monotonic() - started
    served = {"scenes": view.scenes if view is not None else 0, "seconds": elapsed,
              "refused_messages": view.refused if view is not None else 0,
              "tick_errors": view.tick_errors if view is not None else 0}
    served["scenes_per_s"] = served["scenes"] / max(elapsed, 1e-9)
    progress(f"served {served['scenes']} scenes in {elapsed:.1f} s ({served['scenes_per_s']:.1f} per second); "
             f"{served['refused_messages']} message(s) refused, {served['tick_errors']} tick(s) failed")
    if summary is not None:
        summary.parent.mkdir(parents=True, exist_ok=True)
        summary.write_text(json.dumps(served) + "\n")
    if picture is not None and "scene" in kept:
        force = kept["scene"].largest_force_n
        draw_scene(kept["scene"], picture, f"liver-sim view: the scene at the largest contact force ({force:.2f} N)")
        progress(f"wrote {picture}")
    elif picture is not None:
        print("liver-sim view: no scene was received (is the network running on this ROS_DOMAIN_ID?)",
              file=sys.stderr)
    return served
