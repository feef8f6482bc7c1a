"""`liver-sim mesh build SEGMENTATION`: a label volume → ``NAME.msh`` (or .vtu) and ``NAME.support.yaml``.

:func:`build_from_segmentation` reads the file (label_volume), meshes the label (segmentation), derives its support
(anatomical_support) and writes both files through temporary files renamed at the end, so a refused input or a
failure leaves no output behind.  It returns the summary the command prints.
"""
from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

from liver_sim.mesh.anatomical_support import (
    CONTACT_MM,
    bare_area_region,
    contact_regions,
    held_skin_nodes,
    support_path,
    write_support,
)
from liver_sim.mesh.io import checked_output_path, write_mesh
from liver_sim.mesh.label_volume import LabelVolume, read_label_volume, select_label
from liver_sim.mesh.segmentation import LabelMesh, Progress, mesh_from_label
from liver_sim.mesh.tetmesh import MeshError

#: Tet count aimed at when --target-tets is not given: fine for the anatomy, light for the 150 Hz frame.
DEFAULT_SEGMENTATION_TETS = 5000
#: The placement the summary states.
PLACEMENT = ("liver frame = patient axes: +x left, +y posterior, +z superior (up = superior, front = anterior = "
             "-y); origin at the mesh's bounding-box centre")


def build_from_segmentation(path, out, label: int | None = None, target_tets: int | None = None,
                            support_label: int | None = None, support_regions=None,
                            progress: Progress | None = None) -> dict:
    """Mesh `label` of the segmentation at `path` to about `target_tets` tets, write it to `out` and its support
    beside it (anatomical_support.support_path); return the summary.  `support_label` (a second label, e.g. the
    vena cava) or `support_regions` (rows x, y, z, radius m, k_A N/m³ in the liver frame) replace the bare area.
    MeshError / ValueError naming the file or option when refused; nothing is written then."""
    started = time.perf_counter()
    out = checked_output_path(out)
    if support_label is not None and support_regions:
        raise ValueError("give either --support-label or --support-regions, not both")
    volume = read_label_volume(path)
    label, mask = select_label(volume, label)
    if support_label is not None:
        if support_label == label:
            raise ValueError(f"--support-label {support_label} is the organ's own label; give another one (e.g. "
                             "the vena cava's)")
        support_label, support_mask = select_label(volume, support_label)
    target = target_tets or DEFAULT_SEGMENTATION_TETS
    built = mesh_from_label(volume, label, mask, target, progress)
    if support_label is not None:
        regions = contact_regions(_contact_points_m(volume, built, support_mask))
        how = (f"support: where label {support_label} touches the liver (within {CONTACT_MM:g} mm), "
               f"{len(regions)} spheres")
    elif support_regions:
        regions = [tuple(float(v) for v in row) for row in support_regions]
        how = f"support: {len(regions)} region(s) given with --support-regions"
    else:
        regions = [bare_area_region(built.mesh)]
        how = "support: the bare area, a sphere over the superior-posterior skin (derived from anatomy)"
    held = held_skin_nodes(built.mesh, regions)
    if held == 0:
        raise ValueError(f"the support regions hold no skin node of the mesh ({how}); give regions in the liver "
                         "frame (m) that reach its skin")
    support_file = support_path(out)
    _write_both(built, out, support_file, regions, f"{how}; written by liver-sim mesh build from {path}")
    lower, upper = built.mesh.bounds
    return {
        "source": str(path), "label": label, "voxels": list(volume.labels.shape),
        "spacing_mm": [round(float(v), 4) for v in volume.spacing_mm], "axes": volume.axes,
        "label_voxels": built.label_voxels, "label_volume_ml": built.label_volume_ml,
        "kept_volume_ml": built.kept_volume_ml, "other_components_ml": list(built.other_components_ml),
        "cavities_filled_ml": built.cavities_ml, "touched_faces": list(built.touched_faces),
        "mesh_volume_ml": built.mesh.volume * 1e6, "nodes": int(len(built.mesh.points)),
        "tetrahedra": int(len(built.mesh.tets)), "skin_triangles": int(len(built.mesh.skin)),
        "min_dihedral_deg": float(built.mesh.dihedral_angles_deg.min()),
        "max_surface_distance_voxels": built.max_distance_voxels,
        "max_surface_distance_mm": built.max_distance_mm, "placement": PLACEMENT,
        "lps_origin_mm": [round(float(v), 3) for v in built.lps_origin_mm],
        "size_m": [float(v) for v in upper - lower], "support": how, "support_regions": [list(r) for r in regions],
        "support_skin_nodes": held, "out": str(out), "support_file": str(support_file),
        "seconds": time.perf_counter() - started, "warnings": list(built.warnings), "sha256": built.mesh.sha256,
    }


def _contact_points_m(volume: LabelVolume, built: LabelMesh, support_mask: np.ndarray) -> np.ndarray:
    """Liver frame positions (m) of the kept label's boundary voxels within CONTACT_MM of `support_mask`;
    ValueError when there are none."""
    spacing = volume.spacing_mm
    margin = np.ceil(CONTACT_MM / spacing).astype(int) + 1  # voxels around the kept label that may touch it
    padded = np.pad(support_mask, [(m + 1, m + 1) for m in margin])  # so the window never leaves the array
    start = built.mask_offset + 1
    window = tuple(slice(s, s + n + 2 * m) for s, n, m in zip(start, built.kept_mask.shape, margin))
    distance_mm = ndimage.distance_transform_edt(~padded[window], sampling=spacing)
    liver = np.pad(built.kept_mask, [(m, m) for m in margin])
    touching = np.argwhere(liver & ~ndimage.binary_erosion(liver) & (distance_mm <= CONTACT_MM))
    if not len(touching):
        raise ValueError(f"{volume.source}: --support-label: that label does not touch the organ (no voxel within "
                         f"{CONTACT_MM:g} mm); choose the vena cava's label, or give --support-regions")
    return built.to_liver_frame_m(touching - margin + built.mask_offset, volume.affine_lps_mm)


def _write_both(built: LabelMesh, out: Path, support_file: Path, regions, how: str) -> None:
    """The mesh and its support file, each written to a temporary file beside it and renamed once both exist."""
    temporary = [out.with_name(f".{out.stem}.{os.getpid()}.partial{suffix}") for suffix in (out.suffix, ".yaml")]
    try:
        write_mesh(built.mesh, temporary[0])
        write_support(temporary[1], regions, how)
        os.replace(temporary[1], support_file)
        os.replace(temporary[0], out)
    except OSError as exc:
        raise MeshError(str(out), f"cannot write: {exc.strerror or exc}") from None
    finally:
        for name in temporary:
            with contextlib.suppress(FileNotFoundError):
                name.unlink()

