"""Mesh neighbourhoods of a contact surface: the nodes that never contact each triangle (its
mesh neighbourhood and, optionally, the nodes near it in a reference state), the triangles
around each triangle, and each node's distance from the seams where bodies are sewn
together."""

from __future__ import annotations

import numpy as np

__all__ = ["adjacent_triangles", "merge_exclusions", "reference_neighbours", "seam_distances",
           "triangle_halo", "vertex_adjacency"]


def _padded_rows(keys: np.ndarray, num_rows: int, first: np.ndarray | None = None
                 ) -> np.ndarray:
    """Padded table of the sorted, distinct ``keys = row·num_rows + col``: row ``r`` holds
    its columns ascending (after ``first[r]``, if given), then ``-1``."""
    row, col = np.divmod(keys, num_rows)
    degree = np.bincount(row, minlength=num_rows)
    lead = 0 if first is None else 1
    table = np.full((num_rows, int(degree.max(initial=0)) + lead), -1, dtype=np.int64)
    if first is not None:
        table[:, 0] = first
    rank = np.arange(len(row)) - (np.cumsum(degree) - degree)[row]
    table[row, lead + rank] = col
    return table


def vertex_adjacency(triangles: np.ndarray, num_nodes: int) -> np.ndarray:
    """Closed edge neighbourhoods of the nodes as a padded table.

    Returns an ``(N, W)`` integer array whose row ``p`` holds ``p`` itself, then
    the nodes sharing an edge with ``p`` (ascending), then ``-1`` padding;
    ``W - 1`` is the largest vertex degree.
    """
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    edges = triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    edges = np.concatenate([edges, edges[:, ::-1]])
    keys = np.unique(edges[:, 0] * num_nodes + edges[:, 1])
    return _padded_rows(keys, num_nodes, first=np.arange(num_nodes))


def adjacent_triangles(triangles: np.ndarray, body: np.ndarray) -> np.ndarray:
    """``(M, K)`` table of the triangles of the same body that share a vertex with each
    triangle (itself excluded), ascending, padded with ``-1``."""
    from scipy.sparse import csr_matrix

    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    m = len(triangles)
    if m == 0:
        return np.empty((0, 0), dtype=np.int64)
    incidence = csr_matrix((np.ones(3 * m), (np.repeat(np.arange(m), 3), triangles.ravel())))
    shared = (incidence @ incidence.T).tocoo()
    t, u = shared.row.astype(np.int64), shared.col.astype(np.int64)
    keep = (t != u) & (body[t] == body[u])
    return _padded_rows(np.unique(t[keep] * m + u[keep]), m)



def triangle_halo(triangles: np.ndarray, num_nodes: int) -> np.ndarray:
    """Nodes that never contact each triangle: its vertices and their edge-neighbours.

    Returns an ``(M, U)`` table, ascending ids per row padded with ``-1``
    (``U`` = 12 for a regular mesh of degree-6 vertices).
    """
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    around = vertex_adjacency(triangles, num_nodes)[triangles].reshape(len(triangles), -1)
    around = np.where(around < 0, num_nodes, around)
    around.sort(axis=1)
    repeated = np.zeros(around.shape, dtype=bool)
    repeated[:, 1:] = around[:, 1:] == around[:, :-1]
    around[repeated] = num_nodes
    around.sort(axis=1)
    width = int((around < num_nodes).sum(axis=1).max(initial=0))
    halo = around[:, :width]
    halo[halo == num_nodes] = -1
    return halo



def reference_neighbours(triangles: np.ndarray, reference: np.ndarray, body: np.ndarray,
                         radius: float) -> list[np.ndarray]:
    """For each triangle, the nodes of its own body within ``radius`` of it in the reference state.

    ``reference`` holds each triangle's vertex coordinates in the stress-free
    state, ``(M, 3, D)`` (the flat leaflet, D = 2; a node shared by two bodies may
    have different coordinates in each).  A node counts if its reference
    distance to the triangle's centroid is below ``radius`` plus the
    triangle's centroid-to-vertex radius (a cheap superset of "within
    ``radius`` of the triangle").
    """
    from scipy.spatial import cKDTree

    out: list[np.ndarray] = [np.empty(0, dtype=np.int64)] * len(triangles)
    centroid = reference.mean(axis=1)
    size = np.linalg.norm(reference - centroid[:, None], axis=2).max(axis=1)
    for b in np.unique(body):
        cells = np.flatnonzero(body == b)
        nodes = triangles[cells].ravel()
        coords = reference[cells].reshape(-1, reference.shape[2])
        nodes, first = np.unique(nodes, return_index=True)
        tree = cKDTree(coords[first])
        hits = tree.query_ball_point(centroid[cells], radius + size[cells])
        for cell, found in zip(cells, hits, strict=True):
            out[cell] = nodes[np.asarray(found, dtype=np.int64)]
    return out



def merge_exclusions(halo: np.ndarray, extra: list[np.ndarray]) -> np.ndarray:
    """Padded table of the union, per row, of ``halo`` (padded with -1) and ``extra``."""
    rows = [np.union1d(h[h >= 0], e) for h, e in zip(halo, extra, strict=True)]
    width = max((len(r) for r in rows), default=0)
    table = np.full((len(rows), width), -1, dtype=np.int64)
    for i, r in enumerate(rows):
        table[i, :len(r)] = r
    return table



def seam_distances(triangles: np.ndarray, body: np.ndarray, placed: np.ndarray,
                   num_bodies: int) -> np.ndarray:
    """``(N, B)`` distance of every node from the seam its body shares with each body.

    Two bodies are sewn together where they share nodes (the commissures of the valve):
    the seam is the set of edges (and lone nodes) common to both.  Entry ``[p, b]`` is
    the distance, in the ``placed`` state ``(N, 3)``, from node ``p`` to the seam between
    its own body (the lowest body among its triangles) and body ``b``: ``inf`` where the two
    share no node, and for ``b`` its own body.
    """
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    num_nodes = len(placed)
    member = np.zeros((num_nodes, num_bodies), dtype=bool)
    for k in range(3):
        member[triangles[:, k], body] = True
    own = np.argmax(member, axis=1)
    edges = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges = np.unique(edges, axis=0)
    out = np.full((num_nodes, num_bodies), np.inf)
    for a in range(num_bodies):
        for b in range(a + 1, num_bodies):
            shared = member[:, a] & member[:, b]
            if not shared.any():
                continue
            seam = edges[shared[edges[:, 0]] & shared[edges[:, 1]]]
            lone = np.setdiff1d(np.flatnonzero(shared), seam.ravel())
            seam = np.concatenate([seam, np.stack([lone, lone], axis=1)])
            start, end = placed[seam[:, 0]], placed[seam[:, 1]]
            for one, other in ((a, b), (b, a)):
                nodes = np.flatnonzero(own == one)
                out[nodes, other] = _segment_distances(placed[nodes], start, end).min(axis=1)
    return out


def _segment_distances(points: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """``(P, S)`` distances of points from segments (a segment may be a single point)."""
    along = end - start
    length2 = np.einsum("ij,ij->i", along, along)
    rel = points[:, None, :] - start[None, :, :]
    t = np.einsum("psi,si->ps", rel, along) / np.where(length2 > 0.0, length2, 1.0)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(rel - t[:, :, None] * along[None, :, :], axis=2)
