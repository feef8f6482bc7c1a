"""Mesh files in and out (docs/contract.md, "Files").

:func:`load_mesh` reads volume meshes (Gmsh ``.msh`` 2.2/4.1 and the old v1 format,
VTK ``.vtu``/``.vtk``, Medit ``.mesh``) and closed surfaces (``.stl``, ``.obj``,
``.ply``, ``.off``), which are turned into tets by isosurface stuffing of their signed
distance.  :func:`write_mesh` writes ``.msh`` (Gmsh 2.2 ASCII) or ``.vtu`` with the skin
tagged.  Coordinates are read as metres after multiplying them by the caller's `scale`
(``--scale``, ``mesh_scale``), before any check or stuffing; a mesh whose bounding box is
not the size of an organ (:data:`ORGAN_SIZE_RANGE_M`) is refused with the unit factor that
would make it one.  Every refused input raises :class:`MeshError` naming the file and the
defect; reader crashes (including meshio's ``sys.exit``) are converted, never propagated.
"""
from __future__ import annotations

import contextlib
import io
import math
from pathlib import Path

import meshio
import numpy as np
import trimesh

from liver_sim.mesh.signed_distance import SurfaceSignedDistance
from liver_sim.mesh.stuffing import tetrahedralize_to_target
from liver_sim.mesh.tetmesh import MeshError, TetMesh

#: Tet count aimed at when a surface is tetrahedralised without an explicit target.
DEFAULT_SURFACE_TETS = 1150
#: Physical group (Gmsh) / ``region`` value (VTU) of the skin triangles and of the tets.
CAPSULE_REGION = 1
PARENCHYMA_REGION = 2

VOLUME_READERS = {
    ".msh": ("Gmsh", meshio.gmsh.read),
    ".vtu": ("VTK XML", meshio.vtu.read),
    ".vtk": ("legacy VTK", meshio.vtk.read),
    ".mesh": ("Medit", meshio.medit.read),
}
SURFACE_SUFFIXES = (".stl", ".obj", ".ply", ".off")
WRITE_SUFFIXES = (".msh", ".vtu")

#: A surface triangle with area below this fraction of (bounding-box diagonal)^2 is degenerate.
DEGENERATE_RELATIVE_AREA = 1e-12
#: Longest reader error text quoted in a MeshError.
_MAX_REASON_CHARS = 200
#: Plausible largest bounding-box side of an organ (m): a mesh outside is refused (a unit mistake).
ORGAN_SIZE_RANGE_M = (0.02, 0.5)
#: Largest side (m) a suggested scale aims at: an adult liver is 0.15-0.2 m across.
TYPICAL_ORGAN_SIZE_M = 0.15


def load_mesh(path, target_tets: int | None = None, scale: float = 1.0) -> TetMesh:
    """Read a volume mesh or a closed surface file into a validated :class:`TetMesh` in metres.

    The file's coordinates times `scale` (> 0; e.g. 0.01 for a file in centimetres, 0.001 for
    millimetres) are metres.  `target_tets` is the tet count aimed at when a surface is
    tetrahedralised (default :data:`DEFAULT_SURFACE_TETS`); volume meshes are taken as they
    are and ignore it.  Raises :class:`MeshError` (file, defect) for anything refused,
    including a size implausible for an organ (:func:`check_organ_size`).
    """
    path = Path(path)
    source = str(path)
    if not (math.isfinite(scale) and scale > 0.0):
        raise MeshError(source, f"scale {scale!r} is not a finite factor > 0")
    if not path.exists():
        raise MeshError(source, "no such file")
    if not path.is_file():
        raise MeshError(source, "not a regular file")
    suffix = path.suffix.lower()
    if suffix not in VOLUME_READERS and suffix not in SURFACE_SUFFIXES:
        known = ", ".join(sorted([*VOLUME_READERS, *SURFACE_SUFFIXES]))
        raise MeshError(source, f"unsupported file format '{suffix}' (readable: {known})")
    try:
        if path.stat().st_size == 0:
            raise MeshError(source, "empty file")
        if suffix in SURFACE_SUFFIXES:
            return _load_surface(path, target_tets or DEFAULT_SURFACE_TETS, scale)
        if suffix == ".msh" and _is_gmsh_v1(path):
            points, tets = _read_gmsh_v1(path)
        else:
            points, tets = _read_volume(path, *VOLUME_READERS[suffix])
    except OSError as exc:
        raise MeshError(source, f"cannot read: {exc.strerror or exc}") from None
    mesh = TetMesh.from_arrays(np.asarray(points, dtype=np.float64) * scale, tets, source)
    check_organ_size(source, mesh.points, mesh.volume, scale)
    return mesh


def check_organ_size(source: str, points_m: np.ndarray, volume_m3: float, scale: float = 1.0) -> None:
    """MeshError unless the largest bounding-box side of `points_m` lies in :data:`ORGAN_SIZE_RANGE_M`.

    The message gives the size and volume, and the scale (a power of ten times `scale`, the one
    already applied) that brings the largest side nearest :data:`TYPICAL_ORGAN_SIZE_M`.
    """
    size = np.ptp(points_m, axis=0)
    largest = float(size.max())
    low, high = ORGAN_SIZE_RANGE_M
    if low <= largest <= high:
        return
    exponent = round(math.log10(TYPICAL_ORGAN_SIZE_M / largest)) if largest > 0.0 else 0
    suggested = float(f"{scale * 10.0 ** exponent:.6g}")
    applied = f" after scaling by {scale:g}" if scale != 1.0 else ""
    raise MeshError(source, f"implausible size for an organ: {' x '.join(f'{s:.4g}' for s in size)} m across, "
                            f"{volume_m3:.4g} m^3 ({volume_m3 * 1e3:.4g} L){applied}; an organ is "
                            f"{low:g}-{high:g} m across. Coordinates are read as metres: if the file is in "
                            f"other units, give the factor to metres with --scale (physics node: mesh_scale), "
                            f"e.g. --scale {suggested:g} (0.01 for centimetres, 0.001 for millimetres)")


def write_mesh(mesh: TetMesh, path) -> Path:
    """Write `mesh` with its skin tagged; return the path written.

    ``.msh``: Gmsh 2.2 ASCII, tets in physical group 2 "parenchyma", skin triangles in
    physical group 1 "capsule".  ``.vtu``: tets and skin triangles with the integer cell
    data ``region`` (1 = capsule skin, 2 = parenchyma).  Raises :class:`MeshError` for
    another extension or when the file cannot be written.
    """
    path = checked_output_path(path)
    cells = [meshio.CellBlock("triangle", mesh.skin), meshio.CellBlock("tetra", mesh.tets)]
    regions = [np.full(len(mesh.skin), CAPSULE_REGION, dtype=np.int32),
               np.full(len(mesh.tets), PARENCHYMA_REGION, dtype=np.int32)]
    try:
        if path.suffix.lower() == ".msh":
            tagged = meshio.Mesh(
                mesh.points, cells,
                cell_data={"gmsh:physical": regions, "gmsh:geometrical": regions},
                field_data={"capsule": np.array([CAPSULE_REGION, 2]),  # (group, dimension)
                            "parenchyma": np.array([PARENCHYMA_REGION, 3])},
            )
            meshio.gmsh.write(str(path), tagged, fmt_version="2.2", binary=False)
        else:
            meshio.vtu.write(str(path), meshio.Mesh(mesh.points, cells, cell_data={"region": regions}))
    except OSError as exc:
        raise MeshError(str(path), f"cannot write: {exc.strerror or exc}") from None
    return path


def checked_output_path(path) -> Path:
    """`path` as a Path if :func:`write_mesh` can write its format into an existing folder, else MeshError (checked
    before a long build, not after it)."""
    path = Path(path)
    if path.suffix.lower() not in WRITE_SUFFIXES:
        raise MeshError(str(path), f"unsupported output format '{path.suffix}' (writable: "
                                   f"{', '.join(WRITE_SUFFIXES)})")
    if not path.parent.is_dir():
        raise MeshError(str(path), f"cannot write: the folder {path.parent} does not exist (make it first)")
    return path


def _reason(exc: BaseException) -> str:
    """A short description of a reader's exception."""
    if isinstance(exc, SystemExit):
        return "the reader gave up"
    if isinstance(exc, UnicodeDecodeError):
        return "binary content where text was expected"
    text = " ".join(str(exc).split())
    # An ImportError is trimesh asking for an optional decoder for non-UTF-8 "text".
    if not text or isinstance(exc, ImportError):
        return "content not recognised"
    return text[:_MAX_REASON_CHARS]


def _read_volume(path: Path, format_name: str, reader) -> tuple[np.ndarray, np.ndarray]:
    """Points and concatenated tetra cells read by a meshio format reader, output silenced."""
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            data = reader(str(path))
    except (Exception, SystemExit) as exc:
        raise MeshError(str(path), f"unreadable {format_name} file: {_reason(exc)}") from None
    if not data.cells:
        raise MeshError(str(path), "empty mesh: no cells")
    blocks = [block.data for block in data.cells if block.type == "tetra"]
    if not blocks:
        found = ", ".join(sorted({block.type for block in data.cells}))
        raise MeshError(str(path), f"no tetrahedra (cell types found: {found})")
    return data.points, np.concatenate(blocks)


def _is_gmsh_v1(path: Path) -> bool:
    """True when the file starts with the v1 ``$NOD`` section (v2+ starts with ``$MeshFormat``)."""
    with path.open("rb") as stream:
        return stream.read(64).lstrip().startswith(b"$NOD")


def _read_gmsh_v1(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and type-4 (tetrahedron) elements of a Gmsh v1 file; node numbers are labels."""
    source = str(path)
    try:
        lines = path.read_bytes().decode("ascii").splitlines()
    except UnicodeDecodeError:
        raise MeshError(source, "unreadable Gmsh v1 file: not ASCII text") from None
    rows = [(number, line.split()) for number, line in enumerate(lines, 1) if line.strip()]
    index: dict[int, int] = {}
    points = []
    for number, fields in _gmsh_v1_section(rows, "$NOD", "$ENDNOD", source):
        try:
            label, coords = int(fields[0]), [float(v) for v in fields[1:]]
        except ValueError:
            raise MeshError(source, f"line {number}: malformed node") from None
        if len(coords) != 3:
            raise MeshError(source, f"line {number}: node needs a number and 3 coordinates")
        if label in index:
            raise MeshError(source, f"line {number}: node {label} defined twice")
        index[label] = len(points)
        points.append(coords)
    tets = []
    for number, fields in _gmsh_v1_section(rows, "$ELM", "$ENDELM", source):
        try:
            values = [int(v) for v in fields]
        except ValueError:
            raise MeshError(source, f"line {number}: malformed element") from None
        if len(values) < 5 or len(values) != 5 + values[4]:
            raise MeshError(source, f"line {number}: element node count does not match its nodes")
        if values[1] != 4:
            continue
        if values[4] != 4:
            raise MeshError(source, f"line {number}: tetrahedron with {values[4]} nodes")
        missing = [label for label in values[5:] if label not in index]
        if missing:
            raise MeshError(source, f"line {number}: element {values[0]} refers to undefined node {missing[0]}")
        tets.append([index[label] for label in values[5:]])
    if not tets:
        raise MeshError(source, "no tetrahedra (no type-4 elements in $ELM)")
    return np.array(points, dtype=np.float64), np.array(tets, dtype=np.int64)


def _gmsh_v1_section(rows, start: str, end: str, source: str):
    """The (line number, fields) entries between `start` and `end`, checked against the count."""
    tags = [fields[0] for _, fields in rows]
    if start not in tags:
        raise MeshError(source, f"malformed Gmsh v1 file: no {start} section")
    first = tags.index(start) + 1
    if first >= len(rows) or len(rows[first][1]) != 1 or not rows[first][1][0].isdigit():
        raise MeshError(source, f"malformed Gmsh v1 file: {start} is not followed by a count")
    count = int(rows[first][1][0])
    entries = rows[first + 1:first + 1 + count]
    closing = first + 1 + count
    if len(entries) != count or closing >= len(rows) or tags[closing] != end:
        raise MeshError(source, f"malformed Gmsh v1 file: {start} announces {count} entries "
                                f"but {end} does not follow them")
    return entries


def _load_surface(path: Path, target_tets: int, scale: float) -> TetMesh:
    """Check a closed surface file, fix its winding, scale it to metres, check its size and
    tetrahedralise its interior."""
    source = str(path)
    vertices, faces = _read_closed_surface(path)
    vertices = vertices * scale
    check_organ_size(source, vertices, float(trimesh.Trimesh(vertices, faces, process=False).volume), scale)
    return tetrahedralize_surface(vertices, faces, target_tets, source)


def tetrahedralize_surface(vertices_m: np.ndarray, faces: np.ndarray, target_tets: int, source: str) -> TetMesh:
    """The interior of a closed, outward-wound surface (vertices in m) stuffed to about `target_tets` tets;
    MeshError naming `source` when the stuffing refuses."""
    try:
        return tetrahedralize_to_target(SurfaceSignedDistance(vertices_m, faces), vertices_m.min(axis=0),
                                        vertices_m.max(axis=0), target_tets, source)
    except MeshError:
        raise
    except ValueError as exc:  # the stuffing's refusals, already prefixed with the source
        raise MeshError(source, f"cannot tetrahedralise: {str(exc).removeprefix(source + ': ')}") from None


def _read_closed_surface(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (file units) and outward-wound triangles of a watertight, non-degenerate surface."""
    source = str(path)
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            loaded = trimesh.load(source, force="mesh", process=False)
    except (Exception, SystemExit) as exc:
        raise MeshError(source, f"unreadable surface file: {_reason(exc)}") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(source, "empty surface: no triangles")
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise MeshError(source, f"{int(bad.sum())} surface vertices with NaN or infinite coordinates, "
                                f"first at vertex {int(np.argmax(bad))}")
    surface = trimesh.Trimesh(vertices, loaded.faces, process=True)  # merges STL's repeated corners
    diagonal = float(np.linalg.norm(surface.extents))
    flat = surface.area_faces <= DEGENERATE_RELATIVE_AREA * diagonal ** 2
    if flat.any():
        raise MeshError(source, f"degenerate surface: {int(flat.sum())} zero-area triangles, "
                                f"first is triangle {int(np.argmax(flat))}")
    edges = np.sort(surface.edges, axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    if (uses != 2).any():
        raise MeshError(source, f"open surface, not watertight: {int((uses == 1).sum())} boundary "
                                f"edges, {int((uses > 2).sum())} edges shared by more than two triangles")
    surface.fix_normals()
    if not surface.is_winding_consistent:
        raise MeshError(source, "surface cannot be wound consistently (non-orientable)")
    if surface.volume <= DEGENERATE_RELATIVE_AREA * diagonal ** 3:
        raise MeshError(source, "degenerate surface: encloses no volume")
    return np.asarray(surface.vertices, dtype=np.float64), np.asarray(surface.faces, dtype=np.int64)
