"""The virtual traction test of §3.2 (R1 of docs/paper.md, Figs. 4–5).

A cylinder of tets, top fixed, equal axial forces on all bottom nodes, relaxed to static
equilibrium at several force levels; its global force–elongation curve is set beside the
connector law (Eq. 1) scaled to the same small-strain stiffness.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from liver_sim.mesh.stuffing import tetrahedralize_implicit
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.model import LiverModel
from liver_sim.physics.params import FIG2_LAW, ModelParams, SpringLaw, TissueProperties

CYLINDER_RADIUS_M = 0.02
CYLINDER_LENGTH_M = 0.10
#: Target strains (relative elongation) the force levels are chosen to span.
TARGET_STRAINS = (0.005, 0.01, 0.02, 0.04, 0.06, 0.08, 0.10, 0.12, 0.15, 0.18, 0.22, 0.26)


@dataclass(frozen=True)
class TractionResult:
    """Applied total force (N) and measured relative elongation at each level, plus the law's scale."""

    force_n: np.ndarray
    elongation: np.ndarray
    law: SpringLaw
    small_strain_stiffness_n: float
    mesh: TetMesh

    def law_force_n(self, elongation):
        """Eq. 1 (without viscosity) scaled to the cylinder's small-strain stiffness: K·(d + λ1/λ2·d³)."""
        d = np.asarray(elongation)
        return self.small_strain_stiffness_n * (d + self.law.lambda1_n / self.law.lambda2_n * d ** 3)


def cylinder_mesh(spacing_m: float = 0.0125) -> TetMesh:
    """A stuffed cylinder of radius 2 cm and length 10 cm along z, bottom at z = 0."""
    def signed_distance(p):
        radial = np.hypot(p[:, 0], p[:, 1]) - CYLINDER_RADIUS_M
        axial = np.abs(p[:, 2] - CYLINDER_LENGTH_M / 2) - CYLINDER_LENGTH_M / 2
        return np.maximum(radial, axial)
    margin = CYLINDER_RADIUS_M / 2
    lower = (-CYLINDER_RADIUS_M - margin, -CYLINDER_RADIUS_M - margin, -margin)
    upper = (CYLINDER_RADIUS_M + margin, CYLINDER_RADIUS_M + margin, CYLINDER_LENGTH_M + margin)
    return tetrahedralize_implicit(signed_distance, lower, upper, spacing_m, source="traction cylinder")


def relax(model: LiverModel, rate_tolerance_per_s: float = 1e-3, max_frames: int = 50_000) -> int:
    """Step until no node moves faster than `rate_tolerance_per_s` × the largest displacement
    (static equilibrium); returns the frames used."""
    for frame in range(1, max_frames + 1):
        result = model.step_frame(None)
        if result.divergence:
            raise RuntimeError(result.divergence)
        speed = np.sqrt((model.velocities ** 2).sum(axis=1)).max()
        if frame >= 10 and speed < rate_tolerance_per_s * model.displacement_m().max():
            return frame
    raise RuntimeError(f"no static equilibrium within {max_frames} frames")


def run_traction(law: SpringLaw = FIG2_LAW, mesh: TetMesh | None = None, progress=None,
                 tissue: TissueProperties | None = None) -> TractionResult:
    """Pull the cylinder at force levels spanning TARGET_STRAINS and measure the elongation at rest.

    Every spring follows `law` (Fig. 2's by default: the paper's per-spring constants, symplectic Euler);
    with `tissue`, the springs get the liver's materials instead (physics.materials: parenchyma on the tet
    edges, capsule on the skin), whose law has Fig. 2's shape with the tissue's cubic_ratio (`law` is
    then that shape, scaled).  Only the equilibrium is measured, which
    neither mass nor damping change, so a heavy density and strong environmental damping make
    the relaxation quick, and the substeps are set from the model's stability bound.
    """
    mesh = mesh or cylinder_mesh()
    z = mesh.points[:, 2]
    top = np.flatnonzero(z > z.max() - 1e-6)
    bottom = np.flatnonzero(z < z.min() + 1e-6)
    length = z.max() - z.min()
    viscous = SpringLaw(law.lambda1_n, law.lambda2_n, mu_ns_per_m=0.02)
    params = ModelParams(spring_constants="paper", capsule=SpringLaw(0.0, 0.0, 0.0), parenchyma=viscous,
                         integrator="symplectic_euler", fixed_nodes=tuple(top.tolist()), support="paper",
                         environment_damping_per_s=30.0, density_kg_m3=1e5, substeps=1).validate()
    # the stability bound at rest, for springs stiffened as they are at the largest strain
    strain = 1.5 * TARGET_STRAINS[-1]
    stiffening = 1.0 + 3 * law.lambda1_n / law.lambda2_n * strain ** 2
    if tissue is not None:
        law = SpringLaw(tissue.cubic_ratio, 1.0, 0.0)
        params = params.with_changes(spring_constants="material", tissue=tissue)
        stiffened = replace(tissue, parenchyma_young_modulus_kpa=tissue.parenchyma_young_modulus_kpa * stiffening,
                            capsule_stiffness_n_per_m=tissue.capsule_stiffness_n_per_m * stiffening)
        stable = LiverModel(mesh, params.with_changes(tissue=stiffened)).stable_dt_s
    else:
        stiffened = SpringLaw(law.lambda1_n, law.lambda2_n * stiffening, viscous.mu_ns_per_m)
        stable = LiverModel(mesh, params.with_changes(parenchyma=stiffened)).stable_dt_s
    model = LiverModel(mesh, params.with_changes(substeps=math.ceil(1.0 / (params.frame_rate_hz * 0.8 * stable))))

    def elongation_at(total_force_n: float) -> float:
        model.external_forces_n[:] = 0.0
        model.external_forces_n[bottom, 2] = -total_force_n / len(bottom)
        relax(model)
        return float(-(model.positions[bottom, 2] - mesh.points[bottom, 2]).mean() / length)

    probe_force = 1e-3
    stiffness = probe_force / elongation_at(probe_force)
    forces, elongations = [], []
    for index, strain in enumerate(TARGET_STRAINS):
        force = stiffness * (strain + law.lambda1_n / law.lambda2_n * strain ** 3)
        forces.append(force)
        elongations.append(elongation_at(force))
        if progress:
            progress(index + 1, len(TARGET_STRAINS), force, elongations[-1])
    return TractionResult(np.array(forces), np.array(elongations), law, stiffness, mesh)


def write_traction(result: TractionResult, out_dir: Path) -> tuple[Path, Path]:
    """Write traction.csv (force_N, elongation, law_force_N) and traction.png (Fig. 5) to out_dir."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path = out_dir / "traction.csv"
    with csv_path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["force_N", "elongation", "law_force_N"])
        for force, elongation in zip(result.force_n, result.elongation):
            writer.writerow([f"{force:.9g}", f"{elongation:.9g}", f"{result.law_force_n(elongation):.9g}"])
    png_path = out_dir / "traction.png"
    fig, ax = plt.subplots(figsize=(6.4, 4.6), dpi=120)
    strains = np.linspace(0.0, max(result.elongation.max(), 0.12) * 1.05, 200)
    ax.plot(strains * 100, result.law_force_n(strains), ":", color="tab:blue",
            label=f"connector law, Eq. 1 (λ1={result.law.lambda1_n:g}, λ2={result.law.lambda2_n:g}), scaled")
    ax.plot(result.elongation * 100, result.force_n, "x", color="tab:red", markersize=8,
            label="traction test on the cylinder model")
    ax.set_xlabel("relative elongation (%)")
    ax.set_ylabel("applied force (N)")
    ax.set_title(f"Traction test (Figs. 4–5): {len(result.mesh.tets)}-tet cylinder, top fixed")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path)
    plt.close(fig)
    return csv_path, png_path
