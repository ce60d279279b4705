"""Vectorised point–triangle geometry (closest point, barycentric coordinates, normals)."""

from __future__ import annotations

import numpy as np

__all__ = [
    "closest_point_on_triangles",
    "triangle_normals",
    "plane_projection",
    "barycentric_gradients",
]


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
    points.  ``gradients[:, j]`` is :math:`g_j`.  A zero-area triangle has
    non-finite gradients, so no point ever projects inside it.
    """
    e1, e2 = b - a, c - a
    n, _ = triangle_normals(a, b, c)
    g11 = np.einsum("ij,ij->i", e1, e1)
    g12 = np.einsum("ij,ij->i", e1, e2)
    g22 = np.einsum("ij,ij->i", e2, e2)
    det = g11 * g22 - g12 * g12
    grad = np.empty(e1.shape[:-1] + (3, 3))
    grad[:, 1] = (g22[:, None] * e1 - g12[:, None] * e2) / det[:, None]
    grad[:, 2] = (g11[:, None] * e2 - g12[:, None] * e1) / det[:, None]
    grad[:, 0] = -grad[:, 1] - grad[:, 2]
    return n, grad


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
    triangle; Ericson, *Real-Time Collision Detection*, §5.1.5), evaluated for
    all pairs at once with masks.  Returns the closest points ``(K, 3)`` and
    their barycentric coordinates ``(K, 3)``.
    """
    p, a, b, c = (np.asarray(v, dtype=float) for v in (p, a, b, c))
    ab, ac, ap = b - a, c - a, p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)

    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        denom = 1.0 / (va + vb + vc)
        v, w = vb * denom, vc * denom
        face = 1 - v - w
    # the regions in Ericson's order; the first that holds wins (np.select)
    regions = [(d1 <= 0) & (d2 <= 0),                                   # vertex a
               (d3 >= 0) & (d4 <= d3),                                  # vertex b
               (vc <= 0) & (d1 >= 0) & (d3 <= 0),                       # edge ab
               (d6 >= 0) & (d5 <= d6),                                  # vertex c
               (vb <= 0) & (d2 >= 0) & (d6 <= 0),                       # edge ac
               (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)]         # edge bc
    #              a    b    ab        c    ac        bc          face interior
    weights = ([1.0, 0.0, 1 - t_ab, 0.0, 1 - t_ac, 0.0], face), \
              ([0.0, 1.0, t_ab, 0.0, 0.0, 1 - t_bc], v), \
              ([0.0, 0.0, 0.0, 1.0, t_ac, t_bc], w)
    bary = np.stack([np.select(regions, choices, default=inside)
                     for choices, inside in weights], axis=1)
    q = bary[:, [0]] * a + bary[:, [1]] * b + bary[:, [2]] * c
    return q, bary
