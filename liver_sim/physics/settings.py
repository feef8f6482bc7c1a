"""Model constants: the tissue (or the paper's spring laws), the integrator and the scene (paper P2–P8, P10:
docs/paper.md; materials: docs/materials.md).

Every quantity is in SI units (the modulus in kPa); the field names carry them.  `validate()` refuses
out-of-range values with a ValueError that names the parameter.

Each field the physics node exposes is declared once, here, with its description, range or choices
(`declared`); the node's table of those parameters and the record they name are derived from these declarations
(`node_parameters`, `from_node_values`; liver_sim.physics.parameters).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, fields, replace

import numpy as np

from liver_sim.base.parameters import Param

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
#: (physics.tissue.fem_kernels); 'neo_hookean', stable neo-Hookean tetrahedra with the same constants
#: (physics.tissue.neo_hookean).  The two continuum laws need the implicit integrator and material constants.  The
#: capsule is Eq. 1 springs on the skin edges with any.
TISSUE_LAWS = ("springs", "fem", "neo_hookean")
#: The laws whose parenchyma is tetrahedra (physics.tissue.fem_kernels.TetArrays) rather than springs.
CONTINUUM_LAWS = ("fem", "neo_hookean")
#: How the tool meets the skin (contact.tool_geometry.contact_rows): 'probe', Eq. 3 as the paper has it, one penalty λ
#: per contact probe at its closest points; 'surface', a ball meets the skin as a surface, a penalty per unit area at
#: every skin node and face it presses (implicit integrator only).
CONTACT_MODELS = ("probe", "surface")
#: The preconditioners of the implicit step's PCG (physics.solver.pcg): 'block_jacobi', 'two_level' (block-Jacobi plus
#: the coarse correction of physics.solver.coarse_space), or 'auto': two-level on livers of implicit.TWO_LEVEL_MIN_NODES
#: nodes and more.  Each keeps the answer within the solver's tolerance; they differ in iterations.
PRECONDITIONERS = ("auto", "block_jacobi", "two_level")
#: The threads of the numba kernels of a frame (the explicit spring pass, the implicit step's assembly and PCG):
#: 'auto', all of numba's from structure.PARALLEL_MIN_EDGES springs on, on four cores or more (structure.auto_parallel:
#: beside the 1 kHz loops on two cores the threads wait for each other); 'one'; 'all' (fastest alone on the
#: machine).  The same bits whichever.
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


#: The key of a field's NodeParameter in its metadata; a nested record's field holds its parameters' name prefix under
#: NODE_RECORD.
NODE, NODE_RECORD = "node_parameter", "node_record"


@dataclass(frozen=True)
class NodeParameter:
    """How a model field is a parameter of the physics node: its `description` (with its unit), range `low`..`high`
    (what the node accepts; ModelParams.validate checks only what the model needs, a wider range) or `choices`, its
    `name` there (None: the field's), and its value there and back (`to_node`, `from_node`: the identity unless the
    node's form differs, e.g. None as 0)."""

    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple | None = None
    name: str | None = None
    to_node: Callable | None = None
    from_node: Callable | None = None


def declared(default=MISSING, *, description: str, low: float | None = None, high: float | None = None,
             choices: tuple | None = None, name: str | None = None, to_node: Callable | None = None,
             from_node: Callable | None = None):
    """A dataclass field with `default` (none if not given), declared as a parameter of the physics node
    (NodeParameter; `{record}` in its description: the record's name, for a record nested twice)."""
    return field(default=default, metadata={NODE: NodeParameter(description, low, high, choices, name, to_node,
                                                                from_node)})


def nested(default, prefix: str):
    """A dataclass field holding a record whose declared fields are node parameters named `prefix` + their name."""
    return field(default=default, metadata={NODE_RECORD: prefix})


def _flat_regions(regions) -> list:
    return [float(v) for region in regions for v in region]


def _grouped_regions(values) -> tuple:
    values = list(values)
    if len(values) % 5:
        raise ValueError(f"parameter support_regions must hold five numbers per region (x, y, z, radius m, "
                         f"stiffness N/m³), got {len(values)} numbers")
    return tuple(tuple(values[i:i + 5]) for i in range(0, len(values), 5))


@dataclass(frozen=True)
class SpringLaw:
    """Eq. 1: F = λ1·d³ + λ2·d + μ·ṗ, d = (l − l0)/l0, ṗ the elongation rate (m/s).

    λ1 and λ2 are forces (N) since d is dimensionless; μ is in N·s/m.
    """

    lambda1_n: float = declared(description="paper: {record} cubic stiffness λ1 of Eq. 1 (N)", low=0.0, high=1e6)
    lambda2_n: float = declared(description="paper: {record} linear stiffness λ2 of Eq. 1 (N)", low=0.0, high=1e6)
    mu_ns_per_m: float = declared(description="paper: {record} viscosity μ of Eq. 1 (N·s/m)", low=0.0, high=1e4)

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

    parenchyma_young_modulus_kpa: float = declared(2.0, description="parenchyma Young's modulus (kPa)", low=0.01,
                                                   high=1e4)
    parenchyma_poisson_ratio: float = declared(0.45, description="parenchyma Poisson's ratio (the network matches the "
                                               "indentation modulus E/(1-ν²))", low=0.0, high=0.499)
    parenchyma_viscosity_pa_s: float = declared(500.0, description="parenchyma viscosity η (Pa·s)", low=0.0, high=1e6)
    capsule_stiffness_n_per_m: float = declared(500.0, description="capsule membrane stiffness E·t (N/m)", low=0.0,
                                                high=1e6)
    capsule_viscosity_ns_per_m: float = declared(0.025, description="capsule membrane viscosity η·t (N·s/m)",
                                                 low=0.0, high=1e4)
    cubic_ratio: float = declared(CUBIC_RATIO, description="material: λ1/λ2 of Eq. 1 on every spring (dimensionless; "
                                  "Fig. 2's 143 by default, 0: linear springs)", low=0.0, high=1e5)

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
    tetrahedra with the tissue's E, ν (up to 0.499) and Kelvin–Voigt η (physics.tissue.fem_kernels); 'neo_hookean':
    stable neo-Hookean tetrahedra (hyperelastic, Hooke's law with the same E, ν at small strain, defined through
    inversion) with the same constants (physics.tissue.neo_hookean); with either the capsule stays springs (implicit
    integrator and material constants only).
    `contact_model` 'probe' (default): Eq. 3 with one penalty `contact_stiffness_n_per_m` per contact probe;
    'surface': a ball tool (sphere, capsule) meets the skin as a surface, `contact_stiffness_per_area_n_per_m3` per
    unit area of every node and face it presses (contact.tool_geometry.contact_rows; implicit integrator only).
    `preconditioner`: the implicit step's PCG preconditioner (PRECONDITIONERS; 'auto' by default).
    `solver_threads`: the threads of a frame's kernels (SOLVER_THREADS; 'auto' by default).
    With `tearing`, an interior face whose stretch across it exceeds `tear_strain_parenchyma`
    (`tear_strain_capsule` for a face with an edge on the capsule) opens (P13, §2.6).
    """

    spring_constants: str = declared("material", description="material: each spring's λ1, λ2, μ from the tissue "
                                     "properties and the mesh; paper: the paper's per-spring constants below",
                                     choices=SPRING_CONSTANTS)
    tissue_law: str = declared("springs", description="the parenchyma: springs (Eq. 1 on the tet edges, the paper's) "
                               "or fem (co-rotational linear tetrahedra with parenchyma E, ν and η) or neo_hookean "
                               "(stable neo-Hookean tetrahedra, the same constants); the last two implicit_euler and "
                               "material only", choices=TISSUE_LAWS)
    tissue: TissueProperties = nested(TissueProperties(), "")
    capsule: SpringLaw = nested(SpringLaw(lambda1_n=1430.0, lambda2_n=10.0, mu_ns_per_m=0.02), "capsule_")
    parenchyma: SpringLaw = nested(SpringLaw(lambda1_n=71.5, lambda2_n=0.5, mu_ns_per_m=5.0), "parenchyma_")
    density_kg_m3: float = declared(1060.0, description="tissue density for the lumped masses (kg/m³)", low=1.0,
                                    high=1e5)
    min_node_mass_fraction: float = 0.4
    environment_damping_per_s: float = declared(3.0, description="environmental viscosity c: a −= c·v (1/s)",
                                                low=0.0, high=1e4)
    gravity_m_s2: tuple = declared((0.0, 0.0, 0.0), description="gravity vector in the liver frame (m/s²)",
                                   to_node=list, from_node=tuple)
    integrator: str = declared("implicit_euler", description="implicit_euler (linearised backward Euler), "
                               "symplectic_euler or explicit_euler (Eq. 2)", choices=INTEGRATORS)
    frame_rate_hz: float = declared(150.0, description="physics frame rate (Hz)", low=1.0, high=1000.0,
                                    name="rate_hz")
    substeps: int | None = declared(None, description="integration steps per frame; 0: the integrator's own ("
                                    + ", ".join(f"{k} {n}" for k, n in INTEGRATOR_SUBSTEPS.items()) + ")", low=0,
                                    high=10_000, to_node=lambda n: n or 0, from_node=lambda n: n or None)
    fixed_nodes: tuple | None = declared(None, description="indices of fixed nodes; [-1]: none with support organ (the "
                                         "central tet's four nodes if support_regions hold no skin node), the central "
                                         "tet's with support paper", to_node=lambda n: [-1] if n is None else list(n),
                                         from_node=lambda n: None if list(n) == [-1] else tuple(n))
    support: str = declared("organ", description="how the liver is held: organ (skin in support_regions tied to its "
                            "rest position) or paper (the four nodes of the tet nearest the centroid fixed, paper "
                            "§3.1)", choices=SUPPORTS)
    support_regions: tuple = declared(DEFAULT_SUPPORT_REGIONS, description="support organ: spheres, five numbers "
                                      "each: centre x, y, z (m, liver frame), radius (m), stiffness per unit skin area "
                                      "(N/m³); each skin node inside is tied to its rest position with that stiffness "
                                      "times its share of skin area (m²). Default: the default liver's bare area, vena "
                                      "cava, left triangular ligament, visceral bed", to_node=_flat_regions,
                                      from_node=_grouped_regions)
    support_damping_s: float = declared(0.01, description="support organ: damping of each tie over its stiffness (s, "
                                        "Kelvin-Voigt time constant)", low=0.0, high=10.0)
    contact_stiffness_n_per_m: float = declared(300.0, description="penalty λ of Eq. 3 (N/m)", low=0.0, high=1e6)
    contact_damping_ns_per_m: float = declared(1.0, description="penalty μ of Eq. 3 (N·s/m)", low=0.0, high=1e4)
    contact_model: str = declared("probe", description="probe: Eq. 3, one penalty per contact probe; surface: a sphere "
                                  "or capsule meets the skin as a surface, contact_stiffness_per_area_n_per_m3 at "
                                  "every node and face it presses (implicit_euler only)", choices=CONTACT_MODELS)
    contact_stiffness_per_area_n_per_m3: float = declared(3.0e7, description="contact_model surface: penalty per unit "
                                                          "skin area (N/m³, a pressure per metre of depth)", low=0.0,
                                                          high=1e10)
    max_node_speed_m_s: float = 20.0
    tearing: bool = declared(False, description="separate tetrahedra stretched beyond the tearing strains (paper "
                             "§2.6); the torn mesh is republished on surface_topic")
    tear_strain_parenchyma: float = declared(0.4, description="stretch across a face between two tets (mean normal "
                                             "strain, dimensionless) above which they separate", low=0.01, high=10.0)
    tear_strain_capsule: float = declared(0.5, description="the same for a face with an edge on the capsule "
                                          "(dimensionless)", low=0.01, high=10.0)
    preconditioner: str = "auto"
    solver_threads: str = declared("auto", description="threads of a frame's numba kernels (the implicit step's "
                                   "assembly and PCG, the explicit spring pass): auto (all from 20 000 springs on, "
                                   "on 4 cores or more), one or all", choices=SOLVER_THREADS)

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
        if self.tissue_law in CONTINUUM_LAWS and (self.integrator != "implicit_euler"
                                                  or self.spring_constants != "material"):
            raise ValueError(f"parameter tissue_law {self.tissue_law!r} needs integrator 'implicit_euler' and "
                             f"spring_constants 'material', got {self.integrator!r} and {self.spring_constants!r}")
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


def _declared_fields(record, prefix: str = "", label: str = ""):
    """(node name, NodeParameter, value, record label) of each declared field of `record` (an instance; a record
    class: its fields' defaults), the fields of nested records flattened under their prefix."""
    instance = not isinstance(record, type)
    for f in fields(record):
        value = getattr(record, f.name) if instance else f.default
        if NODE_RECORD in f.metadata:
            yield from _declared_fields(value, prefix + f.metadata[NODE_RECORD], f.name)
        elif NODE in f.metadata:
            spec = f.metadata[NODE]
            yield prefix + (spec.name or f.name), spec, value, label


def node_parameters() -> dict[str, Param]:
    """The physics node's parameters of ModelParams' declared fields (liver_sim.base.parameters.Param), their
    defaults the fields' defaults in the node's form."""
    return {name: Param(spec.to_node(value) if spec.to_node else value,
                        spec.description.replace("{record}", label), spec.low, spec.high, spec.choices)
            for name, spec, value, label in _declared_fields(ModelParams)}


def from_node_values(values, record_type: type | None = None, prefix: str = ""):
    """The ModelParams (validated) named by the node's parameters `values` (a mapping or a record holding the names
    of node_parameters()); the fields not declared keep their defaults."""
    record_type = record_type or ModelParams
    changes = {}
    for f in fields(record_type):
        if NODE_RECORD in f.metadata:
            changes[f.name] = from_node_values(values, type(f.default), prefix + f.metadata[NODE_RECORD])
        elif NODE in f.metadata:
            spec = f.metadata[NODE]
            name = prefix + (spec.name or f.name)
            value = values[name] if isinstance(values, Mapping) else getattr(values, name)
            changes[f.name] = spec.from_node(value) if spec.from_node else value
    record = record_type(**changes)
    return record.validate() if record_type is ModelParams else record
