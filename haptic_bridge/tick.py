"""One tick of the haptic loop without ROS: tool tip + newest local model (or physics wrench) → the
safe force command for the device (paper §2.5, P11 of docs/paper.md; docs/contract.md, "Haptic safety").

The `haptic_bridge` node runs a BridgeTick at rate_hz on live messages; `liver-sim resimulate`
runs the same BridgeTick on recorded tool poses.  Parameters: haptic_bridge.parameters.PARAMETERS.
"""
from __future__ import annotations

import math

import numpy as np

from haptic_bridge.rendering import ModelGlide, contact_force, max_passive_stiffness
from haptic_bridge.safety import SafeForceOutput
from liver_sim.geometry.device_map import DeviceMap
from liver_sim.local_model import LocalModel, penetration


def check_passivity(p: dict) -> None:
    """Refuse a stiffness the device cannot render passively at rate_hz (Colgate: b > K·T/2 + |B|).

    At the device a liver-side stiffness K and damping B are felt as K·scale and B·scale.
    """
    stiffness, scale = p["stiffness_n_per_m"], p["device_scale"]
    limit = max_passive_stiffness(p["device_damping_ns_per_m"], 1.0 / p["rate_hz"], p["damping_ns_per_m"] * scale)
    if stiffness * scale >= limit and stiffness + p["damping_ns_per_m"] > 0.0:
        raise ValueError(
            f"parameter stiffness_n_per_m={stiffness:g} is not passive: with device_damping_ns_per_m="
            f"{p['device_damping_ns_per_m']:g}, damping_ns_per_m={p['damping_ns_per_m']:g}, "
            f"device_scale={scale:g} and rate_hz={p['rate_hz']:g}, Colgate's b > K·T/2 + B allows "
            f"stiffness_n_per_m < {limit / scale:g} N/m")


class DepthRate:
    """Rate (m/s) of the penetration depth: finite difference over the tick, one-pole low-passed."""

    def __init__(self, period_s: float, cutoff_hz: float):
        self.period_s = period_s
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff_hz * period_s) if cutoff_hz > 0.0 else 1.0
        self.depth = 0.0
        self.rate = 0.0

    def update(self, depth: float) -> float:
        """The filtered rate after this tick's `depth` (m)."""
        raw = (depth - self.depth) / self.period_s
        self.depth = depth
        self.rate += self.alpha * (raw - self.rate)
        return self.rate


class BridgeTick:
    """F_device = SafeForceOutput(Rᵀ·F_liver): F_liver is the local model's penalty force on the tool sphere
    (`local_model` plane/sphere, rendered through a ModelGlide of `model_glide_s`) or the held physics
    contact force (`local_model: none`, Fig. 8 baseline).

    Refuses (ValueError naming the parameter) a non-passive stiffness, a bad device map, and a rate
    limit too low for the watchdog ramp.
    """

    def __init__(self, p: dict):
        check_passivity(p)
        self.p = p
        self.mode = p["local_model"]
        self.device_map = DeviceMap.from_parameters(p)
        period = 1.0 / p["rate_hz"]
        try:
            self.safety = SafeForceOutput(p["max_force_n"], p["max_force_rate_n_per_s"], period,
                                          p["lifetime_s"], p["ramp_time_s"])
        except ValueError as exc:
            raise ValueError(f"parameter max_force_rate_n_per_s={p['max_force_rate_n_per_s']:g} with "
                             f"max_force_n={p['max_force_n']:g}, ramp_time_s={p['ramp_time_s']:g}: {exc}") from None
        self.depth_rate = DepthRate(period, p["depth_rate_cutoff_hz"])
        self.glide = ModelGlide(p["model_glide_s"])

    def render(self, model: LocalModel | None, tip: np.ndarray | None) -> np.ndarray:
        """Local-model force on the tool (N, liver frame); zero without a model or a tip."""
        if model is None or tip is None:
            depth, direction = 0.0, np.zeros(3)
        else:
            depth, direction = penetration(model, tip, self.p["tool_radius_m"])
        rate = self.depth_rate.update(depth)
        return contact_force(depth, rate, direction, self.p["stiffness_n_per_m"], self.p["damping_ns_per_m"])

    def step(self, now_s: float, tip: np.ndarray | None, pose_age_s: float, source, source_age_s: float) -> np.ndarray:
        """The (3,) command (N, device frame) of the tick at `now_s` (s, any clock that ticks in seconds).

        `source` is the newest input with its age `source_age_s` (s): with local_model none the physics
        force (3,) N, else (local model or None, lifetime s); None before any arrived.
        """
        if self.mode == "none":
            force = source if source is not None else np.zeros(3)
            lifetime = self.p["lifetime_s"]
        else:
            model, lifetime = source if source is not None else (None, self.p["lifetime_s"])
            force = self.render(self.glide.update(model, now_s), tip)
        return self.safety.step(self.device_map.liver_to_device_force(force), source_age_s, pose_age_s, lifetime)
