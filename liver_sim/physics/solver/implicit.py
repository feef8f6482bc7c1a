"""Linearised backward Euler: one implicit step of the spring network per frame ([dLC99], paper P7).

With f(x, v) the forces of the Eq. 1 springs, environment damping, gravity, external loads and
penalty contacts, K = ∂f/∂x and D = ∂f/∂v, one step of length h solves

    (M − h·D − h²·K)·Δv = h·(f(x, v) + h·K·v),   v ← v + Δv,   x ← x + h·v

(Baraff & Witkin 1998), then — when the residual of the nonlinear step
r = M·Δv − h·f(x + h·v_new, v_new) exceeds `newton_tolerance_n`·h on some node — Newton
iterations J·δ = −r with J re-assembled at the iterate.  Each linear solve stops at ‖r‖ ≤ cg_tolerance·‖b‖, or
once ‖r‖ ≤ CG_FLOOR_OF_NEWTON·newton_tolerance_n·h, so that no node's linear residual exceeds that fraction of what
the Newton check accepts: near equilibrium ‖b‖ is small and the relative tolerance alone would solve far below it.

Second order (BDF2, default from the second step on).  Backward Euler damps the liver's slow
oscillations (about its fixed nodes) by ~(ω·h)²/2 per step, which at h = 1/150 s shows beside symplectic
Euler at 72 substeps (docs/performance.md, "The physics").  BDF2,
x₊ = (4·x − x₋)/3 + (2h/3)·v₊ and M·(v₊ − (4·v − v₋)/3) = (2h/3)·f(x₊, v₊), is exactly the step
above of length 2h/3 from the extrapolated state ((4·x − x₋)/3, (4·v − v₋)/3) (held nodes are not
extrapolated), so the same solver makes it; it is A-stable, L-stable and its error is second order.
The previous state (StepHistory) is used only when the step starts from the state the
last step left (same free nodes' x and v, same h); otherwise (first step, reset, topology change,
state set from outside) the step is backward Euler.

The numba kernels: physics.solver.implicit_kernels (forces, the system's blocks, support and contact terms,
the Newton residual, the BDF2 start, the step), physics.solver.pcg (the solver).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse

from liver_sim.physics.contact.rows import Contacts, node_contacts
from liver_sim.physics.settings import PRECONDITIONERS
from liver_sim.physics.solver.coarse_space import CoarseSpace, aggregates, build_coarse_space, node_graph
from liver_sim.physics.solver.implicit_kernels import bdf2_start, implicit_step, system_terms
from liver_sim.physics.solver.pcg import (
    ENDED,
    block_jacobi,
    pcg,
    pcg_parallel,
    pcg_resumable,
    pcg_resumable_parallel,
)
from liver_sim.physics.solver.records import ContactRows, Loads, Operator, Scratch, SolveSettings, Tissue
from liver_sim.physics.tissue.fem_kernels import TetArrays
from liver_sim.physics.tissue.organ_support import SupportArrays
from liver_sim.physics.tissue.spring_law import spring_arrays
from liver_sim.physics.tissue.springs import SpringNetwork

#: From this many nodes on, 'auto' takes the two-level preconditioner.  It pays from about the default liver's size
#: (334 nodes) on; the default liver keeps block-Jacobi, so that its steps stay those of before it, bit for bit.
TWO_LEVEL_MIN_NODES = 500

#: The step length (s) of the quasi-static solve in ImplicitEuler.compliance, and its CG tolerance
#: (docs/performance.md, "The physics": what it costs in accuracy and iterations against a tighter one).
COMPLIANCE_HORIZON_S = 30.0
COMPLIANCE_TOLERANCE = 3e-2
#: The step length (s) of ImplicitEuler.equilibrium's backward-Euler iterations and their CG tolerance.
STATIC_HORIZON_S = 1e3
STATIC_CG_TOLERANCE = 1e-6


NO_COARSE_SPACE = CoarseSpace.none()

#: The linear solve's absolute floor as a fraction of the Newton tolerance (‖r‖ in N·s, over all nodes, against
#: newton_tolerance_n·h on each).  What it moves and saves: docs/performance.md, "The physics".
CG_FLOOR_OF_NEWTON = 0.003

#: The version of the step's arithmetic, named in `ImplicitEuler.solver` (/diagnostics, re-simulated bags): a session
#: re-simulates to the bit under the version it was recorded with (version 2: and its threads).  2: the coarse solve
#: without fastmath (the same bits on every x86-64 CPU), the local model's compliance solved in slices.  3: the
#: product in fixed groups and every sum over fixed chunks (physics.solver.pcg), the same bits on any thread count.
#: 4: the linear solve's absolute floor (CG_FLOOR_OF_NEWTON).  5: the coarse matrix summed in closed form
#: (physics.solver.coarse_space.coarse_matrix).
SOLVER_VERSION = 5
#: The first version whose bits do not depend on the threads.
THREAD_FREE_VERSION = 3


def same_arithmetic(recorded: str, solver: str) -> bool:
    """Whether the solver described `recorded` (ImplicitEuler.solver; without '; solver N': version 1) does the
    arithmetic of `solver` to the bit: the same version, and before THREAD_FREE_VERSION the same threads too."""

    def version(description: str) -> int:
        head, _, tail = description.rpartition("; solver ")
        return int(tail) if head and tail.isdigit() else 1

    if version(recorded) != version(solver):
        return False
    return version(solver) >= THREAD_FREE_VERSION or recorded == solver



class StepHistory:
    """What a step leaves the next one on the same nodes and elements: `warm`, the Δv (N, 3) that starts its CG
    solve; BDF2's `states`, (x, v) of the last step and (x₋, v₋) of the one before, with its length `dt_s` (0: none,
    the next step is backward Euler); `rotations`, the unit quaternions (M, 4: x, y, z, w) of the 'fem' law's
    elements that start the next extraction of their rotations (physics.tissue.fem_kernels; identity at rest; the
    'neo_hookean' law's elements leave them be); and
    what the last step took: `cg_iterations`, `newton_iterations`, its final `residual_n` (N) and whether it was
    BDF2 (`second_order`).  Part of the model's state; a new one (ImplicitEuler.new_history) after a topology
    change."""

    def __init__(self, n_nodes: int, n_tets: int = 0):
        self.warm = np.zeros((n_nodes, 3))
        self.states = np.zeros((4, n_nodes, 3))
        self.dt_s = 0.0
        self.rotations = np.zeros((n_tets, 4))
        self.rotations[:, 3] = 1.0
        self.cg_iterations = 0
        self.newton_iterations = 0
        self.residual_n = 0.0
        self.second_order = False

    def reset(self) -> None:
        """Forget the previous Δv, the previous state and the elements' rotations: the next step is backward Euler
        from zero, its rotations extracted from the identity."""
        self.warm[:] = 0.0
        self.dt_s = 0.0
        self.rotations[:] = 0.0
        self.rotations[:, 3] = 1.0


class ImplicitEuler:
    """Linearised backward Euler on one spring network, its support (none by default) and the tetrahedra of the
    'fem' or 'neo_hookean' law (physics.tissue.fem_kernels; none by default): its per-spring matrix blocks, element
    rotations and work arrays, which depend on the topology only; with `second_order`, BDF2 from the second step on
    (see the module docstring), from the StepHistory each step is given; its PCG's `preconditioner`
    (settings.PRECONDITIONERS: 'auto' is two-level from TWO_LEVEL_MIN_NODES nodes on), with the two-level one
    a coarse space per step length, built at its first step (physics.solver.coarse_space); `layout_of`, a solver of
    the same network and elements whose operator groups (physics.solver.partition) and aggregates it shares (a
    `workspace`).  Build a new one after a topology change."""

    def __init__(self, springs: SpringNetwork, n_nodes: int, cg_tolerance: float = 1e-3,
                 max_cg_iterations: int = 500, newton_tolerance_n: float = 1e-2, max_newton: int = 2,
                 second_order: bool = True, support: SupportArrays | None = None, tets: TetArrays | None = None,
                 preconditioner: str = "auto", threads: int = 1, layout_of: "ImplicitEuler | None" = None):
        if preconditioner not in PRECONDITIONERS:
            raise ValueError(f"parameter preconditioner must be one of {', '.join(PRECONDITIONERS)}, "
                             f"got {preconditioner!r}")
        self.springs = springs
        self.support = support or SupportArrays.none()
        self.tets = tets if tets is not None else TetArrays.none()
        self.n_nodes = int(n_nodes)
        self.cg_tolerance = float(cg_tolerance)
        self.max_cg_iterations = int(max_cg_iterations)
        self.newton_tolerance_n = float(newton_tolerance_n)
        self.max_newton = int(max_newton)
        self.second_order = bool(second_order)
        #: Whether the PCG adds the coarse correction to block-Jacobi.
        self.two_level = preconditioner == "two_level" or (preconditioner == "auto"
                                                           and self.n_nodes >= TWO_LEVEL_MIN_NODES)
        #: Threads of the step's assembly and PCG (their parallel kernels above one; the same bits whatever their
        #: count).
        self.threads = max(1, int(threads))
        self._aggregate: np.ndarray | None = None
        self._coarse: dict[float, CoarseSpace] = {}
        if layout_of is None:
            # unsigned indices spare numba's negative-index wraparound in the inner loops
            node_i, node_j = springs.node_i.astype(np.uint32), springs.node_j.astype(np.uint32)
            self._op = Operator.allocate(node_i, node_j, self.n_nodes, self.tets.tets)
            # the kernels' record of the same springs, in the operator's order
            self._springs = spring_arrays(springs, node_i, node_j).taken(self._op.spring_order)
        else:  # a workspace: the groups and aggregates are the solver's, found once
            self._op = layout_of._op.emptied()
            self._springs = layout_of._springs
            self._aggregate = layout_of._aggregate
        self._scratch = Scratch(np.zeros((10, self.n_nodes, 3)), np.zeros((self.n_nodes, 3, 3)), self.threads > 1)
        self._coefficient = np.zeros(0)
        self._inv_mass = np.zeros(self.n_nodes)
        self._tet_weight = 0.0
        self._compliance_workspace: ImplicitEuler | None = None

    def step(self, history: StepHistory, x: np.ndarray, v: np.ndarray, inv_mass: np.ndarray,
             external_force: np.ndarray, dt: float, environment_damping: float, gravity: np.ndarray,
             contacts: Contacts | None = None) -> np.ndarray:
        """Advance x, v (N, 3, in place) by one step of `dt` s from `history` (updated for the next step);
        returns the contact force on the liver (N) at the new state (the tool feels its opposite)."""
        if len(history.rotations) != len(self.tets.tets):
            raise ValueError(f"a step history of {len(history.rotations)} elements for a solver of "
                             f"{len(self.tets.tets)}: take ImplicitEuler.new_history")
        tets = self.tets._replace(quaternion=history.rotations)
        contacts = contacts or Contacts.none()
        if len(self._coefficient) != len(contacts):
            self._coefficient = np.zeros(len(contacts))
        self._inv_mass = inv_mass
        x_last, v_last, x_prev, v_prev = history.states
        second = bdf2_start(x, v, x_last, v_last, x_prev, v_prev, inv_mass,
                            self.second_order and history.dt_s == dt)
        h = 2.0 * dt / 3.0 if second else float(dt)
        if self.two_level and h not in self._coarse:  # the system at x for the coarse space of this h
            self._assemble_at_rest(x, inv_mass, np.zeros_like(x), environment_damping, h, tets)
        coarse = self._coarse_space(h, x, inv_mass, tets)
        loads = Loads(external_force, np.asarray(gravity, dtype=np.float64), float(environment_damping))
        contact, history.cg_iterations, history.newton_iterations, history.residual_n = implicit_step(
            x, v, inv_mass, loads, h, Tissue(self._springs, self.support, tets), self._op,
            ContactRows.of(contacts, self._coefficient), coarse, history.warm,
            SolveSettings(self.cg_tolerance, self.max_cg_iterations, self.newton_tolerance_n, self.max_newton,
                          CG_FLOOR_OF_NEWTON * self.newton_tolerance_n * h),
            self._scratch)
        x_last[:], v_last[:] = x, v
        history.dt_s = float(dt)
        history.second_order = second
        return contact

    def new_history(self) -> StepHistory:
        """A StepHistory of this solver's nodes and elements, at rest."""
        return StepHistory(self.n_nodes, len(self.tets.tets))

    def _rotations(self, rotations: np.ndarray | None) -> TetArrays:
        """The elements with the rotations' warm start `rotations` (a state's StepHistory.rotations, updated in
        place), or from the identity when None."""
        if rotations is None:
            rotations = self.new_history().rotations
        return self.tets._replace(quaternion=rotations)

    @property
    def solver(self) -> str:
        """Which solver the steps take: 'pcg block-jacobi' or 'pcg two-level' (with its aggregates once built), its
        threads when more than one, and SOLVER_VERSION ('; solver 5')."""
        threads = f", {self.threads} threads" if self.threads > 1 else ""
        version = f"; solver {SOLVER_VERSION}"
        if not self.two_level:
            return f"pcg block-jacobi{threads}{version}"
        built = {c.aggregates for c in self._coarse.values()}
        return f"pcg two-level{threads}" + (f", {built.pop()} aggregates" if len(built) == 1 else "") + version

    def _coarse_space(self, h: float, x: np.ndarray, inv_mass: np.ndarray, tets: TetArrays) -> CoarseSpace:
        """The coarse space of step length `h` (none without the two-level preconditioner); the first time, built
        from the system last assembled, which must be the one of `h` at `x`."""
        if not self.two_level:
            return NO_COARSE_SPACE
        coarse = self._coarse.get(h)
        if coarse is None:
            if self._aggregate is None:
                self._aggregate = aggregates(*node_graph(self.n_nodes, np.stack([self._op.node_i, self._op.node_j],
                                                                                axis=1),
                                                         self.tets.tets[:, [0, 1, 0, 2, 0, 3, 1, 2, 1, 3, 2, 3]]))
            coarse = build_coarse_space(x, self._aggregate, (*self._op[:6], inv_mass, tets, self._tet_weight))
            self._coarse[h] = coarse
        return coarse

    def matrix(self) -> scipy.sparse.csr_matrix:
        """The spring, support, mass and damping part of the last assembled system matrix, (3N, 3N) sparse
        (contacts and tetrahedra excluded; held nodes' rows and columns are the identity)."""
        free = self._inv_mass > 0.0
        op = self._op
        blocks = op.iso[:, None, None] * np.eye(3) + op.axial[:, None, None] * (
            op.unit[:, :, None] * op.unit[:, None, :])
        blocks = blocks * (free[op.node_i] & free[op.node_j])[:, None, None]
        nodes = np.arange(self.n_nodes)
        rows = np.concatenate([nodes, op.node_i, op.node_j])
        cols = np.concatenate([nodes, op.node_j, op.node_i])
        values = np.concatenate([op.diagonal, -blocks, -blocks])
        r = (3 * rows)[:, None, None] + np.arange(3)[None, :, None]
        c = (3 * cols)[:, None, None] + np.arange(3)[None, None, :]
        size = 3 * self.n_nodes
        return scipy.sparse.coo_matrix((values.ravel(), (np.broadcast_to(r, values.shape).ravel(),
                                                          np.broadcast_to(c, values.shape).ravel())),
                                       shape=(size, size)).tocsr()

    def compliance(self, x: np.ndarray, inv_mass: np.ndarray, load: np.ndarray, environment_damping: float,
                   guess: np.ndarray, contacts: Contacts | None = None, rotations: np.ndarray | None = None) -> float:
        """Static compliance bᵀ·K⁻¹·b (m/N) of the network at x under the load pattern b = `load` (N, 3) N, held nodes
        (inv_mass 0) fixed, solved at once: `compliance_solve` on a workspace this solver keeps for it, to the end."""
        if self._compliance_workspace is None:
            self._compliance_workspace = self.workspace()
        return self.compliance_solve(self._compliance_workspace, x, inv_mass, load, environment_damping, guess,
                                     contacts, rotations).finish()

    def workspace(self) -> "ImplicitEuler":
        """A solver of the same network, settings and elements with work arrays of its own (its operator, element
        rotations and tangents, coarse spaces), where a solve can run in slices between this one's steps."""
        return ImplicitEuler(self.springs, self.n_nodes, self.cg_tolerance, self.max_cg_iterations,
                             self.newton_tolerance_n, self.max_newton, self.second_order, self.support,
                             self.tets._replace(quaternion=self.tets.quaternion.copy(),
                                                rotation=self.tets.rotation.copy(),
                                                rotated_gradients=self.tets.rotated_gradients.copy(),
                                                tangent=self.tets.tangent.copy()),
                             "two_level" if self.two_level else "block_jacobi", self.threads, layout_of=self)

    @staticmethod
    def compliance_solve(workspace: "ImplicitEuler", x: np.ndarray, inv_mass: np.ndarray, load: np.ndarray,
                         environment_damping: float, guess: np.ndarray, contacts: Contacts | None = None,
                         rotations: np.ndarray | None = None) -> "ComplianceSolve":
        """The static compliance bᵀ·K⁻¹·b (m/N) of the network at x under the load pattern b = `load` (N, 3) N, held
        nodes (inv_mass 0) fixed, assembled now into `workspace` (a `workspace()`, whose last solve it ends) and
        solved in slices (ComplianceSolve): the tangent stiffness K of the springs (physics.solver.implicit_kernels)
        and of the organ's supports at x, and of `contacts` (each row taken as active: another tool's penalty
        holding the tissue), solved by the step's PCG as (M·(1 + H·c_env) + H·C + H²·K)·z = b with
        H = COMPLIANCE_HORIZON_S, so the mass and damping terms weigh ≲ 1 % against K; `guess` (N, 3), the previous
        solution ·H², starts the solve and receives this one when it ends; `rotations` the elements' warm start
        (StepHistory.rotations, None: the identity; x and `rotations` are not read after this call)."""
        h = COMPLIANCE_HORIZON_S
        tets = workspace._rotations(None if rotations is None else rotations.copy())
        contacts = contacts or Contacts.none()
        coefficient = h * contacts.damping_ns_per_m + h * h * contacts.stiffness_n_per_m
        workspace._assemble_at_rest(x, inv_mass, np.zeros_like(x), environment_damping, h, tets, contacts,
                                    coefficient)
        free = (inv_mass > 0.0)[:, None]
        return ComplianceSolve(workspace, inv_mass.copy(), np.where(free, load, 0.0),
                               np.where(free, guess / (h * h), 0.0), guess,
                               workspace._coarse_space(h, x, inv_mass, tets), tets,
                               ContactRows.of(contacts, coefficient))

    def equilibrium(self, x: np.ndarray, inv_mass: np.ndarray, external_force: np.ndarray, tolerance_n: float,
                    max_iterations: int = 500, rotations: np.ndarray | None = None) -> np.ndarray:
        """Static equilibrium of the network and its support under `external_force` (N, 3) N, no gravity:
        x (N, 3) m moves in place until |f(x)| ≤ `tolerance_n` on every free node, held nodes (inv_mass 0)
        staying where x has them.  Newton's iterations (M + H·C + H²·K)·δx = H²·f(x), x ← x + δx, K the
        tangent stiffness at x: backward-Euler steps of H = STATIC_HORIZON_S from rest, whose mass and
        damping terms only regularise K.  K leaves out compressed springs' negative geometric stiffness
        (physics.solver.implicit_kernels), so where springs are compressed the iterations converge linearly.  Returns
        f(x) (N, 3): ≈ 0 on free nodes; on held nodes the pull of the network (and loads) that holding them
        resists; `rotations` as in `compliance`.  Raises RuntimeError when not converged."""
        h = STATIC_HORIZON_S
        tets = self._rotations(rotations)
        free = (inv_mass > 0.0)[:, None]
        for _ in range(max_iterations + 1):
            f = self._assemble_at_rest(x, inv_mass, external_force, 0.0, h, tets)
            residual = float(np.sqrt((np.where(free, f, 0.0) ** 2).sum(axis=1)).max(initial=0.0))
            if residual <= tolerance_n:
                return f
            step = np.zeros_like(x)
            self._solve(inv_mass, np.where(free, f * (h * h), 0.0), step, STATIC_CG_TOLERANCE,
                        self._coarse_space(h, x, inv_mass, tets), tets)
            x += step
        raise RuntimeError(f"no static equilibrium within {max_iterations} Newton iterations "
                           f"(largest residual force {residual:.3g} N)")

    def _assemble_at_rest(self, x: np.ndarray, inv_mass: np.ndarray, external_force: np.ndarray,
                          environment_damping: float, h: float, tets: TetArrays, contacts: Contacts | None = None,
                          coefficient: np.ndarray | None = None) -> np.ndarray:
        """Assemble the step's system at x, v = 0 (springs and support; `contacts` with their `coefficient`,
        h·c + h²·k each, in the preconditioner) and its preconditioner; returns the forces f(x) (N, 3)."""
        zero = np.zeros_like(x)
        f, ky = np.zeros_like(x), np.zeros_like(x)
        rows = ContactRows.of(contacts or Contacts.none(), np.zeros(0) if coefficient is None else coefficient)
        system_terms(x, zero, zero, inv_mass, Loads(external_force, np.zeros(3), float(environment_damping)), h,
                     Tissue(self._springs, self.support, tets), self._op, f, ky, True, self.threads > 1)
        self._tet_weight = h * h + h * tets.viscous_time_s
        block_jacobi(self._op.diagonal, inv_mass, rows, self._scratch.preconditioner)
        return f

    def _solve(self, inv_mass: np.ndarray, b: np.ndarray, solution: np.ndarray, tolerance: float,
               coarse: CoarseSpace, tets: TetArrays, contacts: Contacts | None = None,
               coefficient: np.ndarray | None = None) -> None:
        """solution ← A⁻¹·b by PCG from `solution` (the last assembled system, with `contacts` and their
        `coefficient` if given) with `coarse`."""
        vectors = tuple(np.zeros_like(b) for _ in range(4))
        rows = ContactRows.of(contacts or Contacts.none(), np.zeros(0) if coefficient is None else coefficient)
        solve = pcg_parallel if self.threads > 1 else pcg
        solve(self._op, inv_mass, rows, tets, self._tet_weight, self._scratch.preconditioner, coarse, b, solution,
              SolveSettings(tolerance, self.max_cg_iterations, 0.0, 0), vectors)

    def warm_up(self) -> None:
        """Compile the kernels (numba, cached on disk) before a timed loop starts."""
        springs = self.springs
        x = np.random.default_rng(0).normal(size=(self.n_nodes, 3))
        v = np.zeros_like(x)
        contacts = node_contacts(np.array([0]), np.array([[0.0, 0.0, 1.0]]), np.array([0.0]), np.array([0.0]),
                                 1.0, 0.0)
        probe = ImplicitEuler(springs, self.n_nodes, max_cg_iterations=1, max_newton=0, support=self.support,
                              preconditioner="two_level",
                              tets=self.tets._replace(quaternion=self.tets.quaternion.copy(),
                                                      rotation=self.tets.rotation.copy(),
                                                      rotated_gradients=self.tets.rotated_gradients.copy(),
                                                      tangent=self.tets.tangent.copy()))
        probe.step(probe.new_history(), x, v, np.ones(self.n_nodes), np.zeros_like(x), 1e-3, 0.0, np.zeros(3),
                   contacts)


class ComplianceSolve:
    """A compliance solve (ImplicitEuler.compliance_solve) on its workspace's assembled system, run in slices of
    PCG iterations (pcg.pcg_resumable) between the steps of the solver it was taken from: the same iterations in
    the same order as one solve, so its result does not depend on how it was sliced.  Its kernels, as the step's,
    run without the GIL: a node's executor thread delivers messages meanwhile."""

    def __init__(self, workspace: ImplicitEuler, inv_mass: np.ndarray, b: np.ndarray, solution: np.ndarray,
                 guess: np.ndarray, coarse: CoarseSpace, tets: TetArrays, rows: ContactRows):
        self.workspace = workspace
        self._inv_mass, self._b, self._solution, self._guess = inv_mass, b, solution, guess
        self._coarse, self._tets, self._rows = coarse, tets, rows
        self._vectors = tuple(np.zeros_like(b) for _ in range(4))
        self._status = np.zeros(4)
        self._preconditioner = workspace._scratch.preconditioner
        #: PCG iterations made so far
        self.iterations = 0
        self._started = False

    @property
    def ended(self) -> bool:
        """Whether the solve has converged (or reached the workspace's max_cg_iterations)."""
        return self._started and (self._status[ENDED] > 0.0
                                  or self.iterations >= self.workspace.max_cg_iterations)

    def advance(self, iterations: int) -> bool:
        """Up to `iterations` more PCG iterations (the first slice also starts the solve); returns `ended`."""
        if self.ended:
            return True
        w = self.workspace
        solve = pcg_resumable_parallel if w.threads > 1 else pcg_resumable
        steps = max(0, min(int(iterations), w.max_cg_iterations - self.iterations))
        self.iterations += solve(w._op, self._inv_mass, self._rows, self._tets, w._tet_weight, self._preconditioner,
                                 self._coarse, self._b, self._solution, COMPLIANCE_TOLERANCE, not self._started,
                                 steps, self._vectors, self._status)
        self._started = True
        return self.ended

    def finish(self) -> float:
        """Run the solve to its end; the compliance bᵀ·z (m/N), the solution ·H² written into the guess."""
        self.advance(self.workspace.max_cg_iterations)
        h = COMPLIANCE_HORIZON_S
        self._guess[:] = self._solution * (h * h)
        return float(np.einsum("ij,ij->", self._b, self._guess))
