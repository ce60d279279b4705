"""Presence of a contact row: how fully it takes part in its contact, from 0 where the row
appears or vanishes to 1, so that no row enters or leaves the blend of its (node, body)
with a finite weight (a jump in the residual that makes Newton's method cycle).

A face row fades out as the node's projection leaves its triangle, across a band beyond
each side; an edge/vertex row fades in as the node reaches the triangle's plane and as its
projection leaves the triangle; every row fades out towards the law's cut-off.  Each fade
is a C¹ smoothstep (:func:`row_presence`), and the Jacobian takes the gradient of its
logarithm (:func:`presence_gradients`).  Both are loops over the rows compiled by Numba: a
row's work is a few dozen flops.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

__all__ = ["RowPlanes", "presence_gradients", "row_presence"]


class RowPlanes(NamedTuple):
    """Per contact row, the plane of its triangle as the row's presence depends on it
    (from :func:`row_presence` and the narrow phase's rows): ``(A,)`` arrays unless noted."""

    edge: np.ndarray           # an edge/vertex row (its closest point on the boundary)
    side: np.ndarray           # s = ±1, the side of the triangle the node comes from
    normal: np.ndarray         # (A, 3) the triangle's unit normal n_t
    lam: np.ndarray            # (A, 3) barycentric coordinates of the node's projection
    distance: np.ndarray       # d₀ = (x_p - x_{t0})·n_t, the unsided plane distance
    side_distance: np.ndarray  # s d₀
    in_plane: np.ndarray       # ρ, the projection's distance from the triangle (0: face row)
    offset: np.ndarray         # (A, 3) x_p - q, from the closest point q (d₀ n_t: face row)
    lam_min: np.ndarray        # the smallest of ``lam``
    band: np.ndarray           # (A, 3) the fade band beyond each side (face rows)


@numba.njit(cache=True)
def _ramp(x, width):  # pragma: no cover
    """C¹ smoothstep: 0 for ``x <= 0``, 1 for ``x >= width``."""
    xi = x / width
    xi = 0.0 if xi < 0.0 else (1.0 if xi > 1.0 else xi)
    return xi * xi * (3.0 - 2.0 * xi)


@numba.njit(cache=True)
def row_presence(side, d0, gap, offset, plane_lam, plane_normal, thickness, band, eps,
                 tapered, cutoff):  # pragma: no cover
    r"""Distance, direction and presence of each candidate row
    (:meth:`~valve_dolfinx.contact.surface.SurfaceContact._find_contacts`), from its
    ``side`` ``s``, its unsided plane distance ``d0``, its distance ``gap`` from the closest
    point (NaN on face rows) and ``offset`` ``(K, 3)`` from it, the barycentric coordinates
    ``plane_lam`` ``(K, 3)`` of its projection and its triangle's unit normal
    ``plane_normal`` ``(K, 3)``.

    A face row (``gap`` NaN) is at its sided plane distance ``s d₀`` along ``s n_t``; an
    edge/vertex row at its distance ``gap`` from the closest point, along the offset from
    it; both less the contact ``thickness``.  The presence fades each row smoothly to 0
    where it appears or vanishes, so that no row enters or leaves the blend with a finite
    weight (a jump in the residual): a face row as the node's projection leaves the
    triangle, :math:`Π_j \operatorname{ramp}(λ_j + b_j, b_j)` over the ``band`` ``b``
    (smooth also near the vertices, where a min would kink); an edge/vertex row as the node
    reaches the triangle's plane (behind it the neighbouring face takes over) and as the
    in-plane distance of its projection from the triangle, :math:`ρ = \sqrt{gap² − d₀²}`,
    falls to 0 (where the projection re-enters the triangle its face row takes over, and a
    row vanishing with a finite weight there would make the blend jump and Newton cycle, a
    graft node at a free edge); every row as ``d`` reaches the cut-off, over ``eps`` if
    ``tapered``, else at once (the literal law jumps there anyway).  Ramps have width
    ``eps`` except the bands'.

    Returns ``edge``, ``d``, the unit directions ``(K, 3)``, ``s d₀``, the smallest
    barycentric coordinate of the projection, ``ρ`` (0 on face rows) and the presence.
    """
    count = len(side)
    edge = np.empty(count, dtype=np.bool_)
    d = np.empty(count)
    normal = np.empty((count, 3))
    side_distance = np.empty(count)
    lam_min = np.empty(count)
    in_plane = np.empty(count)
    presence = np.empty(count)
    for i in range(count):
        edge[i] = not np.isnan(gap[i])
        side_distance[i] = side[i] * d0[i]
        low = plane_lam[i, 0] if plane_lam[i, 0] < plane_lam[i, 1] else plane_lam[i, 1]
        lam_min[i] = low if low < plane_lam[i, 2] else plane_lam[i, 2]
        if edge[i]:
            d[i] = gap[i] - thickness[i]
            scale = max(gap[i], 1e-300)
            for a in range(3):
                normal[i, a] = offset[i, a] / scale
            spread = gap[i] * gap[i] - d0[i] * d0[i]
            in_plane[i] = np.sqrt(spread if spread >= 0.0 else 0.0)
            fade = _ramp(side_distance[i], eps) * _ramp(in_plane[i], eps)
        else:
            d[i] = side_distance[i] - thickness[i]
            for a in range(3):
                normal[i, a] = side[i] * plane_normal[i, a]
            in_plane[i] = 0.0
            fade = _ramp(plane_lam[i, 0] + band[i, 0], band[i, 0])
            fade = fade * _ramp(plane_lam[i, 1] + band[i, 1], band[i, 1])
            fade = fade * _ramp(plane_lam[i, 2] + band[i, 2], band[i, 2])
        if tapered:
            fade = fade * _ramp(cutoff - d[i], eps)
        else:
            fade = fade * (1.0 if d[i] < cutoff else 0.0)
        presence[i] = fade
    return edge, d, normal, side_distance, lam_min, in_plane, presence


@numba.njit(cache=True)
def _log_ramp_slope(x, width):  # pragma: no cover
    """``d log(ramp(x))/dx`` of the C¹ smoothstep ``ramp`` of ``width`` where it is positive
    (0 where it is 1)."""
    xi = min(max(x / width, 1e-300), 1.0)
    return 6.0 * (1.0 - xi) / (xi * (3.0 - 2.0 * xi)) / width


@numba.njit(cache=True)
def presence_gradients(B, normal, d, dlam, planes, eps, tapered, cutoff):  # pragma: no cover
    r"""``∂log p/∂x`` ``(A, m, 3)`` over ``[node, support]`` of each row's presence ``p``
    (:func:`row_presence`, with its ``eps``, ``tapered`` and ``cutoff``), for rows with
    ``B = [1, -λ]`` ``(A, m)``, direction ``normal`` ``(A, 3)`` and distance ``d``, whose
    triangles' ``planes`` are a :class:`RowPlanes`: the taper towards the cut-off
    (``tapered``), with ``∇d = B ⊗ n``; on edge/vertex rows the fade in from the plane
    (``∇(s d₀) = B^{plane} ⊗ s n_t``) and with the in-plane distance ``ρ = √(gap² − d₀²)``
    (``∇ρ = (B ⊗ (x_p − q) − d₀ B^{plane} ⊗ n_t)/ρ``); on face rows fading out beyond their
    triangle (a barycentric coordinate of the projection below 0) the band ramps of those
    coordinates, through their derivatives ``dlam`` ``(A, m-1, m, 3)``
    (:func:`~valve_dolfinx.contact.linearisation.direction_derivatives`)."""
    edge, side, plane_normal, plane_lam = planes.edge, planes.side, planes.normal, planes.lam
    plane_distance, side_distance, in_plane = planes.distance, planes.side_distance, planes.in_plane
    offset, lam_min, band = planes.offset, planes.lam_min, planes.band
    count, m = B.shape
    out = np.zeros((count, m, 3))
    for i in range(count):
        if tapered:
            taper = _log_ramp_slope(cutoff - d[i], eps)
            for r in range(m):
                for s in range(3):
                    out[i, r, s] = out[i, r, s] - taper * (B[i, r] * normal[i, s])
        if edge[i]:
            fade = _log_ramp_slope(side_distance[i], eps)
            rho = in_plane[i]
            spread = _log_ramp_slope(rho, eps) / max(rho, 1e-300)
            for r in range(m):
                plane_B = 1.0 if r == 0 else -plane_lam[i, r - 1]
                for s in range(3):
                    sided = side[i] * plane_normal[i, s]
                    out[i, r, s] = out[i, r, s] + (fade * plane_B) * sided
            for r in range(m):
                plane_B = 1.0 if r == 0 else -plane_lam[i, r - 1]
                for s in range(3):
                    grad_rho = (B[i, r] * offset[i, s]
                                - (plane_distance[i] * plane_B) * plane_normal[i, s])
                    out[i, r, s] = out[i, r, s] + spread * grad_rho
        elif lam_min[i] < 0.0:  # a face row beyond its triangle, in the band
            s0 = _log_ramp_slope(plane_lam[i, 0] + band[i, 0], band[i, 0])
            s1 = _log_ramp_slope(plane_lam[i, 1] + band[i, 1], band[i, 1])
            s2 = _log_ramp_slope(plane_lam[i, 2] + band[i, 2], band[i, 2])
            for r in range(m):
                for s in range(3):
                    total = s0 * dlam[i, 0, r, s] + s1 * dlam[i, 1, r, s]
                    out[i, r, s] = out[i, r, s] + (total + s2 * dlam[i, 2, r, s])
    return out
