"""Scripted tool-tip trajectories: pure functions of time, in metres and seconds (no ROS).

A script is anchored at `anchor_m`, the rest-surface point it presses on (by default the liver's
dome), and presses along −z. The tool is a sphere of `tool_radius_m` centred on the tip, so the
tip touches the rest surface at anchor + radius·z; `clearance_m` is the gap between the tool's
surface and the anchor when the tool is up, `depth_m` how far below the rest surface the tool's
surface is driven. Every script first waits `start_delay_s` at its start point (again at each
repetition when it loops). Between waypoints the tip moves along a straight line with a cosine-eased
profile (zero velocity at every waypoint). SCRIPT_PARAMETERS declare the settings for the nodes that
play a script (liver_tool, phantom_sim); `script_from` reads them back.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from liver_sim.base.parameters import Param, parameter_record, vector_parameter

#: Every script name, for parameter choices.
SCRIPT_NAMES = ("press", "press_release", "slide", "withdraw", "press_slide_release", "hold", "pull", "explore")
#: Orientation of a scripted tool: the liver frame's.
IDENTITY_XYZW = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class ScriptSettings:
    """Where and how a script moves: anchor and distances (m), segment durations (s), looping."""

    anchor_m: tuple = (-0.0461755, 0.0038245, 0.06591025)
    tool_radius_m: float = 0.015
    depth_m: float = 0.01
    clearance_m: float = 0.01
    slide_m: float = 0.03
    pull_m: float = 0.05
    approach_s: float = 0.5
    press_s: float = 1.0
    hold_s: float = 0.5
    slide_s: float = 1.5
    withdraw_s: float = 0.3
    rest_s: float = 1.0
    start_delay_s: float = 0.0
    hand_speed_m_s: float = 0.15
    loop: bool = False


@dataclass(frozen=True, eq=False)
class ScriptedTrajectory:
    """Waypoints `positions_m` (k, 3) reached at `times_s` (k,), cosine-eased in between.

    Before the first waypoint the tip is at the first, after the last at the last; with `loop`
    the script repeats with period `duration_s` (only allowed when it ends where it starts).
    """

    name: str
    times_s: np.ndarray
    positions_m: np.ndarray
    loop: bool = False

    @property
    def duration_s(self) -> float:
        """Time (s) from the first waypoint to the last."""
        return float(self.times_s[-1])

    @property
    def cyclic(self) -> bool:
        """True when the script ends where it starts, so it can loop without a jump."""
        return bool(np.allclose(self.positions_m[0], self.positions_m[-1], rtol=0.0, atol=1e-12))

    def position_at(self, t: float) -> np.ndarray:
        """Tool tip (m, (3,)) at time `t` (s) since the start of the script."""
        times, points = self.times_s, self.positions_m
        if self.loop and self.duration_s > 0.0:
            t = t % self.duration_s
        if t <= times[0]:
            return points[0].copy()
        if t >= times[-1]:
            return points[-1].copy()
        k = int(np.searchsorted(times, t, side="right")) - 1  # times[k] <= t < times[k+1]
        eased = 0.5 - 0.5 * math.cos(math.pi * (t - times[k]) / (times[k + 1] - times[k]))
        return points[k] + eased * (points[k + 1] - points[k])


def _checked(settings: ScriptSettings) -> np.ndarray:
    """The anchor as a (3,) array after checking every setting; ValueError naming the parameter."""
    anchor = np.array(settings.anchor_m, dtype=np.float64)
    if anchor.shape != (3,) or not np.isfinite(anchor).all():
        raise ValueError(f"parameter anchor_m must be a finite [x, y, z] (m), got {settings.anchor_m!r}")
    for name in ("tool_radius_m", "depth_m", "clearance_m", "slide_m", "pull_m", "approach_s", "press_s", "hold_s",
                 "slide_s", "withdraw_s", "rest_s", "start_delay_s", "hand_speed_m_s"):
        value = getattr(settings, name)
        if not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f"parameter {name} must be finite and >= 0, got {value!r}")
    if not settings.hand_speed_m_s > 0.0:
        raise ValueError(f"parameter hand_speed_m_s must be > 0, got {settings.hand_speed_m_s!r}")
    return anchor


#: The exploration's taps, (x, y) offsets (m) from the anchor, and its pause (s) at the bottom of a tap.
EXPLORE_TAPS_M = ((0.0, 0.0), (0.015, 0.0), (-0.012, 0.01), (0.0, -0.015), (0.01, 0.012))
EXPLORE_PAUSE_S = 0.1
#: Strokes move at this share of the hand speed (slower than the taps, as a hand feels along a surface).
EXPLORE_STROKE_SPEED = 0.6


def _explore_moves(anchor: np.ndarray, s: ScriptSettings) -> list:
    """The `explore` script's moves [(duration s, point)], each eased segment timed so that its peak speed,
    π·|Δ|/(2·T) for a cosine-eased move of length |Δ| over T, is `hand_speed_m_s` (taps) or
    EXPLORE_STROKE_SPEED times it (strokes in contact)."""
    up_z, deep_z = s.tool_radius_m + s.clearance_m, s.tool_radius_m - s.depth_m
    moves, here = [], anchor + [0.0, 0.0, up_z]

    def go(offset_xy, dz, speed):
        nonlocal here
        point = anchor + [offset_xy[0], offset_xy[1], dz]
        moves.append((math.pi * float(np.linalg.norm(point - here)) / (2.0 * speed), point))
        here = point

    for offset in EXPLORE_TAPS_M:  # move over the spot, tap it, lift
        go(offset, up_z, s.hand_speed_m_s)
        go(offset, deep_z, s.hand_speed_m_s)
        moves.append((EXPLORE_PAUSE_S, here))
        go(offset, up_z, s.hand_speed_m_s)
    half, stroke = s.slide_m / 2.0, EXPLORE_STROKE_SPEED * s.hand_speed_m_s
    go((-half, 0.0), up_z, s.hand_speed_m_s)  # strokes: along −x → +x, across to −y, back to the start, lift
    go((-half, 0.0), deep_z, s.hand_speed_m_s)
    for offset in ((half, 0.0), (0.0, -half), (-half, 0.0)):
        go(offset, deep_z, stroke)
    go((-half, 0.0), up_z, s.hand_speed_m_s)
    go((0.0, 0.0), up_z, s.hand_speed_m_s)
    return moves


def make_script(name: str, settings: ScriptSettings = ScriptSettings()) -> ScriptedTrajectory:
    """The trajectory of script `name` (one of SCRIPT_NAMES) with `settings`.

    - hold: stay `clearance_m` above contact;
    - press: approach from clearance to contact, press to `depth_m`, hold there;
    - press_release: press, hold, withdraw to clearance, rest;
    - slide: press, hold, slide `slide_m` along +x and back at depth, withdraw, rest;
    - press_slide_release: press, hold, slide `slide_m` along +x, withdraw there, then return
      above the start during `rest_s` (so it loops smoothly);
    - withdraw: from depth back to clearance, rest;
    - pull: press, hold, then pull `pull_m` back along +z during `slide_s` and stay there (a grasped
      tool tearing the tissue: see the physics node's `tool_mode: grasp`);
    - explore: a hand exploring the surface at `hand_speed_m_s` (Fig. 8): taps `depth_m` deep at the
      EXPLORE_TAPS_M spots around the anchor, then strokes in contact along a triangle of side about
      `slide_m` at depth, and back above the anchor (it loops smoothly); the durations follow from the speed.

    Unknown names raise ValueError naming the parameter `script`; `loop` with a script that
    does not end where it starts raises ValueError naming `loop_script`.
    """
    anchor = _checked(settings)
    s = settings
    up = anchor + [0.0, 0.0, s.tool_radius_m + s.clearance_m]
    contact = anchor + [0.0, 0.0, s.tool_radius_m]
    deep = anchor + [0.0, 0.0, s.tool_radius_m - s.depth_m]
    along = np.array([s.slide_m, 0.0, 0.0])
    press = [(s.approach_s, contact), (s.press_s, deep), (s.hold_s, deep)]
    legs = {
        "hold": (up, []),
        "press": (up, press),
        "press_release": (up, press + [(s.withdraw_s, up), (s.rest_s, up)]),
        "slide": (up, press + [(s.slide_s, deep + along), (s.slide_s, deep), (s.withdraw_s, up), (s.rest_s, up)]),
        "press_slide_release": (up, press + [(s.slide_s, deep + along), (s.withdraw_s, up + along),
                                             (s.rest_s, up)]),
        "withdraw": (deep, [(s.withdraw_s, up), (s.rest_s, up)]),
        "pull": (up, press + [(s.slide_s, deep + [0.0, 0.0, s.pull_m]), (s.rest_s, deep + [0.0, 0.0, s.pull_m])]),
        "explore": (up, _explore_moves(anchor, s)),
    }
    if name not in legs:
        raise ValueError(f"parameter script={name!r} is not a script; one of {', '.join(SCRIPT_NAMES)}")
    start, moves = legs[name]
    moves = [(s.start_delay_s, start)] + moves
    times = np.cumsum([0.0] + [duration for duration, _ in moves])
    points = np.array([start] + [point for _, point in moves], dtype=np.float64)
    trajectory = ScriptedTrajectory(name, times, points, s.loop)
    if s.loop and not trajectory.cyclic:
        raise ValueError(f"parameter loop_script: script {name!r} does not end where it starts, so it cannot "
                         f"loop; use press_release, slide, press_slide_release, explore or hold")
    return trajectory


_DEFAULT = ScriptSettings()
#: Durations (s) a script segment may last.
_SEGMENT_S = (0.0, 3600.0)
#: A script's settings as node parameters, shared by liver_tool and phantom_sim so both take the same values.
SCRIPT_PARAMETERS = {
    "script": Param("press_slide_release", f"scripted tool-tip trajectory: {', '.join(SCRIPT_NAMES)}",
                    choices=SCRIPT_NAMES),
    "anchor_m": Param(list(_DEFAULT.anchor_m), "rest-surface point the script presses on, liver frame [x, y, z] "
                      "(m); default: the default liver's dome"),
    "tool_radius_m": Param(_DEFAULT.tool_radius_m, "radius of the tool sphere centred on the tip (m)", 0.0, 0.2),
    "depth_m": Param(_DEFAULT.depth_m, "press depth of the tool below the rest surface (m)", 0.0, 0.2),
    "clearance_m": Param(_DEFAULT.clearance_m, "gap between tool and rest surface when up (m)", 0.0, 0.5),
    "slide_m": Param(_DEFAULT.slide_m, "slide length along +x at depth (m)", 0.0, 0.5),
    "pull_m": Param(_DEFAULT.pull_m, "pull length back along +z after the hold, script pull (m)", 0.0, 0.5),
    "start_delay_s": Param(_DEFAULT.start_delay_s, "wait at the start point before the script (s)", *_SEGMENT_S),
    "approach_s": Param(_DEFAULT.approach_s, "clearance → contact (s)", *_SEGMENT_S),
    "press_s": Param(_DEFAULT.press_s, "contact → depth (s)", *_SEGMENT_S),
    "hold_s": Param(_DEFAULT.hold_s, "hold at depth (s)", *_SEGMENT_S),
    "slide_s": Param(_DEFAULT.slide_s, "each slide along x, or the pull (s)", *_SEGMENT_S),
    "withdraw_s": Param(_DEFAULT.withdraw_s, "depth → clearance (s)", *_SEGMENT_S),
    "rest_s": Param(_DEFAULT.rest_s, "rest at clearance after the release (s)", *_SEGMENT_S),
    "hand_speed_m_s": Param(_DEFAULT.hand_speed_m_s, "peak speed of the tip in each move of script explore (m/s)",
                            0.001, 1.0),
    "loop_script": Param(False, "repeat the script (press_release, slide, press_slide_release, explore, hold)"),
}


#: A script's parameters as one typed record (liver_sim.base.parameters.parameter_record); a node takes it from
#: its own parameters with ScriptParameters.take.
ScriptParameters = parameter_record("ScriptParameters", SCRIPT_PARAMETERS,
                                    "The settings of a tool script (SCRIPT_PARAMETERS).")


def script_from(p: ScriptParameters) -> ScriptedTrajectory:
    """The script named by the script parameters `p`, or ValueError naming the bad parameter."""
    settings = ScriptSettings(
        anchor_m=tuple(vector_parameter(p, "anchor_m", 3)), loop=p.loop_script,
        tool_radius_m=p.tool_radius_m, depth_m=p.depth_m, clearance_m=p.clearance_m, slide_m=p.slide_m,
        pull_m=p.pull_m, start_delay_s=p.start_delay_s, approach_s=p.approach_s, press_s=p.press_s,
        hold_s=p.hold_s, slide_s=p.slide_s, withdraw_s=p.withdraw_s, rest_s=p.rest_s, hand_speed_m_s=p.hand_speed_m_s)
    return make_script(p.script, settings)
