"""The virtual traction test of §3.2 (R1 of docs/paper.md, Figs. 4–5).

A cylinder of tets, top fixed, equal axial forces on all bottom nodes (or both ends clamped, the
bottom clamp pulled), solved for static equilibrium at several levels; its global force–elongation
curve is set beside the connector law (Eq. 1) scaled to the same small-strain stiffness.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from liver_sim.mesh.stuffing import tetrahedralize_implicit
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.settings import FIG2_LAW, ModelParams, SpringLaw, TissueProperties
from liver_sim.physics.solver.implicit import ImplicitEuler
from liver_sim.physics.tissue.materials import network_young_modulus_pa
from liver_sim.physics.tissue.springs import build_springs

CYLINDER_RADIUS_M = 0.02
CYLINDER_LENGTH_M = 0.10
#: Target strains (relative elongation) the force levels are chosen to span.
TARGET_STRAINS = (0.005, 0.01, 0.02, 0.04, 0.06, 0.08, 0.10, 0.12, 0.15, 0.18, 0.22, 0.26)
#: The probe giving the small-strain stiffness: a total force (N, paper's set-up) or a strain (clamped).
PROBE_FORCE_N = 1e-3
PROBE_STRAIN = 1e-4
#: Equilibrium: residual force on every free node below this share of the load per loaded node
#: (paper's set-up) or of the stiffest spring's λ2 × strain (clamped).
RESIDUAL_FRACTION = 1e-5
#: The clamped set-up's extensometer spans this middle share of the gauge length.
EXTENSOMETER_SHARE = 0.5
#: The clamped set-up for the liver's materials (R1 in `liver-sim validate`): clamp length (m) and the
#: cylinder's node spacing (m).
CLAMP_LENGTH_M = 0.005
CLAMPED_SPACING_M = 0.00625
MAX_CG_ITERATIONS = 5000


@dataclass(frozen=True)
class TractionResult:
    """Applied total force (N) and measured relative elongation at each level, plus the law's scale."""

    force_n: np.ndarray
    elongation: np.ndarray
    law: SpringLaw
    small_strain_stiffness_n: float
    mesh: TetMesh
    clamp_length_m: float = 0.0

    def law_force_n(self, elongation):
        """Eq. 1 (without viscosity) scaled to the cylinder's small-strain stiffness: K·(d + λ1/λ2·d³)."""
        d = np.asarray(elongation)
        return self.small_strain_stiffness_n * (d + self.law.lambda1_n / self.law.lambda2_n * d ** 3)

    def shape_deviation(self) -> float:
        """The largest |F − law_force_n(d)| / F over the levels: how far the curve is from Eq. 1's shape."""
        return float((np.abs(self.force_n - self.law_force_n(self.elongation)) / self.force_n).max())


def section_stiffness_n(tissue: TissueProperties) -> float:
    """The cylinder section's axial stiffness F/d (N) for the tissue: E·πR² + Y·2πR, E the network's
    (materials.network_young_modulus_pa), Y the capsule's E·t."""
    return (network_young_modulus_pa(tissue) * math.pi * CYLINDER_RADIUS_M ** 2
            + tissue.capsule_stiffness_n_per_m * 2.0 * math.pi * CYLINDER_RADIUS_M)


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


def run_traction(law: SpringLaw = FIG2_LAW, mesh: TetMesh | None = None, progress=None,
                 tissue: TissueProperties | None = None, clamp_length_m: float = 0.0) -> TractionResult:
    """Pull the cylinder to levels spanning TARGET_STRAINS and measure force and elongation at static equilibrium
    (ImplicitEuler.equilibrium, each level from the last), after a probe at a tiny load that gives the
    small-strain stiffness K.

    Every spring follows `law` (Fig. 2's by default: the paper's per-spring constants); with `tissue`, the
    springs get the liver's materials instead (physics.tissue.materials: parenchyma on the tet edges, capsule on the
    skin), whose law has Fig. 2's shape with the tissue's cubic_ratio (`law` is then that shape, scaled).
    Set-up with `clamp_length_m` 0, the paper's (Fig. 4): top face fixed, equal axial forces on the bottom
    face's nodes, chosen as K·(d + λ1/λ2·d³) for the target strains d; elongation: their mean displacement over
    the length.  Else a materials lab's: the nodes within `clamp_length_m` of each end move with their clamp,
    the top one fixed, the bottom one pulled along the axis by d × the gauge length (between the clamps);
    force: the bottom clamp's reaction; elongation: an extensometer's, the mean axial strain of the middle
    EXTENSOMETER_SHARE of the gauge length (least-squares slope of the axial displacement against z).
    """
    mesh = mesh or cylinder_mesh()
    if tissue is None:
        params = ModelParams(spring_constants="paper", parenchyma=law, capsule=SpringLaw(0.0, 0.0, 0.0))
    else:
        params = ModelParams(spring_constants="material", tissue=tissue)
        law = SpringLaw(tissue.cubic_ratio, 1.0, 0.0)
    springs = build_springs(mesh, params)
    solver = ImplicitEuler(springs, len(mesh.points), max_cg_iterations=MAX_CG_ITERATIONS)
    rest = mesh.points
    z = rest[:, 2]
    length = z.max() - z.min()
    end = max(clamp_length_m, 1e-6)
    top, bottom = np.flatnonzero(z > z.max() - end), np.flatnonzero(z < z.min() + end)
    inv_mass = 1.0 / mesh.lumped_masses(params.density_kg_m3)
    inv_mass[top] = 0.0
    x = rest.copy()
    external = np.zeros_like(x)
    if clamp_length_m > 0.0:
        inv_mass[bottom] = 0.0
        gauge = length - 2.0 * clamp_length_m
        middle = np.flatnonzero(np.abs(z - (z.max() + z.min()) / 2) <= EXTENSOMETER_SHARE * gauge / 2)
        node_force = float(springs.lambda2_n.max())

        def pull(strain: float) -> tuple[float, float]:
            x[bottom, 2] = rest[bottom, 2] - strain * gauge
            f = solver.equilibrium(x, inv_mass, external, RESIDUAL_FRACTION * node_force * strain)
            return float(f[bottom, 2].sum()), float(np.polyfit(z[middle], x[middle, 2] - z[middle], 1)[0])
    else:
        def pull(force: float) -> tuple[float, float]:
            external[bottom, 2] = -force / len(bottom)
            solver.equilibrium(x, inv_mass, external, RESIDUAL_FRACTION * force / len(bottom))
            return force, float(-(x[bottom, 2] - rest[bottom, 2]).mean() / length)

    probe_force, probe_elongation = pull(PROBE_FORCE_N if clamp_length_m == 0.0 else PROBE_STRAIN)
    stiffness = probe_force / probe_elongation
    forces, elongations = [], []
    for index, strain in enumerate(TARGET_STRAINS):
        force, elongation = pull(stiffness * (strain + law.lambda1_n / law.lambda2_n * strain ** 3)
                                 if clamp_length_m == 0.0 else strain)
        forces.append(force)
        elongations.append(elongation)
        if progress:
            progress(index + 1, len(TARGET_STRAINS), force, elongation)
    return TractionResult(np.array(forces), np.array(elongations), law, stiffness, mesh, clamp_length_m)


def write_traction(result: TractionResult, out_dir: Path) -> tuple[Path, Path]:
    """Write traction.csv (force_N, elongation, law_force_N) and traction.png (Fig. 5) to out_dir."""
    import matplotlib  # heavy, and only for the commands that draw
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
    set_up = f"{result.clamp_length_m * 1e3:g} mm clamps" if result.clamp_length_m else "top fixed"
    ax.set_title(f"Traction test (Figs. 4–5): {len(result.mesh.tets)}-tet cylinder, {set_up}")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path)
    plt.close(fig)
    return csv_path, png_path
