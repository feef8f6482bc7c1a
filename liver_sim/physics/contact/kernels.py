"""numba kernels of the tool's contact with the skin triangles (Eq. 3), shared by both integrators.

The tool over one frame (`ToolSweep`, kind TOOL_*) is a set of probes p, balls of radius r moving at v_tool;
`near_triangles` picks its candidate skin triangles.  `probe_geometry` gives, per probe and candidate
triangle, the closest point q of the triangle to p (Ericson), its barycentric weights w_a, the unit
normal n pushing the liver, the depth δ = r − |p − q| (m, negative apart; a probe inside the liver exits
through q) and the row's share of its probe's contact (shares of a probe sum to 1 or all vanish, so an
edge or corner is never counted twice).  Eq. 3 per row: F = share·max(0, λ·δ + μ·δ̇)·n, δ̇ = n·(v_tool −
Σ w_a·v_a), spread over the triangle's nodes as w_a·F; the tool feels the sum's opposite.
`add_contact_forces` applies it (the explicit frame: physics.solver.explicit_kernels.add_forces);
`contact_elements` hands the same rows, linearised, to the implicit integrator (implicit.Contacts).

Array conventions: positions `x` and velocities `v` are (N, 3) float64 in m and m/s; forces accumulate
in `f` (N, 3) in newtons.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from liver_sim.base.geometry.closest_point import closest_point_on_triangle

TOOL_NONE = 0
TOOL_SPHERE = 1
TOOL_CAPSULE = 2
TOOL_BOX = 3


class ToolSweep(NamedTuple):
    """The tool over one frame and its contact geometry (Eq. 3 on the skin triangles).

    kind: TOOL_NONE, TOOL_SPHERE, TOOL_CAPSULE or TOOL_BOX; `probes` (P, 3) m: the tool's contact probes
    (tool_geometry.tool_probes: a sphere's centre, points along a capsule's shaft, a grid on a box's faces)
    where the frame starts, each a ball of `radius_m` (0 for a box), moving at `velocity_m_s`; penalty λ
    (N/m) and μ (N·s/m); `skin` (T, 3) the skin triangles and `triangles` the candidates near the tool;
    per probe and candidate (probe_geometry's rows), the contact geometry the last step left: `nodes`,
    `weights`, `normal`, `depth` (m), `share`, `point`, and `surface_weight`: the row's part of its triangle when a
    ball meets the skin as a surface (contact.tool_geometry.contact_rows): γ where the closest point is the triangle's
    interior, γ/2 on an edge (the two triangles sharing it), 0 at a corner (a node's own contact), γ the
    local-minimum fade of probe_geometry.
    """

    kind: int
    probes: np.ndarray
    radius_m: float
    velocity_m_s: np.ndarray
    stiffness_n_per_m: float
    damping_ns_per_m: float
    skin: np.ndarray
    triangles: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    share: np.ndarray
    point: np.ndarray
    surface_weight: np.ndarray


@numba.njit(cache=True)
def near_triangles(x, skin, centre, reach):
    """Indices of the skin triangles whose centroid lies within `reach` + the largest circumradius
    (centroid to corner, over all the skin) of `centre` (m): the tool's candidate triangles."""
    count = skin.shape[0]
    centroids = np.empty((count, 3))
    spread = 0.0
    for t in range(count):
        for a in range(3):
            centroids[t, a] = (x[skin[t, 0], a] + x[skin[t, 1], a] + x[skin[t, 2], a]) / 3.0
        for c in range(3):
            d2 = 0.0
            for a in range(3):
                d = x[skin[t, c], a] - centroids[t, a]
                d2 += d * d
            spread = max(spread, d2)
    limit = (reach + math.sqrt(spread)) ** 2
    near = np.empty(count, dtype=np.int64)
    found = 0
    for t in range(count):
        d2 = 0.0
        for a in range(3):
            d = centroids[t, a] - centre[a]
            d2 += d * d
        if d2 <= limit:
            near[found] = t
            found += 1
    return near[:found]


@numba.njit(cache=True, inline="always")
def _barycentric(q, corners):
    """Barycentric weights (3-tuple, ≥ 0, sum 1) of a point q of the triangle `corners` (3, 3)."""
    ax, ay, az = corners[0, 0], corners[0, 1], corners[0, 2]
    v0 = (corners[1, 0] - ax, corners[1, 1] - ay, corners[1, 2] - az)
    v1 = (corners[2, 0] - ax, corners[2, 1] - ay, corners[2, 2] - az)
    v2 = (q[0] - ax, q[1] - ay, q[2] - az)
    d00 = v0[0] * v0[0] + v0[1] * v0[1] + v0[2] * v0[2]
    d01 = v0[0] * v1[0] + v0[1] * v1[1] + v0[2] * v1[2]
    d11 = v1[0] * v1[0] + v1[1] * v1[1] + v1[2] * v1[2]
    d20 = v2[0] * v0[0] + v2[1] * v0[1] + v2[2] * v0[2]
    d21 = v2[0] * v1[0] + v2[1] * v1[1] + v2[2] * v1[2]
    denom = d00 * d11 - d01 * d01
    if denom <= 0.0:
        return 1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0
    b = max((d11 * d20 - d01 * d21) / denom, 0.0)
    c = max((d00 * d21 - d01 * d20) / denom, 0.0)
    a = max(1.0 - b - c, 0.0)
    total = a + b + c
    return a / total, b / total, c / total


#: Distance (m) over which a closest point on an edge or corner fades out as a triangle sharing that
#: feature comes nearer (probe_geometry).
FEATURE_FADE_M = 3e-4


@numba.njit(cache=True, inline="always")
def _local_minimum(skin, triangles, feature, distance, t):
    """1 for a row whose closest point is a triangle's interior; for one on an edge or corner, 1 − (its
    distance − the least distance of the candidates holding that feature)/FEATURE_FADE_M, clipped to 0..1:
    the point is then no local minimum of the distance to the skin (a neighbour is nearer), and fades out
    continuously as the neighbour pulls ahead.  `feature` and `distance`: the candidates' closest features
    (Ericson's numbering) and distances."""
    f = feature[t]
    if f == 6:
        return 1.0
    tri = skin[triangles[t]]
    a = tri[f] if f < 3 else tri[f - 3]
    b = a if f < 3 else tri[(f - 2) % 3]
    dist = distance[t]
    least = dist
    for s in range(triangles.shape[0]):
        other = skin[triangles[s]]
        has_a = other[0] == a or other[1] == a or other[2] == a
        has_b = other[0] == b or other[1] == b or other[2] == b
        if s != t and has_a and has_b:
            least = min(least, distance[s])
    return min(max(1.0 - (dist - least) / FEATURE_FADE_M, 0.0), 1.0)


@numba.njit(cache=True)
def probe_geometry(x, v, tool, shift, dt):
    """The contacts of the `tool`'s probes p (a ToolSweep: `probes` + `shift`, balls of `radius_m` moving at
    `velocity_m_s`) with its candidate skin `triangles`, written into its row arrays: row c·T + t for probe c and
    candidate t (T candidates).  Each row is the triangle's `nodes`, the barycentric `weights` of its closest
    point q to p (Ericson), the unit `normal`
    pushing the liver (from p to q; from q to p when p lies behind the triangle's outward face; the inward
    face normal when p is on it), the `depth` δ = radius ∓ |p − q| (m, negative apart), q (`point`), and
    the row's `share` of its probe's contact: s_t/Σ s, s_t = γ_t·max(δ_t, 0)² (when no row of the probe
    touches, max(δ_t + dt·δ̇_t, 0)²: touching after `dt` at the nodes' and the tool's velocity), γ_t: 1 where q is
    a local minimum of the distance to the skin, fading to 0 where a triangle sharing q's edge or corner is nearer
    (_local_minimum; 0 on a row touching neither now nor after `dt`, which then has no share); `surface_weight`: γ_t
    on a triangle's interior, γ_t/2 on an edge, 0 at a corner.  A probe
    inside the liver (behind the outward face of its nearest triangle, at d_min) leaves through q: normals from q to
    p and δ = radius + 2·d_min − |p − q|, radius + d_min on the nearest row, continuous with the outside form at
    d_min = 0 and negative on far triangles.

    The shares of a probe sum to 1 (or all vanish), so a probe is never counted twice where triangles share
    the closest edge or corner; on a flat or convex skin only the nearest point acts (exactly Eq. 3 there);
    every δ_t, γ_t and share is a continuous function of the tool and the mesh (a triangle enters with share
    0): the force is continuous as the tool slides over edges and corners, and the contact direction blends
    between the local minima where the skin wraps around the tool (a dent) instead of jumping.
    """
    skin, triangles, probes, radius, tool_velocity = tool.skin, tool.triangles, tool.probes, tool.radius_m, \
        tool.velocity_m_s
    nodes, weights, normal, depth, share, point = tool.nodes, tool.weights, tool.normal, tool.depth, tool.share, \
        tool.point
    surface_weight = tool.surface_weight
    count = triangles.shape[0]
    feature = np.empty(count, dtype=np.int64)
    distance = np.empty(count)
    ahead = np.empty(count)
    fade = np.empty(count)
    for c in range(probes.shape[0]):
        p = (probes[c, 0] + shift[0], probes[c, 1] + shift[1], probes[c, 2] + shift[2])
        nearest_d = np.inf
        inside = False
        for t in range(count):  # closest points; the nearest triangle's outward face says whether p is inside
            row = c * count + t
            tri = skin[triangles[t]]
            corners = x[tri]
            q, feature[t] = closest_point_on_triangle(p, corners)
            ox, oy, oz = q[0] - p[0], q[1] - p[1], q[2] - p[2]
            dist = math.sqrt(ox * ox + oy * oy + oz * oz)
            e1 = corners[1] - corners[0]
            e2 = corners[2] - corners[0]
            fx = e1[1] * e2[2] - e1[2] * e2[1]
            fy = e1[2] * e2[0] - e1[0] * e2[2]
            fz = e1[0] * e2[1] - e1[1] * e2[0]
            fn = math.sqrt(fx * fx + fy * fy + fz * fz)
            if dist > 1e-12:
                normal[row, 0], normal[row, 1], normal[row, 2] = ox / dist, oy / dist, oz / dist
            else:  # p on the triangle: the inward face normal
                normal[row, 0], normal[row, 1], normal[row, 2] = -fx / fn, -fy / fn, -fz / fn
            distance[t] = dist
            point[row, 0], point[row, 1], point[row, 2] = q[0], q[1], q[2]
            a, b, w = _barycentric(q, corners)
            weights[row, 0], weights[row, 1], weights[row, 2] = a, b, w
            for k in range(3):
                nodes[row, k] = tri[k]
            if dist < nearest_d:
                nearest_d = dist
                inside = dist > 1e-12 and ox * fx + oy * fy + oz * fz > 0.0  # q − p along the outward face
        touching = False
        for t in range(count):
            row = c * count + t
            dist = distance[t]
            if inside:  # p exits through q: the nearest row is δ = radius + its distance, farther ones less
                for k in range(3):
                    normal[row, k] = -normal[row, k]
                depth[row] = radius + 2.0 * nearest_d - dist
            else:
                depth[row] = radius - dist
            nx, ny, nz = normal[row, 0], normal[row, 1], normal[row, 2]
            rate = nx * tool_velocity[0] + ny * tool_velocity[1] + nz * tool_velocity[2]
            for k in range(3):
                n = nodes[row, k]
                rate -= weights[row, k] * (nx * v[n, 0] + ny * v[n, 1] + nz * v[n, 2])
            ahead[t] = max(depth[row] + dt * rate, 0.0)
            # γ_t weighs only rows that touch now or after dt (a share and a surface weight of 0 otherwise)
            fade[t] = _local_minimum(skin, triangles, feature, distance, t) if depth[row] > 0.0 or ahead[t] > 0.0 \
                else 0.0
            surface_weight[row] = fade[t] if feature[t] == 6 else (0.5 * fade[t] if feature[t] >= 3 else 0.0)
            touching = touching or depth[row] > 0.0
        total = 0.0
        for t in range(count):  # shared by the rows touching now; by those touching after dt when none does
            row = c * count + t
            reach = max(depth[row], 0.0) if touching else ahead[t]
            share[row] = fade[t] * reach * reach
            total += share[row]
        for t in range(count):
            row = c * count + t
            share[row] = share[row] / total if total > 0.0 else 0.0


@numba.njit(cache=True)
def add_contact_forces(x, v, tool, shift, dt, f):
    """Eq. 3 between the tool's probes (moved by `shift`) and the skin triangles (probe_geometry, shares
    from a step of `dt`): each row pushes its closest point q with share·max(0, λ·δ + μ·δ̇)·n, δ̇ = n·(v_tool
    − Σ w_a·v_a), spread over the triangle's nodes as w_a times that.  Returns the total force on the liver
    (the tool feels its opposite); the rows' geometry is left in the tool's arrays."""
    t = tool
    probe_geometry(x, v, t, shift, dt)
    tx, ty, tz = 0.0, 0.0, 0.0
    for c in range(t.depth.shape[0]):
        if not (t.share[c] > 0.0 and t.depth[c] > 0.0):
            continue
        nx, ny, nz = t.normal[c, 0], t.normal[c, 1], t.normal[c, 2]
        rate = nx * t.velocity_m_s[0] + ny * t.velocity_m_s[1] + nz * t.velocity_m_s[2]
        for k in range(3):
            n = t.nodes[c, k]
            rate -= t.weights[c, k] * (nx * v[n, 0] + ny * v[n, 1] + nz * v[n, 2])
        magnitude = t.share[c] * max(0.0, t.stiffness_n_per_m * t.depth[c] + t.damping_ns_per_m * rate)
        for k in range(3):
            n = t.nodes[c, k]
            g = t.weights[c, k] * magnitude
            f[n, 0] += g * nx
            f[n, 1] += g * ny
            f[n, 2] += g * nz
        tx += magnitude * nx
        ty += magnitude * ny
        tz += magnitude * nz
    return np.array([tx, ty, tz])


@numba.njit(cache=True)
def contact_elements(x, nodes, weights, normal, depth, row_stiffness, row_damping, tool_velocity):
    """The contact rows with a stiffness > 0, as penalty elements linearised about the skin at x (implicit.Contacts'
    fields): their nodes, weights and normal; offset o = δ + n·Σ w_a·x_a (so that δ = o − n·Σ w_a·x_a); speed
    n·v_tool; `row_stiffness` k and `row_damping` c (Eq. 3)."""
    count = 0
    for r in range(row_stiffness.shape[0]):
        if row_stiffness[r] > 0.0:
            count += 1
    nodes_out = np.empty((count, 3), dtype=np.int64)
    weights_out = np.empty((count, 3))
    normal_out = np.empty((count, 3))
    offset = np.empty(count)
    speed = np.empty(count)
    k = np.empty(count)
    c = np.empty(count)
    e = 0
    for r in range(row_stiffness.shape[0]):
        if not row_stiffness[r] > 0.0:
            continue
        along = 0.0
        for a in range(3):
            n = nodes[r, a]
            nodes_out[e, a] = n
            weights_out[e, a] = weights[r, a]
            normal_out[e, a] = normal[r, a]
            if n >= 0:
                along += weights[r, a] * (normal[r, 0] * x[n, 0] + normal[r, 1] * x[n, 1] + normal[r, 2] * x[n, 2])
        offset[e] = depth[r] + along
        speed[e] = normal[r, 0] * tool_velocity[0] + normal[r, 1] * tool_velocity[1] + normal[r, 2] * tool_velocity[2]
        k[e] = row_stiffness[r]
        c[e] = row_damping[r]
        e += 1
    return nodes_out, weights_out, normal_out, offset, speed, k, c
