"""The two-level preconditioner's coarse space: its aggregates, A_c = Tᵀ·F·A·F·T against a dense assembly of the
matrix-free operator, its Cholesky factor and correction, and a PCG solve to the same answer in fewer iterations."""
import numpy as np
import pytest

from liver_sim.mesh.liver_shape import build_liver
from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver import pcg
from liver_sim.physics.solver.coarse_space import (
    MODES,
    CoarseSpace,
    aggregates,
    build_coarse_space,
    cholesky,
    coarse_matrix,
    coarse_solve,
    node_graph,
    prolong,
    restrict,
)
from liver_sim.physics.solver.implicit_kernels import system_terms
from liver_sim.physics.solver.records import ContactRows, Loads, Operator, SolveSettings, Tissue
from liver_sim.physics.tissue.fem_kernels import TetArrays, build_tets
from liver_sim.physics.tissue.organ_support import SupportArrays
from liver_sim.physics.tissue.spring_law import spring_arrays
from liver_sim.physics.tissue.springs import build_springs

from meshes import box_mesh

NO_ROWS = ContactRows.of(Contacts.none(), np.zeros(0))

H_S = 1.0 / 150.0


def assembled_system(mesh, params: ModelParams, x, inv_mass):
    """The step's matrix-free system at x (v = 0, h = H_S) of `mesh`'s springs and, with params.tissue_law 'fem', its
    tetrahedra: (its records.Operator, the operator's arrays as coarse_matrix takes them, the block-Jacobi inverse)."""
    springs = build_springs(mesh, params)
    tets = TetArrays.none()
    if params.tissue_law == "fem":
        tets = build_tets(mesh.points, mesh.tets, 2e3, 0.45, 500.0)
    n = len(x)
    f, ky, zero = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    node_i, node_j = springs.node_i.astype(np.uint32), springs.node_j.astype(np.uint32)
    op = Operator.allocate(node_i, node_j, n, tets.tets)
    law = spring_arrays(springs, node_i, node_j).taken(op.spring_order)
    system_terms(x, zero, zero, inv_mass, Loads(zero, np.zeros(3), 3.0), H_S, Tissue(law, SupportArrays.none(), tets),
                 op, f, ky, True, False)
    inverse = np.zeros_like(op.diagonal)
    pcg.block_jacobi(op.diagonal, inv_mass, NO_ROWS, inverse)
    return op, (*op[:6], inv_mass, tets, H_S * H_S + H_S * tets.viscous_time_s), inverse


def graph(mesh):
    return node_graph(len(mesh.points), mesh.edges)


def perturbed_box(law: str):
    """A 3×2×2 box of 1 cm cubes, perturbed by 1 mm, two nodes held; (mesh, params, x, inv_mass)."""
    mesh = box_mesh(3, 2, 2, 0.01)
    x = mesh.points + np.random.default_rng(7).normal(scale=1e-3, size=mesh.points.shape)
    inv_mass = 1.0 / mesh.lumped_masses(1060.0)
    inv_mass[[0, 5]] = 0.0
    return mesh, ModelParams(tissue_law=law), x, inv_mass


def dense_operator(op, operator):
    """pcg.apply's operator `op` (no contacts; `operator` its arrays) as a dense (3N × 3N) matrix, column by
    column."""
    inv_mass = operator[6]
    columns = []
    for k in range(3 * len(inv_mass)):
        p = np.zeros((len(inv_mass), 3))
        p.flat[k] = 1.0
        p[inv_mass == 0.0] = 0.0
        out = np.zeros_like(p)
        pcg.apply(op, inv_mass, NO_ROWS, *operator[7:], p, out)
        columns.append(out.ravel())
    return np.array(columns).T


def modes_matrix(coarse: CoarseSpace, inv_mass):
    """F·T (3N × 6C): node n of aggregate a moves by t_a + ω_a × d_n; held nodes do not."""
    n = len(coarse.aggregate)
    t = np.zeros((3 * n, MODES * coarse.aggregates))
    for node in np.flatnonzero(inv_mass > 0.0):
        a, d = coarse.aggregate[node], coarse.offset_m[node]
        t[3 * node:3 * node + 3, MODES * a:MODES * a + 3] = np.eye(3)
        for k in range(3):
            t[3 * node:3 * node + 3, MODES * a + 3 + k] = np.cross(np.eye(3)[k], d)
    return t


def test_aggregates_cover_every_node_once_and_stay_under_the_target():
    mesh = box_mesh(6, 5, 4, 0.01)
    for target in (1, 8, 40):
        aggregate = aggregates(*graph(mesh), target)
        count = aggregate.max() + 1
        assert np.array_equal(np.unique(aggregate), np.arange(count)) and count <= target
        np.testing.assert_array_equal(aggregates(*graph(mesh), target), aggregate)  # the same each time


@pytest.mark.parametrize("law", ["springs", "fem"])
def test_the_coarse_matrix_is_the_operator_on_the_aggregates_rigid_motions(law):
    mesh, params, x, inv_mass = perturbed_box(law)
    op, operator, _ = assembled_system(mesh, params, x, inv_mass)
    aggregate = aggregates(*graph(mesh), 4)
    coarse = build_coarse_space(x, aggregate, operator)
    t = modes_matrix(coarse, inv_mass)
    expected = t.T @ dense_operator(op, operator) @ t
    actual = coarse_matrix(*operator, aggregate, coarse.offset_m, coarse.aggregates)
    np.testing.assert_allclose(actual, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(coarse.factor @ coarse.factor.T, actual, rtol=1e-9, atol=1e-9 * np.abs(actual).max())


def test_cholesky_factors_and_refuses_an_indefinite_matrix():
    a = np.random.default_rng(0).normal(size=(30, 30))
    spd = a @ a.T + 30 * np.eye(30)
    factor = cholesky(spd)
    np.testing.assert_allclose(factor @ factor.T, spd, rtol=1e-12, atol=1e-10)
    assert np.allclose(np.triu(factor, 1), 0.0)
    with pytest.raises(ValueError, match="positive definite"):
        cholesky(-spd)


def test_the_coarse_correction_is_f_t_ac_inverse_t_transpose_r_and_its_part_of_r_dot_z():
    mesh, params, x, inv_mass = perturbed_box("fem")
    _, operator, _ = assembled_system(mesh, params, x, inv_mass)
    coarse = build_coarse_space(x, aggregates(*graph(mesh), 5), operator)
    t = modes_matrix(coarse, inv_mass)
    r = np.random.default_rng(1).normal(size=x.shape)
    r[inv_mass == 0.0] = 0.0
    restricted = np.zeros((2, len(coarse.work)))  # two chunks of nodes, summed by the solve
    half = len(r) // 2
    restrict(coarse, r, 0, half, restricted[0])
    restrict(coarse, r, half, len(r), restricted[1])
    r_dot_z = coarse_solve(coarse, restricted)
    z = np.array([prolong(coarse, coarse.work, n) if inv_mass[n] > 0.0 else (0.0, 0.0, 0.0) for n in range(len(r))])
    expected = t @ np.linalg.solve(coarse.factor @ coarse.factor.T, t.T @ r.ravel())
    np.testing.assert_allclose(z.ravel(), expected, rtol=1e-8, atol=1e-10 * np.abs(expected).max())
    assert r_dot_z == pytest.approx(r.ravel() @ expected, rel=1e-10)


def test_two_levels_solve_the_same_system_in_fewer_iterations():
    mesh = build_liver(10_000)
    inv_mass = 1.0 / mesh.lumped_masses(1060.0)
    inv_mass[:4] = 0.0
    op, operator, inverse = assembled_system(mesh, ModelParams(), mesh.points, inv_mass)
    coarse = build_coarse_space(mesh.points, aggregates(*graph(mesh)), operator)
    b = np.random.default_rng(2).normal(scale=1e-3, size=mesh.points.shape) * operator[5][:, None]
    b[inv_mass == 0.0] = 0.0

    def solve(space, tolerance):
        z = np.zeros_like(b)
        iterations = pcg.pcg(op, inv_mass, NO_ROWS, *operator[7:], inverse, space, b, z,
                             SolveSettings(tolerance, 1000, 0.0, 0), tuple(np.zeros_like(b) for _ in range(4)))
        return z, iterations

    exact, _ = solve(CoarseSpace.none(), 1e-12)
    scale = np.abs(exact).max()
    (one_level, jacobi_iterations), (two_level, iterations) = solve(CoarseSpace.none(), 1e-3), solve(coarse, 1e-3)
    assert np.abs(one_level - exact).max() <= 1e-2 * scale and np.abs(two_level - exact).max() <= 1e-2 * scale
    assert iterations < jacobi_iterations / 2
    assert np.abs(solve(coarse, 1e-12)[0] - exact).max() <= 1e-8 * scale
