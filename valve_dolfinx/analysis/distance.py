"""Exact point-to-surface distances for the coaptation and orifice measures."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from valve_dolfinx.contact.broadphase import candidate_pairs
from valve_dolfinx.contact.geometry import closest_point_on_triangles

__all__ = ["distance_to_surface", "within_distance"]

#: Nearest centroids examined first by the point–surface distance search.
_FIRST_NEIGHBOURS = 16
#: Point–triangle pairs evaluated at once (bounds the memory of the exact test).
_PAIR_CHUNK = 400_000


def _pair_distances(points: np.ndarray, tri: np.ndarray, pi: np.ndarray,
                    ti: np.ndarray) -> np.ndarray:
    """Exact distances from ``points[pi]`` to triangles ``tri[ti]``, in bounded chunks."""
    out = np.empty(len(pi))
    for s in range(0, len(pi), _PAIR_CHUNK):
        sl = slice(s, s + _PAIR_CHUNK)
        p, t = points[pi[sl]], tri[ti[sl]]
        q, _ = closest_point_on_triangles(p, t[:, 0], t[:, 1], t[:, 2])
        out[sl] = np.linalg.norm(p - q, axis=1)
    return out


def distance_to_surface(points: np.ndarray, vertices: np.ndarray,
                        triangles: np.ndarray) -> np.ndarray:
    """Exact distance from each point ``(n, 3)`` to a triangulated surface.

    A k-d tree on the triangle centroids gives candidates: with ``ρ`` the
    largest centroid-to-vertex distance, a triangle whose centroid is farther
    than ``u + ρ`` from the point cannot be closer than ``u``, where ``u`` is
    the exact distance to the nearest-centroid triangles.  The nearest
    centroids are fetched in doubling batches until the next one lies beyond
    that bound; the exact point–triangle distance (Ericson's closest-point
    test) is then evaluated on all candidates at once.
    """
    tri = np.asarray(vertices, float)[np.asarray(triangles)]
    m = len(tri)
    points = np.asarray(points, float)
    if m == 0:
        return np.full(len(points), np.inf)
    centroids = tri.mean(axis=1)
    reach = float(np.linalg.norm(tri - centroids[:, None], axis=2).max())
    tree = cKDTree(centroids)

    k = min(_FIRST_NEIGHBOURS, m)
    dc, idx = (a.reshape(len(points), k) for a in tree.query(points, k=k))
    rows = np.repeat(np.arange(len(points)), k)
    best = _pair_distances(points, tri, rows, idx.ravel()).reshape(-1, k).min(axis=1)
    active = np.flatnonzero(dc[:, -1] <= best + reach) if k < m else np.empty(0, int)
    while active.size:
        k_old, k = k, min(2 * k, m)
        dc, idx = (a.reshape(len(active), k) for a in tree.query(points[active], k=k))
        dc, idx = dc[:, k_old:], idx[:, k_old:]
        cand = dc <= (best[active] + reach)[:, None]
        r, c = np.nonzero(cand)
        d = _pair_distances(points, tri, active[r], idx[r, c])
        np.minimum.at(best, active[r], d)
        still = dc[:, -1] <= best[active] + reach
        active = active[still] if k < m else np.empty(0, int)
    return best


def within_distance(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
                    distance: float) -> np.ndarray:
    """Whether each point ``(n, 3)`` lies within ``distance`` (closed) of a triangulated
    surface: ``distance_to_surface(...) <= distance``, decided on fewer triangles.

    Only a triangle whose bounding box, padded by ``distance``, holds the point can lie
    that close; the contact's broad phase finds those pairs, and the exact point–triangle
    distance (the one :func:`distance_to_surface` takes) decides.  The boxes are padded a
    little further (1e-9 mm) so that no rounding of a box drops a triangle at the limit.
    """
    points = np.asarray(points, float).reshape(-1, 3)
    vertices = np.asarray(vertices, float)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    inside = np.zeros(len(points), dtype=bool)
    if len(points) == 0 or len(triangles) == 0:
        return inside
    x = np.concatenate([vertices, points])
    node, tri = candidate_pairs(x, triangles, np.arange(len(vertices), len(x)),
                                distance + 1e-9)
    d = _pair_distances(x, vertices[triangles], node, tri)
    inside[node[d <= distance] - len(vertices)] = True
    return inside
