"""Model constants: the tissue (or the paper's spring laws), the integrator and the scene (paper P2–P8, P10:
docs/paper.md; materials: docs/materials.md).

Every quantity is in SI units (the modulus in kPa); the field names carry them.  `validate()` refuses
out-of-range values with a ValueError that names the parameter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

#: The integrators and their steps per 150 Hz frame when `substeps` is not given: linearised backward
#: Euler is stable at one step per frame; the explicit ones need steps under the parenchyma's viscous stability
#: bound (physics.tissue.springs.stable_time_step), a fraction of a millisecond on the default liver.
INTEGRATOR_SUBSTEPS = {"implicit_euler": 1, "symplectic_euler": 72, "explicit_euler": 72}
INTEGRATORS = tuple(INTEGRATOR_SUBSTEPS)
#: Where the springs' λ1, λ2, μ come from: the tissue's properties and the mesh (physics.tissue.materials), or the
#: paper's per-spring constants (`capsule`, `parenchyma`; its figures and the traction test R1).
SPRING_CONSTANTS = ("material", "paper")
#: The parenchyma's law: 'springs', the paper's Eq. 1 springs on the tet edges (physics.tissue.springs,
#: physics.tissue.materials); 'fem', co-rotational linear tetrahedra with the tissue's E, ν and η
#: (physics.tissue.fem_kernels; implicit integrator and material constants only).  The capsule is Eq. 1 springs on the
#: skin edges with either.
TISSUE_LAWS = ("springs", "fem")
#: How the tool meets the skin (contact.tool_geometry.contact_rows): 'probe', Eq. 3 as the paper has it, one penalty λ
#: per contact probe at its closest points; 'surface', a ball meets the skin as a surface, a penalty per unit area at
#: every skin node and face it presses (implicit integrator only).
CONTACT_MODELS = ("probe", "surface")
#: The preconditioners of the implicit step's PCG (physics.solver.pcg): 'block_jacobi', 'two_level' (block-Jacobi plus
#: the coarse correction of physics.solver.coarse_space), or 'auto': two-level on livers of implicit.TWO_LEVEL_MIN_NODES
#: nodes and more.  Each keeps the answer within the solver's tolerance; they differ in iterations.
PRECONDITIONERS = ("auto", "block_jacobi", "two_level")
#: The threads of the numba kernels of a frame (the explicit spring pass, the implicit step's PCG): 'auto', all of
#: numba's from structure.PARALLEL_MIN_EDGES springs on (fastest alone on the machine); 'one' (beside 1 kHz loops on
#: two cores, where the threads wait for each other); 'all'.
SOLVER_THREADS = ("auto", "one", "all")
#: How the liver is held (physics.tissue.organ_support): 'organ' (anchored where a liver is held) or 'paper'
#: (§3.1's scene).
SUPPORTS = ("organ", "paper")
#: The default liver's supports (physics.tissue.organ_support), spheres (x, y, z, radius; m) with a stiffness per unit
#: skin area (N/m³), LPS axes (+x left, +y posterior, +z superior; liver_sim.mesh.liver_shape): the bare area
#: (posterior-superior face of the right lobe, fused to the diaphragm by the coronary ligament) and the
#: inferior vena cava's groove (posterior, between the lobes), stiff; the left triangular ligament
#: (posterior-superior edge of the left lobe); and the viscera the visceral face rests on (liver_shape's
#: sphere carving it, 5 mm wider), soft.
DEFAULT_SUPPORT_REGIONS = (
    (-0.06, 0.065, 0.025, 0.03, 1.0e6),
    (-0.01, 0.05, 0.035, 0.025, 1.0e6),
    (-0.01, 0.05, 0.0, 0.025, 1.0e6),
    (0.09, 0.02, 0.02, 0.025, 2.0e5),
    (-0.0001, 0.173, -0.2621, 0.305, 2.0e4),
)


@dataclass(frozen=True)
class SpringLaw:
    """Eq. 1: F = λ1·d³ + λ2·d + μ·ṗ, d = (l − l0)/l0, ṗ the elongation rate (m/s).

    λ1 and λ2 are forces (N) since d is dimensionless; μ is in N·s/m.
    """

    lambda1_n: float
    lambda2_n: float
    mu_ns_per_m: float

    def force_n(self, strain, strain_rate_m_s=0.0):
        """Tension (N, positive pulls the two nodes together) for strain d and elongation rate ṗ."""
        return self.lambda1_n * strain ** 3 + self.lambda2_n * strain + self.mu_ns_per_m * strain_rate_m_s


#: Fig. 2 of the paper plots Eq. 1 with these stiffnesses.
FIG2_LAW = SpringLaw(lambda1_n=50.0, lambda2_n=0.35, mu_ns_per_m=0.0)
#: Fig. 2's cubic-to-linear stiffness ratio λ1/λ2.
CUBIC_RATIO = FIG2_LAW.lambda1_n / FIG2_LAW.lambda2_n


@dataclass(frozen=True)
class TissueProperties:
    """Continuum properties of the liver; physics.tissue.materials derives every spring's Eq. 1 coefficients from
    them and the mesh.  Defaults and their sources: docs/materials.md.

    Parenchyma: Young's modulus (kPa), Poisson's ratio (the network matches the tissue's indentation
    modulus E/(1 − ν²), see materials.network_young_modulus_pa) and viscosity (Pa·s, Kelvin–Voigt).
    Capsule: a membrane of stiffness E·t (N/m) and viscosity η·t (N·s/m).  `cubic_ratio`: λ1/λ2 (Fig. 2).
    """

    parenchyma_young_modulus_kpa: float = 2.0
    parenchyma_poisson_ratio: float = 0.45
    parenchyma_viscosity_pa_s: float = 500.0
    capsule_stiffness_n_per_m: float = 500.0
    capsule_viscosity_ns_per_m: float = 0.025
    cubic_ratio: float = CUBIC_RATIO

    def validate(self) -> "TissueProperties":
        """Return self, or raise ValueError naming the first value out of range (finite and >= 0;
        Poisson's ratio in [0, 0.5))."""
        for f in fields(self):
            value = getattr(self, f.name)
            numeric = isinstance(value, (int, float)) and not isinstance(value, bool)
            if not (numeric and math.isfinite(value) and value >= 0.0):
                raise ValueError(f"parameter {f.name} must be finite and >= 0, got {value!r}")
        if not self.parenchyma_poisson_ratio < 0.5:
            raise ValueError("parameter parenchyma_poisson_ratio must be in [0, 0.5), "
                             f"got {self.parenchyma_poisson_ratio!r}")
        return self


@dataclass(frozen=True)
class ModelParams:
    """Constants of one simulated liver.  Defaults reproduce the paper's scene (P8).

    The capsule (Glisson's capsule, skin triangle edges) is stiff and barely viscous;
    the parenchyma (tet edges) is soft and strongly viscous (P6).  Both keep Fig. 2's
    cubic-to-linear ratio λ1/λ2 ≈ 143, linear below ~10 % strain.  With `spring_constants`
    'material' (default) the springs' coefficients come from `tissue` and the mesh, so a finer
    mesh of the same liver is as stiff; with 'paper', every spring has the paper's per-spring
    `capsule` and `parenchyma` laws (forces, so a finer mesh is stiffer).
    `substeps` None: the integrator's own (INTEGRATOR_SUBSTEPS); `with_changes(integrator=…)` without
    `substeps` takes the new integrator's.
    `support` 'organ' (default): the capsule nodes inside `support_regions` (spheres x, y, z, radius in m,
    each with a stiffness per unit skin area in N/m³) are tied to their rest positions, with damping
    `support_damping_s` × stiffness (physics.tissue.organ_support); no node is fixed unless `fixed_nodes` says so;
    'paper': §3.1's scene, `fixed_nodes` None fixes the central tet (as it does when the regions hold no
    capsule node).
    `tissue_law` 'springs' (default): the parenchyma is Eq. 1 springs on the tet edges; 'fem': co-rotational linear
    tetrahedra with the tissue's E, ν (up to 0.499) and Kelvin–Voigt η (physics.tissue.fem_kernels), the capsule staying
    springs (implicit integrator and material constants only).
    `contact_model` 'probe' (default): Eq. 3 with one penalty `contact_stiffness_n_per_m` per contact probe;
    'surface': a ball tool (sphere, capsule) meets the skin as a surface, `contact_stiffness_per_area_n_per_m3` per
    unit area of every node and face it presses (contact.tool_geometry.contact_rows; implicit integrator only).
    `preconditioner`: the implicit step's PCG preconditioner (PRECONDITIONERS; 'auto' by default).
    `solver_threads`: the threads of a frame's kernels (SOLVER_THREADS; 'auto' by default).
    With `tearing`, an interior face whose stretch across it exceeds `tear_strain_parenchyma`
    (`tear_strain_capsule` for a face with an edge on the capsule) opens (P13, §2.6).
    """

    spring_constants: str = "material"
    tissue_law: str = "springs"
    tissue: TissueProperties = TissueProperties()
    capsule: SpringLaw = SpringLaw(lambda1_n=1430.0, lambda2_n=10.0, mu_ns_per_m=0.02)
    parenchyma: SpringLaw = SpringLaw(lambda1_n=71.5, lambda2_n=0.5, mu_ns_per_m=5.0)
    density_kg_m3: float = 1060.0
    min_node_mass_fraction: float = 0.4
    environment_damping_per_s: float = 3.0
    gravity_m_s2: tuple = (0.0, 0.0, 0.0)
    integrator: str = "implicit_euler"
    frame_rate_hz: float = 150.0
    substeps: int | None = None
    fixed_nodes: tuple | None = None
    support: str = "organ"
    support_regions: tuple = DEFAULT_SUPPORT_REGIONS
    support_damping_s: float = 0.01
    contact_stiffness_n_per_m: float = 300.0
    contact_damping_ns_per_m: float = 1.0
    contact_model: str = "probe"
    contact_stiffness_per_area_n_per_m3: float = 3.0e7
    max_node_speed_m_s: float = 20.0
    tearing: bool = False
    tear_strain_parenchyma: float = 0.4
    tear_strain_capsule: float = 0.5
    preconditioner: str = "auto"
    solver_threads: str = "auto"

    def __post_init__(self):
        if self.substeps is None and self.integrator in INTEGRATOR_SUBSTEPS:
            object.__setattr__(self, "substeps", INTEGRATOR_SUBSTEPS[self.integrator])

    @property
    def dt_s(self) -> float:
        """Integration time step: one frame divided into `substeps`."""
        return 1.0 / (self.frame_rate_hz * self.substeps)

    def with_changes(self, **changes) -> "ModelParams":
        """A validated copy with some fields replaced (a new integrator without `substeps`: its own)."""
        if "integrator" in changes and "substeps" not in changes:
            changes["substeps"] = None
        return replace(self, **changes).validate()

    def validate(self) -> "ModelParams":
        """Return self, or raise ValueError naming the first out-of-range parameter."""
        for name, law in (("capsule", self.capsule), ("parenchyma", self.parenchyma)):
            for f in fields(law):
                value = getattr(law, f.name)
                if not (math.isfinite(value) and value >= 0.0):
                    raise ValueError(f"parameter {name}.{f.name} must be finite and >= 0, got {value!r}")
        positive = {
            "density_kg_m3": self.density_kg_m3,
            "frame_rate_hz": self.frame_rate_hz,
            "max_node_speed_m_s": self.max_node_speed_m_s,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"parameter {name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.min_node_mass_fraction) and 0.0 <= self.min_node_mass_fraction <= 1.0):
            raise ValueError("parameter min_node_mass_fraction must be in [0, 1], "
                             f"got {self.min_node_mass_fraction!r}")
        non_negative = {
            "environment_damping_per_s": self.environment_damping_per_s,
            "contact_stiffness_n_per_m": self.contact_stiffness_n_per_m,
            "contact_damping_ns_per_m": self.contact_damping_ns_per_m,
            "contact_stiffness_per_area_n_per_m3": self.contact_stiffness_per_area_n_per_m3,
            "support_damping_s": self.support_damping_s,
        }
        for name, value in non_negative.items():
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"parameter {name} must be finite and >= 0, got {value!r}")
        if self.spring_constants not in SPRING_CONSTANTS:
            raise ValueError(f"parameter spring_constants must be one of {SPRING_CONSTANTS}, "
                             f"got {self.spring_constants!r}")
        self.tissue.validate()
        if self.tissue_law not in TISSUE_LAWS:
            raise ValueError(f"parameter tissue_law must be one of {TISSUE_LAWS}, got {self.tissue_law!r}")
        if self.tissue_law == "fem" and (self.integrator != "implicit_euler" or self.spring_constants != "material"):
            raise ValueError("parameter tissue_law 'fem' needs integrator 'implicit_euler' and spring_constants "
                             f"'material', got {self.integrator!r} and {self.spring_constants!r}")
        if self.contact_model not in CONTACT_MODELS:
            raise ValueError(f"parameter contact_model must be one of {CONTACT_MODELS}, got {self.contact_model!r}")
        if self.contact_model == "surface" and self.integrator != "implicit_euler":
            raise ValueError("parameter contact_model 'surface' needs integrator 'implicit_euler', "
                             f"got {self.integrator!r}")
        if self.support not in SUPPORTS:
            raise ValueError(f"parameter support must be one of {SUPPORTS}, got {self.support!r}")
        regions = np.asarray(self.support_regions, dtype=np.float64)
        if (regions.ndim != 2 or regions.shape[1] != 5 or not np.isfinite(regions).all()
                or (regions[:, 3:] < 0).any()):
            raise ValueError("parameter support_regions must be rows (x, y, z, radius m, stiffness N/m³) of finite "
                             f"numbers, radius and stiffness >= 0, got {self.support_regions!r}")
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"parameter integrator must be one of {INTEGRATORS}, got {self.integrator!r}")
        if not (isinstance(self.substeps, int) and 1 <= self.substeps <= 10_000):
            raise ValueError(f"parameter substeps must be an integer in 1..10000, got {self.substeps!r}")
        if self.solver_threads not in SOLVER_THREADS:
            raise ValueError(f"parameter solver_threads must be one of {SOLVER_THREADS}, got {self.solver_threads!r}")
        if self.preconditioner not in PRECONDITIONERS:
            raise ValueError(f"parameter preconditioner must be one of {PRECONDITIONERS}, got {self.preconditioner!r}")
        if not isinstance(self.tearing, bool):
            raise ValueError(f"parameter tearing must be True or False, got {self.tearing!r}")
        for name in ("tear_strain_parenchyma", "tear_strain_capsule"):
            value = getattr(self, name)
            numeric = isinstance(value, (int, float)) and not isinstance(value, bool)
            if not (numeric and math.isfinite(value) and value > 0.0):
                raise ValueError(f"parameter {name} must be finite and > 0, got {value!r}")
        if len(self.gravity_m_s2) != 3 or not all(math.isfinite(g) for g in self.gravity_m_s2):
            raise ValueError(f"parameter gravity_m_s2 must be three finite numbers, got {self.gravity_m_s2!r}")
        return self
