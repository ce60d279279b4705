"""The side each node approaches each triangle from, remembered while the pair stays close.

A node of a thin sheet meets a triangle on one of the triangle's two faces: the one it
came from (SPEC §5).  Which face that is cannot be read off the current positions alone --
a node pulled a little past a neighbour's mid-surface looks just like one resting on the
other face -- so it is remembered.  A (node, triangle) pair gets its side when it first
comes close (within the tracking distance of the triangle at an accepted state) and keeps
it for as long as it stays close, however far the node is pushed or pulled through the
triangle meanwhile; only a pair that separates forgets its side.  A pair seen for the first
time takes the side its node has on an adjacent triangle of the same body, if the node has
one: a node sliding over a sheet keeps its face from triangle to triangle, and a crossing
cannot begin in the middle of a contacted region.  Only a node that meets a sheet afresh
(from afar, or around its free edge) takes the side it is on, and so does a node that no
longer lies over a body's surface at an accepted state (its nearest pair with the body is
not a face it projects into, :func:`nearest_inside`): it has nothing it could have passed
through.

The side is the face of the triangle's *oriented* sheet (+1: the side its normal
``(x1 − x0) × (x2 − x0)`` points to), so passing it on to an adjacent triangle assumes the
sheet's triangles are consistently oriented, as every surface of a body here is (a Gmsh
mesh of one outline).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["SideMemory", "nearest_inside", "present_side"]


def present_side(d0: np.ndarray) -> np.ndarray:
    """The side a node is on now, from its unsided plane distance ``d0``: ±1 (+1 on the plane)."""
    return np.where(d0 < 0.0, -1.0, 1.0)


@dataclass(frozen=True)
class SideMemory:
    """Remembered sides ``±1`` of (node, triangle) pairs, keyed ``node · M + triangle``.

    Attributes
    ----------
    keys
        Sorted keys of the remembered pairs.
    sides
        Their sides (+1: the face the triangle's normal points to).
    num_triangles
        ``M``, the number of triangles of the surface.
    node_start
        ``keys[node_start[n]:node_start[n + 1]]`` are node ``n``'s pairs (nodes up to the
        largest remembered one).
    """

    keys: np.ndarray
    sides: np.ndarray
    num_triangles: int
    node_start: np.ndarray

    @classmethod
    def of(cls, node: np.ndarray, tri: np.ndarray, sides: np.ndarray,
           num_triangles: int) -> SideMemory:
        """The memory of the pairs ``(node, tri)`` (distinct) with ``sides``."""
        node = np.asarray(node, dtype=np.int64)
        keys = node * num_triangles + np.asarray(tri, dtype=np.int64)
        order = np.argsort(keys, kind="stable")
        keys = keys[order]
        bounds = np.arange(node.max(initial=-1) + 2, dtype=np.int64) * num_triangles
        return cls(keys, np.asarray(sides)[order].astype(np.int8), int(num_triangles),
                   np.searchsorted(keys, bounds))

    def lookup(self, node: np.ndarray, tri: np.ndarray, adjacent: np.ndarray) -> np.ndarray:
        """Sides of the pairs ``(node, tri)``: remembered, else the side the node has on the
        first remembered triangle of ``adjacent[tri]`` (the same body's triangles around
        it, :func:`~valve_dolfinx.contact.exclusions.adjacent_triangles`), else 0 (a new
        pair)."""
        return _lookup(self.keys, self.sides, self.node_start,
                       np.asarray(node, dtype=np.int64), np.asarray(tri, dtype=np.int64),
                       np.asarray(adjacent, dtype=np.int64), self.num_triangles)


@numba.njit(cache=True)
def _remembered(keys, sides, lo, hi, key):  # pragma: no cover
    """The side remembered for ``key`` (a binary search of the sorted ``keys[lo:hi]``), 0
    if none."""
    end = hi
    while lo < hi:
        mid = (lo + hi) // 2
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return sides[lo] if lo < end and keys[lo] == key else np.int8(0)


@numba.njit(cache=True)
def _lookup(keys, sides, node_start, node, tri, adjacent, num_triangles):  # pragma: no cover
    out = np.zeros(len(node), dtype=np.int8)
    for i in range(len(node)):
        n = node[i]
        if n + 1 >= len(node_start):  # beyond the largest remembered node
            continue
        lo, hi = node_start[n], node_start[n + 1]  # the node's pairs
        side = _remembered(keys, sides, lo, hi, n * num_triangles + tri[i])
        for j in range(adjacent.shape[1]):
            if side != 0:
                break
            around = adjacent[tri[i], j]
            if around >= 0:
                side = _remembered(keys, sides, lo, hi, n * num_triangles + around)
        out[i] = side
    return out


@numba.njit(cache=True)
def nearest_inside(group, distance, inside):  # pragma: no cover
    """Per pair, whether the nearest pair of its ``group`` (smallest ``distance``, NaN last;
    of equal distances an ``inside`` one, then the first) is ``inside``: the order of
    ``np.lexsort((~inside, distance, group))``, linear in the pairs and the largest label
    instead of a sort.  With the pairs of a (node, body) as a group and ``inside`` a face
    the node projects into, whether the node lies over the body's surface and keeps its
    remembered sides with it
    (:meth:`~valve_dolfinx.contact.surface.SurfaceContact.update_history`)."""
    size = 0
    for g in group:
        size = max(size, g + 1)
    best = np.full(size, -1, dtype=np.int64)
    for i in range(len(group)):
        b = best[group[i]]
        if b < 0:
            best[group[i]] = i
            continue
        d, e = distance[i], distance[b]
        if d != d or e != e:  # NaN: after every number, equal to another NaN
            nearer = e != e and d == d
            tie = d != d and e != e
        else:
            nearer, tie = d < e, d == e
        if nearer or (tie and inside[i] and not inside[b]):
            best[group[i]] = i
    out = np.empty(len(group), dtype=np.bool_)
    for i in range(len(group)):
        out[i] = inside[best[group[i]]]
    return out
