"""The implicit step's matrix-free PCG (physics.solver.pcg): A·p by hand on one spring, the block-Jacobi inverse with
a contact row, and a small SPD system solved as numpy.linalg.solve does, on one thread and on several."""
import numpy as np
import pytest

from liver_sim.physics.contact.rows import Contacts, node_contacts
from liver_sim.physics.solver import pcg
from liver_sim.physics.solver.coarse_space import CoarseSpace
from liver_sim.physics.solver.records import ContactRows, Operator, SolveSettings
from liver_sim.physics.tissue.fem_kernels import TetArrays, build_tets

from meshes import box_mesh

NO_ROWS = ContactRows.of(Contacts.none(), np.zeros(0))


def spring_operator(node_i, node_j, unit, iso, axial, shift) -> Operator:
    """The records.Operator of these springs (uint32 nodes) and shifts, its diagonal blocks shift·I + Σ B."""
    n = len(shift)
    diagonal = shift[:, None, None] * np.eye(3)
    blocks = iso[:, None, None] * np.eye(3) + axial[:, None, None] * unit[:, :, None] * unit[:, None, :]
    for s, (i, j) in enumerate(zip(node_i, node_j)):
        diagonal[i] += blocks[s]
        diagonal[j] += blocks[s]
    op = Operator.allocate(np.asarray(node_i, np.uint32), np.asarray(node_j, np.uint32), n)
    order = op.spring_order
    return op._replace(unit=unit[order], iso=iso[order], axial=axial[order], shift=shift,
                       diagonal=diagonal.reshape(n, 3, 3))


def dense(op: Operator) -> np.ndarray:
    """A of `op` (no contact, no element, every node free) as a (3N, 3N) matrix from its definition."""
    n = len(op.shift)
    a = np.zeros((3 * n, 3 * n))
    for k in range(n):
        a[3 * k:3 * k + 3, 3 * k:3 * k + 3] += op.shift[k] * np.eye(3)
    for s, (i, j) in enumerate(zip(op.node_i, op.node_j)):
        b = op.iso[s] * np.eye(3) + op.axial[s] * np.outer(op.unit[s], op.unit[s])
        for r, c, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            a[3 * r:3 * r + 3, 3 * c:3 * c + 3] += sign * b
    return a


def test_apply_by_hand_on_one_spring_and_a_held_node():
    # B = 2·I + 3·uuᵀ, u = x̂; p_0 − p_1 = (1, 1, 0): B·(1, 1, 0) = (5, 2, 0) to node 0, its opposite to node 1
    op = spring_operator([0], [1], np.array([[1.0, 0.0, 0.0]]), np.array([2.0]), np.array([3.0]),
                         np.array([10.0, 20.0, 30.0]))
    p = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    out = np.full_like(p, 99.0)
    inv_mass = np.ones(3)
    pcg.apply(op, inv_mass, NO_ROWS, TetArrays.none(), 0.0, p, out)
    np.testing.assert_allclose(out, [[15.0, 12.0, 0.0], [-5.0, -2.0, 0.0], [30.0, 60.0, 90.0]])
    inv_mass[2] = 0.0  # a held node: its row of A·p vanishes
    pcg.apply(op, inv_mass, NO_ROWS, TetArrays.none(), 0.0, p, out)
    np.testing.assert_allclose(out[2], 0.0)


def test_block_jacobi_inverts_the_diagonal_blocks_with_the_contacts():
    diagonal = np.array([[[4.0, 1.0, 0.0], [1.0, 3.0, 0.0], [0.0, 0.0, 2.0]], np.eye(3) * 5.0])
    contacts = node_contacts(np.array([1]), np.array([[0.0, 0.0, 1.0]]), np.zeros(1), np.zeros(1), 1.0, 0.0)
    inverse = np.zeros_like(diagonal)
    pcg.block_jacobi(diagonal, np.ones(2), ContactRows.of(contacts, np.array([3.0])), inverse)
    np.testing.assert_allclose(inverse[0], np.linalg.inv(diagonal[0]))
    np.testing.assert_allclose(inverse[1], np.linalg.inv(np.diag([5.0, 5.0, 8.0])))  # + 3·w²·nnᵀ


@pytest.fixture(scope="module")
def system():
    """Six nodes joined by eight springs of random axes and blocks, masses 1..6: A (SPD), b."""
    rng = np.random.default_rng(11)
    node_i, node_j = np.array([0, 1, 2, 3, 4, 0, 1, 2]), np.array([1, 2, 3, 4, 5, 3, 4, 5])
    unit = rng.normal(size=(8, 3))
    unit /= np.linalg.norm(unit, axis=1)[:, None]
    op = spring_operator(node_i, node_j, unit, rng.uniform(0.5, 2.0, 8), rng.uniform(1.0, 50.0, 8),
                         np.arange(1.0, 7.0))
    return op, rng.normal(size=(6, 3))


@pytest.mark.parametrize("threads", [1, 2])
def test_pcg_solves_a_small_spd_system_as_numpy_does(system, threads):
    op, b = system
    expected = np.linalg.solve(dense(op), b.ravel()).reshape(-1, 3)
    inverse = np.zeros_like(op.diagonal)
    pcg.block_jacobi(op.diagonal, np.ones(6), NO_ROWS, inverse)
    z = np.zeros_like(b)
    vectors = tuple(np.zeros_like(b) for _ in range(4))
    solve = pcg.pcg if threads == 1 else pcg.pcg_parallel
    iterations = solve(op, np.ones(6), NO_ROWS, TetArrays.none(), 0.0, inverse, CoarseSpace.none(), b, z,
                       SolveSettings(1e-12, 100, 0.0, 0), vectors)
    np.testing.assert_allclose(z, expected, rtol=1e-9, atol=1e-12)
    assert 0 < iterations <= 18  # CG ends within the dimension (18), up to rounding


def test_pcg_stops_at_the_tolerance_and_at_the_iteration_limit(system):
    op, b = system
    inverse = np.zeros_like(op.diagonal)
    pcg.block_jacobi(op.diagonal, np.ones(6), NO_ROWS, inverse)

    def solve(tolerance, limit, floor=0.0):
        z = np.zeros_like(b)
        used = pcg.pcg(op, np.ones(6), NO_ROWS, TetArrays.none(), 0.0, inverse, CoarseSpace.none(), b, z,
                       SolveSettings(tolerance, limit, 0.0, 0, floor), tuple(np.zeros_like(b) for _ in range(4)))
        return used, np.linalg.norm(b.ravel() - dense(op) @ z.ravel())

    used, residual = solve(1e-2, 100)
    assert residual <= 1e-2 * np.linalg.norm(b)
    assert 0 < used < solve(1e-12, 100)[0]  # a looser tolerance stops sooner
    assert solve(1e-12, 2)[0] == 2
    # the absolute floor: a tolerance of 1e-12 stops where ‖r‖ reaches 1e-2·‖b‖ given as the floor …
    floor = 1e-2 * float(np.linalg.norm(b))
    floored, floored_residual = solve(1e-12, 100, floor)
    assert floored_residual <= floor and floored == used
    # … and a floor below the relative target changes nothing
    assert solve(1e-2, 100, 1e-6 * floor) == (used, residual)


def test_the_product_refuses_an_operator_allocated_without_the_elements():
    mesh = box_mesh(2, 1, 1, 0.01)
    tets = build_tets(mesh.points, mesh.tets, 2e3, 0.45, 0.0)
    n = len(mesh.points)
    none = np.zeros(0, np.uint32)
    p, out = np.random.default_rng(4).normal(size=(n, 3)), np.zeros((n, 3))
    with pytest.raises(ValueError, match="element groups"):
        pcg.apply(Operator.allocate(none, none, n), np.ones(n), NO_ROWS, tets, 1e-4, p, out)
    pcg.apply(Operator.allocate(none, none, n, tets.tets), np.ones(n), NO_ROWS, tets, 1e-4, p, out)
    assert np.abs(out - p).max() > 1e-3 * np.abs(p).max()  # the elements' part beside shift·p
