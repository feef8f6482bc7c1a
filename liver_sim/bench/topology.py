"""`liver-sim bench topology`: the cost of tearing and cutting (tear detection per frame, one tear, one cut,
the model rebuilt) on the default liver and larger ones."""
from __future__ import annotations

import time

import numpy as np

from liver_sim.bench.machine import machine
from liver_sim.bench.physics import livers
from liver_sim.mesh.landmarks import upper_skin_path
from liver_sim.physics.model import LiverModel
from liver_sim.physics.settings import ModelParams
from liver_sim.physics.topology.tearing import TearDetector, tear

#: A topology change of the default liver should fit in one 150 Hz frame (s).
TOPOLOGY_TARGETS = {"default_topology_change_s_max": 1.0 / 150.0}


def _median_s(run, repeats: int) -> float:
    """Median wall time (s) of `run()` over `repeats` calls."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def bench_topology_mesh(name: str, mesh, repeats: int = 9) -> dict:
    """Times (s) of tear detection per frame, of one tear (detect, separate, apply to the model) and of one
    cut (split, separate, apply) on `mesh`.

    The tear opens the mesh across the plane x = centre: the nodes beyond it are moved 30 % of the
    mesh's length along +x, which stretches the tets straddling the plane past the thresholds.  The
    cut runs 8 cm along x over the upper skin, one mean edge deep.
    """

    params = ModelParams(tearing=True)
    lower, upper = mesh.bounds
    middle = (lower + upper) / 2.0
    stretched = mesh.points + (mesh.points[:, 0] > middle[0])[:, None] * [0.3 * (upper - lower)[0], 0.0, 0.0]
    template = LiverModel(mesh, params)
    template.warm_up()
    detector = TearDetector(mesh.points, mesh.tets, template.structure.capsule_triangles, params.tear_strain_parenchyma,
                            params.tear_strain_capsule)
    detect_s = _median_s(lambda: detector.torn_faces(stretched), max(repeats, 20))

    def fresh(positions):
        model = LiverModel(mesh, params)
        model.state.positions = positions.copy()
        return model

    faces = []

    def tear_once():
        change = tear(mesh.points, mesh.tets, stretched, template.structure.capsule_triangles,
                      params.tear_strain_parenchyma, params.tear_strain_capsule, detector=detector)
        faces.append(change.separated_faces)
        models.pop().apply(change)

    models = [fresh(stretched) for _ in range(repeats)]
    tear_s = _median_s(tear_once, repeats)
    edges = mesh.points[mesh.edges]
    depth = float(np.linalg.norm(edges[:, 1] - edges[:, 0], axis=1).mean())
    top = mesh.points[mesh.skin_nodes][np.argmax(mesh.points[mesh.skin_nodes, 2])]
    path = upper_skin_path(mesh, (top[0] - 0.04, top[1]), (top[0] + 0.04, top[1]))
    models = [fresh(mesh.points) for _ in range(repeats)]
    cut_nodes = []

    def cut_once():
        model = models.pop()
        model.cut(path, depth)
        cut_nodes.append(len(model.state.positions) - len(mesh.points))

    cut_s = _median_s(cut_once, repeats)
    return {"mesh": name, "tetrahedra": int(len(mesh.tets)), "nodes": int(len(mesh.points)),
            "tear_detection_per_frame_s": detect_s, "tear_s": tear_s, "tear_faces_opened": int(np.median(faces)),
            "cut_s": cut_s, "cut_depth_m": depth, "cut_new_nodes": int(np.median(cut_nodes))}


def run_topology_bench(sizes=(10_000,), repeats: int = 9, progress=None) -> dict:
    """The topology benchmark's JSON object: machine, results (default liver first), targets met."""
    results = [bench_topology_mesh(name, mesh, repeats)
               for name, mesh in livers(sizes, progress, "tearing and cutting")]
    slowest = max(results[0]["tear_s"], results[0]["cut_s"])
    met = {"default_topology_change_s_max": slowest <= TOPOLOGY_TARGETS["default_topology_change_s_max"]}
    return {"benchmark": "topology", "machine": machine(), "results": results, "targets": TOPOLOGY_TARGETS,
            "met": met}
