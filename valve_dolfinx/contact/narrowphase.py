"""Narrow phase of the contact search: which (node, triangle) pairs of the broad phase
(:mod:`~valve_dolfinx.contact.broadphase`) make contact rows, and where on the triangle
each node meets it.

Two compiled passes over the pairs: :func:`near_pairs` keeps the pairs whose node lies
near the triangle's plane, over the triangle or its fade band or possibly within reach of
its boundary, and outside its neighbourhood, from the triangle's frame
(:class:`TriangleFrames`: a projection is a few dot products); :func:`narrow_rows` turns
them into rows, a face row where the projection lies in the triangle or its fade band and
an edge/vertex row at the closest point of the boundary (Ericson's region test,
:func:`~valve_dolfinx.contact.geometry.closest_point_weights`) where it lies outside and
that point is within reach.  A pair's work is a few dozen flops; as NumPy expressions over
all pairs it would go into temporaries the size of the result.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from valve_dolfinx.contact.geometry import closest_point_weights, triangle_frames

__all__ = ["NearPairs", "TriangleFrames", "narrow_rows", "near_pairs"]


class TriangleFrames(NamedTuple):
    """Per-triangle data of the projection test, by axis ``(3, M)``.

    ``origin`` is vertex 0, ``normal`` the unit normal and ``grad1``, ``grad2``
    the in-plane gradients of the barycentric coordinates λ1, λ2
    (:func:`~valve_dolfinx.contact.geometry.triangle_frames`), so that a
    point ``p`` projects to ``λ_j = grad_j·(p - origin)`` at distance
    ``normal·(p - origin)``.  ``collapsed`` ``(M,)`` flags the collapsed triangles, whose
    gradients are NaN.
    """

    origin: np.ndarray
    normal: np.ndarray
    grad1: np.ndarray
    grad2: np.ndarray
    altitudes: np.ndarray  # (3, M): 1/|∇λ_j|, the altitude of the triangle at vertex j
    gradients_by_triangle: np.ndarray  # (M, 3, 3): the gradients g_j, [triangle, j, axis]
    collapsed: np.ndarray  # (M,) bool

    @classmethod
    def at(cls, xt: np.ndarray, triangles: np.ndarray) -> TriangleFrames:
        """The frames of ``triangles`` ``(M, 3)`` at the node positions ``xt`` ``(3, N)``."""
        a, b, c = (xt[:, triangles[:, j]] for j in range(3))
        normal, grad, altitudes, collapsed = triangle_frames(a, b, c)
        return cls(origin=a, normal=normal, grad1=grad[1], grad2=grad[2], altitudes=altitudes,
                   gradients_by_triangle=np.ascontiguousarray(grad.transpose(2, 0, 1)),
                   collapsed=collapsed)

    def gradients(self, tri: np.ndarray) -> np.ndarray:
        """``(K, 3, 3)`` barycentric gradients ``g_j`` (``[j, axis]``) of triangles ``tri``."""
        return self.gradients_by_triangle[tri]


class NearPairs(NamedTuple):
    """The pairs :func:`near_pairs` keeps, ``(K,)`` each: the node and the triangle, the
    node's plane distance ``d0``, the barycentric coordinates ``lam`` ``(K, 3)`` of its
    projection, ``beyond`` (a lower bound on the projection's in-plane distance from the
    triangle) and ``in_band`` (the projection in the triangle or its fade band)."""

    node: np.ndarray
    tri: np.ndarray
    d0: np.ndarray
    lam: np.ndarray
    beyond: np.ndarray
    in_band: np.ndarray


@numba.njit(cache=True)
def _nan_max(a, b):  # pragma: no cover
    """``np.maximum`` of two scalars: NaN if either is (a degenerate triangle's bound)."""
    if a != a or b != b:
        return np.nan
    return a if a > b else b


@numba.njit(cache=True)
def near_pairs(node, tri, xt, frames, node_body, triangle_body, side_band, face_band, excluded,
               search_distance, reach):  # pragma: no cover
    """The cheap narrow-phase tests of the (node, triangle) pairs ``node, tri`` from the broad
    phase, with the node positions ``xt`` ``(3, N)`` and the triangles' ``frames``
    (:class:`TriangleFrames`).

    Keeps a pair when the node lies within ``search_distance`` of the triangle's plane,
    its projection falls in the triangle or its fade band (``side_band`` ``(M, 3)`` beyond
    the sides of a triangle of another body than the node's, by the labels ``node_body``
    and ``triangle_body``; ``face_band`` otherwise) or possibly within ``reach`` of it,
    and it is not in the triangle's neighbourhood (``excluded``: per triangle the node ids
    in ascending order, then ``-1`` padding, as :mod:`~valve_dolfinx.contact.exclusions`
    makes them).  Returns the :class:`NearPairs` in the order of the input.
    """
    origin, normal, grad1, grad2 = frames.origin, frames.normal, frames.grad1, frames.grad2
    altitudes = frames.altitudes
    count = len(node)
    out_node = np.empty(count, dtype=np.int64)
    out_tri = np.empty(count, dtype=np.int64)
    out_d0 = np.empty(count)
    out_lam = np.empty((count, 3))
    out_beyond = np.empty(count)
    out_in_band = np.empty(count, dtype=np.bool_)
    kept = 0
    for k in range(count):
        p, t = node[k], tri[k]
        r0 = xt[0, p] - origin[0, t]
        r1 = xt[1, p] - origin[1, t]
        r2 = xt[2, p] - origin[2, t]
        d0 = r0 * normal[0, t] + r1 * normal[1, t] + r2 * normal[2, t]
        if not abs(d0) < search_distance:
            continue
        lam1 = r0 * grad1[0, t] + r1 * grad1[1, t] + r2 * grad1[2, t]
        lam2 = r0 * grad2[0, t] + r1 * grad2[1, t] + r2 * grad2[2, t]
        lam0 = 1.0 - lam1 - lam2
        beyond = _nan_max(_nan_max(-lam0 * altitudes[0, t], -lam1 * altitudes[1, t]),
                          -lam2 * altitudes[2, t])
        other = node_body[p] != triangle_body[t]
        b0 = side_band[t, 0] if other else face_band
        b1 = side_band[t, 1] if other else face_band
        b2 = side_band[t, 2] if other else face_band
        in_band = lam0 > -b0 and lam1 > -b1 and lam2 > -b2
        if not (in_band or (beyond < reach and abs(d0) < reach)):
            continue
        neighbour = False
        for e in excluded[t]:  # ascending, then -1
            if e < 0 or e > p:
                break
            if e == p:
                neighbour = True
                break
        if neighbour:
            continue
        out_node[kept], out_tri[kept], out_d0[kept] = p, t, d0
        out_lam[kept, 0], out_lam[kept, 1], out_lam[kept, 2] = lam0, lam1, lam2
        out_beyond[kept], out_in_band[kept] = beyond, in_band
        kept += 1
    return NearPairs(out_node[:kept], out_tri[:kept], out_d0[:kept], out_lam[:kept],
                     out_beyond[:kept], out_in_band[:kept])


@numba.njit(cache=True)
def narrow_rows(near, xt, triangles, normal, reach, bound, inside_tolerance):  # pragma: no cover
    """The rows of the pairs :func:`near_pairs` kept (``near``, :class:`NearPairs`), with the
    node positions ``xt`` ``(3, N)``, the ``triangles`` ``(M, 3)`` and their unit
    ``normal`` ``(3, M)`` (:meth:`~valve_dolfinx.contact.surface.SurfaceContact._narrow`):
    first the face rows (``in_band``), then the edge/vertex rows: the pairs whose
    projection lies outside the triangle (a barycentric coordinate below
    ``-inside_tolerance``) with the lower bound ``√(beyond² + d0²)`` on their distance below
    ``bound`` and their closest point on the triangle within ``reach``, each in the order of
    the input (a pair whose projection lies in the fade band outside the triangle makes one
    row of each kind).

    Returns ``node, tri``, ``d0``, the distance ``gap`` to the closest point (NaN on face
    rows), the barycentric coordinates ``(K, 3)`` of the closest point (the projection's on
    face rows), the offset ``(K, 3)`` of the node from it (``d0 n`` on face rows) and those
    of the projection.
    """
    node, tri, d0, lam, beyond, in_band = (near.node, near.tri, near.d0, near.lam, near.beyond,
                                           near.in_band)
    count = len(node)
    size = 2 * count  # a pair in a face's fade band, outside the triangle, makes both rows
    out_node = np.empty(size, dtype=np.int64)
    out_tri = np.empty(size, dtype=np.int64)
    out_d0 = np.empty(size)
    out_gap = np.empty(size)
    out_lam = np.empty((size, 3))
    out_offset = np.empty((size, 3))
    out_plane_lam = np.empty((size, 3))
    kept = 0
    for k in range(count):
        if not in_band[k]:
            continue
        t = tri[k]
        out_node[kept], out_tri[kept], out_d0[kept], out_gap[kept] = node[k], t, d0[k], np.nan
        for j in range(3):
            out_lam[kept, j] = lam[k, j]
            out_plane_lam[kept, j] = lam[k, j]
            out_offset[kept, j] = d0[k] * normal[j, t]
        kept += 1
    for k in range(count):
        l0, l1, l2 = lam[k, 0], lam[k, 1], lam[k, 2]
        if l0 != l0 or l1 != l1 or l2 != l2:  # np.min of a degenerate triangle's NaN
            continue
        if not (min(l0, min(l1, l2)) < -inside_tolerance
                and math.hypot(beyond[k], d0[k]) < bound):
            continue
        p, t = node[k], tri[k]
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        u, v, w = closest_point_weights(xt[0, p], xt[1, p], xt[2, p], xt[0, a], xt[1, a],
                                        xt[2, a], xt[0, b], xt[1, b], xt[2, b], xt[0, c],
                                        xt[1, c], xt[2, c])
        o0 = xt[0, p] - (u * xt[0, a] + v * xt[0, b] + w * xt[0, c])
        o1 = xt[1, p] - (u * xt[1, a] + v * xt[1, b] + w * xt[1, c])
        o2 = xt[2, p] - (u * xt[2, a] + v * xt[2, b] + w * xt[2, c])
        gap = math.sqrt((o0 * o0 + o1 * o1) + o2 * o2)  # np.linalg.norm's order
        if not gap < reach:
            continue
        out_node[kept], out_tri[kept], out_d0[kept], out_gap[kept] = p, t, d0[k], gap
        out_lam[kept, 0], out_lam[kept, 1], out_lam[kept, 2] = u, v, w
        out_offset[kept, 0], out_offset[kept, 1], out_offset[kept, 2] = o0, o1, o2
        out_plane_lam[kept, 0], out_plane_lam[kept, 1], out_plane_lam[kept, 2] = l0, l1, l2
        kept += 1
    return (out_node[:kept], out_tri[:kept], out_d0[:kept], out_gap[:kept], out_lam[:kept],
            out_offset[:kept], out_plane_lam[:kept])

