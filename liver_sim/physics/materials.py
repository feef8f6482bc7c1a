"""Tissue properties → Eq. 1 spring coefficients per mesh edge, so that the network's response does not
depend on the mesh resolution.

Parenchyma (tet edges).  A spring of axial stiffness k = λ2/l0 along unit u stores ½·k·l0²·(uᵀεu)²
under a uniform small strain ε.  Over springs with isotropically spread directions,
⟨(uᵀεu)²⟩ = ((tr ε)² + 2·ε:ε)/15, so a volume V whose springs have Σ k·l0² = 6·E·V has the
Lamé constants λ = G = E/2.5, i.e. Young's modulus E and Poisson's ratio 1/4.  Giving each
tet's six edges k·l0² = E·V_tet (per tet) meets that in every tet:

    λ2 = E · Σ_{tets ∋ edge} V_tet / l0     (N; regular tet: k = E·V/l² = (√2/12)·E·l, Lloyd et al. 2007)

Capsule (skin-triangle edges, a membrane of E·t = Y, N/m).  In 2-D, ⟨(uᵀεu)²⟩ = ((tr ε)² + 2·ε:ε)/8
gives Y = Σ k·l0²/(3·A), hence per triangle k·l0² = Y·A_tri:

    λ2 = Y · Σ_{triangles ∋ edge} A_tri / l0     (a regular triangle: k = (√3/4)·Y; Van Gelder 1998)

Viscosity, as a Kelvin–Voigt solid σ = E·ε + η·ε̇ (the viscous spring force μ·ṗ, ṗ = l0·ḋ, paired with
λ2·d the same way): μ = η·Σ V_tet/l0² and, for the capsule, μ = η_s·Σ A_tri/l0² with η_s = η·t.
The cubic term keeps Fig. 2's ratio: λ1 = (λ1/λ2)_Fig.2 · λ2 ≈ 143·λ2 (linear below ~10 % strain).

Poisson's ratio is not a parameter: a network of central springs is a Cauchy solid, ν = 1/4 (3-D) and
1/3 (membrane) whatever its constants.  Liver (ν ≈ 0.45–0.5) would need a volume term.  Matching E,
the network's shear modulus is G = 0.4·E.

Check: the current per-spring defaults (params.py: λ2 = 0.5 N parenchyma, 10 N capsule) read back
with `equivalent_properties` on the default liver as E ≈ 2.1 kPa and E·t ≈ 585 N/m, and η ≈ 506 Pa·s,
η·t ≈ 0.026 N·s/m.

Defaults (`TissueProperties`) and sources:
- parenchyma E = 5 kPa: transient elastography of healthy livers measures a Young's modulus about
  5 kPa (Sandrin et al., Ultrasound Med. Biol. 29:1705, 2003); MR elastography a shear modulus about
  2 kPa (Yin et al., Clin. Gastroenterol. Hepatol. 5:1207, 2007), which is 0.4·E of this network;
- parenchyma η = 500 Pa·s: calibrated, not measured — the value the current model has (the paper's
  slow return, B3, τ = η/E = 0.1 s).  Shear-wave dispersion gives ~1–2 Pa·s (Chen et al., Radiology
  266:964, 2013), which governs 50–500 Hz waves, not the slow creep the paper shows;
- capsule E·t = 500 N/m: Glisson's capsule in uniaxial tension has a modulus of the order of 10 MPa
  over a thickness of some tens of µm (Brunon et al., J. Biomech. 43:2221, 2010), E·t a few hundred N/m;
- capsule η·t = 0.025 N·s/m: calibrated like η (the current model's);
- density 1060 kg/m³ (liver, as ModelParams).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from liver_sim.mesh.tetmesh import TET_EDGES, TRIANGLE_EDGES, TetMesh, edge_keys, signed_volumes, unique_edges
from liver_sim.physics.params import FIG2_LAW
from liver_sim.physics.springs import SpringNetwork

#: Fig. 2's cubic-to-linear stiffness ratio λ1/λ2.
CUBIC_RATIO = FIG2_LAW.lambda1_n / FIG2_LAW.lambda2_n


@dataclass(frozen=True)
class TissueProperties:
    """Continuum properties of the liver (SI units; see the module docstring for the defaults' sources)."""

    parenchyma_young_modulus_pa: float = 5000.0
    parenchyma_viscosity_pa_s: float = 500.0
    capsule_stiffness_n_per_m: float = 500.0
    capsule_viscosity_ns_per_m: float = 0.025
    density_kg_m3: float = 1060.0
    cubic_ratio: float = CUBIC_RATIO

    def validate(self) -> "TissueProperties":
        """Return self, or raise ValueError naming the first value that is not finite and >= 0."""
        for f in fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"parameter {f.name} must be finite and >= 0, got {value!r}")
        if not self.density_kg_m3 > 0.0:
            raise ValueError(f"parameter density_kg_m3 must be > 0, got {self.density_kg_m3!r}")
        return self


def _edge_sums(edges: np.ndarray, cells: np.ndarray, local_edges: np.ndarray, measure: np.ndarray,
               node_count: int) -> np.ndarray:
    """Per edge (rows of sorted `edges`), the sum of `measure` over the cells having it as an edge."""
    table = edge_keys(edges, node_count)
    keys = edge_keys(cells[:, local_edges], node_count)
    index = np.searchsorted(table, keys.ravel())
    found = index < len(table)
    found[found] = table[index[found]] == keys.ravel()[found]
    return np.bincount(index[found], np.repeat(measure, len(local_edges))[found], len(edges))


def triangle_areas(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Areas (m²) of triangles (K, 3)."""
    corners = points[triangles]
    return 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)


def _capsule(mesh: TetMesh, capsule_triangles: np.ndarray | None) -> np.ndarray:
    """The capsule triangles (K, 3): the given ones, or the whole skin."""
    return mesh.skin if capsule_triangles is None else np.asarray(capsule_triangles, np.int64).reshape(-1, 3)


def edge_measures(mesh: TetMesh, rest_points: np.ndarray | None = None,
                  capsule_triangles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per mesh edge (mesh.edges order): rest length l0 (m), Σ V_tet over its tets (m³) and Σ A_tri over its
    capsule triangles (m², 0 off the capsule; default capsule: the skin)."""
    points = mesh.points if rest_points is None else rest_points
    edges = mesh.edges
    n = len(points)
    triangles = _capsule(mesh, capsule_triangles)
    rest = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
    volume = _edge_sums(edges, mesh.tets, TET_EDGES, signed_volumes(points, mesh.tets), n)
    area = _edge_sums(edges, triangles, TRIANGLE_EDGES, triangle_areas(points, triangles), n)
    return rest, volume, area


def material_springs(mesh: TetMesh, tissue: TissueProperties | None = None, rest_points: np.ndarray | None = None,
                     capsule_triangles: np.ndarray | None = None) -> SpringNetwork:
    """The spring network of `mesh` (as springs.build_springs: one connector per edge, capsule on the edges
    of `capsule_triangles`, default the skin) with coefficients from the tissue's properties:
    λ2 = (E·ΣV + Y·ΣA)/l0, μ = (η·ΣV + η_s·ΣA)/l0², λ1 = cubic_ratio·λ2."""
    tissue = (tissue or TissueProperties()).validate()
    rest, volume, area = edge_measures(mesh, rest_points, capsule_triangles)
    lambda2 = (tissue.parenchyma_young_modulus_pa * volume + tissue.capsule_stiffness_n_per_m * area) / rest
    mu = (tissue.parenchyma_viscosity_pa_s * volume + tissue.capsule_viscosity_ns_per_m * area) / rest ** 2
    edges = mesh.edges
    capsule = len(unique_edges(_capsule(mesh, capsule_triangles), TRIANGLE_EDGES))
    return SpringNetwork(node_i=np.ascontiguousarray(edges[:, 0]), node_j=np.ascontiguousarray(edges[:, 1]),
                         rest_length_m=rest, lambda1_n=tissue.cubic_ratio * lambda2, lambda2_n=lambda2,
                         mu_ns_per_m=mu, capsule_springs=capsule, parenchyma_springs=len(edges))


def equivalent_properties(mesh: TetMesh, parenchyma_lambda2_n: float, capsule_lambda2_n: float,
                          parenchyma_mu_ns_per_m: float = 0.0, capsule_mu_ns_per_m: float = 0.0) -> dict:
    """The tissue properties that uniform per-spring constants (params.SpringLaw style) amount to on `mesh`:
    E = λ2·Σ l0/(6·V), Y = λ2·Σ l0/(3·A) over the skin edges, η = μ·Σ l0²/(6·V),
    η_s = μ·Σ l0²/(3·A)."""
    points = mesh.points
    rest = np.linalg.norm(points[mesh.edges[:, 1]] - points[mesh.edges[:, 0]], axis=1)
    skin = mesh.skin_edges
    skin_rest = np.linalg.norm(points[skin[:, 1]] - points[skin[:, 0]], axis=1)
    volume, area = mesh.volume, float(triangle_areas(points, mesh.skin).sum())
    return {
        "parenchyma_young_modulus_pa": parenchyma_lambda2_n * rest.sum() / (6.0 * volume),
        "parenchyma_viscosity_pa_s": parenchyma_mu_ns_per_m * (rest ** 2).sum() / (6.0 * volume),
        "capsule_stiffness_n_per_m": capsule_lambda2_n * skin_rest.sum() / (3.0 * area),
        "capsule_viscosity_ns_per_m": capsule_mu_ns_per_m * (skin_rest ** 2).sum() / (3.0 * area),
    }
