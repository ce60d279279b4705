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
(from afar, or around its free edge) takes the side it is on.

The side is the face of the triangle's *oriented* sheet (+1: the side its normal
``(x1 − x0) × (x2 − x0)`` points to), so passing it on to an adjacent triangle assumes the
sheet's triangles are consistently oriented, as every surface of a body here is (a Gmsh
mesh of one outline).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SideMemory", "adjacent_triangles"]


def adjacent_triangles(triangles: np.ndarray, body: np.ndarray) -> np.ndarray:
    """``(M, K)`` table of the triangles of the same body that share a vertex with each
    triangle (itself excluded), ascending, padded with ``-1``."""
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    m = len(triangles)
    if m == 0:
        return np.empty((0, 0), dtype=np.int64)
    owner = np.repeat(np.arange(m), 3)
    vertex = triangles.ravel()
    order = np.argsort(vertex, kind="stable")
    vertex, owner = vertex[order], owner[order]
    # all (t, u) with a common vertex: pair every incidence with every other one of its vertex
    starts = np.flatnonzero(np.r_[True, vertex[1:] != vertex[:-1]])
    counts = np.diff(np.r_[starts, len(vertex)])
    pairs = [np.empty((0, 2), dtype=np.int64)]
    for c in np.unique(counts):
        group = starts[counts == c][:, None] + np.arange(c)
        members = owner[group]
        t = np.repeat(members, c, axis=1).ravel()
        u = np.tile(members, (1, c)).ravel()
        pairs.append(np.stack([t, u], axis=1))
    pairs = np.concatenate(pairs)
    pairs = pairs[(pairs[:, 0] != pairs[:, 1]) & (body[pairs[:, 0]] == body[pairs[:, 1]])]
    keys = np.unique(pairs[:, 0] * m + pairs[:, 1])
    row, col = np.divmod(keys, m)
    degree = np.bincount(row, minlength=m)
    table = np.full((m, int(degree.max(initial=0))), -1, dtype=np.int64)
    rank = np.arange(len(row)) - (np.cumsum(degree) - degree)[row]
    table[row, rank] = col
    return table


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
    """

    keys: np.ndarray
    sides: np.ndarray
    num_triangles: int

    @classmethod
    def empty(cls, num_triangles: int) -> SideMemory:
        return cls(np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int8), int(num_triangles))

    @classmethod
    def of(cls, node: np.ndarray, tri: np.ndarray, sides: np.ndarray,
           num_triangles: int) -> SideMemory:
        """The memory of the pairs ``(node, tri)`` (distinct) with ``sides``."""
        keys = np.asarray(node, dtype=np.int64) * num_triangles + np.asarray(tri, dtype=np.int64)
        order = np.argsort(keys, kind="stable")
        return cls(keys[order], np.asarray(sides)[order].astype(np.int8), int(num_triangles))

    def __len__(self) -> int:
        return len(self.keys)

    def _find(self, keys: np.ndarray) -> np.ndarray:
        """Side of each key, 0 where it is not remembered."""
        out = np.zeros(len(keys), dtype=np.int8)
        if len(self.keys) == 0 or len(keys) == 0:
            return out
        at = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
        hit = self.keys[at] == keys
        out[hit] = self.sides[at[hit]]
        return out

    def lookup(self, node: np.ndarray, tri: np.ndarray, adjacent: np.ndarray) -> np.ndarray:
        """Sides of the pairs ``(node, tri)``: remembered, else the side the node has on the
        first remembered triangle of ``adjacent[tri]`` (the same body's triangles around
        it), else 0 (a new pair)."""
        node = np.asarray(node, dtype=np.int64)
        tri = np.asarray(tri, dtype=np.int64)
        m = self.num_triangles
        side = self._find(node * m + tri)
        unknown = np.flatnonzero(side == 0)
        for j in range(adjacent.shape[1] if len(unknown) else 0):
            around = adjacent[tri[unknown], j]
            found = np.where(around >= 0, self._find(node[unknown] * m + around), 0)
            side[unknown] = found
            unknown = unknown[found == 0]
            if len(unknown) == 0:
                break
        return side
