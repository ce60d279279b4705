"""Unstructured triangle mesh of a flat leaflet outline with Gmsh's Python API."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from valve_dolfinx.exceptions import MeshError
from valve_dolfinx.geometry.outline import LeafletShape
from valve_dolfinx.interrupts import reclaim_signals

__all__ = ["FlatLeafletMesh", "mesh_flat_leaflet", "commissure_node_count", "triangle_angles"]

log = logging.getLogger(__name__)

#: Points used to describe the lower attachment curve to Gmsh (an interpolating
#: spline); mesh nodes on it are afterwards projected exactly onto the curve.
_LOWER_EDGE_POINTS = 81


@dataclass(frozen=True)
class FlatLeafletMesh:
    """A flat leaflet triangulation (mm).

    Attributes
    ----------
    points
        ``(n, 2)`` flat coordinates (x across, y up from the nadir).
    triangles
        ``(m, 3)`` node indices, counter-clockwise (positive flat area).
    lower, left, right, free
        Node indices of the boundary curves, ordered: lower edge left→right,
        commissures bottom→top, free edge left→right.  Corners are shared.
    shape
        The outline that was meshed.
    """

    points: np.ndarray
    triangles: np.ndarray
    lower: np.ndarray
    left: np.ndarray
    right: np.ndarray
    free: np.ndarray
    shape: LeafletShape

    @property
    def attachment(self) -> np.ndarray:
        """Attachment nodes: left commissure top→bottom, lower edge, right commissure bottom→top."""
        return np.concatenate([self.left[::-1], self.lower[1:], self.right[1:]])

    def boundary_edges(self) -> dict[str, np.ndarray]:
        """Consecutive node pairs along each boundary curve, ``(k, 2)`` arrays."""
        def pairs(chain: np.ndarray) -> np.ndarray:
            return np.stack([chain[:-1], chain[1:]], axis=1)

        return {
            "lower": pairs(self.lower),
            "left": pairs(self.left),
            "right": pairs(self.right),
            "free": pairs(self.free),
        }


def commissure_node_count(commissure_height: float, mesh_size: float) -> int:
    """Nodes on a commissure segment (uniformly spaced, ends included)."""
    return max(3, int(round(commissure_height / mesh_size)) + 1)


def mesh_flat_leaflet(shape: LeafletShape, mesh_size: float, n_commissure: int | None = None
                      ) -> FlatLeafletMesh:
    """Mesh the flat outline ``shape`` with target edge length ``mesh_size`` (mm).

    The commissures get ``n_commissure`` uniformly spaced nodes (by default from
    the *native* commissure height), so that the commissures of neighbouring
    leaflets -- and of a graft, whose commissure is mapped onto the native one by
    normalised arc length -- carry nodes at identical heights and can share them.
    """
    import gmsh  # here, so that the geometry's parameters load without Gmsh

    shape.check_mesh_size(mesh_size)
    if n_commissure is None:
        n_commissure = commissure_node_count(shape.native().commissure_height, mesh_size)
    initialised_here = not gmsh.isInitialized()
    if initialised_here:
        gmsh.initialize(interruptible=False)
        reclaim_signals()  # Gmsh installs its own SIGTERM handler
    try:
        return _mesh_with_gmsh(shape, mesh_size, n_commissure)
    finally:
        if initialised_here:
            gmsh.finalize()


def _mesh_with_gmsh(shape: LeafletShape, h: float, n_commissure: int) -> FlatLeafletMesh:
    """Mesh the right half (x >= 0) with Gmsh and mirror it across the midline x = 0.

    The leaflet is mirror-symmetric, and so is its mesh: the midline is a chain
    of mesh edges.  In the closed valve every leaflet folds along its midline
    at the centre of the valve (the free-edge middle meets the other two
    leaflets there), so the fold can form exactly along mesh edges instead of
    cutting through triangles, and the central coaptation height does not
    depend on where an unstructured mesh happens to put its nodes.
    """
    points, triangles, chains = _gmsh_right_half(shape, h, n_commissure)
    _snap_to_outline(shape, points, chains, n_commissure)
    points, triangles, chains = _without_unused_nodes(points, triangles, chains)
    return _mirrored(shape, points, triangles, chains)


#: a half mesh's boundary chains, node ids in order: lower edge and free edge from the
#: midline to the right corner, right commissure and midline from bottom to top
_Chains = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _gmsh_right_half(shape: LeafletShape, h: float, n_commissure: int
                     ) -> tuple[np.ndarray, np.ndarray, _Chains]:
    """Gmsh's mesh of the right half of the outline (Frontal-Delaunay, ``n_commissure``
    uniform nodes on the commissure): 2-D points, triangles and the boundary chains."""
    import gmsh

    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("General.Verbosity", 1)
    name = f"leaflet_{id(shape)}"
    gmsh.model.add(name)
    try:
        geo = gmsh.model.geo
        a, top = shape.half_width, shape.height
        xs = np.linspace(0.0, a, _LOWER_EDGE_POINTS // 2 + 1)
        ys = shape.lower_edge(xs)
        lower_pts = [geo.addPoint(x, y, 0.0, h) for x, y in zip(xs, ys, strict=True)]
        tr = geo.addPoint(a, top, 0.0, h)
        tm = geo.addPoint(0.0, top, 0.0, h)
        lower = geo.addSpline(lower_pts)
        right = geo.addLine(lower_pts[-1], tr)
        free = geo.addLine(tr, tm)
        mid = geo.addLine(tm, lower_pts[0])
        loop = geo.addCurveLoop([lower, right, free, mid])
        surf = geo.addPlaneSurface([loop])
        geo.synchronize()
        gmsh.model.mesh.setTransfiniteCurve(right, n_commissure)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 1)
        gmsh.option.setNumber("Mesh.Algorithm", 6)  # Frontal-Delaunay: well-shaped triangles
        gmsh.option.setNumber("Mesh.Smoothing", 5)
        gmsh.model.mesh.generate(2)

        tags, coords, _ = gmsh.model.mesh.getNodes()
        index = {int(t): i for i, t in enumerate(tags)}
        points = coords.reshape(-1, 3)[:, :2].copy()
        etypes, _, enodes = gmsh.model.mesh.getElements(2, surf)
        tri_pos = list(etypes).index(2)
        triangles = np.array([index[int(t)] for t in enodes[tri_pos]], dtype=np.int64)
        triangles = triangles.reshape(-1, 3)

        def chain(curve: int, key) -> np.ndarray:
            node_tags, _, _ = gmsh.model.mesh.getNodes(1, curve, includeBoundary=True)
            ids = np.unique(np.array([index[int(t)] for t in node_tags], dtype=np.int64))
            return ids[np.argsort(key(points[ids]))]

        chains = (chain(lower, lambda p: p[:, 0]), chain(right, lambda p: p[:, 1]),
                  chain(free, lambda p: p[:, 0]), chain(mid, lambda p: p[:, 1]))
    finally:
        gmsh.model.remove()
    return points, triangles, chains


def _snap_to_outline(shape: LeafletShape, points: np.ndarray, chains: _Chains,
                     n_commissure: int) -> None:
    """Put the boundary nodes exactly onto the analytic outline (in place), the
    commissure's uniformly."""
    lower_ids, right_ids, free_ids, mid_ids = chains
    points[lower_ids, 1] = shape.lower_edge(points[lower_ids, 0])
    points[right_ids, 0] = shape.half_width
    points[mid_ids, 0] = 0.0
    if len(right_ids) != n_commissure:
        raise MeshError(f"Gmsh placed {len(right_ids)} commissure nodes, expected {n_commissure}")
    points[right_ids, 1] = np.linspace(shape.commissure_bottom, shape.height, n_commissure)
    points[free_ids, 1] = shape.height


def _without_unused_nodes(points: np.ndarray, triangles: np.ndarray, chains: _Chains
                          ) -> tuple[np.ndarray, np.ndarray, _Chains]:
    """Drop the nodes on no triangle (Gmsh also meshes the spline's control points)."""
    used = np.unique(triangles)
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    return points[used], renumber[triangles], tuple(renumber[c] for c in chains)


def _mirrored(shape: LeafletShape, points: np.ndarray, triangles: np.ndarray,
              chains: _Chains) -> FlatLeafletMesh:
    """The whole leaflet: every node of the half mesh off the midline gets an image at -x."""
    lower_ids, right_ids, free_ids, mid_ids = chains
    n = len(points)
    image = np.full(n, -1, dtype=np.int64)
    off = np.setdiff1d(np.arange(n), mid_ids)
    image[off] = n + np.arange(len(off))
    image[mid_ids] = mid_ids
    points = np.concatenate([points, points[off] * np.array([-1.0, 1.0])])
    triangles = np.concatenate([triangles, image[triangles]])
    left_ids = image[right_ids]
    lower_ids = np.concatenate([image[lower_ids[::-1]], lower_ids[1:]])
    free_ids = np.concatenate([image[free_ids[::-1]], free_ids[1:]])
    triangles = _orient_ccw(points, triangles)
    log.debug("flat leaflet W=%g%% H=%g%%: %d nodes, %d triangles", shape.width_pct,
              shape.height_pct, len(points), len(triangles))
    return FlatLeafletMesh(points, triangles, lower_ids, left_ids, right_ids, free_ids, shape)


def _orient_ccw(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Reorder triangles to counter-clockwise (positive signed area)."""
    p = points[triangles]
    area2 = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
             - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    if np.any(np.abs(area2) < 1e-14):
        raise MeshError("Gmsh produced a degenerate (zero-area) triangle")
    out = triangles.copy()
    neg = area2 < 0
    out[neg, 1], out[neg, 2] = triangles[neg, 2], triangles[neg, 1]
    return out


def triangle_angles(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Interior angles (degrees) of each triangle, ``(m, 3)``; works in 2-D and 3-D."""
    p = points[triangles]
    angles = np.empty(triangles.shape)
    for i in range(3):
        u = p[:, (i + 1) % 3] - p[:, i]
        v = p[:, (i + 2) % 3] - p[:, i]
        cos = np.einsum("ij,ij->i", u, v) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        angles[:, i] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return angles

