"""Where the loaded leaflets pass through one another or through themselves (SPEC §6).

The contact (SPEC §5) keeps each node out of the triangles it is in contact with, so its
own measures (``max_penetration_mm``) cannot see a triangle that slices through another
between its nodes, nor a node that went past the contact's reach.  This check is
independent of the contact: it asks the IPC Toolkit (``ipctk``) for every edge of the
loaded surface that passes through a triangle of it, between leaflets and within one.

* One surface holds every leaflet.  The library's broad phase (an LBVH) lists the
  edge–triangle pairs whose boxes overlap and leaves out the pairs that share a vertex:
  the leaflets share their nodes along the commissures, and an edge always touches the
  triangles around its own ends.  Its exact predicate (``edge_triangle_intersection``,
  orientation tests in exact arithmetic) says whether the edge passes through the
  triangle, boundary included, and where.  An edge coplanar with a triangle counts (the
  library answers yes conservatively); it is placed at the edge's midpoint.
* Nodes at the same place are one node: a valve drawn as one solved leaflet and its mirror
  images has two copies of each commissure node.
* A commissure post is a seam where two leaflets are sewn together: the edges (and lone
  nodes) that triangles of both leaflets share.  Each pair records its distance from the
  nearest post in the loaded state.

Any pair at all means the surfaces pass through each other; a competent valve has none
(:func:`valve_dolfinx.result.competence`).
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

__all__ = ["LISTED_PAIRS", "IntersectingPair", "Intersections", "commissure_posts",
           "find_intersections", "leaflet_labels", "valve_intersections"]

log = logging.getLogger(__name__)

#: ``result.json`` lists at most this many pairs, spread evenly over their distances from a
#: post, the nearest and the farthest included (the count, the leaflets and the range of
#: distances cover them all)
LISTED_PAIRS = 20
#: nodes closer than this fraction of the surface's size are one node
WELD_TOLERANCE = 1e-9


@dataclass(frozen=True)
class IntersectingPair:
    """An edge that passes through a triangle (node and cell numbers of the surface)."""

    edge: tuple[int, int]
    triangle: int
    #: the edge's leaflet and the triangle's (one name twice: a leaflet through itself)
    leaflets: tuple[str, str]
    #: where the edge meets the triangle (mm)
    point: tuple[float, float, float]
    #: distance of ``point`` from the nearest commissure post (mm; inf without posts)
    post_distance_mm: float

    @property
    def label(self) -> str:
        """``graft/left-coronary`` for two leaflets (in alphabetical order), ``graft/self``
        for one through itself."""
        a, b = sorted(self.leaflets)
        return f"{a}/self" if a == b else f"{a}/{b}"

    def to_dict(self) -> dict:
        return {"leaflets": self.label, "point_mm": [round(c, 4) for c in self.point],
                "post_distance_mm": _finite(self.post_distance_mm)}


def _finite(value: float, digits: int = 4) -> float | None:
    return round(float(value), digits) if np.isfinite(value) else None


@dataclass(frozen=True)
class Intersections:
    """Every intersecting edge–triangle pair of a surface (:func:`find_intersections`)."""

    pairs: tuple[IntersectingPair, ...]
    #: edge–triangle pairs the broad phase offered to the exact test
    candidates: int
    #: wall time of the check (s)
    time_s: float

    @property
    def count(self) -> int:
        return len(self.pairs)

    @property
    def points(self) -> np.ndarray:
        """``(count, 3)`` where the pairs meet (mm)."""
        return np.array([p.point for p in self.pairs], dtype=float).reshape(-1, 3)

    def between(self) -> dict[str, int]:
        """Pairs per :attr:`IntersectingPair.label`, most first."""
        return dict(Counter(p.label for p in self.pairs).most_common())

    def post_distance_mm(self) -> tuple[float, float] | None:
        """Smallest and largest distance of a pair from the nearest post (None: no pair)."""
        if not self.pairs:
            return None
        d = [p.post_distance_mm for p in self.pairs]
        return min(d), max(d)

    def where(self) -> str:
        """``0.20–1.30 mm from a post (graft/left-coronary 24, graft/self 6)`` ("" without
        pairs): the words of ``competence_reason``."""
        span = self.post_distance_mm()
        if span is None:
            return ""
        leaflets = ", ".join(f"{label} {n}" for label, n in self.between().items())
        if not np.isfinite(span[1]):
            return f"no post to measure from ({leaflets})"
        low, high = span
        distance = f"{low:.2f} mm" if high - low < 0.005 else f"{low:.2f}–{high:.2f} mm"
        return f"{distance} from a post ({leaflets})"

    def to_dict(self, listed: int = LISTED_PAIRS) -> dict:
        """``result.json``'s ``intersections``: pairs per leaflets, the range of distances
        from a post, and at most ``listed`` pairs, nearest a post first, spread evenly over
        the pairs in that order (the nearest and the farthest included)."""
        span = self.post_distance_mm()
        order = sorted(self.pairs, key=lambda p: p.post_distance_mm)
        if len(order) > listed:
            order = [order[i] for i in np.linspace(0, len(order) - 1, listed).round().astype(int)]
        return {"between": self.between(),
                "post_distance_mm": None if span is None else [_finite(s) for s in span],
                "pairs": [p.to_dict() for p in order],
                "candidates": self.candidates,
                "check_time_s": round(self.time_s, 4)}


def _weld(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """``cells`` with the nodes at one place (within :data:`WELD_TOLERANCE` of the surface's
    size) numbered as one: the lowest number among them."""
    used = np.unique(cells)
    size = float(np.ptp(points[used], axis=0).max()) if len(used) else 0.0
    close = cKDTree(points[used]).query_pairs(WELD_TOLERANCE * max(size, 1.0),
                                              output_type="ndarray")
    if len(close) == 0:
        return cells
    n = len(used)
    graph = coo_matrix((np.ones(len(close)), (close[:, 0], close[:, 1])), shape=(n, n))
    _, group = connected_components(graph, directed=False)
    first = np.full(group.max() + 1, np.iinfo(np.int64).max)
    np.minimum.at(first, group, used)
    renumber = np.arange(points.shape[0])
    renumber[used] = first[group]
    return renumber[cells]


def _edge_leaflets(cells: np.ndarray, tags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every edge of ``cells`` (sorted node pairs, (E, 2)) and the lowest and highest tag of
    the triangles around it ((E, 2))."""
    sides = np.sort(cells[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges, which = np.unique(sides, axis=0, return_inverse=True)
    side_tags = np.repeat(tags, 3)
    low = np.full(len(edges), np.iinfo(np.int64).max)
    high = np.full(len(edges), np.iinfo(np.int64).min)
    np.minimum.at(low, which, side_tags)
    np.maximum.at(high, which, side_tags)
    return edges, np.stack([low, high], axis=1)


def commissure_posts(cells: np.ndarray, tags: np.ndarray) -> np.ndarray:
    """``(S, 2)`` node pairs of the segments where two leaflets (distinct ``tags``) are sewn
    together: the edges both have triangles on, and each node shared without such an edge
    as a segment of one point."""
    cells = np.asarray(cells, dtype=np.int64)
    tags = np.asarray(tags, dtype=np.int64)
    edges, edge_tags = _edge_leaflets(cells, tags)
    seams = edges[edge_tags[:, 0] != edge_tags[:, 1]]
    n = int(cells.max()) + 1
    low = np.full(n, np.iinfo(np.int64).max)
    high = np.full(n, np.iinfo(np.int64).min)
    np.minimum.at(low, cells.ravel(), np.repeat(tags, 3))
    np.maximum.at(high, cells.ravel(), np.repeat(tags, 3))
    shared = np.flatnonzero(low != high)
    lone = np.setdiff1d(shared, seams.ravel())
    return np.concatenate([seams, np.stack([lone, lone], axis=1)]).astype(np.int64)


def _distance_to_segments(points: np.ndarray, start: np.ndarray, end: np.ndarray
                          ) -> np.ndarray:
    """``(P,)`` distance of each point from the nearest of the segments ``start``–``end``
    (inf without segments)."""
    if len(start) == 0:
        return np.full(len(points), np.inf)
    along = end - start
    length2 = np.einsum("ij,ij->i", along, along)
    rel = points[:, None, :] - start[None, :, :]
    t = np.einsum("psi,si->ps", rel, along) / np.where(length2 > 0.0, length2, 1.0)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(rel - t[..., None] * along[None], axis=2).min(axis=1)


def find_intersections(points: np.ndarray, cells: np.ndarray, cell_tags: np.ndarray,
                       names: Mapping[int, str] | None = None) -> Intersections:
    """Every edge of the surface ``points`` (N, 3) / ``cells`` (M, 3) that passes through
    one of its triangles, by the IPC Toolkit (see the module docstring).

    ``cell_tags`` (M,) says which leaflet each triangle belongs to, ``names`` what to call
    it (default: the tag).  An edge on a seam belongs to both its leaflets; it passes
    through its own leaflet when the triangle's is either.
    """
    import ipctk

    start = time.perf_counter()
    points = np.asarray(points, dtype=float)
    tags = np.asarray(cell_tags, dtype=np.int64)
    cells = _weld(points, np.asarray(cells, dtype=np.int64))
    name = {int(t): (names or {}).get(int(t), str(t)) for t in np.unique(tags)}

    vertices = np.asfortranarray(points)
    faces = np.asfortranarray(cells, dtype=np.int32)
    edges, edge_tags = _edge_leaflets(cells, tags)
    broad = ipctk.LBVH()
    broad.build(vertices, np.asfortranarray(edges, dtype=np.int32), faces, 0.0)
    candidates = broad.detect_edge_face_candidates()

    hits: list[tuple[int, int, np.ndarray]] = []
    for c in candidates:
        a, b = edges[c.edge_id]
        t0, t1, t2 = cells[c.face_id]
        meets, _, _, s = ipctk.edge_triangle_intersection(
            points[a], points[b], points[t0], points[t1], points[t2])
        if meets:
            s = 0.5 if not np.isfinite(s) else s  # coplanar: the edge's midpoint
            hits.append((c.edge_id, c.face_id, points[a] + s * (points[b] - points[a])))

    posts = commissure_posts(cells, tags)
    where = np.array([h[2] for h in hits]).reshape(-1, 3)
    distance = _distance_to_segments(where, points[posts[:, 0]], points[posts[:, 1]])
    pairs = []
    for (edge, face, point), d in zip(hits, distance, strict=True):
        own = edge_tags[edge]
        face_tag = int(tags[face])
        edge_tag = face_tag if face_tag in own else int(own[0])
        pairs.append(IntersectingPair(
            (int(edges[edge, 0]), int(edges[edge, 1])), int(face),
            (name[edge_tag], name[face_tag]), tuple(float(v) for v in point), float(d)))
    found = Intersections(tuple(pairs), len(candidates), time.perf_counter() - start)
    log.info("intersection check: %d edge–triangle pairs intersect (%d candidates, %.3f s)%s",
             found.count, found.candidates, found.time_s,
             f": {found.where()}" if found.pairs else "")
    return found


def leaflet_labels(valve) -> dict[int, str]:
    """What each leaflet of a valve mesh is called in the check: its name with hyphens
    (``left-coronary``), ``graft`` for the graft."""
    return {p.tag: "graft" if p.is_graft else p.name.replace("_", "-") for p in valve.leaflets}


def valve_intersections(positions: np.ndarray, valve) -> Intersections:
    """:func:`find_intersections` of a valve mesh's loaded ``positions``, its leaflets
    named by :func:`leaflet_labels`."""
    return find_intersections(positions, valve.cells, valve.cell_tags, leaflet_labels(valve))
