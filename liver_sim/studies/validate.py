"""`liver-sim validate`: the paper's behaviours (B1–B4 of docs/paper.md), the traction test with the
liver's own materials (R1) and the local model's continuity, each as numbers beside their thresholds.

Runs on the default liver and parameters (or the given ones), offline and without ROS:

* B1, local deformation: a 10 mm press of the sphere at `scenarios.press_anchor`; at the peak force, the
  distance from the press point to the node that moved most, the organ's rigid rotation (Kabsch) and the
  paper's near/far ratio (mean shape change within 4 cm over that beyond 12 cm).
* B2, return to rest, and B3, slow return: the strong press (scenarios.offline_press_release, 2 cm); the
  residual displacement over its peak, and the half-recovery time over that of the same liver whose
  parenchyma is only as viscous as the capsule.
* B4, smooth sliding, and the continuity check: the closed-loop demo's script (press_slide_release) with
  1 kHz tool poses; physics frames at 150 Hz take the newest pose before they start and are published at
  their end (as `liver-sim resimulate` does), and the bridge's BridgeTick renders the newest local model
  at every pose (model_glide_s 0: the tick at an update renders that update's model).  B4: frames of the
  slide with no contact force, and the largest change of the force between frames of the slide over its
  mean.  Continuity: at the first tick at or after each update, the rendered force against the update's
  physics force: norm within 5 % or 0.01 N, direction within 5°, contact in both or in neither.
* R1 with the materials: the traction cylinder whose springs are the parenchyma's (then parenchyma and
  capsule) from `TissueProperties` (liver_sim.studies.traction); its small-strain stiffness against the tissue's
  (E·πR², plus Y·2πR for the capsule) and the largest deviation from Eq. 1's shape.  Set-up for a stiff
  skin on a soft core: a 6.25 mm cylinder, both ends clamped, strain read by an extensometer on the middle
  of the gauge length (traction.run_traction; the paper's set-up loads the parenchyma only, docs/paper.md, R1).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from haptic_bridge.tick import BridgeTick
from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.sessions.parameters import node_parameters
from liver_sim.studies.scenarios import (
    deformation_m,
    offline_press_release,
    press_release,
    recovery_time_s,
    rigid_rotation_deg,
)
from liver_sim.studies.traction import (
    CLAMP_LENGTH_M,
    CLAMPED_SPACING_M,
    cylinder_mesh,
    run_traction,
    section_stiffness_n,
)
from liver_sim.tool.scripts import ScriptSettings, make_script

#: B1's press depth (m) and its short script (s).
B1_DEPTH_M = 0.01
#: B4: the largest force change between consecutive frames of the slide, over the slide's mean force.
B4_MAX_JUMP_RATIO = 0.25
#: Continuity tolerances (paper §2.5 as issue 12 states them): norm within 5 % or 0.01 N, direction 5°.
CONTINUITY_RELATIVE = 0.05
CONTINUITY_ABSOLUTE_N = 0.01
CONTINUITY_ANGLE_DEG = 5.0
#: R1 with materials: small-strain stiffness within this fraction of the tissue's, shape within 25 % of Eq. 1.
TRACTION_STIFFNESS_TOLERANCE = 0.3
TRACTION_SHAPE_TOLERANCE = 0.25


@dataclass(frozen=True)
class Figure:
    """One measured figure beside its threshold: met when value <= threshold ('max') or >= ('min')."""

    check: str
    name: str
    value: float
    threshold: float
    kind: str
    unit: str

    @property
    def met(self) -> bool:
        return bool(self.value <= self.threshold if self.kind == "max" else self.value >= self.threshold)

    def line(self) -> str:
        sign = "<=" if self.kind == "max" else ">="
        return (f"{self.check:11s} {self.name:44s} {self.value:10.4g} {sign} {self.threshold:<8.4g} {self.unit:5s} "
                f"{'met' if self.met else 'NOT met'}")


def b1_local_deformation(mesh: TetMesh, params: ModelParams) -> tuple[list[Figure], dict]:
    """B1 from a 10 mm press at the press anchor (see the module docstring)."""
    model = LiverModel(mesh, params)
    settings = ScriptSettings(anchor_m=tuple(press_anchor(mesh)), tool_radius_m=model.tool.shape.radius_m,
                              depth_m=B1_DEPTH_M, clearance_m=0.005, approach_s=0.1, press_s=0.6, hold_s=0.3,
                              withdraw_s=0.05, rest_s=0.05)
    trace = press_release(model, settings)
    peak = trace.peak_positions_m
    moved = np.linalg.norm(peak - mesh.points, axis=1)
    distance = np.linalg.norm(mesh.points - np.asarray(settings.anchor_m), axis=1)
    change = deformation_m(mesh.points, peak)
    ratio = change[distance < 0.04].mean() / max(change[distance > 0.12].mean(), 1e-12)
    figures = [Figure("B1", "distance of the largest displacement to the tool", float(distance[np.argmax(moved)]),
                      0.03, "max", "m"),
               Figure("B1", "rigid rotation of the organ", rigid_rotation_deg(mesh.points, peak), 2.0, "max", "deg"),
               Figure("B1", "shape change near (<4 cm) / far (>12 cm)", float(ratio), 4.0, "min", ""),
               Figure("B1", "dent: displacement under the tool", float(moved[np.argmin(distance)]), 0.002, "min",
                      "m")]
    return figures, {"distance_m": distance, "displacement_m": moved}


def b2_b3_return(mesh: TetMesh, params: ModelParams) -> tuple[list[Figure], dict]:
    """B2 and B3 from the strong press (see the module docstring)."""
    ratio = params.capsule.mu_ns_per_m / params.parenchyma.mu_ns_per_m
    quick_params = params.with_changes(tissue=replace(
        params.tissue, parenchyma_viscosity_pa_s=params.tissue.parenchyma_viscosity_pa_s * ratio),
        parenchyma=replace(params.parenchyma, mu_ns_per_m=params.capsule.mu_ns_per_m))
    traces = {}
    for name, run_params in (("viscous", params), ("capsule-like", quick_params)):
        model = LiverModel(mesh, run_params)
        traces[name] = press_release(model, offline_press_release(mesh, model.tool.shape.radius_m))
    data = traces["viscous"].arrays()
    residual = data["max_displacement_m"][-1] / data["max_displacement_m"].max()
    slow, quick = (recovery_time_s(traces[name], 0.5, "max_displacement_m") for name in ("viscous", "capsule-like"))
    figures = [Figure("B2", "residual / peak displacement after release", float(residual), 0.02, "max", ""),
               Figure("B2", "peak displacement of the strong press", float(data["max_displacement_m"].max()),
                      0.015, "min", "m"),
               Figure("B3", "half-recovery time, viscous parenchyma", slow, 0.0, "min", "s"),
               Figure("B3", "half-recovery: viscous / capsule-like", slow / quick, 1.25, "min", "")]
    return figures, {name: trace.arrays() for name, trace in traces.items()}


def b4_and_continuity(mesh: TetMesh, params: ModelParams, bridge: dict) -> tuple[list[Figure], dict]:
    """B4 and the local model's continuity over the demo's script with 1 kHz poses (module docstring)."""

    model = LiverModel(mesh, params)
    settings = ScriptSettings(anchor_m=tuple(press_anchor(mesh)), tool_radius_m=model.tool.shape.radius_m)
    script = make_script("press_slide_release", settings)
    slide_start = settings.approach_s + settings.press_s + settings.hold_s
    slide_end = slide_start + settings.slide_s
    tick = BridgeTick(bridge.replace(model_glide_s=0.0))
    period = 1.0 / bridge.rate_hz
    frame_s = model.structure.frame_period_s
    frames = int(round(script.duration_s / frame_s))
    frame_force, frame_time, rendered = [], [], []
    local = None
    for k in range(frames):
        published = (k + 1) * frame_s  # the frame ends with the tool where the script has it then
        result = model.step_frame(ToolPose(script.position_at(published)))
        first = True
        local = (result.local_model if result.local_model.valid else None, bridge.lifetime_s)
        frame_force.append(result.tool_force_n)
        frame_time.append(published)
        for tick_index in range(int(round(published / period)), int(round((published + frame_s) / period))):
            now = tick_index * period
            command = tick.step(now, script.position_at(now), 0.0, local, now - published)
            if first:
                rendered.append(command)
                first = False
    force = np.asarray(frame_force)
    times = np.asarray(frame_time)
    shown = np.asarray(rendered)
    magnitude = np.linalg.norm(force, axis=1)
    slide = (times >= slide_start) & (times <= slide_end)
    slide_force = magnitude[slide]
    jumps = np.abs(np.diff(slide_force))
    shown_norm = np.linalg.norm(shown, axis=1)
    error = np.abs(shown_norm - magnitude) / np.maximum(CONTINUITY_RELATIVE * magnitude, CONTINUITY_ABSOLUTE_N)
    both = (magnitude > CONTINUITY_ABSOLUTE_N) & (shown_norm > CONTINUITY_ABSOLUTE_N)
    cosine = np.einsum("ij,ij->i", force[both], shown[both]) / (magnitude[both] * shown_norm[both])
    angle = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    one_sided = (magnitude > 0.0) != (shown_norm > 0.0)
    figures = [Figure("B4", "slide frames without contact force", int((slide_force <= 0.0).sum()), 0, "max",
                      "frames"),
               Figure("B4", "largest slide force step / mean slide force",
                      float(jumps.max() / max(slide_force.mean(), 1e-12)) if jumps.size else 0.0,
                      B4_MAX_JUMP_RATIO, "max", ""),
               Figure("continuity", "worst |rendered| - |physics| / max(5 %, 0.01 N)", float(error.max()), 1.0,
                      "max", ""),
               Figure("continuity", "worst direction error", float(angle.max()) if angle.size else 0.0,
                      CONTINUITY_ANGLE_DEG, "max", "deg"),
               Figure("continuity", "updates in contact in only one of them", int(one_sided.sum()), 0, "max",
                      "")]
    return figures, {"time_s": times, "physics_n": magnitude, "rendered_n": shown_norm,
                     "slide_s": (slide_start, slide_end)}


def traction_materials(params: ModelParams) -> tuple[list[Figure], dict]:
    """R1 on the clamped traction cylinder with the parenchyma's springs, then the parenchyma's and the capsule's."""
    mesh = cylinder_mesh(CLAMPED_SPACING_M)
    figures, results = [], {}
    for name, tissue in (("parenchyma", replace(params.tissue, capsule_stiffness_n_per_m=0.0)),
                         ("capsule+parenchyma", params.tissue)):
        result = run_traction(mesh=mesh, tissue=tissue, clamp_length_m=CLAMP_LENGTH_M)
        results[name] = result
        figures += [Figure("R1", f"{name}: |stiffness / tissue's - 1|",
                           abs(result.small_strain_stiffness_n / section_stiffness_n(tissue) - 1.0),
                           TRACTION_STIFFNESS_TOLERANCE, "max", ""),
                    Figure("R1", f"{name}: largest deviation from Eq. 1's shape", result.shape_deviation(),
                           TRACTION_SHAPE_TOLERANCE, "max", "")]
    return figures, results


def run_validation(mesh: TetMesh | None = None, params: ModelParams | None = None, bridge: dict | None = None,
                   progress=print) -> tuple[list[Figure], dict]:
    """Every figure (B1–B4, R1 with the materials, continuity) and the data of their plots."""
    mesh = mesh or default_liver()
    params = (params or ModelParams()).validate()
    if bridge is None:
        bridge = node_parameters()["haptic_bridge"]
    figures, data = [], {}
    for name, run in (("B1", lambda: b1_local_deformation(mesh, params)),
                      ("B2-B3", lambda: b2_b3_return(mesh, params)),
                      ("B4-continuity", lambda: b4_and_continuity(mesh, params, bridge)),
                      ("R1", lambda: traction_materials(params))):
        progress(f"running {name} ...")
        found, data[name] = run()
        figures += found
        for figure in found:
            progress("  " + figure.line())
    return figures, data


def figures_json(figures: list[Figure]) -> dict:
    """{"all_met": bool, "figures": [{check, name, value, threshold, kind, unit, met}]}."""
    return {"all_met": all(f.met for f in figures), "figures": [{**asdict(f), "met": f.met} for f in figures]}


def write_plots(data: dict, out_dir: Path) -> list[Path]:
    """One PNG per behaviour (b1.png, b2_b3.png, b4_continuity.png, traction_materials.png) in out_dir."""
    import matplotlib  # heavy, and only for the commands that draw
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []

    def save(fig, name):
        fig.tight_layout()
        fig.savefig(out_dir / name)
        plt.close(fig)
        paths.append(out_dir / name)

    b1 = data["B1"]
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=110)
    ax.plot(b1["distance_m"] * 100, b1["displacement_m"] * 1e3, ".", color="tab:blue")
    ax.axvline(3.0, ls=":", color="grey", label="3 cm")
    ax.set(xlabel="distance from the press point at rest (cm)", ylabel="displacement at peak press (mm)",
           title=f"B1: {B1_DEPTH_M * 1e3:.0f} mm press, displacement of every node")
    ax.legend()
    save(fig, "b1.png")

    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=110)
    for name, trace in data["B2-B3"].items():
        ax.plot(trace["time_s"], trace["max_displacement_m"] * 1e3, label=name)
    ax.set(xlabel="time (s)", ylabel="largest displacement (mm)", title="B2-B3: strong press, release, return")
    ax.legend()
    save(fig, "b2_b3.png")

    b4 = data["B4-continuity"]
    fig, ax = plt.subplots(figsize=(7.2, 4.4), dpi=110)
    ax.axvspan(*b4["slide_s"], color="0.9", label="slide")
    ax.plot(b4["time_s"], b4["physics_n"], label="physics contact force (150 Hz)")
    ax.plot(b4["time_s"], b4["rendered_n"], "--", label="bridge command at each update")
    ax.set(xlabel="time (s)", ylabel="|force| (N)", title="B4 and continuity: the demo's press, slide, release")
    ax.legend()
    save(fig, "b4_continuity.png")

    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=110)
    for name, result in data["R1"].items():
        strains = np.linspace(0.0, result.elongation.max() * 1.05, 200)
        line, = ax.plot(strains * 100, result.law_force_n(strains), ":")
        ax.plot(result.elongation * 100, result.force_n, "x", color=line.get_color(), label=name)
    ax.set(xlabel="relative elongation (%)", ylabel="applied force (N)",
           title="R1 with the liver's materials (x: cylinder, dotted: Eq. 1 scaled)")
    ax.legend()
    save(fig, "traction_materials.png")
    return paths


def main_validate(json_output: bool, out_dir: Path | None, progress=print) -> int:
    """The `liver-sim validate` command: print the figures, JSON on stdout with `json_output`, plots to
    out_dir; 0 when every figure meets its threshold, else 1."""
    figures, data = run_validation(progress=progress)
    if out_dir is not None:
        for path in write_plots(data, out_dir):
            progress(f"wrote {path}")
        (out_dir / "validate.json").write_text(json.dumps(figures_json(figures), indent=2) + "\n")
    if json_output:
        print(json.dumps(figures_json(figures), indent=2))
    return 0 if all(f.met for f in figures) else 1
