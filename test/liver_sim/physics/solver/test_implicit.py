"""Linearised backward Euler (physics.solver.implicit): against a dense NumPy assembly, stability at one step per
frame, energy, held nodes, and a press and release against symplectic Euler at 72 substeps."""
import numpy as np
import pytest
from implicit_scene import tiny_scene

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose, ToolShape, contact_rows, tool_sweep
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver import explicit_kernels, implicit, reference
from liver_sim.physics.solver.implicit import ImplicitEuler, same_arithmetic
from liver_sim.physics.tools.tool import Tool
from liver_sim.tool.scripts import ScriptSettings, make_script

FRAME_S = 1.0 / 150.0


def dense_reference_step(springs, x, v, inv_mass, contacts, external, h, c_env, gravity):
    """Baraff–Witkin step from a dense NumPy assembly (the module docstring's equations)."""
    n = len(x)
    free = inv_mass > 0.0
    mass = np.where(free, 1.0 / np.where(free, inv_mass, 1.0), 0.0)
    f = reference.spring_forces(x, v, springs) + external + mass[:, None] * (gravity - c_env * v)
    A = np.zeros((3 * n, 3 * n))
    K = np.zeros((3 * n, 3 * n))
    for s in range(springs.edges):
        i, j = springs.node_i[s], springs.node_j[s]
        axis = x[j] - x[i]
        length = np.linalg.norm(axis)
        u = axis / length
        d = (length - springs.rest_length_m[s]) / springs.rest_length_m[s]
        elastic = springs.lambda1_n[s] * d ** 3 + springs.lambda2_n[s] * d
        stiff = ((3 * springs.lambda1_n[s] * d ** 2 + springs.lambda2_n[s]) / springs.rest_length_m[s] * np.outer(u, u)
                 + max(elastic, 0.0) / length * (np.eye(3) - np.outer(u, u)))
        damp = springs.mu_ns_per_m[s] * np.outer(u, u)
        for a, b, sign in ((i, i, -1), (j, j, -1), (i, j, 1), (j, i, 1)):
            K[3 * a:3 * a + 3, 3 * b:3 * b + 3] += sign * stiff
            A[3 * a:3 * a + 3, 3 * b:3 * b + 3] -= sign * (h * h * stiff + h * damp)
    for e in range(len(contacts)):
        nodes = contacts.nodes[e]
        w = contacts.weights[e]
        nrm = contacts.normal[e]
        k, c = contacts.stiffness_n_per_m[e], contacts.damping_ns_per_m[e]
        used = nodes >= 0
        depth = contacts.offset_m[e] - nrm @ (w[used] @ x[nodes[used]])
        rate = contacts.normal_speed_m_s[e] - nrm @ (w[used] @ v[nodes[used]])
        predicted = depth - h * nrm @ (w[used] @ (v[nodes[used]] * free[nodes[used], None]))
        if k * predicted + c * rate <= 0.0:
            continue
        for a, wa in zip(nodes[used], w[used]):
            f[a] += wa * (k * depth + c * rate) * nrm
            for b, wb in zip(nodes[used], w[used]):
                K[3 * a:3 * a + 3, 3 * b:3 * b + 3] -= wa * wb * k * np.outer(nrm, nrm)
                A[3 * a:3 * a + 3, 3 * b:3 * b + 3] += wa * wb * (h * c + h * h * k) * np.outer(nrm, nrm)
    A += np.diag(np.repeat(mass * (1.0 + h * c_env), 3))
    dofs = np.repeat(free, 3)
    v_free = (v * free[:, None]).ravel()
    b = h * (f.ravel() + h * K @ v_free)
    dv = np.zeros(3 * n)
    dv[dofs] = np.linalg.solve(A[np.ix_(dofs, dofs)], b[dofs])
    v_new = v + dv.reshape(n, 3)
    x_new = np.where(free[:, None], x + h * v_new, x)
    return x_new, v_new


def test_step_matches_dense_numpy_assembly():
    mesh, springs, x, v, inv_mass, contacts, external = tiny_scene()
    gravity = np.array([0.0, 0.0, -9.81])
    x_ref, v_ref = dense_reference_step(springs, x, v, inv_mass, contacts, external, FRAME_S, 3.0, gravity)
    # no Newton iteration, and a Newton tolerance that leaves the linear solve's absolute floor out of the way
    solver = ImplicitEuler(springs, len(x), cg_tolerance=1e-13, newton_tolerance_n=1e-12, max_newton=0)
    history = solver.new_history()
    solver.step(history, x, v, inv_mass, external, FRAME_S, 3.0, gravity, contacts)
    np.testing.assert_allclose(v, v_ref, atol=1e-10)
    np.testing.assert_allclose(x, x_ref, atol=1e-12)


def test_newton_iterations_solve_the_nonlinear_step():
    # the Jacobian leaves out compressed springs' geometric stiffness and the viscous force's turning, so the
    # iterations converge linearly: fast near rest (here ~1 % strain), slowly for violent states
    mesh, springs, x, v, inv_mass, contacts, external = tiny_scene(offset_m=0.0002, speed_m_s=0.005)
    x0, v0 = x.copy(), v.copy()
    solver = ImplicitEuler(springs, len(x), cg_tolerance=1e-12, newton_tolerance_n=1e-9, max_newton=10)
    history = solver.new_history()
    solver.step(history, x, v, inv_mass, external, FRAME_S, 3.0, np.zeros(3))
    assert 1 <= history.newton_iterations < 10 and history.residual_n <= 1e-9
    # backward Euler: M·(v − v0) = h·f(x0 + h·v, v) on every free node
    free = inv_mass > 0.0
    f = reference.spring_forces(x, v, springs) + external - 3.0 * v / np.where(free, inv_mass, 1.0)[:, None]
    momentum = (v - v0) / np.where(free, inv_mass, 1.0)[:, None]
    np.testing.assert_allclose(momentum[free], FRAME_S * f[free], atol=1e-9 * FRAME_S)
    np.testing.assert_allclose(x[free], x0[free] + FRAME_S * v[free])


@pytest.fixture(scope="module")
def liver():
    return LiverModel(default_liver(), ModelParams(spring_constants="paper", support="paper"))  # its fixed tet


def perturbed(model, seed=0, scale=0.002):
    rng = np.random.default_rng(seed)
    x = model.structure.mesh.points + rng.normal(scale=scale, size=model.structure.mesh.points.shape)
    x[model.structure.fixed_nodes] = model.structure.mesh.points[model.structure.fixed_nodes]
    return x, np.zeros_like(x)


def test_a_free_vibration_follows_the_same_steps_solved_tightly(liver, monkeypatch):
    """The liver let go 2 mm from rest, every node at random (paper constants), over 2 s: the steps at the solver's
    tolerances stay within 0.3 mm of the same steps with each linear solve taken to 1e-10 and no floor (the
    linearisation and the Newton check the same): a looser relative tolerance leaves the slow modes' decay behind."""
    p = liver.structure.params

    def free_vibration(**settings):
        x, v = perturbed(liver)
        solver = ImplicitEuler(liver.structure.springs, len(x), **settings)
        history, positions = solver.new_history(), []
        for _ in range(300):
            solver.step(history, x, v, liver.state.inv_mass, np.zeros_like(x), FRAME_S, p.environment_damping_per_s,
                        np.zeros(3))
            positions.append(x.copy())
        return np.array(positions)

    default = free_vibration()
    monkeypatch.setattr(implicit, "CG_FLOOR_OF_NEWTON", 0.0)
    tight = free_vibration(cg_tolerance=1e-10)
    assert np.abs(default - tight).max() < 3e-4


def test_stable_at_one_step_per_frame_where_symplectic_euler_diverges(liver):
    p = liver.structure.params
    x, v = perturbed(liver)
    solver = ImplicitEuler(liver.structure.springs, len(x))
    history = solver.new_history()
    for _ in range(150):
        solver.step(history, x, v, liver.state.inv_mass, np.zeros_like(x), FRAME_S, p.environment_damping_per_s,
                    np.zeros(3))
    assert np.isfinite(x).all() and np.abs(x - liver.structure.mesh.points).max() < 0.002
    assert np.abs(v).max() < 1e-3
    xe, ve = perturbed(liver)
    settings = explicit_kernels.StepSettings(FRAME_S, 30, p.environment_damping_per_s, np.zeros(3), True)
    no_tool = tool_sweep(liver.tool.shape, None, None, p, 0.0, xe, liver.structure.mesh.skin)
    work = explicit_kernels.WorkArrays(np.zeros_like(xe), np.zeros((1, len(xe), 3)), False)
    with np.errstate(all="ignore"):
        explicit_kernels.run_frame(xe, ve, liver.state.inv_mass, np.zeros_like(xe), liver.structure.spring_arrays,
                                   liver.structure.support, settings, no_tool, work)
    assert not (np.isfinite(xe).all() and np.abs(xe - liver.structure.mesh.points).max() < 0.1)


def energy_j(model, x, v):
    """Kinetic energy plus the springs' elastic energy, ∫T dl = l0·(λ1·d⁴/4 + λ2·d²/2)."""
    s = model.structure.springs
    d = np.linalg.norm(x[s.node_j] - x[s.node_i], axis=1) / s.rest_length_m - 1.0
    elastic = (s.rest_length_m * (s.lambda1_n * d ** 4 / 4 + s.lambda2_n * d ** 2 / 2)).sum()
    return elastic + 0.5 * (model.structure.masses_kg * (v ** 2).sum(axis=1)).sum()


def test_energy_decreases_without_external_work(liver):
    x, v = perturbed(liver, seed=1, scale=0.003)
    v[:] = np.random.default_rng(2).normal(scale=0.05, size=v.shape)
    v[liver.structure.fixed_nodes] = 0.0
    solver = ImplicitEuler(liver.structure.springs, len(x))
    history = solver.new_history()
    energies = [energy_j(liver, x, v)]
    for _ in range(60):
        solver.step(history, x, v, liver.state.inv_mass, np.zeros_like(x), FRAME_S, 0.0, np.zeros(3))
        energies.append(energy_j(liver, x, v))
    steps = np.diff(energies)
    assert (steps <= 1e-9 * energies[0]).all()
    assert energies[-1] < 0.05 * energies[0]


def test_held_nodes_stay_put(liver):
    x, v = perturbed(liver, seed=4)
    held = np.concatenate([liver.structure.fixed_nodes, default_liver().skin_nodes[:5]])
    inv_mass = liver.state.inv_mass.copy()
    inv_mass[held] = 0.0
    v[held] = 0.01  # a kinematic node's velocity is the scene's: kept, and it does not move during the step
    before = x[held].copy()
    solver = ImplicitEuler(liver.structure.springs, len(x))
    history = solver.new_history()
    for _ in range(5):
        solver.step(history, x, v, inv_mass, np.zeros_like(x), FRAME_S, 3.0, np.array([0.0, 0.0, -9.81]))
    np.testing.assert_array_equal(x[held], before)
    np.testing.assert_array_equal(v[held], 0.01)


def test_press_and_release_matches_symplectic_euler_at_72_substeps():
    mesh = default_liver()
    # the conditions this solver-level check was written for
    paper = ModelParams(spring_constants="paper", support="paper")
    explicit, model = LiverModel(mesh, paper.with_changes(integrator="symplectic_euler")), LiverModel(mesh, paper)
    assert explicit.structure.params.substeps == 72
    p, tool = model.structure.params, model.tool.shape
    settings = ScriptSettings(anchor_m=tuple(press_anchor(mesh)), tool_radius_m=tool.radius_m, depth_m=0.01,
                              clearance_m=0.005, approach_s=0.1, press_s=0.3, hold_s=0.2, withdraw_s=0.1, rest_s=0.3)
    script = make_script("press_release", settings)
    solver = ImplicitEuler(model.structure.springs, len(mesh.points))
    history = solver.new_history()
    x, v = model.state.positions, model.state.velocities
    skin = np.asarray(mesh.skin, dtype=np.int64)
    previous = None
    worst_position = worst_force = peak = 0.0
    for frame in range(int(round(script.duration_s / FRAME_S))):
        pose = ToolPose(script.position_at((frame + 1) * FRAME_S))
        expected = -explicit.step_frame(pose).tool_force_n
        state = tool_sweep(tool, pose, previous, p, 0.02, x, skin)
        previous = pose
        # the tool at the end of the frame, as the explicit kernel's last substep
        contacts = contact_rows(x, v, state, state.velocity_m_s * FRAME_S, FRAME_S)
        force = solver.step(history, x, v, model.state.inv_mass, model.state.external_forces_n, FRAME_S,
                            p.environment_damping_per_s, np.zeros(3), contacts)
        worst_position = max(worst_position, np.abs(x - explicit.state.positions).max())
        worst_force = max(worst_force, np.abs(force - expected).max())
        peak = max(peak, np.linalg.norm(expected))
    assert peak > 0.3  # a real press
    assert worst_position < 0.2e-3
    assert worst_force < 0.01


def test_bdf2_is_second_order_and_falls_back_to_backward_euler(liver):
    # the liver set turning about its fixed nodes: halving h divides BDF2's error by ~4, backward Euler's by ~2
    def run(steps, second_order, duration_s=0.2):
        x = liver.structure.mesh.points.copy()
        v = 0.5 * np.cross([0.0, 0.0, 1.0], x - x.mean(axis=0))
        v[liver.structure.fixed_nodes] = 0.0
        solver = ImplicitEuler(liver.structure.springs, len(x), cg_tolerance=1e-10, newton_tolerance_n=1e-9,
                               max_newton=10, second_order=second_order)
        history = solver.new_history()
        for _ in range(steps):
            solver.step(history, x, v, liver.state.inv_mass, np.zeros_like(x), duration_s / steps, 0.0, np.zeros(3))
        return x, v, solver, history
    exact = run(1600, True)[0]
    errors = {order: [np.abs(run(n, order)[0] - exact).max() for n in (15, 30)] for order in (True, False)}
    assert errors[True][0] / errors[True][1] > 3.5
    assert 1.7 < errors[False][0] / errors[False][1] < 2.3
    assert errors[True][0] < errors[False][0] / 5
    x, v, solver, history = run(2, True)
    assert history.second_order
    x += 1e-6  # a state set from outside: the next step has no history
    solver.step(history, x, v, liver.state.inv_mass, np.zeros_like(x), 0.1, 0.0, np.zeros(3))
    assert not history.second_order


def demo_script(mesh, tool):
    """The closed-loop demo's press, slide and release (the phantom's default script) at the top of `mesh`."""
    return make_script("press_slide_release", ScriptSettings(anchor_m=tuple(press_anchor(mesh)),
                                                             tool_radius_m=tool.radius_m))


def test_demo_press_slide_and_release_matches_symplectic_euler_at_72_substeps():
    mesh = default_liver()
    model, reference_model = LiverModel(mesh), LiverModel(mesh, ModelParams(integrator="symplectic_euler"))
    assert model.structure.params.substeps == 1 and reference_model.structure.params.substeps == 72
    script = demo_script(mesh, model.tool.shape)
    worst_position = worst_force = peak = 0.0
    for frame in range(int(round(script.duration_s / FRAME_S))):
        pose = ToolPose(script.position_at((frame + 1) * FRAME_S))
        result, expected = model.step_frame(pose), reference_model.step_frame(pose)
        assert result.divergence is None and expected.divergence is None
        worst_position = max(worst_position, np.abs(model.state.positions - reference_model.state.positions).max())
        worst_force = max(worst_force, np.abs(result.tool_force_n - expected.tool_force_n).max())
        peak = max(peak, np.linalg.norm(expected.tool_force_n))
    rested = reference_model.state.displacement_m(reference_model.structure).max()
    assert peak > 0.2 and rested < 1e-3  # a real press, then back at rest
    assert worst_position < 0.2e-3
    assert worst_force < 0.01


@pytest.mark.parametrize("kind", ["capsule", "box"])
def test_capsule_and_box_tools_press_with_the_implicit_step(kind):
    mesh = default_liver()
    shape = ToolShape(kind, radius_m=0.01, length_m=0.04, half_extents_m=(0.015, 0.015, 0.01))
    model, reference_model = (LiverModel(mesh, params, Tool(shape)) for params in
                              (ModelParams(), ModelParams(integrator="symplectic_euler")))
    top = press_anchor(mesh)
    reach = shape.half_extents_m[2] if kind == "box" else shape.radius_m
    errors, peak = [], 0.0
    # 8 mm in 0.2 s, then held 0.2 s: the symplectic reference with a box (72 substeps of probes) costs 0.3 s a
    # frame, so the press is as short as shows the agreement (120 frames took 38 s of the suite)
    for frame in range(60):
        depth = 0.008 * min(1.0, frame / 30)
        pose = ToolPose(top + [0.0, 0.0, reach + 0.002 - depth])
        result, expected = model.step_frame(pose), reference_model.step_frame(pose)
        errors.append(np.abs(result.tool_force_n - expected.tool_force_n).max())
        peak = max(peak, np.linalg.norm(expected.tool_force_n))
    # the box pushes each node through its nearest face, a choice that jumps as nodes pass its edges: a frame
    # may differ by some 20 %, the press as a whole does not
    assert peak > 0.1 and np.mean(errors) < 0.03 * peak and max(errors) < 0.4 * peak
    assert np.abs(result.tool_force_n - expected.tool_force_n).max() < 0.02 * peak
    assert result.local_model.valid and result.local_model.in_contact
    np.testing.assert_allclose(result.local_model.normal, expected.local_model.normal, atol=0.05)


def test_the_same_arithmetic_is_the_same_version_and_before_version_3_the_same_threads():
    assert same_arithmetic("pcg two-level, 2 threads, 50 aggregates; solver 3", "pcg two-level; solver 3")
    assert not same_arithmetic("pcg two-level; solver 2", "pcg two-level; solver 3")
    assert not same_arithmetic("pcg two-level, 2 threads; solver 2", "pcg two-level; solver 2")
    assert same_arithmetic("pcg block-jacobi; solver 2", "pcg block-jacobi; solver 2")
    assert same_arithmetic("pcg block-jacobi", "pcg block-jacobi")  # before versions were named: version 1
    assert not same_arithmetic("pcg block-jacobi", "pcg block-jacobi; solver 3")
