"""Point–triangle geometry of arrays of pairs (closest point, barycentric coordinates, normals)."""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "closest_point_on_triangles",
    "triangle_normals",
    "plane_projection",
    "barycentric_gradients",
    "triangle_frames",
    "COLLAPSE_TOLERANCE",
]

#: A triangle has collapsed when the Gram determinant of its edges, 4A² (A its area), is at
#: most this times the square of the sum of its squared edge lengths Σℓ²: its mean-ratio
#: quality 4√3·A/Σℓ² (1 for an equilateral triangle) is below √(12·1e-12) ≈ 3.5e-6.  Above
#: it the determinant's rounding error (about 1e-16·(Σℓ²)²) is far below the determinant.
COLLAPSE_TOLERANCE = 1e-12


def triangle_normals(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals ``(K, 3)`` (right-hand rule a→b→c) and areas ``(K,)`` of triangles."""
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=-1)
    return n / np.maximum(norm, 1e-300)[..., None], 0.5 * norm


def plane_projection(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project points on their triangles' planes.

    Returns the signed distance ``d`` (positive on the side the normal
    ``(b-a)×(c-a)`` points to), the barycentric coordinates ``(K, 3)`` of the
    projection (all in [0, 1] when it falls inside the triangle) and the unit
    normals.
    """
    n, _ = triangle_normals(a, b, c)
    d = np.einsum("ij,ij->i", p - a, n)
    q = p - d[:, None] * n
    bary = _barycentric(q, a, b, c)
    return d, bary, n


def barycentric_gradients(a: np.ndarray, b: np.ndarray, c: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    r"""Unit normals ``(K, 3)`` and in-plane gradients ``(K, 3, 3)`` of the barycentric coordinates.

    For a triangle with edges :math:`e_1 = b - a`, :math:`e_2 = c - a` the
    gradients :math:`g_j = \nabla\lambda_j` are the dual basis of the edges in
    the triangle's plane (:math:`g_i\cdot e_j = \delta_{ij}`, :math:`g_j\cdot n = 0`):

    .. math::

        g_1 = \frac{(e_2\cdot e_2)\,e_1 - (e_1\cdot e_2)\,e_2}{\det G},\quad
        g_2 = \frac{(e_1\cdot e_1)\,e_2 - (e_1\cdot e_2)\,e_1}{\det G},\quad
        g_0 = -g_1 - g_2,

    :math:`G` the Gram matrix of the edges.  The barycentric coordinates of the
    projection of any point ``p`` on the plane are then
    :math:`\lambda_j = \delta_{j0} + g_j\cdot(p - a)` and its signed distance
    :math:`n\cdot(p - a)`, i.e. :func:`plane_projection` with the per-triangle
    work done once, which pays off when each triangle is tested against many
    points.  ``gradients[:, j]`` is :math:`g_j`.  A collapsed triangle
    (:data:`COLLAPSE_TOLERANCE`) has NaN gradients, so no point ever projects inside it.
    The work is :func:`triangle_frames`'.
    """
    normal, grad, _, _ = triangle_frames(*(np.ascontiguousarray(np.asarray(v, dtype=float).T)
                                           for v in (a, b, c)))
    return normal.T, np.moveaxis(grad, 2, 0)


def triangle_frames(a: np.ndarray, b: np.ndarray, c: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Unit normals ``(3, M)``, barycentric gradients ``(3, 3, M)`` (``[j, axis]``, as in
    :func:`barycentric_gradients`), altitudes ``1/|g_j|`` ``(3, M)`` and collapse flags
    ``(M,)`` of triangles whose vertices are given by axis, ``(3, M)`` each: a loop
    compiled by Numba with the floating-point operations of the NumPy formulas
    (:func:`triangle_normals`, ``np.linalg.norm``, :func:`dot3`), so the bits are theirs.

    A collapsed triangle (:data:`COLLAPSE_TOLERANCE`) is flagged and has NaN gradients and
    altitudes: its Gram determinant is not divided by."""
    count = a.shape[1]
    normal, grad, altitudes = np.empty((3, count)), np.empty((3, 3, count)), np.empty((3, count))
    collapsed = np.empty(count, dtype=np.bool_)
    _triangle_frames(a, b, c, normal, grad, altitudes, collapsed)
    return normal, grad, altitudes, collapsed


@numba.njit(cache=True)
def _triangle_frames(a, b, c, normal, grad, altitudes, collapsed):  # pragma: no cover
    for t in range(a.shape[1]):
        e10, e11, e12 = b[0, t] - a[0, t], b[1, t] - a[1, t], b[2, t] - a[2, t]
        e20, e21, e22 = c[0, t] - a[0, t], c[1, t] - a[1, t], c[2, t] - a[2, t]
        N0 = e11 * e22 - e12 * e21
        N1 = e12 * e20 - e10 * e22
        N2 = e10 * e21 - e11 * e20
        length = max(math.sqrt((N0 * N0 + N1 * N1) + N2 * N2), 1e-300)
        normal[0, t], normal[1, t], normal[2, t] = N0 / length, N1 / length, N2 / length
        g11 = dot3(e10, e11, e12, e10, e11, e12)
        g12 = dot3(e10, e11, e12, e20, e21, e22)
        g22 = dot3(e20, e21, e22, e20, e21, e22)
        det = g11 * g22 - g12 * g12
        squared_edges = 2.0 * (g11 + g22 - g12)  # |e1|² + |e2|² + |e2 - e1|²
        collapsed[t] = det <= COLLAPSE_TOLERANCE * squared_edges * squared_edges
        if collapsed[t]:
            grad[:, :, t] = np.nan
            altitudes[:, t] = np.nan
            continue
        for i in range(3):
            u = e10 if i == 0 else (e11 if i == 1 else e12)
            v = e20 if i == 0 else (e21 if i == 1 else e22)
            g1 = (g22 * u - g12 * v) / det
            g2 = (g11 * v - g12 * u) / det
            grad[1, i, t] = g1
            grad[2, i, t] = g2
            grad[0, i, t] = -g1 - g2
        for j in range(3):
            altitudes[j, t] = 1.0 / math.sqrt((grad[j, 0, t] * grad[j, 0, t]
                                               + grad[j, 1, t] * grad[j, 1, t])
                                              + grad[j, 2, t] * grad[j, 2, t])


def _barycentric(q: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    v0, v1, v2 = b - a, c - a, q - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    denom = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / denom
    w = (d00 * d21 - d01 * d20) / denom
    return np.stack([1.0 - v - w, v, w], axis=1)


def closest_point_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray]:
    """Closest point of each triangle ``(a, b, c)[i]`` to ``p[i]`` (all ``(K, 3)``).

    Region-based algorithm (vertex, edge or face Voronoi region of the
    triangle; Ericson, *Real-Time Collision Detection*, §5.1.5), a loop over the
    pairs compiled by Numba.  Returns the closest points ``(K, 3)`` and their
    barycentric coordinates ``(K, 3)``.
    """
    p, a, b, c = (np.ascontiguousarray(v, dtype=float).reshape(-1, 3) for v in (p, a, b, c))
    q, bary = np.empty_like(p), np.empty_like(p)
    _closest_points(p, a, b, c, q, bary)
    return q, bary


@numba.njit(cache=True)
def dot3(u0, u1, u2, v0, v1, v2):  # pragma: no cover
    """``u·v`` of 3-vectors for compiled loops, summed as ``(u₀v₀ + u₂v₂) + u₁v₁``: the
    order of ``np.einsum("ij,ij->i")`` (:func:`barycentric_gradients`, the narrow phase),
    so that a triangle's geometry has the same bits in compiled and NumPy code."""
    return (u0 * v0 + u2 * v2) + u1 * v1


@numba.njit(cache=True)
def closest_point_weights(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2):  # pragma: no cover
    """Barycentric coordinates ``(u, v, w)`` of the point of triangle ``(a, b, c)`` closest
    to ``p`` (one pair of :func:`closest_point_on_triangles`, for compiled loops)."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    ap0, ap1, ap2 = p0 - a0, p1 - a1, p2 - a2
    bp0, bp1, bp2 = p0 - b0, p1 - b1, p2 - b2
    cp0, cp1, cp2 = p0 - c0, p1 - c1, p2 - c2
    d1 = dot3(ab0, ab1, ab2, ap0, ap1, ap2)
    d2 = dot3(ac0, ac1, ac2, ap0, ap1, ap2)
    d3 = dot3(ab0, ab1, ab2, bp0, bp1, bp2)
    d4 = dot3(ac0, ac1, ac2, bp0, bp1, bp2)
    d5 = dot3(ab0, ab1, ab2, cp0, cp1, cp2)
    d6 = dot3(ac0, ac1, ac2, cp0, cp1, cp2)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    # the regions in Ericson's order; the first that holds wins
    if d1 <= 0 and d2 <= 0:                                      # vertex a
        return 1.0, 0.0, 0.0
    if d3 >= 0 and d4 <= d3:                                     # vertex b
        return 0.0, 1.0, 0.0
    if vc <= 0 and d1 >= 0 and d3 <= 0:                          # edge ab
        t = d1 / (d1 - d3)
        return 1 - t, t, 0.0
    if d6 >= 0 and d5 <= d6:                                     # vertex c
        return 0.0, 0.0, 1.0
    if vb <= 0 and d2 >= 0 and d6 <= 0:                          # edge ac
        t = d2 / (d2 - d6)
        return 1 - t, 0.0, t
    if va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:            # edge bc
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1 - t, t
    denom = 1.0 / (va + vb + vc)                                 # face interior
    v, w = vb * denom, vc * denom
    return 1 - v - w, v, w


@numba.njit(cache=True)
def _closest_points(p, a, b, c, q, bary):  # pragma: no cover
    for i in range(len(p)):
        u, v, w = closest_point_weights(p[i, 0], p[i, 1], p[i, 2], a[i, 0], a[i, 1], a[i, 2],
                                        b[i, 0], b[i, 1], b[i, 2], c[i, 0], c[i, 1], c[i, 2])
        bary[i, 0], bary[i, 1], bary[i, 2] = u, v, w
        for k in range(3):
            q[i, k] = u * a[i, k] + v * b[i, k] + w * c[i, k]
