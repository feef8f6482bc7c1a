"""Where a patient's liver is held, for a mesh the default support regions do not fit (docs/segmentation.md).

The physics' `support_regions` are spheres (x, y, z, radius in m, stiffness per unit skin area k_A in N/m³) in the
liver frame (physics.support).  For a mesh built from a segmentation they come from anatomy, one of:

* default, the bare area: the liver is fused to the diaphragm and the vena cava over its superior-posterior
  surface.  One sphere centred on the skin node furthest along (posterior + superior)/√2, radius
  BARE_AREA_RADIUS_FRACTION of the liver's largest side (grown to hold at least MIN_HELD_NODES skin nodes);
* a second label (e.g. the vena cava): spheres covering the liver's boundary voxels within CONTACT_MM of it;
* regions the user gives.

They travel beside the mesh in a ROS 2 parameter file, ``NAME.support.yaml`` for ``NAME.msh``, which
`liver-sim demo --mesh NAME.msh` reads and the physics node takes with ``--params-file``.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from liver_sim.mesh.tetmesh import MeshError, TetMesh

#: k_A of a derived region (N/m³): the default liver's bare area and vena cava regions.
SUPPORT_STIFFNESS_N_PER_M3 = 1.0e6
#: The bare area's radius as a fraction of the liver's largest side.
BARE_AREA_RADIUS_FRACTION = 0.15
#: A derived region holds at least this many skin nodes.
MIN_HELD_NODES = 6
#: A liver boundary voxel within this distance (mm) of the second label is held.
CONTACT_MM = 3.0
#: Radius (m) of the spheres that cover the contact with a second label (their centres on a grid of this step).
CONTACT_SPHERE_RADIUS_M = 0.012
#: The parameter file's node and keys.
PHYSICS_NODE = "liver_physics"
SUPPORT_KEYS = ("support", "support_regions")


def bare_area_region(mesh: TetMesh) -> tuple:
    """(x, y, z, radius, k_A): the sphere over the superior-posterior skin of `mesh` (liver frame, m)."""
    skin = mesh.points[mesh.skin_nodes]
    centre = skin[int(np.argmax(skin[:, 1] + skin[:, 2]))]
    radius = BARE_AREA_RADIUS_FRACTION * float(np.ptp(mesh.points, axis=0).max())
    nearest = np.sort(np.linalg.norm(skin - centre, axis=1))
    radius = max(radius, 1.01 * float(nearest[min(MIN_HELD_NODES, len(nearest)) - 1]))
    return (*(round(float(v), 6) for v in centre), round(radius, 6), SUPPORT_STIFFNESS_N_PER_M3)


def contact_regions(contact_points_m: np.ndarray) -> list[tuple]:
    """Spheres (x, y, z, radius, k_A) covering `contact_points_m` (liver frame, m): one per occupied cell of a grid
    of step CONTACT_SPHERE_RADIUS_M, centred on its points' mean, wide enough to hold them and the skin nodes
    beside them."""
    cells = np.floor(contact_points_m / CONTACT_SPHERE_RADIUS_M).astype(np.int64)
    _, which = np.unique(cells, axis=0, return_inverse=True)
    regions = []
    for cell in range(int(which.max()) + 1):
        points = contact_points_m[which.ravel() == cell]
        centre = points.mean(axis=0)
        reach = float(np.linalg.norm(points - centre, axis=1).max())
        regions.append((*(round(float(v), 6) for v in centre), round(reach + CONTACT_SPHERE_RADIUS_M / 2, 6),
                        SUPPORT_STIFFNESS_N_PER_M3))
    return regions


def held_skin_nodes(mesh: TetMesh, regions) -> int:
    """How many skin nodes of `mesh` lie inside at least one region (x, y, z, radius, …)."""
    skin = mesh.points[mesh.skin_nodes]
    held = np.zeros(len(skin), dtype=bool)
    for x, y, z, radius, *_ in regions:
        held |= np.linalg.norm(skin - (x, y, z), axis=1) <= radius
    return int(held.sum())


def user_regions(values) -> list[tuple]:
    """--support-regions X Y Z R K …: rows of five numbers, radius and stiffness > 0; ValueError naming the option."""
    values = [float(v) for v in values]
    if not values or len(values) % 5 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"--support-regions takes five finite numbers per sphere (x y z radius m, stiffness N/m^3), "
                         f"got {len(values)} numbers")
    rows = [tuple(values[i:i + 5]) for i in range(0, len(values), 5)]
    if any(radius <= 0 or stiffness <= 0 for _, _, _, radius, stiffness in rows):
        raise ValueError("--support-regions: every radius and stiffness must be > 0")
    return rows


def support_path(mesh_path) -> Path:
    """``NAME.support.yaml`` beside ``NAME.msh``."""
    mesh_path = Path(mesh_path)
    return mesh_path.with_name(f"{mesh_path.stem}.support.yaml")


def write_support(path, regions, how: str) -> Path:
    """Write `regions` as the physics node's parameters (support organ) to `path`, `how` as its comment."""
    path = Path(path)
    body = {PHYSICS_NODE: {"ros__parameters": {
        "support": "organ", "support_regions": [float(v) for region in regions for v in region]}}}
    path.write_text(f"# {how}\n" + yaml.safe_dump(body, default_flow_style=None, sort_keys=False))
    return path


def read_support(path) -> dict:
    """The physics parameters `support` and `support_regions` of a file :func:`write_support` wrote; MeshError
    naming the file when it holds anything else."""
    source = str(path)
    try:
        loaded = yaml.safe_load(Path(path).read_text())
        parameters = loaded[PHYSICS_NODE]["ros__parameters"]
        regions = [float(v) for v in parameters["support_regions"]]
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
        raise MeshError(source, f"not a support file ({type(exc).__name__}: {exc}); rebuild the mesh with "
                                "liver-sim mesh build, or delete the file") from None
    if set(parameters) - set(SUPPORT_KEYS) or not regions or len(regions) % 5:
        raise MeshError(source, f"a support file holds {PHYSICS_NODE}.ros__parameters support and support_regions "
                                "(five numbers per sphere) only")
    return {"support": str(parameters.get("support", "organ")), "support_regions": regions}
