"""`liver-sim bench segmentation`: a CT-sized label volume to a ~30 k-tet liver by `liver-sim mesh build`, with its
wall time and peak memory (the command runs as a child process, measured from outside)."""
from __future__ import annotations

import json
import resource
import subprocess
import time
from pathlib import Path

import numpy as np

from liver_sim.base.process_settings import cli_command_line
from liver_sim.bench.machine import machine
from liver_sim.mesh.liver_shape import liver_signed_distance

#: The volume: a CT of 512 × 512 voxels per slice, 130 slices of 2.5 mm, 0.75 mm in plane (LPS, centred).
CT_SHAPE = (512, 512, 130)
CT_SPACING_MM = (0.75, 0.75, 2.5)
LIVER_LABEL, CAVA_LABEL = 1, 2
#: The vena cava: a vertical cylinder behind the liver (LPS mm: x, y of its axis, radius), label CAVA_LABEL.
CAVA_AXIS_MM = (-10.0, 62.0)
CAVA_RADIUS_MM = 12.0
SEGMENTATION_TARGETS = {"seconds_max": 60.0, "peak_memory_mb_max": 2048.0}


def ct_labels(shape=CT_SHAPE, spacing_mm=CT_SPACING_MM) -> tuple[np.ndarray, np.ndarray]:
    """(labels uint8, affine RAS mm): the default liver voxelised (label 1) with a vena cava behind it (label 2),
    on a grid centred on the liver frame's origin."""
    affine_lps = np.eye(4)
    affine_lps[:3, :3] = np.diag(spacing_mm)
    affine_lps[:3, 3] = -np.diag(spacing_mm) @ ((np.array(shape) - 1) / 2.0)
    i, j = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    labels = np.zeros(shape, dtype=np.uint8)
    for k in range(shape[2]):
        lps_mm = np.stack([i, j, np.full_like(i, k)], axis=-1).reshape(-1, 3) @ affine_lps[:3, :3].T + affine_lps[:3, 3]
        cava = np.hypot(lps_mm[:, 0] - CAVA_AXIS_MM[0], lps_mm[:, 1] - CAVA_AXIS_MM[1]) <= CAVA_RADIUS_MM
        liver = liver_signed_distance(lps_mm / 1000.0) <= 0.0
        labels[:, :, k] = np.where(liver, LIVER_LABEL, np.where(cava, CAVA_LABEL, 0)).reshape(shape[:2])
    return labels, np.diag([-1.0, -1.0, 1.0, 1.0]) @ affine_lps


def run_segmentation_bench(folder: Path, target_tets: int = 30_000, progress=None) -> dict:
    """The benchmark's JSON object: machine, the build's summary, wall time and peak memory, targets met."""
    import nibabel  # the volume's writer

    say = progress or (lambda line: None)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    say(f"writing a {' x '.join(map(str, CT_SHAPE))} label volume ({' x '.join(map(str, CT_SPACING_MM))} mm)")
    labels, affine_ras = ct_labels()
    volume_path = folder / "ct_labels.nii.gz"
    nibabel.save(nibabel.Nifti1Image(labels, affine_ras), str(volume_path))
    command = cli_command_line("mesh", "build", str(volume_path), "--label", str(LIVER_LABEL), "--support-label",
                               str(CAVA_LABEL), "--target-tets", str(target_tets), "--out", str(folder / "liver.msh"),
                               "--json")
    say(f"timing: {' '.join(command)}")
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - started
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0  # the largest child: the build
    if done.returncode != 0:
        raise RuntimeError(f"liver-sim mesh build failed ({done.returncode}): {done.stderr.strip()[-400:]}")
    summary_path = folder / "summary.json"
    build = json.loads(done.stdout)
    results = {"voxels": list(CT_SHAPE), "spacing_mm": list(CT_SPACING_MM), "target_tets": target_tets,
               "seconds": seconds, "peak_memory_mb": peak_mb, "build": build}
    met = {"seconds_max": seconds <= SEGMENTATION_TARGETS["seconds_max"],
           "peak_memory_mb_max": peak_mb < SEGMENTATION_TARGETS["peak_memory_mb_max"]}
    report = {"benchmark": "segmentation", "machine": machine(), "results": results,
              "targets": SEGMENTATION_TARGETS, "met": met}
    summary_path.write_text(json.dumps(report, indent=2))
    return report

