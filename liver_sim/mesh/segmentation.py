"""A patient's organ from one label of a segmentation: voxels → closed surface → tets in the liver frame.

:func:`mesh_from_label` (docs/segmentation.md):

1. the label's voxels, cropped and padded with empty voxels so the surface closes where the label touches the
   volume's edge (an organ cut off by the scan gets a flat face there, and a warning naming the faces);
2. thin bridges cut (an opening with the cross of the fine voxel axes, kept only to split components), the largest
   face-connected component kept, the others reported by volume, enclosed cavities filled and reported: the organ
   is one solid;
3. decimation to the resolution the target needs: the mask averaged over blocks of at most a third of the
   stuffing spacing h = (12 V / T)^(1/3) per axis (a lattice tet holds h³/12);
4. marching cubes at 0.5 (scikit-image), voxel indices → patient LPS metres, Taubin smoothing (λ, −ν: no shrinking);
5. the product's isosurface stuffing of that surface (io.tetrahedralize_surface), its largest connected part kept;
6. placement: the liver frame's axes are the patient's (+x left, +y posterior, +z superior: up is superior, the
   front is anterior, −y), its origin the centre of the mesh's bounding box;
7. the largest distance between the mesh's skin and the label's boundary (the voxel faces between the kept label
   and the rest), both ways, in voxel steps (index space) and in millimetres.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse import csgraph

from liver_sim.mesh.io import ORGAN_SIZE_RANGE_M, tetrahedralize_surface
from liver_sim.mesh.label_volume import LabelVolume
from liver_sim.mesh.signed_distance import SurfaceSignedDistance
from liver_sim.mesh.tetmesh import MeshError, TetMesh

#: Surface sampling as a fraction of the stuffing spacing: decimation blocks are at most this long.
SURFACE_SAMPLES_PER_SPACING = 3
#: Taubin smoothing: shrink factor λ, inflate factor ν (applied as −ν), passes.
TAUBIN_LAMBDA = 0.5
TAUBIN_NU = 0.53
TAUBIN_ITERATIONS = 10
#: A voxel axis counts as fine (in the bridge-cutting cross) when its spacing is at most this times the finest.
FINE_AXIS_RATIO = 1.5
#: Voxels beyond the kept part but joined to it through the label, fewer than this in one piece, were trimmed off its
#: surface (a spike, a pole voxel along a coarse axis): not a part of their own.
MIN_PART_VOXELS = 27
#: Stages :func:`mesh_from_label` reports through its `progress` callback.
STAGES = ("components", "surface", "tetrahedra", "distance")
Progress = Callable[[int, int, str], None]
_FACE_NAMES = {(0, 1.0): "left", (0, -1.0): "right", (1, 1.0): "posterior", (1, -1.0): "anterior",
               (2, 1.0): "superior", (2, -1.0): "inferior"}


@dataclass(frozen=True, eq=False)
class LabelMesh:
    """The organ's tet mesh in the liver frame and how it was made.

    `lps_origin_mm`: where the liver frame's origin lies in the scanner's LPS coordinates (mm); a point p (m) of the
    mesh is at lps_origin_mm + 1000·p there.  `kept_mask` (voxels, the volume's indices offset by `mask_offset`) is
    the solid the mesh stands for: the largest component, cavities filled."""

    mesh: TetMesh
    lps_origin_mm: np.ndarray
    kept_mask: np.ndarray
    mask_offset: np.ndarray
    label_voxels: int
    label_volume_ml: float
    kept_volume_ml: float
    other_components_ml: tuple
    cavities_ml: float
    touched_faces: tuple
    max_distance_voxels: float
    max_distance_mm: float
    warnings: tuple

    def to_liver_frame_m(self, index_points: np.ndarray, affine_lps_mm: np.ndarray) -> np.ndarray:
        """Points given as voxel indices of the volume (…, 3) → the liver frame (m)."""
        return (_apply(affine_lps_mm, index_points) - self.lps_origin_mm) / 1000.0


def mesh_from_label(volume: LabelVolume, label: int, mask: np.ndarray, target_tets: int,
                    progress: Progress | None = None) -> LabelMesh:
    """The tet mesh of `mask` (the voxels of `label` in `volume`) with about `target_tets` tets; MeshError naming the
    file when the label is too small or too large for an organ or cannot be tetrahedralised."""
    report = progress or (lambda step, total, text: None)
    source = f"{volume.source} (label {label})"
    spacing = volume.spacing_mm
    voxel_ml = volume.voxel_volume_mm3 / 1e3
    label_voxels = int(np.count_nonzero(mask))
    report(1, len(STAGES), "components")
    touched = _touched_faces(mask, volume.affine_lps_mm)
    lower, upper = _bounds(mask)
    cropped = np.pad(mask[tuple(slice(lo, hi) for lo, hi in zip(lower, upper))], 1)
    offset = lower - 1
    kept, others = _largest_component(cropped, spacing)
    others_ml = tuple(sorted((count * voxel_ml for count in others), reverse=True))
    filled = ndimage.binary_fill_holes(kept)
    cavities_ml = float(np.count_nonzero(filled & ~kept)) * voxel_ml
    _check_size(source, filled, volume.affine_lps_mm, offset)
    kept_ml = float(np.count_nonzero(filled)) * voxel_ml

    report(2, len(STAGES), "surface")
    spacing_m = (12.0 * kept_ml * 1e-6 / target_tets) ** (1.0 / 3.0)
    blocks = np.maximum(1, np.floor(spacing_m * 1e3 / SURFACE_SAMPLES_PER_SPACING / spacing)).astype(int)
    vertices_index, faces = _smooth_surface(filled, blocks)
    vertices_lps_m = _apply(volume.affine_lps_mm, vertices_index + offset) / 1000.0
    vertices_lps_m, faces = _taubin(vertices_lps_m, faces)

    report(3, len(STAGES), "tetrahedra")
    stuffed = _largest_tet_part(tetrahedralize_surface(vertices_lps_m, faces, target_tets, source))
    lo, hi = stuffed.bounds
    origin_m = 0.5 * (lo + hi)
    mesh = TetMesh.from_arrays(stuffed.points - origin_m, stuffed.tets, f"{volume.source} label {label}")

    report(4, len(STAGES), "distance")
    voxels, millimetres = _skin_to_boundary(stuffed, filled, volume.affine_lps_mm, offset)
    warnings = ()
    if touched:
        warnings = (f"label {label} touches the volume's {', '.join(touched)} face(s): the organ is cut off by the "
                    "scan there; built as a closed organ, flat where the scan ends",)
    return LabelMesh(mesh, origin_m * 1000.0, filled, offset, label_voxels, label_voxels * voxel_ml, kept_ml,
                     others_ml, cavities_ml, touched, voxels, millimetres, warnings)


def boundary_quads(mask: np.ndarray) -> np.ndarray:
    """(F, 4, 3) voxel-index corners of the faces between a voxel of `mask` and one outside it (or the array's
    edge), each voxel a unit cube about its index."""
    padded = np.pad(mask.astype(bool), 1)
    quads = []
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64) - 0.5
    for axis in range(3):
        change = np.diff(padded, axis=axis)  # True between p and p + 1 along axis
        cells = np.argwhere(change).astype(np.float64) - 1.0  # padded index → mask index of the lower voxel
        others = [a for a in range(3) if a != axis]
        corners = np.repeat(cells[:, None, :], 4, axis=1)
        corners[:, :, axis] += 0.5
        corners[:, :, others[0]] += square[:, 0]
        corners[:, :, others[1]] += square[:, 1]
        quads.append(corners)
    return np.concatenate(quads)


def _apply(affine: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ affine[:3, :3].T + affine[:3, 3]


def _bounds(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower (inclusive) and upper (exclusive) voxel index of `mask`'s bounding box, per axis."""
    lower, upper = [], []
    for axis in range(3):
        present = np.flatnonzero(mask.any(axis=tuple(a for a in range(3) if a != axis)))
        lower.append(present[0])
        upper.append(present[-1] + 1)
    return np.array(lower), np.array(upper)


def _touched_faces(mask: np.ndarray, affine: np.ndarray) -> tuple:
    """The volume's faces (named 'i = 0 (right)', …) that voxels of `mask` lie on."""
    touched = []
    for axis in range(3):
        for end, index in ((0, 0), (1, mask.shape[axis] - 1)):
            if mask.take(index, axis=axis).any():
                outward = affine[:3, axis] * (1.0 if end else -1.0)
                dominant = int(np.argmax(np.abs(outward)))
                side = _FACE_NAMES[(dominant, math.copysign(1.0, outward[dominant]))]
                touched.append(f"{'ijk'[axis]} = {index} ({side})")
    return tuple(touched)


def _largest_component(mask: np.ndarray, spacing_mm: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """(kept, other voxel counts): the largest face-connected part of `mask` opened with the cross of the fine axes
    (spacing within FINE_AXIS_RATIO of the finest), which cuts bridges one fine voxel thin and trims single voxels off
    the surface; the other parts are the mask's voxels beyond one cross step of the kept one, by component, but for
    those joined to it through `mask` that are smaller than MIN_PART_VOXELS (trimmed off its surface: a spike, a pole
    voxel along a coarse axis)."""
    fine = spacing_mm <= FINE_AXIS_RATIO * spacing_mm.min()
    cross = np.zeros((3, 3, 3), dtype=bool)
    cross[1, 1, 1] = True
    for axis in np.flatnonzero(fine):
        line = [1, 1, 1]
        line[axis] = slice(None)
        cross[tuple(line)] = True
    opened = ndimage.binary_opening(mask, structure=cross)
    core = _largest(opened) if opened.any() else mask
    parts, count = ndimage.label(mask & ~ndimage.binary_dilation(core, structure=cross))
    if not count:
        return core, []
    whole, _ = ndimage.label(mask)
    joined = np.zeros(count + 1, dtype=bool)
    joined[np.unique(parts[(whole == whole[core][0]) & (parts > 0)])] = True
    sizes = np.bincount(parts.ravel(), minlength=count + 1)
    return core, [int(sizes[k]) for k in range(1, count + 1) if not joined[k] or sizes[k] >= MIN_PART_VOXELS]


def _largest(mask: np.ndarray) -> np.ndarray:
    """The largest face-connected component of a non-empty mask."""
    parts, count = ndimage.label(mask)
    if count == 1:
        return parts == 1
    return parts == 1 + int(np.argmax(np.bincount(parts.ravel())[1:]))


def _check_size(source: str, mask: np.ndarray, affine: np.ndarray, offset: np.ndarray) -> None:
    """MeshError unless the kept label's largest extent in the patient lies in ORGAN_SIZE_RANGE_M."""
    lower, upper = _bounds(mask)
    corners = np.array([[(lower if c >> a & 1 == 0 else upper)[a] - 0.5 for a in range(3)] for c in range(8)])
    extent_mm = np.ptp(_apply(affine, corners + offset), axis=0)
    low, high = ORGAN_SIZE_RANGE_M
    if extent_mm.max() < low * 1e3:
        raise MeshError(source, f"too small to be an organ: its largest part spans "
                                f"{' x '.join(f'{v:.3g}' for v in extent_mm)} mm ({np.count_nonzero(mask)} voxels), "
                                f"an organ {low * 1e3:g}-{high * 1e3:g} mm; choose the organ's label with --label")
    if extent_mm.max() > high * 1e3:
        raise MeshError(source, f"too large for an organ: {' x '.join(f'{v:.4g}' for v in extent_mm)} mm; check the "
                                "voxel spacing in the header (millimetres are expected)")


def _smooth_surface(mask: np.ndarray, blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (voxel indices of `mask`) and outward faces of the 0.5 isosurface of `mask` averaged over
    `blocks` voxels per axis (marching cubes, scikit-image)."""
    from skimage.measure import marching_cubes  # this builder's own library

    padded_shape = [(-(-size // b) + 2) * b for size, b in zip(mask.shape, blocks)]  # one empty block each side
    padded = np.zeros(padded_shape, dtype=np.float32)
    padded[tuple(slice(b, b + size) for size, b in zip(mask.shape, blocks))] = mask
    coarse = padded.reshape(padded_shape[0] // blocks[0], blocks[0], padded_shape[1] // blocks[1], blocks[1],
                            padded_shape[2] // blocks[2], blocks[2]).mean(axis=(1, 3, 5))
    vertices, faces, _, _ = marching_cubes(coarse, 0.5, allow_degenerate=False)
    vertices = vertices.astype(np.float64) * blocks + (blocks - 1) / 2.0 - blocks  # coarse → fine index
    return vertices, faces.astype(np.int64)


def _taubin(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Taubin-smoothed vertices, wound outward (the affine may mirror)."""
    import trimesh
    from trimesh.smoothing import filter_taubin

    surface = trimesh.Trimesh(vertices, faces, process=False)
    filter_taubin(surface, lamb=TAUBIN_LAMBDA, nu=TAUBIN_NU, iterations=TAUBIN_ITERATIONS)
    if surface.volume < 0:
        surface.invert()
    return np.asarray(surface.vertices, dtype=np.float64), np.asarray(surface.faces, dtype=np.int64)


def _largest_tet_part(mesh: TetMesh) -> TetMesh:
    """`mesh` without the tets not connected (through shared nodes) to its largest part, by volume."""
    edges = mesh.edges
    graph = sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])),
                              shape=(len(mesh.points), len(mesh.points)))
    count, part = csgraph.connected_components(graph, directed=False)
    if count == 1:
        return mesh
    tet_part = part[mesh.tets[:, 0]]
    largest = int(np.argmax(np.bincount(tet_part, weights=mesh.volumes, minlength=count)))
    return TetMesh.from_arrays(mesh.points, mesh.tets[tet_part == largest], mesh.source)


def _skin_to_boundary(mesh: TetMesh, mask: np.ndarray, affine: np.ndarray,
                      offset: np.ndarray) -> tuple[float, float]:
    """(voxel steps, mm): the largest distance from the skin's nodes and triangle centres to the label's boundary
    and from the boundary's face centres to the skin, measured in voxel-index space and in the patient."""
    quads = boundary_quads(mask) + offset
    quad_triangles = np.arange(4 * len(quads)).reshape(-1, 4)[:, [0, 1, 2, 0, 2, 3]].reshape(-1, 3)
    skin_lps_mm = mesh.points * 1000.0
    inverse = np.linalg.inv(affine)
    skin_index = _apply(inverse, skin_lps_mm)
    samples = lambda points: np.concatenate([points[mesh.skin_nodes], points[mesh.skin].mean(axis=1)])  # noqa: E731
    distances = []
    for quad_points, skin_points in ((quads.reshape(-1, 3), skin_index),
                                     (_apply(affine, quads.reshape(-1, 3)), skin_lps_mm)):
        to_boundary = np.abs(SurfaceSignedDistance(quad_points, quad_triangles)(samples(skin_points)))
        to_skin = np.abs(SurfaceSignedDistance(skin_points, mesh.skin)(quad_points.reshape(-1, 4, 3).mean(axis=1)))
        distances.append(float(max(to_boundary.max(), to_skin.max())))
    return distances[0], distances[1]

