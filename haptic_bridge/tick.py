"""One tick of the haptic loop without ROS: tool tip + newest local model (or physics wrench) → the
safe force command for the device (paper §2.5, P11 of docs/paper.md; docs/contract.md, "Haptic safety").

The `haptic_bridge` node runs a BridgeTick at rate_hz on live messages; `liver-sim resimulate`
runs the same BridgeTick on recorded tool poses.  Parameters: haptic_bridge.parameters.PARAMETERS.
"""
from __future__ import annotations

import math

import numpy as np

from haptic_bridge.parameters import BridgeParameters
from haptic_bridge.passivity import PassivityObserver
from haptic_bridge.rendering import ModelGlide, PassiveModelUpdate, capped, contact_force, max_passive_stiffness
from haptic_bridge.safety import SafeForceOutput
from liver_sim.base.emulated_link import LinkSettings
from liver_sim.base.geometry.device_map import DeviceMap
from liver_sim.base.local_model import LocalModel, penetration

_ZERO = np.zeros(3)
_ZERO.setflags(write=False)


def hold_time_s(p: BridgeParameters) -> float:
    """The longest time T (s) a command can be held at the device while the bridge drives it: a period of what
    is rendered (1/rate_hz; with `local_model: none` the physics wrench, 1/physics_rate_hz), or the longest
    gap between ticks before the supervisor sends zero (stall_bound_s), whichever is longer."""
    rate = p.physics_rate_hz if p.local_model == "none" else p.rate_hz
    return max(1.0 / rate, p.stall_bound_s)


def passivity_problem(p: BridgeParameters, scale: float = 1.0) -> str | None:
    """Why the force `p` renders is not passive at the device (Colgate: b > K·T/2 + |B|), or None.

    Every mode is checked with what it renders: the local model's K, B; with `local_model: none` the physics
    penalty (contact_stiffness_n_per_m, contact_damping_ns_per_m). T is the longest hold (:func:`hold_time_s`),
    not the nominal period: ticks may lie up to stall_bound_s apart. At the device a liver-side K and B are felt
    as K·scale and B·scale (`scale`: the device map's).
    """
    if p.local_model == "none":
        names, rate_name = ("contact_stiffness_n_per_m", "contact_damping_ns_per_m"), "physics_rate_hz"
    else:
        names, rate_name = ("stiffness_n_per_m", "damping_ns_per_m"), "rate_hz"
    stiffness, damping, hold = getattr(p, names[0]), getattr(p, names[1]), hold_time_s(p)
    limit = max_passive_stiffness(p.device_damping_ns_per_m, hold, damping * scale)
    if stiffness * scale < limit or stiffness + damping <= 0.0:
        return None
    return (f"parameter {names[0]}={stiffness:g} is not passive with local_model {p.local_model}: with "
            f"device_damping_ns_per_m={p.device_damping_ns_per_m:g}, {names[1]}={damping:g}, device scale "
            f"{scale:g} and a hold of T={hold * 1e3:g} ms (the longer of 1/{rate_name} and stall_bound_s), "
            f"Colgate's b > K·T/2 + B allows {names[0]} < {limit / scale:g} N/m")


def check_passivity(p: BridgeParameters, scale: float = 1.0) -> None:
    """ValueError with :func:`passivity_problem`'s reason when the rendering is not passive."""
    problem = passivity_problem(p, scale)
    if problem:
        raise ValueError(problem)


#: The safety envelope: the parameters a running bridge takes from its next tick on, each bounded by its value at
#: the process's start from above ("at most") or from below ("at least"). A run-time change may tighten the
#: envelope, and loosen it back up to where it started, never beyond. The start is the process's: a managed
#: bridge's lifecycle (cleanup, configure) does not move it. Every other parameter is read at the start.
ENVELOPE = {"max_force_n": "at most", "max_force_rate_n_per_s": "at most", "lifetime_s": "at most",
            "ramp_time_s": "at most", "stiffness_n_per_m": "at most", "damping_ns_per_m": "at most",
            "contact_stiffness_n_per_m": "at most", "contact_damping_ns_per_m": "at most",
            "model_glide_s": "at most", "soft_start_s": "at least"}
RUNTIME_PARAMETERS = frozenset(ENVELOPE)


def checked_change(p: BridgeParameters, changes: dict, scale: float = 1.0,
                   start: BridgeParameters | None = None) -> BridgeParameters:
    """The parameters `p` with `changes` applied, checked as a start would check them (passivity with the
    device map's `scale` unless `drives_device` is false, the rate limit against the clamp) and against the
    ENVELOPE of the `start` parameters (default `p`); ValueError with the reason for a name outside
    RUNTIME_PARAMETERS, a value outside the envelope or an unsafe combination."""
    fixed = sorted(set(changes) - RUNTIME_PARAMETERS)
    if fixed:
        raise ValueError(f"{', '.join(fixed)}: read at start only; restart haptic_bridge to change "
                         f"{'it' if len(fixed) == 1 else 'them'}")
    start = p if start is None else start
    for name, value in sorted(changes.items()):
        bound = ENVELOPE.get(name)
        start_value = getattr(start, name)
        if (bound == "at most" and value > start_value) or (bound == "at least" and value < start_value):
            raise ValueError(f"{name}={value:g} would loosen the safety envelope fixed at start: at run time it "
                             f"may only be {bound} {start_value:g}; restart haptic_bridge to loosen it")
    candidate = p.replace(**changes)
    if candidate.drives_device:
        check_passivity(candidate, scale)
    safe_output(candidate)  # refuses a rate limit too low for the new clamp and ramp
    return candidate


def safe_output(p: BridgeParameters) -> SafeForceOutput:
    """The SafeForceOutput of the parameters `p`; ValueError naming the parameters that conflict."""
    try:
        return SafeForceOutput(p.max_force_n, p.max_force_rate_n_per_s, 1.0 / p.rate_hz, p.lifetime_s,
                               p.ramp_time_s, p.soft_start_s)
    except ValueError as exc:
        raise ValueError(f"parameter max_force_rate_n_per_s={p.max_force_rate_n_per_s:g} with "
                         f"max_force_n={p.max_force_n:g}, ramp_time_s={p.ramp_time_s:g}: {exc}") from None


def rendered_stiffness(model: LocalModel | None, cap_n_per_m: float) -> float:
    """The K (N/m) a local model is rendered with: its own K capped at `cap_n_per_m` (the bridge's
    stiffness_n_per_m, whose passivity is checked), the cap when it carries none. The bridge renders a model whose K
    is above the cap as :func:`haptic_bridge.rendering.capped` makes it, so that the physics force is felt at the
    physics' pose; this min then only guards the ticks of a glide after the cap was lowered at run time."""
    if model is None or model.stiffness_n_per_m is None:
        return cap_n_per_m
    return min(model.stiffness_n_per_m, cap_n_per_m)


#: A penetration rate beyond this (m/s) is no motion of a hand-held stylus but a jump of the inputs.
MAX_DEPTH_RATE_M_S = 10.0


class DepthRate:
    """Rate (m/s) of the penetration depth: finite difference over the tick, one-pole low-passed.

    A non-finite depth is dropped (the rate stays); a jump faster than MAX_DEPTH_RATE_M_S (or one that
    overflows) restarts the filter at the new depth with rate 0, so no sample, however large, leaves NaN,
    inf or a slowly decaying huge rate behind: the next good sample renders.
    """

    def __init__(self, period_s: float, cutoff_hz: float):
        self.period_s = period_s
        self.set_cutoff(cutoff_hz)
        self.depth = 0.0
        self.rate = 0.0

    def set_cutoff(self, cutoff_hz: float) -> None:
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff_hz * self.period_s) if cutoff_hz > 0.0 else 1.0

    def update(self, depth: float) -> float:
        """The filtered rate after this tick's `depth` (m)."""
        if not math.isfinite(depth):
            return self.rate
        raw = (depth - self.depth) / self.period_s
        self.depth = depth
        if not abs(raw) <= MAX_DEPTH_RATE_M_S:
            self.rate = 0.0
        else:
            self.rate += self.alpha * (raw - self.rate)
        return self.rate


def passive_model_update_on(p: BridgeParameters) -> bool:
    """Whether the bridge renders new local models through a PassiveModelUpdate: `passive_model_update` always, or
    auto with an emulated link (a delay, jitter or loss between the physics and the bridge)."""
    mode = p.passive_model_update
    return mode == "always" or (mode == "auto" and LinkSettings.from_parameters(p).emulated)


class BridgeTick:
    """F_device = SafeForceOutput(Rᵀ·F_liver [− α·v]): F_liver is the local model's penalty force on the tool sphere
    (`local_model` plane/sphere, capped at `stiffness_n_per_m` by :meth:`rendered_model` so that it still renders the
    physics force at the physics' pose, rendered through a ModelGlide of `model_glide_s`, then through a
    PassiveModelUpdate when :func:`passive_model_update_on`) or the held physics contact force (`local_model: none`,
    Fig. 8 baseline). A PassivityObserver (`passivity`) estimates the energy the commands give the hand from the
    stylus samples (:meth:`sample`); with `passivity_control` its damping −α·v joins the force before the safety
    chain.

    `device_map` maps the force into the device frame (default: the identity, as offline); None renders zero
    until :meth:`set_device_map`. A different map replaces the one in use only once the force has ramped to zero
    (`map_waiting` meanwhile), then the force rises again over the soft start. Refuses (ValueError naming the
    parameter) a rate limit too low for the watchdog ramp, and, when it drives a device (`drives_device`), a
    non-passive local-model stiffness; the node also checks the passivity of `none` (:func:`check_passivity`), which
    offline baselines that drive no device skip. A bridge that drives no device reports a non-passive rendering in
    its diagnostics instead.
    """

    def __init__(self, p: BridgeParameters, device_map: DeviceMap | None = DeviceMap()):
        if p.local_model != "none" and p.drives_device:
            check_passivity(p, 1.0 if device_map is None else device_map.scale)
        self.p = p
        self.mode = p.local_model
        self.device_map = device_map
        self.map_waiting: DeviceMap | None = None
        self.maps_taken = 0 if device_map is None else 1
        self.safety = safe_output(p)
        self.depth_rate = DepthRate(1.0 / p.rate_hz, p.depth_rate_cutoff_hz)
        self.glide = ModelGlide(p.model_glide_s)
        self.passivity = PassivityObserver(1.0 / p.rate_hz, p.passivity_control,
                                           p.passivity_max_damping_ns_per_m)
        self.passive_update = PassiveModelUpdate(p.max_force_n) if passive_model_update_on(p) else None
        self._arrived: LocalModel | None = None  # the newest model of the source, and the model rendered for it
        self._arrived_cap = math.nan
        self._rendered: LocalModel | None = None

    def configure(self, p: BridgeParameters) -> None:
        """Take parameters checked by :func:`checked_change`, from this tick on (called by the loop)."""
        self.safety.configure(p.max_force_n, p.max_force_rate_n_per_s, p.lifetime_s, p.ramp_time_s,
                              p.soft_start_s)
        self.glide.duration_s = p.model_glide_s
        if self.passive_update is not None:
            self.passive_update.max_force_n = p.max_force_n
        self.p = p

    def set_device_map(self, device_map: DeviceMap | None) -> None:
        """Render through `device_map` (class docstring); None: zero force now, until a map comes."""
        if device_map is None:
            self.device_map = self.map_waiting = None
            self.safety.restart()
        elif device_map.same_as(self.device_map):
            self.map_waiting = None
        else:
            self.map_waiting = device_map

    def _take_waiting_map(self) -> None:
        self.device_map, self.map_waiting = self.map_waiting, None
        self.maps_taken += 1
        self.passivity.forget_motion()
        self.safety.restart()

    def restart(self) -> None:
        """Zero force now, a soft start from the next fresh inputs (after a stall or an error of the loop)."""
        self.safety.restart()
        self.depth_rate = DepthRate(self.depth_rate.period_s, self.p.depth_rate_cutoff_hz)
        if self.passive_update is not None:
            self.passive_update.forget()
        self.passivity.episode_energy_j = self.passivity.energy_j  # zero force now: a new contact begins

    def rendered_model(self, model: LocalModel | None) -> LocalModel | None:
        """The model rendered for the physics' `model`: :func:`haptic_bridge.rendering.capped` at `stiffness_n_per_m`
        (checked passive). The one way a model enters the rendering (:meth:`step`): the glide, the passive model
        update and the force all take this one. The same object for as long as the model and the cap stay, so that
        the glide sees a new model only when one arrives or the cap changes (then it glides to the new surface)."""
        cap = self.p.stiffness_n_per_m
        if model is not self._arrived or cap != self._arrived_cap:
            self._arrived, self._arrived_cap, self._rendered = model, cap, capped(model, cap)
        return self._rendered

    def render(self, model: LocalModel | None, tip: np.ndarray | None) -> np.ndarray:
        """Local-model force on the tool (N, liver frame) of a rendered model (:meth:`rendered_model`, glided);
        zero without a model or a tip.  The stiffness is the model's K (the tissue's under the tool, at most
        `stiffness_n_per_m` once capped), or that parameter when the model carries no K."""
        if model is None or tip is None:
            depth, direction = 0.0, np.zeros(3)
        else:
            depth, direction = penetration(model, tip, self.p.tool_radius_m)
        rate = self.depth_rate.update(depth)
        return contact_force(depth, rate, direction, rendered_stiffness(model, self.p.stiffness_n_per_m),
                             self.p.damping_ns_per_m)

    def _admit(self, model: LocalModel | None, tip: np.ndarray | None) -> LocalModel | None:
        """`model` through the PassiveModelUpdate, the energies taken at `tip` with the rendered K, the budget the
        passivity observer's: what the hand put into the contact since it began."""
        radius, cap = self.p.tool_radius_m, self.p.stiffness_n_per_m
        return self.passive_update.admit(
            model, lambda m: penetration(m, tip, radius)[0] if tip is not None else 0.0,
            lambda m: rendered_stiffness(m, cap), self.passivity.episode_energy_j - self.passivity.energy_j)

    def sample(self, stamp_s: float, arrival_s: float, position_m: tuple) -> np.ndarray | None:
        """A new stylus sample: its stamp and arrival (s, the clock of the `sent_s` of :meth:`step`) and position (m,
        device frame, three floats), for the passivity observer; returns the tool tip it places in the liver frame
        through the device map (None before a map)."""
        if self.device_map is None:
            return None
        self.passivity.sample(stamp_s, arrival_s, position_m)
        return np.array(self.device_map.device_to_liver_floats(*position_m))

    def step(self, now_s: float, tip: np.ndarray | None, pose_age_s: float, source, source_age_s: float,
             sent_s: float | None = None) -> np.ndarray:
        """The (3,) command (N, device frame) of the tick at `now_s` (s, any clock that ticks in seconds), sent at
        `sent_s` (s, the stylus samples' clock; default `now_s`).

        `source` is the newest input with its age `source_age_s` (s, from its reception): with local_model none
        the physics force (3,) N, else (local model or None, lifetime s), the lifetime capped at `lifetime_s`;
        None before any arrived.
        """
        if self.mode == "none":
            force = source if source is not None else _ZERO
            lifetime = self.p.lifetime_s
        else:
            model, lifetime = source if source is not None else (None, self.p.lifetime_s)
            model = self.glide.update(self.rendered_model(model), now_s)
            if self.passive_update is not None:
                model = self._admit(model, tip)
            force = self.render(model, tip)
        if self.map_waiting is not None and (self.device_map is None or self.safety.watchdog.gain == 0.0):
            self._take_waiting_map()
        if self.device_map is None:  # no map yet: nothing is fresh
            command = self.safety.step(_ZERO, math.inf, math.inf)
        elif self.map_waiting is not None:  # ramp to zero (as on stale inputs) before the map changes
            command = self.safety.step(_ZERO, math.inf, math.inf, None, now_s)
        else:
            command = self.safety.step(self.passivity.damp(self.device_map.liver_to_device_force(force)),
                                       source_age_s, pose_age_s, min(lifetime, self.p.lifetime_s), now_s)
        if pose_age_s > self.p.lifetime_s:
            self.passivity.forget_motion()
        if self.passive_update is not None and self.safety.watchdog.gain == 0.0:
            self.passive_update.forget()
        self.passivity.commanded(now_s if sent_s is None else sent_s, command)
        return command
