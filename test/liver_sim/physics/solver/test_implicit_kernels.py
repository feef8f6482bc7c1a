"""The implicit step's kernels (physics.solver.implicit_kernels): the contacts' force and Jacobian against finite
differences, the Newton residual, the advance of the free nodes and BDF2's extrapolated start, by hand."""
import numpy as np
import pytest
from implicit_scene import tiny_scene

from liver_sim.physics.contact.rows import Contacts
from liver_sim.physics.solver import implicit_kernels, pcg
from liver_sim.physics.solver.records import ContactRows, Loads, Operator, Tissue
from liver_sim.physics.tissue.fem_kernels import TetArrays, build_tets
from liver_sim.physics.tissue.organ_support import SupportArrays
from liver_sim.physics.tissue.spring_law import spring_arrays


def test_contact_jacobian_matches_finite_differences():
    mesh, springs, x, v, inv_mass, contacts, external = tiny_scene()
    inv_mass = np.ones(len(x))

    def force(xs, vs):
        f = np.zeros_like(xs)
        implicit_kernels.contact_forces(xs, vs, np.zeros_like(xs), inv_mass, 0.0,
                                        ContactRows.of(contacts, np.zeros(len(contacts))), f, np.zeros_like(xs))
        return f

    def operator(coefficient, p):
        """The solver's contact term of A·p with per-element coefficient (springs and mass left out)."""
        out = np.zeros_like(p)
        none = np.zeros(0, np.uint32)
        springs_none = Operator.allocate(none, none, len(p))._replace(shift=np.zeros(len(p)))
        pcg.apply(springs_none, inv_mass, ContactRows.of(contacts, coefficient), TetArrays.none(), 0.0, p, out)
        return out

    direction = np.random.default_rng(5).normal(size=x.shape)
    eps = 1e-7
    dfdx = (force(x + eps * direction, v) - force(x - eps * direction, v)) / (2 * eps)
    dfdv = (force(x, v + eps * direction) - force(x, v - eps * direction)) / (2 * eps)
    assert np.abs(dfdx).max() > 1.0  # both contacts active
    np.testing.assert_allclose(-operator(contacts.stiffness_n_per_m, direction), dfdx, atol=1e-6)
    np.testing.assert_allclose(-operator(contacts.damping_ns_per_m, direction), dfdv, atol=1e-6)
    ky = np.zeros_like(x)
    implicit_kernels.contact_forces(x, v, direction, inv_mass, 0.0, ContactRows.of(contacts, np.zeros(len(contacts))),
                                    np.zeros_like(x), ky)
    np.testing.assert_allclose(ky, dfdx, atol=1e-6)


def test_the_newton_rhs_is_h_f_minus_the_momentum_change_on_free_nodes():
    v0 = np.zeros((2, 3))
    v = np.array([[1.0, 0.0, 0.0], [5.0, 5.0, 5.0]])
    f = np.array([[3.0, 4.0, 0.0], [9.0, 9.0, 9.0]])
    rhs = np.full((2, 3), 7.0)
    # node 0 (m = 2 kg): h·f − m·(v − v0) = 0.5·(3, 4, 0) − 2·(1, 0, 0) = (−0.5, 2, 0), |rhs|/h = √4.25/0.5
    worst = implicit_kernels.newton_rhs(v, v0, f, np.array([0.5, 0.0]), 0.5, rhs)
    np.testing.assert_allclose(rhs, [[-0.5, 2.0, 0.0], [0.0, 0.0, 0.0]])  # node 1 held: 0
    assert worst == pytest.approx(np.sqrt(4.25) / 0.5)


def test_advance_moves_the_free_nodes_from_the_steps_start_and_leaves_the_held_ones():
    x0 = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    x, v = x0 + 9.0, np.array([[1.0, 0.0, 0.0], [2.0, 2.0, 2.0]])
    dv = np.array([[0.5, 1.0, 0.0], [4.0, 4.0, 4.0]])
    implicit_kernels.advance(x, x0, v, v.copy(), dv, np.array([1.0, 0.0]), 0.1)
    np.testing.assert_allclose(v, [[1.5, 1.0, 0.0], [2.0, 2.0, 2.0]])  # v ← v + Δv
    np.testing.assert_allclose(x, [[0.15, 0.1, 0.0], [10.0, 10.0, 10.0]])  # x ← x0 + h·v; held: as it was


def test_bdf2_starts_from_the_extrapolated_state_only_after_the_last_step():
    x, v = np.array([[4.0, 0.0, 0.0], [1.0, 1.0, 1.0]]), np.array([[2.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    x_prev, v_prev = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]), np.array([[-1.0, 0.0, 0.0], [3.0, 3.0, 3.0]])
    inv_mass = np.array([1.0, 0.0])
    incoming = x.copy(), v.copy()
    assert implicit_kernels.bdf2_start(x, v, incoming[0], incoming[1], x_prev, v_prev, inv_mass, True)
    np.testing.assert_allclose(x[0], [5.0, 0.0, 0.0])  # (4·4 − 1)/3
    np.testing.assert_allclose(v[0], [3.0, 0.0, 0.0])  # (4·2 + 1)/3
    np.testing.assert_array_equal(x[1], incoming[0][1])  # held: not extrapolated
    np.testing.assert_array_equal(x_prev, incoming[0])  # the next step's x₋, v₋: what came in
    np.testing.assert_array_equal(v_prev, incoming[1])
    moved = incoming[0] + [[1e-9, 0.0, 0.0], [0.0, 0.0, 0.0]]  # not where the last step left it: backward Euler
    x, v = incoming[0].copy(), incoming[1].copy()
    assert not implicit_kernels.bdf2_start(x, v, moved, incoming[1], x_prev, v_prev, inv_mass, True)
    np.testing.assert_array_equal(x, incoming[0])
    assert not implicit_kernels.bdf2_start(x, v, x.copy(), v.copy(), x_prev, v_prev, inv_mass, False)
    np.testing.assert_array_equal(x, incoming[0])


def test_surface_rows_are_rebuilt_on_the_tools_true_surface_at_the_iterate():
    """A node row on a ball of radius 1 cm swept from (0, 0, 0) to (0.02, 0, 0): at the iterate its normal is radial
    from the shaft, its depth r − |x − c| plus its bias, its speed the core's along n; a row of radius 0 keeps its
    geometry."""
    x = np.array([[0.01, 0.0, 0.006], [0.03, 0.0, 0.0]])
    contacts = Contacts(np.array([[0, -1, -1], [1, -1, -1]]), np.tile([1.0, 0.0, 0.0], (2, 1)),
                        np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), np.array([0.0, 0.123]), np.zeros(2),
                        np.array([100.0, 100.0]), np.zeros(2),
                        np.array([[[0.0, 0.0, 0.0], [0.02, 0.0, 0.0]]] * 2), np.array([0.01, 0.0]),
                        np.array([[0.0, 0.0, -0.5], [0.0, 0.0, 0.0]]), np.array([2e-4, 0.0]))
    implicit_kernels.surface_rows(x, ContactRows.of(contacts, np.zeros(2)))
    np.testing.assert_allclose(contacts.normal, [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]], atol=1e-15)
    depth = contacts.offset_m[0] - contacts.normal[0] @ x[0]
    assert depth == pytest.approx(0.01 - 0.006 + 2e-4, abs=1e-15)
    assert contacts.normal_speed_m_s[0] == pytest.approx(-0.5) and contacts.offset_m[1] == 0.123


@pytest.mark.parametrize("law", ["springs", "fem", "neo_hookean"])
@pytest.mark.parametrize("parallel", [False, True])
def test_the_newton_checks_forces_are_the_assemblys_to_the_bit(law, parallel):
    """system_forces, the Newton check's pass, gives the f of system_terms without the matrix, bit for bit: springs
    (their forces alone), support and elements."""
    mesh, springs, x, v, inv_mass, _, external = tiny_scene()
    n = len(x)
    tets = TetArrays.none()
    if law != "springs":
        tets = build_tets(mesh.points, mesh.tets, 2e3, 0.45, 500.0, neo_hookean=law == "neo_hookean")
    node_i, node_j = springs.node_i.astype(np.uint32), springs.node_j.astype(np.uint32)
    op = Operator.allocate(node_i, node_j, n, tets.tets)
    support = SupportArrays(np.array([1, 5]), mesh.points[[1, 5]].copy(), np.array([40.0, 25.0]), np.array([0.2, 0.1]))
    tissue = Tissue(spring_arrays(springs, node_i, node_j).taken(op.spring_order), support, tets)
    loads = Loads(external, np.array([0.0, 0.0, -9.81]), 3.0)
    zero = np.zeros((n, 3))
    h = 1.0 / 150.0
    f, ky = np.zeros((n, 3)), np.zeros((n, 3))
    implicit_kernels.system_terms(x, v, v, inv_mass, loads, h, tissue, op, f, ky, True, parallel)  # the rotations
    implicit_kernels.system_terms(x, v, zero, inv_mass, loads, h, tissue, op, f, ky, False, parallel)
    forces, ky_forces = np.zeros((n, 3)), np.full((n, 3), np.nan)
    implicit_kernels.system_forces(x, v, zero, inv_mass, loads, h, tissue, op, forces, ky_forces, parallel)
    assert np.abs(f).max() > 0.1
    np.testing.assert_array_equal(forces, f)
