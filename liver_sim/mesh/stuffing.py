"""Isosurface stuffing: tetrahedral meshes of implicit solids with bounded dihedral angles.

Uniform (non-graded) variant of F. Labelle and J. R. Shewchuk, "Isosurface
Stuffing: Fast Tetrahedral Meshes with Good Dihedral Angles", ACM Trans. Graph.
26(3), 2007.  The solid is ``{x : f(x) <= 0}`` for a signed distance ``f`` in
metres, negative inside.

1. Body-centred cubic (BCC) lattice of spacing ``h`` anchored at ``lower``:
   cube corners ``lower + h (i, j, k)`` and cube centres ``lower + h (i, j, k) + h/2 (1, 1, 1)``,
   padded by one cube on every side of the box.  Every lattice tet joins two
   neighbouring centres (a *long* edge, length h) to one of the four corner-grid
   edges of the square face between them (the other long edge); its four other
   edges are *short* (length sqrt(3)/2 h).
2. ``f`` at every lattice vertex.
3. A cut point on every edge whose ends have strictly opposite signs, found by
   bisection (fixed step count) and a final regula-falsi step.
4. Warping: a cut point closer to an end than ``alpha`` times the edge length
   *violates* that end (alpha = ALPHA_LONG or ALPHA_SHORT by edge type).  Each
   violated vertex moves onto its nearest violating cut point and becomes a zero
   vertex; the cut points on its other edges disappear.
5. Stencils: each lattice tet is replaced by its part where f <= 0, split into
   tets according to the signs (-, 0, +) of its four vertices.  Quadrilaterals on
   lattice faces take the diagonal that ends at the cut point of the face's long
   edge; when the long edge joins the two inside vertices, the *parity rule*
   decides, so that the tets on both sides of the face agree.

With the paper's alphas every output dihedral angle lies in about [10.7, 164.8]
degrees, whatever the surface.  The arrays depend only on the inputs: the same
call gives byte-identical meshes.
"""
from __future__ import annotations

import math
from functools import lru_cache
from itertools import product
from typing import Callable

import numpy as np

from liver_sim.mesh.tetmesh import TetMesh

SignedDistance = Callable[[np.ndarray], np.ndarray]

#: Warping thresholds of the paper (uniform lattice), as fractions of the edge length.
ALPHA_LONG = 0.24999
ALPHA_SHORT = 0.41189
#: Bisection halvings per cut point: the bracket shrinks to 2**-30 of the edge.
CUT_BISECTION_STEPS = 30
#: Refuse lattices beyond this many vertices (memory guard: about six lattice tets per vertex).
MAX_LATTICE_VERTICES = 4_000_000
#: Significant digits of the spacings tried by :func:`tetrahedralize_to_target`.
SPACING_DIGITS = 5

# Local vertex order of a lattice tet: (a_low, a_high, b_low, b_high), where a and b
# are its two long edges, each listed with the end of smaller coordinate first.
_LOCAL_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
_LONG_LOCAL_EDGES = ((0, 1), (2, 3))
# Face opposite local vertex o (the parity bit o): (long-edge low end, high end, apex).
_PARITY_FACES = {3: (0, 1, 2), 2: (0, 1, 3), 1: (2, 3, 0), 0: (2, 3, 1)}


def tetrahedralize_implicit(signed_distance: SignedDistance, lower, upper, spacing: float,
                            source: str = "<implicit>") -> TetMesh:
    """Stuff the solid ``signed_distance <= 0`` inside the box [lower, upper] (m) with BCC spacing (m).

    ``signed_distance`` maps points (N, 3) to values (N,), negative inside, and
    should be about 1-Lipschitz.  Returns a validated :class:`TetMesh`; raises
    ValueError when the arguments are unusable or the box holds no solid.
    """
    points, tets = _stuff(signed_distance, lower, upper, spacing)
    if len(tets) == 0:
        raise ValueError(f"{source}: no solid inside the box at spacing {spacing} m")
    return TetMesh.from_arrays(points, tets, source)


def tetrahedralize_to_target(signed_distance: SignedDistance, lower, upper, target_tets: int,
                             source: str = "<implicit>", tolerance: float = 0.01,
                             max_evaluations: int = 16) -> TetMesh:
    """Stuff the solid with the spacing whose tet count is nearest ``target_tets`` (within ±10 %).

    Deterministic search on the spacing h: start from the box volume (a lattice
    tet has volume h^3/12), then secant steps on log(count) against log(h),
    bisection once the target is bracketed; stop within ``tolerance`` (relative)
    or after ``max_evaluations`` stuffings.  Spacings are rounded to
    SPACING_DIGITS significant digits.  Raises ValueError when no spacing tried
    lands within 10 % of the target.
    """
    target = int(target_tets)
    if target < 1:
        raise ValueError(f"{source}: target tet count must be positive, got {target_tets}")
    lower, upper = _box(lower, upper)
    box_volume = float(np.prod(upper - lower))
    tried: dict[float, int] = {}
    best: dict = {}  # spacing, points and tets of the count nearest the target so far

    def count(h: float) -> int:
        if h not in tried:
            points, tets = _stuff(signed_distance, lower, upper, h)
            tried[h] = len(tets)
            if not best or (abs(len(tets) - target), h) < (abs(len(best["tets"]) - target), best["h"]):
                best.update(h=h, points=points, tets=tets)
        return tried[h]

    h = _round_spacing((12.0 * box_volume / target) ** (1.0 / 3.0))
    for _ in range(max_evaluations):
        n = count(h)
        if abs(n - target) <= tolerance * target:
            break
        h = _next_spacing(h, tried, target)
        if h in tried:
            break
    if abs(len(best["tets"]) - target) > 0.1 * target:
        raise ValueError(f"{source}: no spacing gives {target} tets within 10 % "
                         f"(nearest: {len(best['tets'])} tets at spacing {best['h']} m)")
    return TetMesh.from_arrays(best["points"], best["tets"], source)


def _round_spacing(h: float) -> float:
    """h rounded to SPACING_DIGITS significant digits, so searches revisit identical spacings."""
    return float(f"{h:.{SPACING_DIGITS}g}")


def _next_spacing(h: float, tried: dict[float, int], target: int) -> float:
    """Next spacing to try: secant in (log h, log count) inside the bracket, else a cube-law step."""
    finer = [s for s, n in tried.items() if n > target]    # too many tets: spacing too small
    coarser = [s for s, n in tried.items() if n < target]  # too few tets: spacing too large
    if finer and coarser:
        h_lo, h_hi = max(finer), min(coarser)
        n_lo, n_hi = tried[h_lo], tried[h_hi]
        log_lo, log_hi = math.log(h_lo), math.log(h_hi)
        if n_hi > 0:
            frac = (math.log(n_lo) - math.log(target)) / (math.log(n_lo) - math.log(n_hi))
            frac = min(max(frac, 0.1), 0.9)
        else:
            frac = 0.5
        candidate = _round_spacing(math.exp(log_lo + frac * (log_hi - log_lo)))
        if candidate in tried:
            candidate = _round_spacing(math.exp(0.5 * (log_lo + log_hi)))
        return candidate
    n = tried[h]
    if n == 0:
        return _round_spacing(0.5 * h)
    return _round_spacing(h * (n / target) ** (1.0 / 3.0))


def _box(lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """Validated float64 box corners."""
    lower = np.asarray(lower, dtype=np.float64).reshape(3)
    upper = np.asarray(upper, dtype=np.float64).reshape(3)
    if not (np.isfinite(lower).all() and np.isfinite(upper).all() and (upper > lower).all()):
        raise ValueError(f"invalid box: lower {lower.tolist()}, upper {upper.tolist()}")
    return lower, upper


def _stuff(signed_distance: SignedDistance, lower, upper, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Raw stuffing: node positions (N, 3) and tets (M, 4), possibly with unused nodes."""
    lower, upper = _box(lower, upper)
    h = float(spacing)
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"spacing must be a positive length in metres, got {spacing}")
    doubled, tets = _bcc_lattice(lower, upper, h)
    positions = lower + doubled * (0.5 * h)
    values = _evaluate(signed_distance, positions)

    edge_u, edge_v = _cut_edges(tets, values)
    long_edge = np.abs(doubled[edge_u] - doubled[edge_v]).sum(axis=1) == 2
    t = _cut_parameters(signed_distance, positions, values, edge_u, edge_v)
    start, stop = positions[edge_u], positions[edge_v]
    cut_points = start + t[:, None] * (stop - start)
    positions, values, warped = _warp(positions, values, edge_u, edge_v, t, long_edge, h, cut_points)

    active = ~(warped[edge_u] | warped[edge_v])
    keys = edge_u[active] * len(positions) + edge_v[active]
    kept = tets[(values[tets] < 0.0).any(axis=1)]
    out = _apply_stencils(kept, doubled, values, keys)
    return np.concatenate([positions, cut_points[active]]), out


def _evaluate(signed_distance: SignedDistance, points: np.ndarray) -> np.ndarray:
    """f at the points, checked to be one finite value per point."""
    values = np.asarray(signed_distance(points), dtype=np.float64)
    if values.shape != (len(points),):
        raise ValueError(f"signed distance returned shape {values.shape}, expected ({len(points)},)")
    if not np.isfinite(values).all():
        raise ValueError("signed distance returned NaN or infinite values")
    return values


def _bcc_lattice(lower: np.ndarray, upper: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Doubled integer coordinates (V, 3) of the BCC vertices and the lattice tets (T, 4).

    Corners have even doubled coordinates 2i (i = -1 .. n + 1), centres odd ones
    2j + 1 (j = -1 .. n), with n = ceil((upper - lower) / h) per axis; the
    position of doubled coordinate D is lower + D h / 2.
    """
    n = np.maximum(np.ceil((upper - lower) / h).astype(np.int64), 1)
    corner_shape, centre_shape = n + 3, n + 2
    n_corners = int(np.prod(corner_shape))
    if n_corners + int(np.prod(centre_shape)) > MAX_LATTICE_VERTICES:
        raise ValueError(f"spacing {h} m gives a lattice of {n.tolist()} cubes, too many vertices")
    corners = np.indices(corner_shape).reshape(3, -1).T - 1
    centres = np.indices(centre_shape).reshape(3, -1).T - 1
    doubled = np.concatenate([2 * corners, 2 * centres + 1])

    def corner_id(i: np.ndarray) -> np.ndarray:
        return ((i[:, 0] + 1) * corner_shape[1] + i[:, 1] + 1) * corner_shape[2] + i[:, 2] + 1

    def centre_id(j: np.ndarray) -> np.ndarray:
        return n_corners + ((j[:, 0] + 1) * centre_shape[1] + j[:, 1] + 1) * centre_shape[2] + j[:, 2] + 1

    blocks = []
    for k in range(3):
        m, l = (k + 1) % 3, (k + 2) % 3
        e_k, e_m, e_l = np.eye(3, dtype=np.int64)[[k, m, l]]
        j = centres[centres[:, k] < n[k]]  # centres whose +k neighbour exists
        c_low, c_high = centre_id(j), centre_id(j + e_k)
        face = j + e_k  # lowest corner of the square face between the two centres
        for p, q in ((face, face + e_m), (face + e_l, face + e_l + e_m),
                     (face, face + e_l), (face + e_m, face + e_m + e_l)):
            blocks.append(np.stack([c_low, c_high, corner_id(p), corner_id(q)], axis=1))
    return doubled, np.concatenate(blocks)


def _cut_edges(tets: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique lattice edges (u < v) whose end values have strictly opposite signs, sorted."""
    signs = np.sign(values)
    mixed = tets[(signs[tets].min(axis=1) < 0) & (signs[tets].max(axis=1) > 0)]
    pairs = np.concatenate([mixed[:, [a, b]] for a, b in _LOCAL_EDGES])
    pairs = pairs[signs[pairs[:, 0]] * signs[pairs[:, 1]] < 0]
    pairs = np.unique(np.sort(pairs, axis=1), axis=0)
    return pairs[:, 0], pairs[:, 1]


def _cut_parameters(signed_distance: SignedDistance, positions: np.ndarray, values: np.ndarray,
                    edge_u: np.ndarray, edge_v: np.ndarray) -> np.ndarray:
    """Zero crossing t in (0, 1) of f along each edge u -> v: bisection, then one regula-falsi step."""
    start, stop = positions[edge_u], positions[edge_v]
    lo, hi = np.zeros(len(edge_u)), np.ones(len(edge_u))
    f_lo, f_hi = values[edge_u].copy(), values[edge_v].copy()
    for _ in range(CUT_BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        f_mid = _evaluate(signed_distance, start + mid[:, None] * (stop - start))
        same_as_lo = np.sign(f_mid) == np.sign(f_lo)
        on_surface = f_mid == 0.0
        lo = np.where(same_as_lo | on_surface, mid, lo)
        f_lo = np.where(same_as_lo | on_surface, f_mid, f_lo)
        hi = np.where(same_as_lo, hi, mid)
        f_hi = np.where(same_as_lo, f_hi, f_mid)
    drop = f_lo - f_hi
    return lo + (hi - lo) * np.divide(f_lo, drop, out=np.zeros_like(drop), where=drop != 0.0)


def _warp(positions: np.ndarray, values: np.ndarray, edge_u: np.ndarray, edge_v: np.ndarray,
          t: np.ndarray, long_edge: np.ndarray, h: float, cut_points: np.ndarray):
    """Move violated vertices onto their nearest violating cut point; return (positions, values, warped).

    Equivalent to visiting violated vertices one at a time: each round warps a set
    of candidates no two of which share a violating cut edge (the lower index wins
    a conflict), then re-examines the cut points that survive.
    """
    alpha = np.where(long_edge, ALPHA_LONG, ALPHA_SHORT)
    length = np.where(long_edge, h, 0.5 * math.sqrt(3.0) * h)
    edge_ids = np.arange(len(edge_u))
    at_u, at_v = t < alpha, 1.0 - t < alpha
    vertex = np.concatenate([edge_u[at_u], edge_v[at_v]])
    other = np.concatenate([edge_v[at_u], edge_u[at_v]])
    edge = np.concatenate([edge_ids[at_u], edge_ids[at_v]])
    distance = np.concatenate([t[at_u], 1.0 - t[at_v]]) * np.concatenate([length[at_u], length[at_v]])

    positions, values = positions.copy(), values.copy()
    warped = np.zeros(len(positions), dtype=bool)
    candidate = np.zeros(len(positions), dtype=bool)
    while True:
        alive = ~(warped[vertex] | warped[other])
        vertex, other, edge, distance = vertex[alive], other[alive], edge[alive], distance[alive]
        if len(vertex) == 0:
            return positions, values, warped
        candidate[:] = False
        candidate[vertex] = True
        blocked = np.maximum(vertex, other)[candidate[other]]
        order = np.lexsort((edge, distance, vertex))
        first = order[np.r_[True, vertex[order][1:] != vertex[order][:-1]]]
        chosen = first[~np.isin(vertex[first], blocked)]
        positions[vertex[chosen]] = cut_points[edge[chosen]]
        values[vertex[chosen]] = 0.0
        warped[vertex[chosen]] = True


def _apply_stencils(tets: np.ndarray, doubled: np.ndarray, values: np.ndarray, cut_keys: np.ndarray) -> np.ndarray:
    """Output tets (global ids) of the lattice tets, cut points numbered len(values) + rank in cut_keys."""
    digits = (np.sign(values[tets]) + 1).astype(np.int64)
    pattern = digits @ np.array([1, 3, 9, 27])
    parity = np.zeros(len(tets), dtype=np.int64)
    for opposite, (a, b, apex) in _PARITY_FACES.items():
        offset = 2 * doubled[tets[:, apex]] - doubled[tets[:, a]] - doubled[tets[:, b]]
        sigma = np.where(offset == 0, 1, np.sign(offset)).prod(axis=1)
        parity |= (sigma > 0).astype(np.int64) << opposite

    local_to_global = np.full((len(tets), 10), -1, dtype=np.int64)
    local_to_global[:, :4] = tets
    n_nodes = len(values)
    padded_keys = np.append(cut_keys, -1)  # sentinel: searchsorted may return len(cut_keys)
    for e, (a, b) in enumerate(_LOCAL_EDGES):
        key = np.minimum(tets[:, a], tets[:, b]) * n_nodes + np.maximum(tets[:, a], tets[:, b])
        rank = np.searchsorted(cut_keys, key)
        found = padded_keys[rank] == key
        local_to_global[found, 4 + e] = n_nodes + rank[found]

    table, counts = _stencil_table()
    code = pattern * 16 + parity
    rows, slots = np.nonzero(np.arange(3) < counts[code][:, None])
    out = np.take_along_axis(local_to_global[rows], table[code[rows], slots], axis=1)
    if (out < 0).any():
        raise RuntimeError("isosurface stuffing: a stencil refers to a missing cut point")
    return out


def _cut(a: int, b: int) -> int:
    """Local id (4..9) of the cut point on the local edge joining a and b."""
    return 4 + _LOCAL_EDGES.index((min(a, b), max(a, b)))


def _diagonal_end(a: int, b: int, c: int, parity: int) -> int:
    """Which inside vertex x of face (a, b, c) (a, b inside, c outside) starts the quad's diagonal.

    The quad a, b, cut(b, c), cut(a, c) is split by the diagonal x -- cut(y, c),
    {x, y} = {a, b}.  If the face's long edge is a-c or b-c, the diagonal ends at
    that edge's cut point; if it is a-b (parity rule), it starts at the low end of
    a-b when the face's parity bit is set, else at the high end.  The bit is a
    function of the face alone (so both tets on it agree) and alternates around
    a long edge, so a (-, -, +, +) tet's two lattice quads start at opposite ends
    of it and its prism stays triangulable.
    """
    if (min(a, c), max(a, c)) in _LONG_LOCAL_EDGES:
        return b
    if (min(b, c), max(b, c)) in _LONG_LOCAL_EDGES:
        return a
    low, high = min(a, b), max(a, b)
    return low if parity >> (6 - a - b - c) & 1 else high


def _prism(bottom: tuple, top: tuple, diagonals: dict) -> list | None:
    """Three tets filling a triangular prism with lateral edges bottom[i]-top[i], or None.

    ``diagonals[(i, j)]`` (i < j) is the diagonal (a vertex pair) of the lateral
    quad bottom[i], bottom[j], top[j], top[i].  Unless the diagonals are cyclic
    (then None: no triangulation without a new vertex), some vertex meets two of
    them; the tet joining it to the opposite cap is cut off and the remaining
    pyramid is split along the third diagonal.
    """
    for cap, other_cap in ((bottom, top), (top, bottom)):
        for i, apex in enumerate(cap):
            j, k = [x for x in range(3) if x != i]
            touching = [d for (p, q), d in diagonals.items() if i in (p, q) and apex in d]
            if len(touching) == 2:
                quad = (cap[j], cap[k], other_cap[k], other_cap[j])
                if set(diagonals[(j, k)]) == {quad[0], quad[2]}:
                    halves = ((quad[0], quad[1], quad[2]), (quad[0], quad[2], quad[3]))
                else:
                    halves = ((quad[0], quad[1], quad[3]), (quad[1], quad[2], quad[3]))
                return [(apex, *other_cap)] + [(apex, *half) for half in halves]
    return None


def _quad_diagonal(a: int, b: int, c: int, parity: int) -> tuple:
    """The diagonal (vertex pair) of the quad a, b, cut(b, c), cut(a, c)."""
    x = _diagonal_end(a, b, c, parity)
    y = a + b - x
    return (x, _cut(y, c))


def _stencil(signs: tuple, parity: int) -> list:
    """Output tets (local ids: 0-3 lattice vertices, 4-9 cut points) of one lattice tet."""
    neg = [i for i in range(4) if signs[i] < 0]
    pos = [i for i in range(4) if signs[i] > 0]
    zero = [i for i in range(4) if signs[i] == 0]
    if not neg:
        return []
    if not pos:
        return [(0, 1, 2, 3)]
    if len(neg) == 1:
        a = neg[0]
        return [(a, *zero, *(_cut(a, p) for p in pos))]
    if len(neg) == 2 and len(pos) == 1:
        (a, b), c, z = neg, pos[0], zero[0]
        x, cut_y = _quad_diagonal(a, b, c, parity)
        y = a + b - x
        return [(z, x, y, cut_y), (z, x, cut_y, _cut(x, c))]
    if len(neg) == 2:
        (a, b), (c, d) = neg, pos
        bottom = (a, _cut(a, c), _cut(a, d))
        top = (b, _cut(b, c), _cut(b, d))
        fixed = {(0, 1): _quad_diagonal(a, b, c, parity), (0, 2): _quad_diagonal(a, b, d, parity)}
        # The isosurface quad's diagonal is free: take the one that is not cyclic.
        return (_prism(bottom, top, {**fixed, (1, 2): (bottom[1], top[2])})
                or _prism(bottom, top, {**fixed, (1, 2): (bottom[2], top[1])}))
    (a, b, c), d = neg, pos[0]
    bottom, top = (a, b, c), (_cut(a, d), _cut(b, d), _cut(c, d))
    diagonals = {}
    for i, j in ((0, 1), (0, 2), (1, 2)):
        x = _diagonal_end(bottom[i], bottom[j], d, parity)
        diagonals[(i, j)] = (x, top[j] if x == bottom[i] else top[i])
    tets = _prism(bottom, top, diagonals)
    if tets is None:  # cannot happen: two faces' diagonals meet at the cut on the long edge
        raise AssertionError("cyclic stencil diagonals")
    return tets


@lru_cache(maxsize=1)
def _stencil_table() -> tuple[np.ndarray, np.ndarray]:
    """Table (81 * 16, 3, 4) of local output tets and their counts, indexed by pattern * 16 + parity.

    pattern = sum (sign_i + 1) 3^i over the four vertices; parity bit o belongs to
    the face opposite vertex o.
    """
    table = np.zeros((81 * 16, 3, 4), dtype=np.int64)
    counts = np.zeros(81 * 16, dtype=np.int64)
    for signs in product((-1, 0, 1), repeat=4):
        pattern = sum((s + 1) * 3 ** i for i, s in enumerate(signs))
        for parity in range(16):
            tets = _stencil(signs, parity)
            counts[pattern * 16 + parity] = len(tets)
            table[pattern * 16 + parity, :len(tets)] = np.reshape(tets, (-1, 4))
    return table, counts
