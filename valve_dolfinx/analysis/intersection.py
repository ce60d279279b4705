"""Where the loaded leaflets' mid-surfaces pass through one another.

Node-to-surface contact keeps every node out of the contact layers of the triangles it is
in contact with, and ``max_penetration_mm`` is measured over those contacts only.  It does
not see a triangle that slices through a neighbour between the neighbour's nodes, nor a
node that has gone deeper than the penetration window.  This check intersects the loaded
triangulated surfaces of every pair of leaflets (VTK's triangle-triangle intersection,
through PyVista) and measures the intersection lines.  The leaflets' attachment lines meet
at the commissures by construction, so the part within ``wall_band_mm`` of the root wall
is reported apart from the part inside the valve.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

__all__ = ["LeafletIntersection", "leaflet_intersections"]


@dataclass(frozen=True)
class LeafletIntersection:
    """The intersection of two leaflets' loaded surfaces (lengths in mm)."""

    leaflets: tuple[int, int]
    total_mm: float
    inner_mm: float
    #: smallest and largest distance from the valve axis of the inner part (None: no inner part)
    inner_radius_mm: tuple[float, float] | None
    #: lowest and highest point of the inner part
    inner_height_mm: tuple[float, float] | None


def leaflet_intersections(points: np.ndarray, cells: np.ndarray, cell_tags: np.ndarray,
                          root_radius_mm: float, wall_band_mm: float = 1.0
                          ) -> list[LeafletIntersection]:
    """Intersection of every pair of leaflets (distinct ``cell_tags``) of the surface
    ``points``/``cells``; a segment of an intersection line counts as inner when its
    midpoint is nearer the axis (z) than ``root_radius_mm - wall_band_mm``."""
    import pyvista as pv

    tags = np.asarray(cell_tags)
    points = np.asarray(points, dtype=float)
    surfaces = {}
    for t in np.unique(tags):
        faces = np.hstack([np.full((np.sum(tags == t), 1), 3), cells[tags == t]]).ravel()
        surfaces[int(t)] = pv.PolyData(points, faces).clean()
    inner_limit = root_radius_mm - wall_band_mm
    out = []
    for a, b in itertools.combinations(sorted(surfaces), 2):
        with pv.vtk_verbosity("off"):  # VTK warns when two surfaces do not intersect
            lines, _, _ = surfaces[a].intersection(surfaces[b], split_first=False,
                                                   split_second=False)
        total = inner = 0.0
        where = []
        for i in range(lines.n_cells):
            ends = lines.get_cell(i).points
            length = float(np.linalg.norm(ends[-1] - ends[0]))
            mid = ends.mean(axis=0)
            radius = float(np.hypot(mid[0], mid[1]))
            total += length
            if radius < inner_limit:
                inner += length
                where.append((radius, float(mid[2])))
        w = np.array(where).reshape(-1, 2)
        out.append(LeafletIntersection(
            (a, b), total, inner,
            (float(w[:, 0].min()), float(w[:, 0].max())) if len(w) else None,
            (float(w[:, 1].min()), float(w[:, 1].max())) if len(w) else None))
    return out
