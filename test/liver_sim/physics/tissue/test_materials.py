"""Tissue properties → spring coefficients: the formulas, the read-back of the current defaults, a bar that
recovers E, and mesh independence of a stretched liver (static equilibria by the implicit solver's equilibrium)."""
import math

import numpy as np
import pytest

from liver_sim.mesh.liver_shape import build_liver, default_liver
from liver_sim.physics.settings import CUBIC_RATIO, ModelParams, TissueProperties
from liver_sim.physics.solver import reference
from liver_sim.physics.solver.implicit import ImplicitEuler
from liver_sim.physics.tissue.materials import edge_measures, equivalent_properties, network_young_modulus_pa
from liver_sim.physics.tissue.springs import build_springs
from liver_sim.studies.traction import cylinder_mesh

from meshes import box_mesh


def material_springs(mesh, tissue=TissueProperties()):
    return build_springs(mesh, ModelParams(tissue=tissue))


def test_regular_tetrahedron_gets_lloyds_stiffness():
    # one regular tet of edge l: k = λ2/l = (√2/12)·E·l (Lloyd et al. 2007); no capsule
    from liver_sim.mesh import TetMesh
    l = 0.01
    points = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float) * l / math.sqrt(8)
    mesh = TetMesh.from_arrays(points, np.array([[0, 1, 2, 3]]))
    if np.linalg.det(points[1:] - points[0]) < 0:
        mesh = TetMesh.from_arrays(points, np.array([[0, 2, 1, 3]]))
    tissue = TissueProperties(parenchyma_young_modulus_kpa=3.0, parenchyma_poisson_ratio=0.25,
                              capsule_stiffness_n_per_m=0.0)
    springs = material_springs(mesh, tissue)
    np.testing.assert_allclose(springs.lambda2_n / springs.rest_length_m, math.sqrt(2) / 12 * 3000.0 * l)
    np.testing.assert_allclose(springs.lambda1_n, CUBIC_RATIO * springs.lambda2_n)


def test_edge_measures_sum_to_six_volumes_and_three_areas():
    mesh = box_mesh(3, 2, 2, 0.01)
    rest, volume, area = edge_measures(mesh)
    assert volume.sum() == pytest.approx(6 * mesh.volume)
    assert area.sum() == pytest.approx(3 * 2 * (0.03 * 0.02 + 0.03 * 0.02 + 0.02 * 0.02))
    assert (area[~np.isin(np.arange(len(rest)), np.flatnonzero(area))] == 0).all()


def test_current_defaults_read_back_as_known_moduli():
    params = ModelParams(spring_constants="paper")
    moduli = equivalent_properties(default_liver(), params.parenchyma.lambda2_n, params.capsule.lambda2_n)
    assert moduli["parenchyma_young_modulus_pa"] == pytest.approx(2.1e3, rel=0.03)
    assert moduli["capsule_stiffness_n_per_m"] == pytest.approx(585.0, rel=0.03)


def test_material_springs_read_back_their_properties_on_average():
    # uniform springs with the material springs' mean λ2·l0 read back as the tissue's E (same formula, inverted)
    mesh = default_liver()
    tissue = TissueProperties(capsule_stiffness_n_per_m=0.0, capsule_viscosity_ns_per_m=0.0)
    springs = material_springs(mesh, tissue)
    e = (springs.lambda2_n * springs.rest_length_m).sum() / (6 * mesh.volume)
    assert e == pytest.approx(network_young_modulus_pa(tissue))
    eta = (springs.mu_ns_per_m * springs.rest_length_m ** 2).sum() / (6 * mesh.volume)
    assert eta == pytest.approx(tissue.parenchyma_viscosity_pa_s)


def test_poisson_ratio_sets_the_indentation_modulus():
    # the network (ν = 1/4) is given E·(1 − 1/16)/(1 − ν²): the same E/(1 − ν²) as the tissue under a sphere
    for nu in (0.25, 0.45, 0.49):
        tissue = TissueProperties(parenchyma_young_modulus_kpa=4.0, parenchyma_poisson_ratio=nu)
        network = network_young_modulus_pa(tissue)
        assert network / (1 - 0.25 ** 2) == pytest.approx(4000.0 / (1 - nu ** 2))
    mesh = default_liver()
    soft, firm = (material_springs(mesh, TissueProperties(parenchyma_poisson_ratio=nu, capsule_stiffness_n_per_m=0.0))
                  for nu in (0.25, 0.45))
    np.testing.assert_allclose(firm.lambda2_n / soft.lambda2_n, (1 - 0.25 ** 2) / (1 - 0.45 ** 2))


def static_reaction(mesh, springs, pulled, fixed, displacement):
    """Static equilibrium (ImplicitEuler.equilibrium) with `fixed` nodes held at rest and `pulled` nodes moved
    by `displacement` (m): the force the springs pull `pulled` back with (N)."""
    x = mesh.points.copy()
    x[pulled] += displacement
    inv_mass = 1.0 / mesh.lumped_masses(1060.0)
    inv_mass[np.concatenate([pulled, fixed])] = 0.0
    solver = ImplicitEuler(springs, len(x), max_cg_iterations=20_000)
    f = solver.equilibrium(x, inv_mass, np.zeros_like(x), 1e-9)
    np.testing.assert_allclose(f[pulled], reference.spring_forces(x, np.zeros_like(x), springs)[pulled], atol=1e-12)
    return f[pulled].sum(axis=0)


def test_bar_recovers_young_modulus():
    mesh = cylinder_mesh(0.005)
    z = mesh.points[:, 2]
    length = z.max() - z.min()
    top, bottom = np.flatnonzero(z > z.max() - 1e-6), np.flatnonzero(z < z.min() + 1e-6)
    tissue = TissueProperties(parenchyma_poisson_ratio=0.25, capsule_stiffness_n_per_m=0.0,
                              capsule_viscosity_ns_per_m=0.0)  # the network's own ν: E is its Young's modulus
    strain = 0.002
    force = static_reaction(mesh, material_springs(mesh, tissue), bottom, top, np.array([0.0, 0.0, -strain * length]))
    area = mesh.volume / length
    measured = force[2] / (area * strain)
    assert measured == pytest.approx(tissue.parenchyma_young_modulus_kpa * 1e3, rel=0.15)


@pytest.fixture(scope="module")
def fine_liver():
    return build_liver(10_000)


def liver_stretch(mesh, springs, strain=0.01, grip_m=0.03):
    """Reaction (N) of a liver whose nodes within grip_m of its left (−x) end are held while those within
    grip_m of its right end are moved right by strain × the length between the grips."""
    x = mesh.points[:, 0]
    left, right = np.flatnonzero(x < x.min() + grip_m), np.flatnonzero(x > x.max() - grip_m)
    span = (x.max() - grip_m) - (x.min() + grip_m)
    return static_reaction(mesh, springs, right, left, np.array([strain * span, 0.0, 0.0]))[0]


def test_stretch_is_mesh_independent_with_material_springs(fine_liver):
    coarse, fine = default_liver(), fine_liver
    material = [liver_stretch(m, material_springs(m)) for m in (coarse, fine)]
    raw = [liver_stretch(m, build_springs(m, ModelParams(spring_constants="paper"))) for m in (coarse, fine)]
    assert material[1] == pytest.approx(material[0], rel=0.25)
    assert raw[1] / raw[0] > 2.0  # per-spring constants: the finer mesh is far stiffer



def test_membrane_patch_has_capsule_modulus_and_poisson_third():
    # a flat equilateral triangle network with k·l0² = Y·A_tri per triangle edge (the capsule's rule), pulled
    # by 1 N over its width in two lattice directions 90° apart: Y and ν = 1/3 in the middle (2-D derivation of the
    # docstring)
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve
    from scipy.spatial import Delaunay

    from liver_sim.mesh.tetmesh import TRIANGLE_EDGES, unique_edges
    from liver_sim.physics.tissue.materials import triangle_areas

    capsule = 500.0  # N/m
    cell = 0.005
    grid = np.array([[(i + 0.5 * (j % 2)) * cell, j * cell * math.sqrt(3) / 2] for j in range(40) for i in range(30)])
    for points in (grid, grid[:, ::-1].copy()):  # rows across the pull, then along it
        triangles = Delaunay(points).simplices
        edges = unique_edges(triangles, TRIANGLE_EDGES)
        keys = edges[:, 0] * len(points) + edges[:, 1]
        ends = np.sort(triangles[:, TRIANGLE_EDGES], axis=2)
        areas = triangle_areas(np.c_[points, np.zeros(len(points))], triangles)
        area_sum = np.bincount(np.searchsorted(keys, (ends[..., 0] * len(points) + ends[..., 1]).ravel()),
                               np.repeat(areas, 3), len(edges))
        d = points[edges[:, 1]] - points[edges[:, 0]]
        length = np.linalg.norm(d, axis=1)
        u = d / length[:, None]
        k = capsule * area_sum / length ** 2
        dof = 2 * edges[:, :, None] + np.arange(2)  # (E, 2 ends, 2 axes)
        block = k[:, None, None] * u[:, :, None] * u[:, None, :]
        rows, cols, vals = [], [], []
        for a, b, sign in ((0, 0, 1), (1, 1, 1), (0, 1, -1), (1, 0, -1)):
            rows.append(np.repeat(dof[:, a, :], 2, axis=1).ravel())
            cols.append(np.tile(dof[:, b, :], 2).ravel())
            vals.append(sign * block.ravel())
        n = 2 * len(points)
        stiffness = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), (n, n)).tocsr()
        x, y = points[:, 0], points[:, 1]
        width, height = np.ptp(x), np.ptp(y)
        bottom, top = np.flatnonzero(y < y.min() + 1e-9), np.flatnonzero(y > y.max() - 1e-9)
        held = np.zeros(n, bool)
        held[2 * bottom + 1] = True
        held[2 * bottom[np.argmin(np.abs(x[bottom] - x.mean()))]] = True
        force = np.zeros(n)
        force[2 * top + 1] = 1.0 / len(top)
        displacement = np.zeros(n)
        displacement[~held] = spsolve(stiffness[~held][:, ~held].tocsc(), force[~held])
        middle = np.flatnonzero((np.abs(y - y.mean()) < 0.2 * height) & (np.abs(x - x.mean()) < 0.3 * width))
        strain_y = np.polyfit(y[middle], displacement[2 * middle + 1], 1)[0]
        strain_x = np.polyfit(x[middle], displacement[2 * middle], 1)[0]
        assert (1.0 / width) / strain_y == pytest.approx(capsule, rel=0.03)
        assert -strain_x / strain_y == pytest.approx(1.0 / 3.0, abs=0.01)
