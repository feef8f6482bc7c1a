"""`liver-sim validate indentation`: the textbook check of a tissue's force, a rigid sphere pressed into a block.

A 12 × 12 × 6 cm block (isosurface stuffing of about `target_tets` tets), its bottom face bonded (fixed), parenchyma
only (no capsule), the product's tissue and contact otherwise; the tool sphere is stepped 1, 2, … 5 mm into the
middle of the top face at the frame rate (each step a cosine-eased move of STEP_S) and held at each depth until the
model is in static equilibrium: the force over the last EQUILIBRIUM_WINDOW_S changes by less than
EQUILIBRIUM_RELATIVE of itself and no node moves faster than EQUILIBRIUM_SPEED_M_S (at most MAX_HOLD_S).

Per depth δ: the equilibrium force F on the tool, Hertz's F_H = 4/3·E/(1 − ν²)·√R·δ^(3/2), the force expected of a
bonded layer of thickness h, F_H·c(χ) with χ = √(R·δ)/h (Dimitriadis et al., Biophys. J. 82:2798–2810, 2002, the
bonded series in χ with their α0(ν), β0(ν)), their ratio; the tool's sink into the skin (the deepest penetration
of the sphere by a skin node or a contact point at equilibrium), apart: the deepest skin node's and the deepest face
dip beyond L²/(6R) (L the face's longest edge: the dip of a face whose nodes sit on the sphere); the reference
force on the same tets (studies.indentation_reference: linear P1 elasticity, an ideal frictionless sphere) and
whether the mesh resolves the contact (that reference within HERTZ_TOLERANCE of the expected force); and the
settling of the hold: the force's peak-to-peak over its mean from HOLD_SETTLE_S to HOLD_SETTLE_S + HOLD_WINDOW_S
after the tool stopped.
Per mesh: the exponent n of F ∝ δ^n (least squares on log F against log δ).
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from liver_sim.mesh.stuffing import tetrahedralize_to_target
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.tools.tool import Tool
from liver_sim.studies.indentation_reference import sphere_indentation

#: The block (m): 12 × 12 cm wide, 6 cm thick, its bottom at z = 0.
BLOCK_SIZE_M = (0.12, 0.12, 0.06)
#: The mesh sizes of the default run (target tetrahedra).
DEFAULT_SIZES = (5_000, 20_000, 80_000)
#: The depths (m) the sphere is stepped to, and its radius (m): the default tool's.
DEPTHS_M = (0.001, 0.002, 0.003, 0.004, 0.005)
SPHERE_RADIUS_M = ToolShape().radius_m
#: Each step's move (s), from the last depth (or 2 mm above the surface) to the next.
STEP_S = 0.2
#: Static equilibrium: over this window (s) the force changes by less than this fraction of itself, and no node
#: is faster than this (m/s); a hold ends there, or at MAX_HOLD_S (then `settled` is false).
EQUILIBRIUM_WINDOW_S = 0.2
EQUILIBRIUM_RELATIVE = 1e-3
EQUILIBRIUM_SPEED_M_S = 1e-4
MAX_HOLD_S = 4.0
#: The hold's settling: peak-to-peak of the force over its mean in this window after the tool stopped (s).
HOLD_SETTLE_S = 0.5
HOLD_WINDOW_S = 0.5
#: Targets: linear law within this of the thickness-corrected Hertz force on meshes of at least RESOLVED_TETS,
#: the exponent within EXPONENT_RANGE; forces at MESH_DEPTHS_M within MESH_SPREAD of each other over the meshes;
#: at 5 mm, no skin node inside the sphere deeper than PENETRATION_MAX_M and no face dipping into it more than
#: PENETRATION_MAX_M beyond L²/(6R) (a face of longest edge L with its nodes on the sphere dips about that between
#: them); a hold's peak-to-peak under SETTLE_MAX.
HERTZ_TOLERANCE = 0.10
RESOLVED_TETS = 20_000
EXPONENT_RANGE = (1.4, 1.6)
MESH_DEPTHS_M = (0.003, 0.004, 0.005)
MESH_SPREAD = 0.10
PENETRATION_MAX_M = 5e-5
SETTLE_MAX = 0.01


def block_mesh(target_tets: int) -> TetMesh:
    """The block (BLOCK_SIZE_M, bottom face at z = 0) stuffed with about `target_tets` tetrahedra."""
    half = np.array([BLOCK_SIZE_M[0] / 2, BLOCK_SIZE_M[1] / 2, BLOCK_SIZE_M[2] / 2])
    centre = np.array([0.0, 0.0, BLOCK_SIZE_M[2] / 2])

    def signed_distance(points: np.ndarray) -> np.ndarray:
        q = np.abs(points - centre) - half
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        return outside + np.minimum(q.max(axis=1), 0.0)

    margin = 0.1 * min(BLOCK_SIZE_M)
    return tetrahedralize_to_target(signed_distance, centre - half - margin, centre + half + margin, target_tets,
                                    source=f"indentation block ~{target_tets} tets")


def hertz_force_n(young_pa: float, poisson: float, radius_m: float, depth_m: float) -> float:
    """Hertz: F = 4/3·E/(1 − ν²)·√R·δ^(3/2) (N), a rigid sphere on an elastic half-space."""
    return 4.0 / 3.0 * young_pa / (1.0 - poisson ** 2) * math.sqrt(radius_m) * depth_m ** 1.5


def bonded_layer_factor(poisson: float, radius_m: float, depth_m: float, thickness_m: float) -> float:
    """Dimitriadis et al. (2002): the force on a sphere indenting a layer bonded to a rigid base over Hertz's,
    1 − (2α0/π)·χ + (4α0²/π²)·χ² − (8/π³)·(α0³ + (4π²/15)·β0)·χ³ − (16α0/π⁴)·(α0³ + (3π²/5)·β0)·χ⁴, χ = √(R·δ)/h,
    α0 = −(1.2876 − 1.4678ν + 1.3442ν²)/(1 − ν), β0 = (0.6387 − 1.0277ν + 1.5164ν²)/(1 − ν)."""
    nu = poisson
    a0 = -(1.2876 - 1.4678 * nu + 1.3442 * nu ** 2) / (1.0 - nu)
    b0 = (0.6387 - 1.0277 * nu + 1.5164 * nu ** 2) / (1.0 - nu)
    chi = math.sqrt(radius_m * depth_m) / thickness_m
    pi = math.pi
    return (1.0 - 2.0 * a0 / pi * chi + 4.0 * a0 ** 2 / pi ** 2 * chi ** 2
            - 8.0 / pi ** 3 * (a0 ** 3 + 4.0 * pi ** 2 / 15.0 * b0) * chi ** 3
            - 16.0 * a0 / pi ** 4 * (a0 ** 3 + 3.0 * pi ** 2 / 5.0 * b0) * chi ** 4)


@dataclass(frozen=True)
class DepthRow:
    """One depth of one run (SI units; see the module docstring)."""

    depth_m: float
    force_n: float
    hertz_n: float
    expected_n: float
    ratio_to_expected: float
    sink_m: float
    node_penetration_m: float
    face_dip_over_sagitta_m: float
    contact_radius_m: float
    reference_n: float
    resolved: bool
    hold_peak_to_peak: float
    hold_s: float
    settled: bool


def block_params(params: ModelParams) -> ModelParams:
    """`params` on the block: parenchyma only (no capsule), the bottom face fixed, no organ support."""
    return params.with_changes(tissue=replace(params.tissue, capsule_stiffness_n_per_m=0.0,
                                              capsule_viscosity_ns_per_m=0.0), support="paper")


def bottom_nodes(mesh: TetMesh) -> tuple:
    """The nodes of the bottom face (z = 0), to be bonded."""
    return tuple(int(n) for n in np.flatnonzero(mesh.points[:, 2] <= 1e-9))


def _sink_m(model: LiverModel) -> float:
    """The deepest penetration of the tool by the skin (m): its contact rows' depths and the skin nodes inside its
    probes' balls."""
    tool = model.state.tools[0].sweep
    deepest = 0.0
    rows = np.isfinite(tool.depth) & (tool.share > 0.0)
    if rows.any():
        deepest = float(tool.depth[rows].max())
    return max(deepest, _node_penetration_m(model))


def _node_penetration_m(model: LiverModel) -> float:
    """The deepest skin node inside the tool's probes' balls (m, 0 if none)."""
    tool = model.state.tools[0].sweep
    skin = model.structure.mesh.skin_nodes
    deepest = 0.0
    for probe in tool.probes + tool.velocity_m_s / model.structure.params.frame_rate_hz:
        distance = np.linalg.norm(model.state.positions[skin] - probe, axis=1)
        deepest = max(deepest, float((tool.radius_m - distance).max()))
    return deepest


def _face_dip_over_sagitta_m(model: LiverModel) -> float:
    """The deepest dip of a candidate skin face into the tool's ball beyond L²/(6R), L its longest edge (m, 0 if
    none): what a face dips more than one whose nodes sit on the ball does between them."""
    tool = model.state.tools[0].sweep
    if not len(tool.triangles):
        return 0.0
    corners = model.state.positions[tool.skin[tool.triangles]]
    longest2 = np.max([((corners[:, a] - corners[:, b]) ** 2).sum(axis=1) for a, b in ((0, 1), (1, 2), (2, 0))],
                      axis=0)
    dips = tool.depth.reshape(len(tool.probes), len(tool.triangles)) - longest2 / (6.0 * tool.radius_m)
    return max(float(dips.max()), 0.0)


def reference_forces_n(mesh: TetMesh, params: ModelParams, depths_m=DEPTHS_M,
                       radius_m: float = SPHERE_RADIUS_M) -> list[float]:
    """The reference force (N) at each depth on `mesh`: studies.indentation_reference with the parenchyma's E and ν
    and a sphere of `radius_m`, the bottom bonded."""
    tissue = params.tissue
    return [row["force_n"] for row in sphere_indentation(
        mesh, tissue.parenchyma_young_modulus_kpa * 1e3, tissue.parenchyma_poisson_ratio,
        radius_m, depths_m, bottom_nodes(mesh))]


def indent(mesh: TetMesh, params: ModelParams, depths_m=DEPTHS_M, progress=None,
           reference_n=None, radius_m: float = SPHERE_RADIUS_M) -> dict:
    """The block test on `mesh` with `params` (block_params applied) and a sphere of `radius_m`: a DepthRow per
    depth, the exponent and the force trace (time s, depth m, force N per frame); `reference_n` the reference force
    per depth (reference_forces_n, computed when not given)."""
    if reference_n is None:
        reference_n = reference_forces_n(mesh, params, depths_m, radius_m)
    fixed = bottom_nodes(mesh)
    model = LiverModel(mesh, block_params(params).with_changes(fixed_nodes=fixed), Tool(ToolShape(radius_m=radius_m)))
    p = model.structure.params
    radius = model.tool.shape.radius_m
    top = float(mesh.points[:, 2].max())
    centre = np.array([0.0, 0.0])
    young = p.tissue.parenchyma_young_modulus_kpa * 1e3
    nu = p.tissue.parenchyma_poisson_ratio
    thickness = BLOCK_SIZE_M[2]
    skin_edges = mesh.skin_edges
    lengths = np.linalg.norm(mesh.points[skin_edges[:, 1]] - mesh.points[skin_edges[:, 0]], axis=1)
    mid = mesh.points[skin_edges].mean(axis=1)
    near = (mid[:, 2] > top - 1e-6) & (np.linalg.norm(mid[:, :2] - centre, axis=1) < 0.02)
    edge_m = float(lengths[near].mean()) if near.any() else float(lengths.mean())
    frame_s = model.structure.frame_period_s
    trace_t, trace_d, trace_f = [], [], []
    rows = []
    last = -0.002

    def frame(depth: float) -> float:
        tip = np.array([centre[0], centre[1], top + radius - depth])
        result = model.step_frame(ToolPose(tip))
        if result.divergence:
            raise RuntimeError(f"{mesh.source}: {result.divergence}")
        force = float(result.tool_force_n[2])
        trace_t.append(model.state.time_s)
        trace_d.append(depth)
        trace_f.append(force)
        return force

    for depth, reference in zip(depths_m, reference_n):
        steps = max(1, int(round(STEP_S / frame_s)))
        for k in range(1, steps + 1):
            s = k / steps
            frame(last + (depth - last) * 0.5 * (1.0 - math.cos(math.pi * s)))
        last = depth
        forces = []
        window = max(2, int(round(EQUILIBRIUM_WINDOW_S / frame_s)))
        settle = int(round(HOLD_SETTLE_S / frame_s))
        settle_end = int(round((HOLD_SETTLE_S + HOLD_WINDOW_S) / frame_s))
        settled = False
        while len(forces) * frame_s < MAX_HOLD_S:
            forces.append(frame(depth))
            if len(forces) >= max(window, settle_end):
                recent = np.asarray(forces[-window:])
                speed = float(np.linalg.norm(model.state.velocities, axis=1).max())
                if (np.ptp(recent) <= EQUILIBRIUM_RELATIVE * abs(recent.mean())
                        and speed <= EQUILIBRIUM_SPEED_M_S):
                    settled = True
                    break
        held = np.asarray(forces[settle:settle_end])
        force = forces[-1]
        hertz = hertz_force_n(young, nu, radius, depth)
        expected = hertz * bonded_layer_factor(nu, radius, depth, thickness)
        contact_radius = math.sqrt(radius * depth)
        rows.append(DepthRow(depth, force, hertz, expected, force / expected, _sink_m(model),
                             _node_penetration_m(model), _face_dip_over_sagitta_m(model), contact_radius,
                             reference, bool(abs(reference / expected - 1.0) <= HERTZ_TOLERANCE),
                             float(np.ptp(held) / abs(held.mean())),
                             len(forces) * frame_s, settled))
        if progress:
            r = rows[-1]
            progress(f"  {mesh.source}: {depth * 1e3:.0f} mm  F {force:.4f} N  /expected {r.ratio_to_expected:.3f}"
                     f"  sink {r.sink_m * 1e3:.3f} mm (node {r.node_penetration_m * 1e3:.3f} mm, face beyond L²/6R "
                     f"{r.face_dip_over_sagitta_m * 1e3:.3f} mm)  hold p-p {r.hold_peak_to_peak:.2%}  "
                     f"{'settled' if settled else 'NOT settled'} after {r.hold_s:.2f} s")
    depth = np.array([r.depth_m for r in rows])
    force = np.array([r.force_n for r in rows])
    exponent = float(np.polyfit(np.log(depth), np.log(np.maximum(force, 1e-12)), 1)[0]) if len(rows) > 1 else math.nan
    return {"mesh": mesh.source, "tetrahedra": int(len(mesh.tets)), "skin_edge_m": edge_m, "sphere_radius_m": radius,
            "rows": [asdict(r) for r in rows], "exponent": exponent,
            "trace": {"time_s": trace_t, "depth_m": trace_d, "force_n": trace_f}}


def variants(base: ModelParams) -> dict:
    """{name: ModelParams} of the runs of `run_indentation` on `base`: the springs' linear law (cubic_ratio 0), their
    default law, the co-rotational tetrahedra (tissue_law 'fem', the reference) and the neo-Hookean ones, each with
    the surface contact, and the product's default (the probe contact) as it was."""
    surface = base.with_changes(contact_model="surface")
    return {"springs linear, surface contact": surface.with_changes(tissue=replace(surface.tissue, cubic_ratio=0.0)),
            "springs default, surface contact": surface,
            "fem, surface contact": surface.with_changes(tissue_law="fem"),
            "neo_hookean, surface contact": surface.with_changes(tissue_law="neo_hookean"),
            "springs default, probe contact": base.with_changes(contact_model="probe")}


def default_variant(params: ModelParams) -> str:
    """The name of the variant (`variants`) that is `params` itself: the product's own tissue and contact."""
    return next(name for name, variant in variants(params).items() if variant == params)


def run_indentation(sizes=DEFAULT_SIZES, params: ModelParams | None = None, progress=None,
                    radius_m: float = SPHERE_RADIUS_M, depths_m=DEPTHS_M) -> dict:
    """Every variant on the block of every size, a sphere of `radius_m` stepped to `depths_m`: {variant:
    [indent(...) per mesh]} (meshed once each, its reference forces solved once)."""
    params = params or ModelParams()
    runs = {name: [] for name in variants(params)}
    for size in sizes:
        mesh = block_mesh(size)
        reference = reference_forces_n(mesh, params, depths_m, radius_m)
        for name, variant in variants(params).items():
            if progress:
                progress(f"{name}: {mesh.source}, {len(mesh.tets)} tets")
            runs[name].append(indent(mesh, variant, depths_m, progress, reference, radius_m))
    return runs


#: The held tool on the default liver, capsule on (`liver_hold`): a press this deep (m) at the press anchor over
#: LIVER_PRESS_S, then held LIVER_HOLD_S.
LIVER_DEPTH_M = 0.01
LIVER_PRESS_S = 0.6
LIVER_HOLD_S = HOLD_SETTLE_S + HOLD_WINDOW_S


def liver_hold(params: ModelParams) -> dict:
    """The default liver (capsule and organ support on) pressed LIVER_DEPTH_M at the press anchor and held: the
    force's peak-to-peak over its mean from HOLD_SETTLE_S to LIVER_HOLD_S after the tool stopped."""
    from liver_sim.mesh.landmarks import press_anchor
    from liver_sim.mesh.liver_shape import default_liver
    mesh = default_liver()
    model = LiverModel(mesh, params)
    radius = model.tool.shape.radius_m
    anchor = press_anchor(mesh)
    frame_s = model.structure.frame_period_s
    forces = []
    press = int(round(LIVER_PRESS_S / frame_s))
    for k in range(1, press + int(round(LIVER_HOLD_S / frame_s)) + 1):
        s = min(k / press, 1.0)
        depth = -0.002 + (LIVER_DEPTH_M + 0.002) * 0.5 * (1.0 - math.cos(math.pi * s))
        result = model.step_frame(ToolPose(anchor + np.array([0.0, 0.0, radius - depth])))
        if k > press:
            forces.append(float(np.linalg.norm(result.tool_force_n)))
    held = np.asarray(forces[int(round(HOLD_SETTLE_S / frame_s)):])
    return {"contact_model": params.contact_model, "force_n": float(held.mean()),
            "hold_peak_to_peak": float(np.ptp(held) / held.mean()), "force_trace_n": forces}


def indentation_figures(runs: dict, holds: dict) -> list:
    """The targets of the module docstring as validate.Figure rows, for the surface-contact runs (the probe
    contact's are reported beside them, not judged)."""
    from liver_sim.studies.validate import Figure
    figures = []
    for name, meshes in runs.items():
        if "surface" not in name:
            continue
        for run in meshes:
            label = f"{name}, {run['tetrahedra']} tets"
            rows = run["rows"]
            if ("linear" in name or "fem" in name) and run["tetrahedra"] >= RESOLVED_TETS * 0.95:
                worst = max(abs(r["ratio_to_expected"] - 1.0) for r in rows)
                figures += [Figure("indentation", f"{label}: worst |F/expected - 1|", worst, HERTZ_TOLERANCE, "max",
                                   ""),
                            Figure("indentation", f"{label}: exponent >=", run["exponent"], EXPONENT_RANGE[0],
                                   "min", ""),
                            Figure("indentation", f"{label}: exponent <=", run["exponent"], EXPONENT_RANGE[1],
                                   "max", "")]
            deepest = max(rows, key=lambda r: r["depth_m"])
            figures += [Figure("indentation", f"{label}: node penetration at {deepest['depth_m'] * 1e3:.0f} mm",
                               deepest["node_penetration_m"], PENETRATION_MAX_M, "max", "m"),
                        Figure("indentation", f"{label}: face dip beyond L²/(6R) at {deepest['depth_m'] * 1e3:.0f} mm",
                               deepest["face_dip_over_sagitta_m"], PENETRATION_MAX_M, "max", "m"),
                        Figure("settling", f"{label}: worst hold peak-to-peak", max(r["hold_peak_to_peak"]
                                                                                    for r in rows), SETTLE_MAX,
                               "max", "")]
        if ("default" in name or "fem" in name) and len(meshes) > 1:
            spread = 0.0
            for depth in MESH_DEPTHS_M:
                forces = [r["force_n"] for run in meshes for r in run["rows"] if abs(r["depth_m"] - depth) < 1e-9]
                spread = max(spread, (max(forces) - min(forces)) / float(np.mean(forces)))
            figures.append(Figure("indentation", f"{name}: force spread over meshes, 3-5 mm", spread, MESH_SPREAD,
                                  "max", ""))
    for name, hold in holds.items():
        figures.append(Figure("settling", f"default liver, capsule, {name}: hold peak-to-peak",
                              hold["hold_peak_to_peak"], SETTLE_MAX, "max", ""))
    return figures


def unresolved_notes(runs: dict) -> list[str]:
    """A line per mesh that does not resolve the contact at some depths: there the reference (linear P1, an ideal
    sphere, on the same tets) is itself more than HERTZ_TOLERANCE from the expected force."""
    notes = []
    first = next(iter(runs.values()))
    for run in first:
        shallow = [r for r in run["rows"] if not r["resolved"]]
        if shallow:
            notes.append(f"{run['mesh']} ({run['tetrahedra']} tets, skin edge under the tool "
                         f"{run['skin_edge_m'] * 1e3:.1f} mm) does not resolve the contact at "
                         + ", ".join(f"{r['depth_m'] * 1e3:.0f} mm (reference "
                                     f"{r['reference_n'] / r['expected_n']:.2f} x expected)" for r in shallow))
    return notes


def over_reference(row: dict) -> float | None:
    """A DepthRow's force over the reference's, None where no node of the mesh lies under the sphere (the
    reference, nodes only, feels nothing there)."""
    return row["force_n"] / row["reference_n"] if row["reference_n"] > 0.0 else None


def reference_notes(runs: dict) -> list[str]:
    """A line per run: its force over the reference's on the same tets at each depth (what the product's law and
    contact add to the textbook model, the mesh's own error apart)."""
    notes = []
    for name, meshes in runs.items():
        for run in meshes:
            notes.append(f"{name}, {run['tetrahedra']} tets: F/reference "
                         + ", ".join("-" if (ratio := over_reference(r)) is None else f"{ratio:.2f}"
                                     for r in run["rows"])
                         + " at " + ", ".join(f"{r['depth_m'] * 1e3:.0f}" for r in run["rows"]) + " mm")
    return notes


def write_plot(runs: dict, out_dir: Path) -> Path:
    """indentation.png in out_dir: force against depth per variant and mesh, with the thickness-corrected Hertz
    force (and plain Hertz, dotted)."""
    import matplotlib  # heavy, and only for the commands that draw
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, len(runs), figsize=(5.0 * len(runs), 4.4), dpi=110, sharey=True)
    for ax, (name, meshes) in zip(np.atleast_1d(axes), runs.items()):
        depth = np.linspace(0.0, max(DEPTHS_M), 100)
        rows = meshes[0]["rows"]
        hertz = np.array([r["hertz_n"] for r in rows])
        factor = np.array([r["expected_n"] / r["hertz_n"] for r in rows])
        law = hertz[-1] / rows[-1]["depth_m"] ** 1.5 * depth ** 1.5
        ax.plot(depth * 1e3, law * np.interp(depth, [r["depth_m"] for r in rows], factor, left=factor[0]), "k-",
                label="Hertz, bonded 6 cm layer")
        ax.plot(depth * 1e3, law, "k:", label="Hertz")
        for run in meshes:
            ax.plot([r["depth_m"] * 1e3 for r in run["rows"]], [r["force_n"] for r in run["rows"]], "o-",
                    label=f"{run['tetrahedra']} tets (n = {run['exponent']:.2f})")
        ax.set(xlabel="depth (mm)", title=name)
        ax.legend(fontsize=8)
    np.atleast_1d(axes)[0].set_ylabel("force on the sphere (N)")
    fig.tight_layout()
    path = out_dir / "indentation.png"
    fig.savefig(path)
    plt.close(fig)
    return path


def main_indentation(sizes, json_output: bool, out_dir, progress=print, radius_m: float = SPHERE_RADIUS_M,
                      depths_m=DEPTHS_M) -> int:
    """The `liver-sim validate indentation` command: run every variant on every mesh size (a sphere of `radius_m`
    stepped to `depths_m`) and the liver holds, print the figures (JSON on stdout with `json_output`: the figures,
    `default_variant` (the product's own tissue and contact), the sphere, the runs with each row's force over the
    reference), write indentation.json and indentation.png to out_dir; 0 when every figure meets its target, else 1."""
    from liver_sim.studies.validate import figures_json
    runs = run_indentation(sizes, progress=progress, radius_m=radius_m, depths_m=depths_m)
    holds = {}
    for model in ("surface", "probe"):
        progress(f"default liver, capsule on, {model} contact: {LIVER_DEPTH_M * 1e3:.0f} mm press and hold")
        holds[f"{model} contact"] = liver_hold(ModelParams(contact_model=model))
    figures = indentation_figures(runs, holds)
    for figure in figures:
        progress("  " + figure.line())
    notes = unresolved_notes(runs) + reference_notes(runs)
    for note in notes:
        progress("  note: " + note)
    result = {**figures_json(figures), "notes": notes, "default_variant": default_variant(ModelParams()),
              "sphere_radius_m": radius_m, "depths_m": list(depths_m),
              "runs": {name: [{**{k: v for k, v in run.items() if k not in ("trace", "rows")},
                               "rows": [{**row, "force_over_reference": over_reference(row)}
                                        for row in run["rows"]]} for run in meshes]
                       for name, meshes in runs.items()},
              "liver_holds": {name: {k: v for k, v in hold.items() if k != "force_trace_n"}
                              for name, hold in holds.items()}}
    if out_dir is not None:
        out_dir = Path(out_dir)
        progress(f"wrote {write_plot(runs, out_dir)}")
        (out_dir / "indentation.json").write_text(json.dumps(result, indent=2) + "\n")
    if json_output:
        print(json.dumps(result, indent=2))
    return 0 if result["all_met"] else 1
