"""`liver-sim bench physics`: step and frame cost of the model for the default liver and larger livers (R2 of
docs/paper.md).

One explicit step = every spring's Eq. 1 force plus one integration of every node (no tool), timed
with the serial kernel, the parallel kernel on all threads, and the plain-NumPy oracle, which also
checks the kernels' result in the same process.  One frame = `LiverModel.step_frame` with the tool
pressing (contact, integration, local model and the frame's Python), timed per integrator over the
same scripted press (`frame_figures`), each integrator's positions compared with symplectic Euler at
its stable step, with the PCG iterations per step and the solver that ran.  Memory: the peak resident memory of a
process that builds the model and plays the press, and what the model added to it (`memory_figures`).
"""
from __future__ import annotations

import math
import subprocess
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

from liver_sim.bench.machine import machine
from liver_sim.mesh.landmarks import press_anchor
from liver_sim.mesh.liver_shape import build_liver, default_liver
from liver_sim.physics.contact.tool_geometry import ToolPose
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.solver import reference
from liver_sim.physics.structure import default_fixed_nodes
from liver_sim.physics.tools.tool import Tool
from liver_sim.studies.peers import NETWORK_POISSON_RATIO, liver_sim_press_force_n, time_mujoco_flex
from liver_sim.tool.scripts import ScriptSettings, make_script

#: Liver sizes measured after the default one (target tetrahedra).
LARGER_LIVERS = (10_000, 30_000, 100_000)
#: Fraction of the stability bound a benchmarked time step may use.
STABILITY_MARGIN = 0.9
#: The integrators and tissue laws timed frame by frame, side by side (the last is the reference's, at its stable
#: step): the implicit step with the springs (the default), with the co-rotational and with the neo-Hookean tetrahedra.
FRAME_INTEGRATORS = (("implicit_euler", "springs"), ("implicit_euler", "fem"), ("implicit_euler", "neo_hookean"),
                     ("symplectic_euler", "springs"))
TARGETS = {"default_us_per_step_1thread_max": 50.0, "default_speedup_vs_numpy_min": 10.0,
           "spring_updates_per_s_min": 50e6, "default_implicit_ms_per_frame_1thread_max": 0.5,
           "liver_10k_implicit_realtime_factor_min": 1.0, "liver_30k_implicit_ms_per_frame_1thread_max": 6.7,
           "liver_100k_implicit_realtime_factor_all_threads_min": 0.5, "peer_ratio_min": 5.0}
#: How near a liver's tets must be to a target's size (10 k, 30 k, 100 k) for the target to be judged on it.
SIZE_MARGIN = 0.2


def _perturb(model: LiverModel) -> None:
    rng = np.random.default_rng(0)
    spacing = float(model.structure.springs.rest_length_m.mean())
    model.state.positions += rng.normal(scale=0.02 * spacing, size=model.state.positions.shape)
    model.state.velocities += rng.normal(scale=0.001, size=model.state.velocities.shape)


def _time_kernel(model: LiverModel, min_seconds: float) -> float:
    """Microseconds per step of the model's kernel, over frames of many substeps."""
    structure = model.structure
    model.structure = replace(structure, params=structure.params.with_changes(
        substeps=max(1, int(2e6 // structure.springs.edges))))
    model.step_frame(None)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < min_seconds:
        model.step_frame(None)
        steps += model.structure.params.substeps
    return (time.perf_counter() - start) / steps * 1e6


def _time_numpy(model: LiverModel, min_seconds: float) -> float:
    x, v = model.state.positions.copy(), model.state.velocities.copy()
    p = model.structure.params
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < min_seconds or steps < 3:
        x, v = reference.step(x, v, model.structure.springs, model.state.inv_mass, p.dt_s, p.environment_damping_per_s,
                              p.gravity_m_s2, p.integrator, model.structure.support)
        steps += 1
    return (time.perf_counter() - start) / steps * 1e6


def _oracle_difference(model: LiverModel) -> float:
    """Largest |x_kernel − x_numpy| (m) after one frame from the same perturbed state."""
    x, v = model.state.positions.copy(), model.state.velocities.copy()
    p = model.structure.params
    model.step_frame(None)
    for _ in range(p.substeps):
        x, v = reference.step(x, v, model.structure.springs, model.state.inv_mass, p.dt_s, p.environment_damping_per_s,
                              p.gravity_m_s2, p.integrator, model.structure.support)
    return float(np.abs(model.state.positions - x).max())


def stable_params(mesh, integrator: str = "symplectic_euler") -> ModelParams:
    """The default parameters with `integrator`; an explicit one with at least enough substeps per frame for
    this mesh's stability bound."""
    params = ModelParams(integrator=integrator)
    stable = LiverModel(mesh, params).structure.stable_dt_s
    needed = math.ceil(1.0 / (params.frame_rate_hz * STABILITY_MARGIN * stable))
    return params.with_changes(substeps=max(params.substeps, needed))


def scripted_press(mesh, tool_radius_m: float) -> list[ToolPose]:
    """Tool poses, one per 150 Hz frame, of a short press 1 cm into the top of `mesh` (0.3 s: approach,
    press, hold), the benchmark's frames."""
    settings = ScriptSettings(anchor_m=tuple(press_anchor(mesh)), tool_radius_m=tool_radius_m, depth_m=0.01,
                              clearance_m=0.002, approach_s=0.05, press_s=0.2, hold_s=0.05)
    script = make_script("press", settings)
    return [ToolPose(script.position_at((frame + 1) / 150.0)) for frame in range(int(round(script.duration_s * 150)))]


def contact_frame_times(anchors, depth_m: float = 0.008, frames: int = 450, approach_frames: int = 60) -> dict:
    """The physics frame's compute (LiverModel.step_frame, one thread) on the default liver with one tool pressing
    `depth_m` into the skin at the first of `anchors` (m), and with a tool pressing into each of them at once:
    {'one_contact': …, 'two_contacts': …} (two: as many as anchors), each the median and p99 (ms) of a frame over
    `frames` frames, the first `approach_frames` (the tools going in) left out, and how many tools the last frame
    found in contact."""
    mesh, figures = default_liver(), {}
    for label, count in (("one_contact", 1), ("two_contacts", len(anchors))):
        model = LiverModel(mesh, tool=[Tool(name=f"tool{k}") for k in range(count)])
        model.warm_up()
        radius, elapsed = model.tool.shape.radius_m, []
        for frame in range(frames):
            depth = depth_m * min(1.0, frame / approach_frames)
            poses = [ToolPose(np.asarray(anchor) + [0.0, 0.0, radius - depth]) for anchor in anchors[:count]]
            start = time.perf_counter()
            result = model.step_frame(*poses)
            elapsed.append(time.perf_counter() - start)
        ms = np.array(elapsed[approach_frames:]) * 1e3
        touching = sum(bool(np.any(force)) for force in result.tool_forces_n)  # in the last frame
        figures[label] = {"tools_in_contact": touching, "median_ms": float(np.median(ms)),
                          "p99_ms": float(np.percentile(ms, 99)), "frames": int(ms.size)}
    return figures


def _run_frames(model: LiverModel, poses, reference_positions=None) -> tuple[np.ndarray, float, list, float]:
    """(each frame's time in ms, largest |x − reference| (m) over the frames, positions per frame if no reference,
    PCG iterations per frame)."""
    model.warm_up()
    model.step_frame(None)
    model.reset()
    trajectory, error, iterations = [], 0.0, 0
    elapsed = []
    for frame, pose in enumerate(poses):
        start = time.perf_counter()
        model.step_frame(pose)
        elapsed.append(time.perf_counter() - start)
        iterations += model.state.history.cg_iterations
        if reference_positions is None:
            trajectory.append(model.state.positions.copy())
        else:
            error = max(error, float(np.abs(model.state.positions - reference_positions[frame]).max()))
    return np.array(elapsed) * 1e3, error, trajectory, iterations / len(poses)


def frame_figures(name: str, mesh, integrators=FRAME_INTEGRATORS) -> list[dict]:
    """Per integrator and tissue law, the whole frame's cost (LiverModel.step_frame: contact, integration, local
    model, Python) over `scripted_press`, its mean and its 99th percentile (the worst frames: those that solve the
    local model's compliance), on one thread and on all (the parallel spring kernel where it has one),
    and its largest position error against symplectic Euler at its stable step over the same frames (for the
    tetrahedra: how far the continuum law's press is from the springs'); for the implicit step its PCG iterations per
    step and solver (one thread's run)."""
    reference_params = stable_params(mesh, "symplectic_euler")
    poses = scripted_press(mesh, LiverModel(mesh, reference_params).tool.shape.radius_m)
    _, _, reference_positions, _ = _run_frames(LiverModel(mesh, reference_params), poses)
    rows = []
    for integrator, law in integrators:
        params = reference_params if integrator == "symplectic_euler" else stable_params(mesh, integrator)
        params = params.with_changes(tissue_law=law)
        serial, parallel = (LiverModel(mesh, params.with_changes(solver_threads=t)) for t in ("one", "all"))
        frames_serial, error, _, iterations = _run_frames(serial, poses, reference_positions)
        frames_parallel, _, _, _ = _run_frames(parallel, poses, reference_positions)
        ms_serial, ms_parallel = float(frames_serial.mean()), float(frames_parallel.mean())
        period_ms = 1e3 / params.frame_rate_hz
        rows.append({"mesh": name, "tetrahedra": int(len(mesh.tets)), "integrator": integrator, "tissue_law": law,
                     "steps_per_frame": params.substeps, "ms_per_frame_1thread": round(ms_serial, 4),
                     "ms_per_frame_all_threads": round(ms_parallel, 4),
                     "ms_per_frame_p99_1thread": round(float(np.percentile(frames_serial, 99)), 4),
                     "ms_per_frame_p99_all_threads": round(float(np.percentile(frames_parallel, 99)), 4),
                     "realtime_factor_150hz": round(period_ms / min(ms_serial, ms_parallel), 3),
                     "realtime_factor_1thread": round(period_ms / ms_serial, 3),
                     "realtime_factor_all_threads": round(period_ms / ms_parallel, 3),
                     "threads": parallel.structure.solver.threads if parallel.structure.implicit else None,
                     "cg_iterations_per_step": round(iterations / params.substeps, 2) if serial.structure.implicit
                     else None,
                     "solver": serial.structure.step_solver,
                     "max_position_error_vs_reference_m": error, "frames": len(poses)})
    return rows


#: The child process of `memory_figures`: argv a mesh file (npz of points and tets); prints its resident memory (KiB)
#: before the model, after the model's press, and its peak.
MEMORY_CHILD = """
import os, resource, sys
import numpy as np
from liver_sim.bench.physics import scripted_press
from liver_sim.mesh.tetmesh import TetMesh
from liver_sim.physics.model import LiverModel
def resident_kib():
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024
with np.load(sys.argv[1]) as arrays:
    mesh = TetMesh.from_arrays(arrays["points"], arrays["tets"])
before = resident_kib()
model = LiverModel(mesh)
model.warm_up()
for pose in scripted_press(mesh, model.tool.shape.radius_m):
    model.step_frame(pose)
print(before, resident_kib(), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def memory_figures(mesh) -> dict:
    """Memory of a process that builds the default model of `mesh` and plays the scripted press (MB): its peak
    resident memory (interpreter and libraries included) and that per 100 k tets, and what the model added to its
    resident memory (`model_rss_mb`) and that per 100 k tets."""
    with tempfile.TemporaryDirectory() as folder:
        path = f"{folder}/mesh.npz"
        np.savez(path, points=mesh.points, tets=mesh.tets)
        run = subprocess.run([sys.executable, "-c", MEMORY_CHILD, path], capture_output=True, text=True, check=True)
    before, after, peak = (int(kib) / 1024.0 for kib in run.stdout.split()[-3:])
    per_100k = 1e5 / len(mesh.tets)
    return {"peak_rss_mb": round(peak, 1), "peak_rss_mb_per_100k_tets": round(peak * per_100k, 1),
            "model_rss_mb": round(after - before, 1),
            "model_rss_mb_per_100k_tets": round((after - before) * per_100k, 1)}


def bench_mesh(name: str, mesh, min_seconds: float = 1.0) -> dict:
    """Figures for one mesh: the explicit kernel's step with the default model parameters and symplectic Euler
    (substeps raised to its stability bound), and `frame_figures` per integrator under `integrators`."""
    params = stable_params(mesh)
    serial = LiverModel(mesh, params.with_changes(solver_threads="one"))
    parallel = LiverModel(mesh, params.with_changes(solver_threads="all"))
    configured = serial.structure.params
    for model in (serial, parallel):
        model.warm_up()
        _perturb(model)
    difference = _oracle_difference(serial)
    us_serial = _time_kernel(serial, min_seconds)
    us_parallel = _time_kernel(parallel, min_seconds)
    us_numpy = _time_numpy(serial, min_seconds)
    best = min(us_serial, us_parallel)
    frame_us = 1e6 / configured.frame_rate_hz
    return {
        "mesh": name,
        "nodes": int(len(mesh.points)),
        "tetrahedra": int(len(mesh.tets)),
        "springs": serial.structure.springs.springs,
        "edges_evaluated": serial.structure.springs.edges,
        "us_per_step_1thread": round(us_serial, 3),
        "us_per_step_all_threads": round(us_parallel, 3),
        "numpy_us_per_step": round(us_numpy, 3),
        "speedup_vs_numpy": round(us_numpy / us_serial, 2),
        "spring_updates_per_s": round(serial.structure.springs.edges / (best * 1e-6)),
        "max_abs_diff_vs_numpy_m": difference,
        "stable_dt_s": serial.structure.stable_dt_s,
        "configured_dt_s": configured.dt_s,
        "substeps_per_frame": configured.substeps,
        "realtime_factor_150hz": round(frame_us / (configured.substeps * best), 3),
        "integrators": frame_figures(name, mesh),
        **memory_figures(mesh),
    }


def livers(sizes, progress=None, doing: str = "timing"):
    """(name, mesh) of the default liver, then of livers of about `sizes` tets, meshed one at a time."""
    for name, make in [("default liver", default_liver)] + [(f"liver ~{n} tets", lambda n=n: build_liver(n))
                                                             for n in sizes]:
        if progress:
            progress(f"meshing {name}")
        mesh = make()
        if progress:
            progress(f"{doing} {name}: {len(mesh.tets)} tets")
        yield name, mesh


def peer_figures(mesh, liver_sim_ms_per_frame: float, force_check: bool = False, progress=None) -> dict:
    """The same mesh and tissue (params.TissueProperties defaults: parenchyma E, η as Rayleigh damping η/E;
    density; ν of the spring network; the default fixed nodes) through MuJoCo's flex (liver_sim.studies.peers), one
    thread: `peer` (its settings and figures), `peer_ms_per_frame` (its mean) and `peer_ratio` (peer ms over
    liver_sim ms per frame, both means).  With `force_check`, also the force on the sphere after the same 5 mm press
    on the default LiverModel and on the peer: `press_force_n`, `peer_press_force_n` and `peer_force_ratio`
    (|peer| / |ours|)."""

    if progress:
        progress(f"MuJoCo flex: {len(mesh.tets)} tets")
    params = ModelParams()
    young_pa = params.tissue.parenchyma_young_modulus_kpa * 1e3
    peer = time_mujoco_flex(mesh, young_pa, NETWORK_POISSON_RATIO, params.density_kg_m3, default_fixed_nodes(mesh),
                            threads=1, damping_s=params.tissue.parenchyma_viscosity_pa_s / young_pa)
    figures = {"peer": peer, "peer_ms_per_frame": round(peer["ms_per_frame_mean"], 3),
               "peer_ratio": round(peer["ms_per_frame_mean"] / liver_sim_ms_per_frame, 3)}
    if force_check:
        ours = liver_sim_press_force_n(LiverModel(mesh, params), peer["frames"])
        figures.update(press_force_n=ours.tolist(), peer_press_force_n=peer["tool_force_n"],
                       peer_force_ratio=round(float(np.linalg.norm(peer["tool_force_n"]) / np.linalg.norm(ours)), 3))
    return figures


def run_physics_bench(sizes=LARGER_LIVERS, min_seconds: float = 1.0, progress=None, peers: bool = False) -> dict:
    """The benchmark's JSON object: machine, results (default liver first; per mesh, `integrators`: the
    frame figures of each integrator) and targets met; with `peers`, each mesh row also has peer_figures
    against the default (implicit) integrator's whole frame, with the force check on the default liver."""
    results = []
    for name, mesh in livers(sizes, progress):
        row = bench_mesh(name, mesh, min_seconds)
        results.append(row)
        if peers:
            ours = next(r for r in row["integrators"] if r["integrator"] == ModelParams().integrator
                        and r["tissue_law"] == ModelParams().tissue_law)
            row.update(peer_figures(mesh, ours["ms_per_frame_1thread"], force_check=len(results) == 1,
                                    progress=progress))
    default = results[0]
    implicit = {r["mesh"]: row for r in results for row in r["integrators"]
                if row["integrator"] == "implicit_euler" and row["tissue_law"] == "springs"}
    met = {
        "default_us_per_step_1thread_max": default["us_per_step_1thread"] <= TARGETS["default_us_per_step_1thread_max"],
        "default_speedup_vs_numpy_min": default["speedup_vs_numpy"] >= TARGETS["default_speedup_vs_numpy_min"],
        "spring_updates_per_s_min": max(r["spring_updates_per_s"] for r in results)
        >= TARGETS["spring_updates_per_s_min"],
        "default_implicit_ms_per_frame_1thread_max": implicit[default["mesh"]]["ms_per_frame_1thread"]
        <= TARGETS["default_implicit_ms_per_frame_1thread_max"],
    }
    for target, tets, judged in (
            ("liver_10k_implicit_realtime_factor_min", 10_000,
             lambda row: row["realtime_factor_150hz"] >= TARGETS["liver_10k_implicit_realtime_factor_min"]),
            ("liver_30k_implicit_ms_per_frame_1thread_max", 30_000,
             lambda row: row["ms_per_frame_1thread"] <= TARGETS["liver_30k_implicit_ms_per_frame_1thread_max"]),
            ("liver_100k_implicit_realtime_factor_all_threads_min", 100_000,
             lambda row: row["realtime_factor_all_threads"]
             >= TARGETS["liver_100k_implicit_realtime_factor_all_threads_min"])):
        near = min(results[1:], key=lambda r: abs(r["tetrahedra"] - tets), default=None)
        if near is not None and abs(near["tetrahedra"] - tets) <= SIZE_MARGIN * tets:
            met[target] = judged(implicit[near["mesh"]])
    if peers:
        met["peer_ratio_min"] = min(r["peer_ratio"] for r in results) >= TARGETS["peer_ratio_min"]
    return {"benchmark": "physics", "machine": machine(), "results": results, "targets": TARGETS, "met": met}
