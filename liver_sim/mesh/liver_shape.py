"""The embedded default liver: a procedural shape, tetrahedralised by isosurface stuffing (paper P1, docs/paper.md).

Frame ``liver`` (metres), patient axes as in DICOM LPS:

* +x towards the patient's left: the large right lobe lies at -x, the thin left lobe at +x;
* +y posterior (anterior is -y);
* +z superior (cranial).

The origin is near the centre of the bounding box, which measures about
25.6 (x) × 14.2 (y) × 12.8 (z) cm; the enclosed volume is about 1.5 L.

Shape: a thick rounded right lobe (ellipsoid) smoothly united with a flat left
lobe (oblate ellipsoid, anterior and superior), domed above; the visceral face
is carved by a large sphere lying inferior, posterior and to the left, which
leaves it gently concave and facing down, back and left.
"""
from __future__ import annotations

import dataclasses
import math
from functools import lru_cache

import numpy as np

from liver_sim.mesh.stuffing import tetrahedralize_to_target
from liver_sim.mesh.tetmesh import TetMesh

#: Tet count of the default liver (paper: 1151 tetrahedra, 370 skin triangles).
DEFAULT_TARGET_TETS = 1150

RIGHT_LOBE_CENTRE = np.array([-0.048, 0.007, -0.018])
RIGHT_LOBE_RADII = np.array([0.080, 0.079, 0.084])
LEFT_LOBE_CENTRE = np.array([0.052, -0.013, 0.012])
LEFT_LOBE_RADII = np.array([0.078, 0.050, 0.030])
#: Smoothing width (m) of the union of the lobes.
LOBE_BLEND = 0.03
#: Outward normal of the visceral face (left, posterior, inferior) and a point on it.
VISCERAL_NORMAL = np.array([0.12, 0.68, -1.0]) / math.sqrt(0.12 ** 2 + 0.68 ** 2 + 1.0)
VISCERAL_POINT = np.array([-0.0297, 0.0051, -0.0152])
#: Radius (m) of the sphere carving the visceral face, and the smoothing width of its edge.
VISCERAL_RADIUS = 0.30
VISCERAL_BLEND = 0.02
#: Box (m) stuffed around the shape, with a margin on every side.
LIVER_BOX_LOWER = np.array([-0.14, -0.09, -0.08])
LIVER_BOX_UPPER = np.array([0.14, 0.09, 0.08])


def liver_signed_distance(points: np.ndarray) -> np.ndarray:
    """Approximate signed distance (m) of points (N, 3) to the liver surface, negative inside.

    d = smax(smin(E_right, E_left; LOBE_BLEND), -S_visceral; VISCERAL_BLEND), with E
    the ellipsoid distance estimate and S the visceral sphere's distance; about
    1-Lipschitz near the surface.  Only arithmetic and square roots, so the
    values are reproducible bit for bit.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lobes = _smooth_min(_ellipsoid(points, RIGHT_LOBE_CENTRE, RIGHT_LOBE_RADII),
                        _ellipsoid(points, LEFT_LOBE_CENTRE, LEFT_LOBE_RADII), LOBE_BLEND)
    sphere_centre = VISCERAL_POINT + VISCERAL_RADIUS * VISCERAL_NORMAL
    outside_visceral = np.sqrt(((points - sphere_centre) ** 2).sum(axis=1)) - VISCERAL_RADIUS
    return -_smooth_min(-lobes, outside_visceral, VISCERAL_BLEND)


def build_liver(target_tets: int) -> TetMesh:
    """The procedural liver stuffed to about ``target_tets`` tetrahedra (within 10 %), deterministic."""
    mesh = tetrahedralize_to_target(liver_signed_distance, LIVER_BOX_LOWER, LIVER_BOX_UPPER, target_tets,
                                    source="default liver")
    return dataclasses.replace(mesh, source=f"default liver ({len(mesh.tets)} tets)")


@lru_cache(maxsize=1)
def default_liver() -> TetMesh:
    """The default liver (about DEFAULT_TARGET_TETS tets), built once per process."""
    return build_liver(DEFAULT_TARGET_TETS)


def _ellipsoid(points: np.ndarray, centre: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Ellipsoid distance estimate k0 (k0 - 1) / k1, k0 = |q / r|, k1 = |q / r^2|, q = p - centre."""
    q = points - centre
    k0 = np.sqrt(((q / radii) ** 2).sum(axis=1))
    k1 = np.sqrt(((q / radii ** 2) ** 2).sum(axis=1))
    at_centre = k1 == 0.0
    return np.where(at_centre, -radii.min(), k0 * (k0 - 1.0) / np.where(at_centre, 1.0, k1))


def _smooth_min(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth minimum: min(a, b) rounded over a band of width k (m)."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)
