"""The exact signed distance (m) to a closed, outward-wound triangle surface, negative inside: what isosurface
stuffing (liver_sim.mesh.stuffing) fills when a mesh file is a surface (liver_sim.mesh.io)."""
from __future__ import annotations

import itertools

import numba
import numpy as np

from liver_sim.base.geometry.closest_point import closest_point_on_triangle, dot, sub

#: Triangles per leaf of the hierarchy :class:`SurfaceSignedDistance` searches.
_BVH_LEAF_TRIANGLES = 8


class SurfaceSignedDistance:
    """Exact signed distance (m) to a closed, outward-wound triangle surface; negative inside.

    Calling it with points (..., 3) in metres returns distances of shape (...).  The
    magnitude is the distance to the nearest triangle, found through a bounding-volume
    hierarchy; the sign is that of the offset along the angle-weighted pseudonormal of
    the nearest vertex, edge or face (Baerentzen & Aanaes 2005), which is exact for a
    watertight consistently wound surface.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self._corners = np.ascontiguousarray(vertices[faces], dtype=np.float64)  # (F, 3, 3)
        self._feature_normals = _feature_pseudonormals(vertices, faces)
        self._tree = _build_bvh(self._corners.min(axis=1), self._corners.max(axis=1))

    def __call__(self, points) -> np.ndarray:
        points = np.asarray(points, dtype=np.float64)
        flat = np.ascontiguousarray(points.reshape(-1, 3))
        face = np.empty(len(flat), dtype=np.int64)
        feature = np.empty(len(flat), dtype=np.int64)
        closest = np.empty_like(flat)
        _nearest_triangles(flat, self._corners, *self._tree, face, feature, closest)
        offset = flat - closest
        distance = np.linalg.norm(offset, axis=1)
        side = np.einsum("ij,ij->i", offset, self._feature_normals[face, feature])
        return np.where(side < 0, -distance, distance).reshape(points.shape[:-1])


def _feature_pseudonormals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 7, 3) pseudonormals of each triangle's corners a, b, c, edges ab, bc, ca and face."""
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    vertex_normals = np.zeros_like(vertices)
    for i in range(3):
        u = corners[:, (i + 1) % 3] - corners[:, i]
        v = corners[:, (i + 2) % 3] - corners[:, i]
        cosine = np.einsum("ij,ij->i", u, v) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        np.add.at(vertex_normals, faces[:, i], np.arccos(np.clip(cosine, -1.0, 1.0))[:, None] * normals)
    edge_keys = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, edge_id = np.unique(edge_keys, axis=0, return_inverse=True)
    edge_normals = np.zeros((edge_id.max() + 1, 3))
    np.add.at(edge_normals, edge_id, np.repeat(normals, 3, axis=0))
    return np.concatenate([vertex_normals[faces], edge_normals[edge_id].reshape(-1, 3, 3),
                           normals[:, None]], axis=1)


def _build_bvh(lower: np.ndarray, upper: np.ndarray) -> tuple:
    """Median-split hierarchy over triangle boxes (F, 3): (order, box_lower, box_upper, span, child, depth).

    Node 0 is the root; node k holds triangles order[span[k, 0]:span[k, 1]] inside the box
    [box_lower[k], box_upper[k]]; child[k] is its two children, or (-1, -1) for a leaf.
    """
    centres = 0.5 * (lower + upper)
    order = np.arange(len(lower))
    spans, children, depths = [(0, len(order))], [(-1, -1)], [0]
    for node in itertools.count():
        if node == len(spans):
            break
        start, stop = spans[node]
        if stop - start <= _BVH_LEAF_TRIANGLES:
            continue
        members = order[start:stop]
        axis = int(np.argmax(np.ptp(centres[members], axis=0)))
        half = (stop - start) // 2
        order[start:stop] = members[np.argpartition(centres[members, axis], half)]
        children[node] = (len(spans), len(spans) + 1)
        spans += [(start, start + half), (start + half, stop)]
        children += [(-1, -1), (-1, -1)]
        depths += [depths[node] + 1] * 2
    span = np.array(spans, dtype=np.int64)
    box_lower = np.array([lower[order[a:b]].min(axis=0) for a, b in spans])
    box_upper = np.array([upper[order[a:b]].max(axis=0) for a, b in spans])
    return order, box_lower, box_upper, span, np.array(children, dtype=np.int64), max(depths)


@numba.njit(cache=True)
def _nearest_triangles(points, corners, order, box_lower, box_upper, span, child, depth,
                       face, feature, closest):
    """Fill face[i], feature[i] and closest[i] with the nearest surface point to points[i].

    Best-first descent of the hierarchy: the nearer child is visited first and a box no
    closer than the best triangle so far is skipped.
    """
    stack = np.empty(2 * depth + 2, dtype=np.int64)
    for i in range(points.shape[0]):
        p = (points[i, 0], points[i, 1], points[i, 2])
        best = np.inf
        stack[0] = 0
        top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            if _box_distance2(p, box_lower[node], box_upper[node]) >= best:
                continue
            if child[node, 0] < 0:
                for k in range(span[node, 0], span[node, 1]):
                    t = order[k]
                    c, f = closest_point_on_triangle(p, corners[t])
                    d2 = dot(sub(p, c), sub(p, c))
                    if d2 < best:
                        best = d2
                        face[i], feature[i] = t, f
                        closest[i, 0], closest[i, 1], closest[i, 2] = c
                continue
            near, far = child[node, 0], child[node, 1]
            if _box_distance2(p, box_lower[near], box_upper[near]) > \
                    _box_distance2(p, box_lower[far], box_upper[far]):
                near, far = far, near
            stack[top] = far
            stack[top + 1] = near
            top += 2


@numba.njit(cache=True, inline="always")
def _box_distance2(p, lower, upper):
    """Squared distance from p to the box [lower, upper]."""
    total = 0.0
    for axis in range(3):
        gap = max(lower[axis] - p[axis], 0.0, p[axis] - upper[axis])
        total += gap * gap
    return total


