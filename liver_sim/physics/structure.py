"""The liver's structure (paper §2): what a frame reads and never changes — the mesh, the springs on it, the
support, the masses and fixed nodes, the settings, and the integrators' arrays sized by the topology.

A tear or a cut replaces the structure whole (`changed_structure`: the new one is built beside the old, which
nothing touches), as a static model `m` beside a changing state `d` (MuJoCo MJX); the state it is stepped with
is liver_sim.physics.state.State.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np

from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.settings import CONTINUUM_LAWS, ModelParams
from liver_sim.physics.solver.explicit_kernels import StepSettings, WorkArrays
from liver_sim.physics.solver.implicit import ImplicitEuler
from liver_sim.physics.tissue.fem_kernels import build_tets
from liver_sim.physics.tissue.organ_support import SupportArrays, build_support, node_areas_m2
from liver_sim.physics.tissue.spring_law import SpringArrays, spring_arrays
from liver_sim.physics.tissue.springs import SpringNetwork, build_springs, estimate_stable_time_step, stable_time_step
from liver_sim.physics.topology.tearing import TearDetector

#: Above this many springs the parallel kernel is used (below it thread start-up costs more).
PARALLEL_MIN_EDGES = 20_000
#: 'auto' takes all threads only on this many cores or more: a rig's 1 kHz loops (bridge, device, tool) keep about a
#: core busy, and on two cores the frame's threads wait for each other beside them (docs/performance.md).
AUTO_PARALLEL_MIN_CORES = 4
#: After a topology change the substeps are raised, when needed, to keep dt under this share of the bound.
STABILITY_MARGIN = 0.9
#: The most substeps a topology change may raise a frame to.
MAX_SUBSTEPS = 10_000


def default_fixed_nodes(mesh: TetMesh) -> np.ndarray:
    """The four nodes of the tet whose centroid is nearest the mesh's volume centroid (paper §3.1)."""
    centroids = mesh.points[mesh.tets].mean(axis=1)
    centre = (centroids * mesh.volumes[:, None]).sum(axis=0) / mesh.volume
    return np.sort(mesh.tets[np.argmin(np.linalg.norm(centroids - centre, axis=1))])


def scaled_masses(masses_kg: np.ndarray, min_fraction: float) -> np.ndarray:
    """Lumped masses raised to at least `min_fraction` × their mean, then rescaled to the same total.

    Mass scaling for the explicit step: the stable time step goes with √m of the lightest nodes,
    which isosurface stuffing makes small at the skin; the organ's mass (paper P2, docs/paper.md) is unchanged.
    """
    floored = np.maximum(masses_kg, min_fraction * masses_kg.mean())
    return floored * (masses_kg.sum() / floored.sum())


@dataclass(frozen=True, eq=False)
class Structure:
    """One topology of the liver and everything that depends on it alone.

    `mesh` (its rest points, m), `capsule_triangles` (the skin triangles carrying capsule springs: the whole skin
    until a tear or a cut opens faces), lumped `masses_kg` (N,), sorted `fixed_nodes`, the Eq. 1 `springs` (and
    `spring_arrays`, their kernel form), the `support` ties (physics.tissue.organ_support), the `params` (their
    `substeps` raised after a change when an explicit integrator needs it), `parallel` (the explicit kernel and the
    implicit
    step's PCG on all threads),
    `stable_dt_s` (the explicit step's bound; inf for the implicit integrator), `version` (0, then one more per
    change); the work arrays of the explicit kernels (`work`) and the implicit integrator (`solver`), whose
    contents are scratch, overwritten by every step.
    """

    mesh: TetMesh
    params: ModelParams
    capsule_triangles: np.ndarray
    masses_kg: np.ndarray
    fixed_nodes: np.ndarray
    springs: SpringNetwork
    spring_arrays: SpringArrays
    support: SupportArrays
    parallel: bool
    stable_dt_s: float
    version: int
    work: WorkArrays
    solver: ImplicitEuler

    @property
    def implicit(self) -> bool:
        """True when the integrator is linearised backward Euler (no stability bound on the step)."""
        return self.params.integrator == "implicit_euler"

    @property
    def step_solver(self) -> str:
        """What steps the liver: the implicit step's solver (ImplicitEuler.solver), else the explicit integrator."""
        return self.solver.solver if self.implicit else self.params.integrator

    @property
    def frame_period_s(self) -> float:
        return 1.0 / self.params.frame_rate_hz

    @property
    def node_count(self) -> int:
        return len(self.mesh.points)

    @cached_property
    def skin(self) -> np.ndarray:
        """The skin triangles (K, 3) as the contact kernels take them (contiguous int64)."""
        return np.ascontiguousarray(self.mesh.skin, dtype=np.int64)

    @cached_property
    def skin_node_area_m2(self) -> np.ndarray:
        """Per node, a third of the area of the skin triangles around it at rest (m², 0 off the skin): its share of
        the tool's contact (contact.tool_geometry.contact_rows)."""
        return node_areas_m2(self.mesh.points, self.mesh.skin)

    @cached_property
    def step_settings(self) -> StepSettings:
        """The explicit kernels' settings of one frame."""
        p = self.params
        return StepSettings(p.dt_s, p.substeps, p.environment_damping_per_s, np.asarray(p.gravity_m_s2, np.float64),
                            p.integrator == "symplectic_euler")

    @cached_property
    def tear_detector(self) -> TearDetector:
        """The interior faces of this mesh and their tearing thresholds (physics.topology.tearing)."""
        p = self.params
        return TearDetector(self.mesh.points, self.mesh.tets, self.capsule_triangles, p.tear_strain_parenchyma,
                            p.tear_strain_capsule)


def auto_parallel(springs: int, cores: int) -> bool:
    """solver_threads 'auto': all threads from PARALLEL_MIN_EDGES `springs` on, on AUTO_PARALLEL_MIN_CORES `cores`
    or more (the bits are the same either way: physics.solver.pcg)."""
    return springs >= PARALLEL_MIN_EDGES and cores >= AUTO_PARALLEL_MIN_CORES


def build_structure(mesh: TetMesh, params: ModelParams, capsule_triangles: np.ndarray, masses_kg: np.ndarray,
                    fixed_nodes: np.ndarray, parallel: bool | None = None, version: int = 0) -> Structure:
    """The Structure of these parts: the springs and support built on `mesh` and `capsule_triangles`, and the
    integrators' arrays for them; `parallel` None: as params.solver_threads says ('auto': `auto_parallel`); a
    change passes its structure's, so that it keeps its threads.

    The explicit step's bound: exact (springs.stable_time_step) for the first structure (`version` 0); after a
    change (`version` > 0) its estimate, and when dt exceeds STABILITY_MARGIN of it (new short springs or light
    nodes) the substeps are raised to ⌈frame period / (STABILITY_MARGIN·bound)⌉ (at most MAX_SUBSTEPS); the
    implicit integrator keeps its steps (no bound)."""
    capsule = np.ascontiguousarray(capsule_triangles, dtype=np.int64).reshape(-1, 3)
    springs = build_springs(mesh, params, capsule_triangles=capsule)
    support = build_support(mesh, capsule, params)
    if parallel is None:
        parallel = {"one": False, "all": True}.get(params.solver_threads,
                                                  auto_parallel(springs.edges, len(os.sched_getaffinity(0))))
    parallel = bool(parallel)
    damping, integrator = params.environment_damping_per_s, params.integrator
    if integrator == "implicit_euler":
        bound = math.inf
    elif version == 0:
        bound = stable_time_step(springs, masses_kg, damping, integrator, mesh.points, support)
    else:
        bound = estimate_stable_time_step(springs, masses_kg, damping, integrator, mesh.points, support=support)
    if version and params.dt_s > STABILITY_MARGIN * bound:
        needed = math.ceil((1.0 / params.frame_rate_hz) / (STABILITY_MARGIN * bound))
        params = params.with_changes(substeps=min(needed, MAX_SUBSTEPS))
    threads = numba.get_num_threads() if parallel else 1
    n = len(mesh.points)
    tissue = params.tissue
    tets = None
    if params.tissue_law in CONTINUUM_LAWS:
        tets = build_tets(mesh.points, mesh.tets, tissue.parenchyma_young_modulus_kpa * 1e3,
                          tissue.parenchyma_poisson_ratio, tissue.parenchyma_viscosity_pa_s,
                          neo_hookean=params.tissue_law == "neo_hookean")
    return Structure(mesh, params, capsule, masses_kg, fixed_nodes, springs,
                     spring_arrays(springs),
                     support, parallel, bound, version,
                     WorkArrays(np.zeros((n, 3)), np.zeros((threads, n, 3)), parallel),
                     ImplicitEuler(springs, n, support=support, tets=tets, preconditioner=params.preconditioner,
                                   threads=threads))


def initial_structure(mesh: TetMesh, params: ModelParams | None = None) -> Structure:
    """The structure of `mesh` with its whole skin as capsule: masses lumped at params.density_kg_m3 (scaled_masses);
    fixed nodes params.fixed_nodes, or when None the paper's central tet unless the organ's support holds the liver
    (params.support 'organ' with capsule nodes in its regions: then none).  ValueError naming the parameter for
    fixed nodes outside the mesh."""
    params = (params or ModelParams()).validate()
    masses = scaled_masses(mesh.lumped_masses(params.density_kg_m3), params.min_node_mass_fraction)
    fixed = params.fixed_nodes
    if fixed is None:  # the paper's scene, unless the organ's support holds the liver
        held = len(build_support(mesh, mesh.skin, params).nodes) > 0
        fixed = np.zeros(0, np.int64) if held else default_fixed_nodes(mesh)
    fixed = np.unique(np.asarray(fixed, np.int64))
    if fixed.size and (fixed.min() < 0 or fixed.max() >= len(mesh.points)):
        raise ValueError(f"parameter fixed_nodes must index nodes 0..{len(mesh.points) - 1}")
    return build_structure(mesh, params, mesh.skin, masses, fixed)
