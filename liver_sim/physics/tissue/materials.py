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

Poisson's ratio.  A network of central springs is a Cauchy solid: its own ν is 1/4 (3-D) and 1/3
(membrane) whatever its constants, and liver (ν ≈ 0.45–0.5) would need a volume term to do better.  So ν
chooses which modulus the network matches: the one a tool feels.  A rigid sphere pressed into an elastic
body meets the force F = (4/3)·E/(1 − ν²)·√R·δ^(3/2) (Hertz), so the network gets the Young's modulus
E_network = E·(1 − 1/16)/(1 − ν²) that gives the tissue's indentation modulus E/(1 − ν²) at the
network's ν = 1/4 (`network_young_modulus_pa`; at ν = 1/4 it is E).  Its shear modulus is 0.4·E_network.

Check: the paper's per-spring constants (params.py: λ2 = 0.5 N parenchyma, 10 N capsule) read back
with `equivalent_properties` on the default liver as E ≈ 2.1 kPa and E·t ≈ 585 N/m, and η ≈ 506 Pa·s,
η·t ≈ 0.026 N·s/m.  Defaults (params.TissueProperties) and their sources: docs/materials.md.
"""
from __future__ import annotations

import numpy as np

from liver_sim.mesh.tetmesh import TET_EDGES, TRIANGLE_EDGES, TetMesh, edge_keys, signed_volumes
from liver_sim.physics.settings import TissueProperties

#: The Poisson's ratio of a central-spring network (a Cauchy solid).
NETWORK_POISSON_RATIO = 0.25


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


def network_young_modulus_pa(tissue: TissueProperties) -> float:
    """The network's Young's modulus (Pa) whose indentation modulus at ν = 1/4 is the tissue's:
    E·(1 − ¼²)/(1 − ν²) (Hertz; see the module docstring)."""
    return (tissue.parenchyma_young_modulus_kpa * 1e3 * (1.0 - NETWORK_POISSON_RATIO ** 2)
            / (1.0 - tissue.parenchyma_poisson_ratio ** 2))


def material_coefficients(mesh: TetMesh, tissue: TissueProperties, rest_points: np.ndarray | None = None,
                          capsule_triangles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 1's λ1 (N), λ2 (N) and μ (N·s/m) of each edge of `mesh` (mesh.edges order) from the tissue's
    properties: λ2 = (E_network·ΣV + Y·ΣA)/l0, μ = (η·ΣV + η_s·ΣA)/l0², λ1 = cubic_ratio·λ2 (capsule:
    the edges of `capsule_triangles`, default the skin)."""
    tissue = tissue.validate()
    rest, volume, area = edge_measures(mesh, rest_points, capsule_triangles)
    lambda2 = (network_young_modulus_pa(tissue) * volume + tissue.capsule_stiffness_n_per_m * area) / rest
    mu = (tissue.parenchyma_viscosity_pa_s * volume + tissue.capsule_viscosity_ns_per_m * area) / rest ** 2
    return tissue.cubic_ratio * lambda2, lambda2, mu


def equivalent_properties(mesh: TetMesh, parenchyma_lambda2_n: float, capsule_lambda2_n: float,
                          parenchyma_mu_ns_per_m: float = 0.0, capsule_mu_ns_per_m: float = 0.0) -> dict:
    """The tissue properties that uniform per-spring constants (params.SpringLaw style) amount to on `mesh`:
    E = λ2·Σ l0/(6·V) (the network's, ν = 1/4), Y = λ2·Σ l0/(3·A) over the skin edges, η = μ·Σ l0²/(6·V),
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
