"""numba geometric primitives on 3-tuples, shared by the mesh loader and the contact kernels."""
import numba


@numba.njit(cache=True, inline="always")
def sub(u, v):
    """u − v."""
    return (u[0] - v[0], u[1] - v[1], u[2] - v[2])


@numba.njit(cache=True, inline="always")
def dot(u, v):
    """u · v."""
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


@numba.njit(cache=True, inline="always")
def along(a, s, u):
    """a + s u."""
    return (a[0] + s * u[0], a[1] + s * u[1], a[2] + s * u[2])


@numba.njit(cache=True)
def closest_point_on_triangle(p, triangle):
    """Closest point to p on a triangle (3, 3) and the feature it lies on.

    p is a 3-tuple; the point is returned as a 3-tuple.  Features: 0-2 corners a, b, c, 3-5 edges
    ab, bc, ca, 6 the interior (Ericson, Real-Time Collision Detection §5.1.5).
    """
    a = (triangle[0, 0], triangle[0, 1], triangle[0, 2])
    b = (triangle[1, 0], triangle[1, 1], triangle[1, 2])
    c = (triangle[2, 0], triangle[2, 1], triangle[2, 2])
    ab, ac = sub(b, a), sub(c, a)
    ap, bp, cp = sub(p, a), sub(p, b), sub(p, c)
    d1, d2 = dot(ab, ap), dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return a, 0
    d3, d4 = dot(ab, bp), dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return b, 1
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        return along(a, d1 / (d1 - d3), ab), 3
    d5, d6 = dot(ab, cp), dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return c, 2
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        return along(a, d2 / (d2 - d6), ac), 5
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 >= d3 and d5 >= d6:
        return along(b, (d4 - d3) / ((d4 - d3) + (d5 - d6)), sub(c, b)), 4
    scale = 1.0 / (va + vb + vc)
    return along(along(a, vb * scale, ab), vc * scale, ac), 6
