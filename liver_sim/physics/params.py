"""Model constants: the spring laws of the capsule and the parenchyma, and the scene (paper P2–P8, P10: docs/paper.md).

Every quantity is in SI units; the field names carry them.  `validate()` refuses
out-of-range values with a ValueError that names the parameter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

INTEGRATORS = ("symplectic_euler", "explicit_euler")


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


@dataclass(frozen=True)
class ModelParams:
    """Constants of one simulated liver.  Defaults reproduce the paper's scene (P8).

    The capsule (Glisson's capsule, skin triangle edges) is stiff and barely viscous;
    the parenchyma (tet edges) is soft and strongly viscous (P6).  Both keep Fig. 2's
    cubic-to-linear ratio λ1/λ2 ≈ 143, linear below ~10 % strain.
    With `tearing`, an interior face whose stretch across it exceeds `tear_strain_parenchyma`
    (`tear_strain_capsule` for a face with an edge on the capsule) opens (P13, §2.6).
    """

    capsule: SpringLaw = SpringLaw(lambda1_n=1430.0, lambda2_n=10.0, mu_ns_per_m=0.02)
    parenchyma: SpringLaw = SpringLaw(lambda1_n=71.5, lambda2_n=0.5, mu_ns_per_m=5.0)
    density_kg_m3: float = 1060.0
    min_node_mass_fraction: float = 0.4
    environment_damping_per_s: float = 3.0
    gravity_m_s2: tuple = (0.0, 0.0, 0.0)
    integrator: str = "symplectic_euler"
    frame_rate_hz: float = 150.0
    substeps: int = 72
    fixed_nodes: tuple | None = None
    contact_stiffness_n_per_m: float = 300.0
    contact_damping_ns_per_m: float = 1.0
    max_node_speed_m_s: float = 20.0
    tearing: bool = False
    tear_strain_parenchyma: float = 0.4
    tear_strain_capsule: float = 0.5

    @property
    def dt_s(self) -> float:
        """Integration time step: one frame divided into `substeps`."""
        return 1.0 / (self.frame_rate_hz * self.substeps)

    def with_changes(self, **changes) -> "ModelParams":
        """A validated copy with some fields replaced."""
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
        }
        for name, value in non_negative.items():
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"parameter {name} must be finite and >= 0, got {value!r}")
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"parameter integrator must be one of {INTEGRATORS}, got {self.integrator!r}")
        if not (isinstance(self.substeps, int) and 1 <= self.substeps <= 10_000):
            raise ValueError(f"parameter substeps must be an integer in 1..10000, got {self.substeps!r}")
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
