"""The same liver through a peer simulator: MuJoCo's flex, for `liver-sim bench physics --peers`.

The peer is MuJoCo's 3-D flex (Saint Venant–Kirchhoff tetrahedra, energy density μ·tr(ε²) + ½·λ·tr(ε)²
of the Green strain, Lamé constants from Young's modulus E and Poisson's ratio ν) built from our
`TetMesh`: one slide-jointed point mass per free node (the tet-lumped mass ρ·V/4 per tet corner, as
`TetMesh.lumped_masses`), the fixed nodes pinned to the world, gravity off, Rayleigh damping
β = η/E (MuJoCo's damping matrix β·K is the Kelvin–Voigt stress σ = E·ε + η·ε̇ of the parenchyma),
and a rigid sphere of the tool's radius that presses the top of the liver as the tool does.

Best stable setting (FlexSettings' defaults, tried on the default and ~10k-tet livers; docs/command-line.md, "Peers,
side by side"): MuJoCo 4.0 integrates flex elasticity implicitly only with `integrator="discrete"` (implicit and
implicitfast refuse it; explicit Euler diverges even at 20 steps per 150 Hz frame); of its two primal
solvers CG gives Newton's forces in 1/2 (default liver) to 1/7 (~10k tets) of its time; with fewer than
~200 iterations the discrete step's solve ends under-converged on the ~10k liver in contact, so the cap is
1000 (CG stops at the tolerance first); one step per frame stays stable.

MuJoCo is an optional extra (`pip install .[peers]`); the product never imports this module.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel

#: How to get the peer.
INSTALL_HINT = "pip install .[peers]"
#: Poisson's ratio of liver_sim's spring network: central springs make a Cauchy solid, ν = 1/4
#: (liver_sim.physics.tissue.materials), so the peer gets the same value by default.
NETWORK_POISSON_RATIO = 0.25
#: Name of the flex in the MJCF model (its bodies are `liver_<node>`).
FLEX_NAME = "liver"
#: The press of the timed frames and of the force check: a sphere of this radius (m, the default tool's)
#: starts this far (m) above the top of the liver and goes this deep (m) below its rest surface.
TOOL_RADIUS_M = 0.015
PRESS_CLEARANCE_M = 0.005
PRESS_DEPTH_M = 0.005
#: A run is stable when every node coordinate stays finite and within this (m) of its rest value.
STABLE_MAX_DISPLACEMENT_M = 0.05


@dataclass(frozen=True)
class FlexSettings:
    """MuJoCo solver options of the peer (the MJCF <option> element)."""

    integrator: str = "discrete"
    solver: str = "CG"
    iterations: int = 1000
    tolerance: float = 1e-8
    frame_rate_hz: float = 150.0
    steps_per_frame: int = 1

    @property
    def timestep_s(self) -> float:
        """MuJoCo's time step: one frame divided into `steps_per_frame`."""
        return 1.0 / (self.frame_rate_hz * self.steps_per_frame)


def import_mujoco():
    """The mujoco module, or ImportError saying how to install it."""
    try:
        import mujoco  # optional: the `peers` extra, for bench physics --peers only
    except ImportError as exc:
        raise ImportError(f"the peers comparison needs MuJoCo, which is not installed: {INSTALL_HINT}") from exc
    return mujoco


def _numbers(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.ravel(values))


def flex_mjcf(mesh: TetMesh, youngs_modulus_pa: float, poisson_ratio: float, fixed_nodes, damping_s: float = 0.0,
              settings: FlexSettings = FlexSettings(), tool_radius_m: float = TOOL_RADIUS_M) -> str:
    """MJCF text of `mesh` as a 3-D flexcomp named FLEX_NAME (points in m, `fixed_nodes` pinned), with a mocap
    sphere `tool` of `tool_radius_m` PRESS_CLEARANCE_M above the press anchor.  Masses are set by build_flex."""
    if not 0.0 <= poisson_ratio < 0.5:
        raise ValueError(f"parameter poisson_ratio must be in [0, 0.5), got {poisson_ratio!r}")
    if not youngs_modulus_pa > 0.0:
        raise ValueError(f"parameter youngs_modulus_pa must be > 0, got {youngs_modulus_pa!r}")
    fixed = np.unique(np.asarray(fixed_nodes, np.int64))
    if fixed.size and (fixed[0] < 0 or fixed[-1] >= len(mesh.points)):
        raise ValueError(f"parameter fixed_nodes must index nodes 0..{len(mesh.points) - 1}")
    pin = f'<pin id="{" ".join(map(str, fixed))}"/>' if fixed.size else ""
    tool = press_anchor(mesh) + [0.0, 0.0, tool_radius_m + PRESS_CLEARANCE_M]
    s = settings
    return f"""<mujoco model="liver_sim peer">
  <option timestep="{s.timestep_s:.12g}" gravity="0 0 0" integrator="{s.integrator}" solver="{s.solver}"
          iterations="{s.iterations}" tolerance="{s.tolerance:g}"/>
  <worldbody>
    <body name="tool" mocap="true" pos="{_numbers(tool)}"><geom type="sphere" size="{tool_radius_m:.9g}"/></body>
    <flexcomp name="{FLEX_NAME}" type="direct" dim="3" radius="0" point="{_numbers(mesh.points)}"
              element="{" ".join(map(str, np.asarray(mesh.tets).ravel()))}">
      <contact selfcollide="none"/>
      <elasticity young="{youngs_modulus_pa:.9g}" poisson="{poisson_ratio:.9g}" damping="{damping_s:.9g}"/>
      {pin}
    </flexcomp>
  </worldbody>
</mujoco>"""


def build_flex(mesh: TetMesh, youngs_modulus_pa: float, poisson_ratio: float, density_kg_m3: float, fixed_nodes,
               damping_s: float = 0.0, settings: FlexSettings = FlexSettings(), tool_radius_m: float = TOOL_RADIUS_M):
    """(mujoco, MjModel) of flex_mjcf with each free node's body weighing its lumped mass ρ·ΣV/4 (kg)."""
    mujoco = import_mujoco()
    if not density_kg_m3 > 0.0:
        raise ValueError(f"parameter density_kg_m3 must be > 0, got {density_kg_m3!r}")
    spec = mujoco.MjSpec.from_string(flex_mjcf(mesh, youngs_modulus_pa, poisson_ratio, fixed_nodes, damping_s,
                                               settings, tool_radius_m))
    masses = mesh.lumped_masses(density_kg_m3)
    prefix = FLEX_NAME + "_"
    for body in spec.bodies:
        if body.name.startswith(prefix):
            body.mass = float(masses[int(body.name[len(prefix):])])
    return mujoco, spec.compile()


def press_depth_m(time_s: float, period_s: float = 1.0) -> float:
    """Depth (m) of the sphere below the rest surface at `time_s`: from PRESS_CLEARANCE_M above it down to
    PRESS_DEPTH_M below over the first half `period_s`, then held."""
    share = min(1.0, 2.0 * time_s / period_s)
    return -PRESS_CLEARANCE_M + (PRESS_CLEARANCE_M + PRESS_DEPTH_M) * 0.5 * (1.0 - np.cos(np.pi * share))


def _tool_force_n(mujoco, model, data) -> np.ndarray:
    """Total contact force (N, world frame) of the liver on the sphere."""
    tool = model.body("tool").id
    total, wrench = np.zeros(3), np.zeros(6)
    for i in range(data.ncon):
        contact = data.contact[i]
        mujoco.mj_contactForce(model, data, i, wrench)
        force = contact.frame.reshape(3, 3).T @ wrench[:3]  # on geom2, from geom1, in world axes
        on_tool = contact.geom[1] >= 0 and model.geom_bodyid[contact.geom[1]] == tool
        total += force if on_tool else -force
    return total


def _displacements_m(mujoco, model, data, rest_m: np.ndarray) -> np.ndarray:
    """Per mesh node, its distance (m) from its rest position `rest_m` in the current state."""
    mujoco.mj_fwdPosition(model, data)
    return np.linalg.norm(data.flexvert_xpos - rest_m, axis=1)


def _warnings(mujoco, data, names) -> int:
    """How many times MuJoCo raised the warnings `names` (mjtWarning members) so far."""
    return sum(int(data.warning[int(getattr(mujoco.mjtWarning, name))].number) for name in names)


#: Warnings after which MuJoCo resets the state (the step diverged) and the one of an under-converged solve.
DIVERGED = ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC")
UNDER_CONVERGED = ("mjWARN_INERTIA",)


def time_mujoco_flex(mesh: TetMesh, youngs_modulus_pa: float, poisson_ratio: float, density_kg_m3: float, fixed_nodes,
                     frames: int = 150, threads: int = 1, damping_s: float = 0.0,
                     settings: FlexSettings = FlexSettings(), tool_radius_m: float = TOOL_RADIUS_M) -> dict:
    """Play `frames` frames of the press (press_depth_m) on the MuJoCo flex, timing each: wall and CPU ms per
    frame (wall: mean, median, p90; CPU: median), steps per frame, stability (no divergence warning — MuJoCo then
    resets the state —, finite, no coordinate beyond STABLE_MAX_DISPLACEMENT_M; the run stops at the first unstable
    frame), steps whose implicit solve under-converged, the last tool force (N) and node displacements (m, all and
    fixed nodes), model size and MuJoCo version."""
    mujoco, model = build_flex(mesh, youngs_modulus_pa, poisson_ratio, density_kg_m3, fixed_nodes, damping_s,
                               settings, tool_radius_m)
    messages = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)  # into the result, not into a log file in the working folder
    try:
        figures = _press(mujoco, model, mesh, fixed_nodes, frames, threads, settings, tool_radius_m, messages)
    finally:
        mujoco.set_mju_user_warning(previous)
    return {**figures, "youngs_modulus_pa": youngs_modulus_pa, "poisson_ratio": poisson_ratio,
            "density_kg_m3": density_kg_m3, "damping_s": damping_s}


def _press(mujoco, model, mesh: TetMesh, fixed_nodes, frames: int, threads: int, settings: FlexSettings,
           tool_radius_m: float, messages: list) -> dict:
    """time_mujoco_flex's frames on the compiled `model`: timing, stability and figures (its docstring)."""
    data = mujoco.MjData(model)
    if threads > 1:
        mujoco.mju_threadpool(data, threads)
    anchor = press_anchor(mesh)
    wall, cpu = np.empty(frames), np.empty(frames)
    stable = True
    for frame in range(frames):
        depth = press_depth_m((frame + 1) / settings.frame_rate_hz)
        data.mocap_pos[0] = anchor + [0.0, 0.0, tool_radius_m - depth]
        start_wall, start_cpu = time.perf_counter(), time.thread_time()
        for _ in range(settings.steps_per_frame):
            mujoco.mj_step(model, data)
        wall[frame], cpu[frame] = time.perf_counter() - start_wall, time.thread_time() - start_cpu
        if (_warnings(mujoco, data, DIVERGED) or not np.isfinite(data.qpos).all()
                or np.abs(data.qpos).max(initial=0.0) > STABLE_MAX_DISPLACEMENT_M):
            stable = False
            wall, cpu = wall[:frame + 1], cpu[:frame + 1]
            break
    moved = _displacements_m(mujoco, model, data, mesh.points)
    fixed = np.asarray(fixed_nodes, np.int64)
    return {
        "simulator": f"MuJoCo {mujoco.__version__} flex",
        "mujoco_version": mujoco.__version__,
        "ms_per_frame_mean": float(np.mean(wall) * 1e3),
        "ms_per_frame_median": float(np.median(wall) * 1e3),
        "ms_per_frame_p90": float(np.percentile(wall, 90) * 1e3),
        "cpu_ms_per_frame_median": float(np.median(cpu) * 1e3),
        "steps_per_frame": settings.steps_per_frame,
        "frames": int(len(wall)),
        "stable": stable,
        "under_converged_steps": _warnings(mujoco, data, UNDER_CONVERGED),
        "warnings": sorted(set(m.split(" Time = ")[0] for m in messages)),
        "max_displacement_m": float(moved.max()),
        "fixed_nodes_max_displacement_m": float(moved[fixed].max(initial=0.0)),
        "tool_force_n": _tool_force_n(mujoco, model, data).tolist(),
        "threads": threads,
        "dofs": int(model.nv),
        "free_mass_kg": float(model.body_mass[np.unique(model.flex_vertbodyid)].sum()),
        "settings": asdict(settings),
    }


def liver_sim_press_force_n(model: LiverModel, frames: int = 150) -> np.ndarray:
    """The force (N) on liver_sim's tool after `frames` frames of the same press (press_depth_m) on `model`."""
    anchor = press_anchor(model.structure.mesh)
    force = np.zeros(3)
    for frame in range(frames):
        depth = press_depth_m((frame + 1) / model.structure.params.frame_rate_hz)
        force = model.step_frame(ToolPose(anchor + [0.0, 0.0, model.tool.shape.radius_m - depth])).tool_force_n
    return np.asarray(force, dtype=float)
