"""A loaded valve's shape carried onto another mesh of the valve (a warm start).

Every leaflet has a flat, stress-free outline; a graft's is the native outline scaled by
``(1 + W, 1 + H)``.  Dividing a leaflet's flat coordinates by its scales puts every leaflet
in the same *native frame*, where the native outline is the common domain.  A node of the
target valve finds the triangle of the source's same leaflet that holds its native-frame
point and takes the barycentric blend of that triangle's loaded positions.  Points just
outside the source outline (a coarser mesh cuts the curved lower edge with chords) take the
nearest point of the nearest triangle.

So the loaded normal valve gives a graft valve its starting shape (the native leaflets
where they were, the graft laid over the loaded native leaflet it replaces), and a solve on
a coarse mesh gives the fine mesh of the same valve its start.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from valve_dolfinx.exceptions import MeshError
from valve_dolfinx.geometry.valve import LeafletPatch, ValveMesh

__all__ = ["ValveState", "native_frame", "transfer_positions"]


class ValveState(NamedTuple):
    """A loaded valve to start a closure from: its mesh, its nodes' positions ``(N, 3)``,
    where it comes from (for the record), and the Newton iterations and wall-clock time
    that reaching it cost (0 where another case paid for it)."""

    valve: ValveMesh
    positions: np.ndarray
    origin: str
    newton_iterations: int = 0
    wall_time_s: float = 0.0


def native_frame(patch: LeafletPatch) -> np.ndarray:
    """``(n, 2)`` flat coordinates of a leaflet's nodes divided by its graft scales."""
    return patch.flat / np.array([patch.shape.sx, patch.shape.sy])


def _barycentric(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``(n, 3)`` of 2-D ``points`` in triangles ``corners`` (n, 3, 2)."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    l1 = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / det
    l2 = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / det
    return np.stack([1.0 - l1 - l2, l1, l2], axis=1)


def _locate(points: np.ndarray, nodes: np.ndarray, triangles: np.ndarray,
            candidates: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """For each point, a triangle and weights whose blend of the corners is the point, or
    the closest point of the nearest triangles (weights clipped to the triangle)."""
    centroids = nodes[triangles].mean(axis=1)
    k = min(candidates, len(triangles))
    _, near = cKDTree(centroids).query(points, k=k)
    near = near.reshape(len(points), k)
    best_tri = np.empty(len(points), dtype=np.int64)
    best_w = np.empty((len(points), 3))
    best_miss = np.full(len(points), np.inf)
    for j in range(k):
        tri = near[:, j]
        w = _barycentric(points, nodes[triangles[tri]])
        miss = np.maximum(-w.min(axis=1), 0.0)  # 0 inside
        better = miss < best_miss
        best_tri[better], best_w[better], best_miss[better] = tri[better], w[better], miss[better]
    outside = best_miss > 0.0
    if np.any(outside):  # clip to the triangle: nearest-point weights, renormalised
        w = np.clip(best_w[outside], 0.0, None)
        best_w[outside] = w / w.sum(axis=1, keepdims=True)
    return best_tri, best_w


def transfer_positions(source: ValveMesh, positions: np.ndarray, target: ValveMesh
                       ) -> np.ndarray:
    """Positions ``(N_target, 3)`` of the target valve's nodes on the source's loaded shape.

    Parameters
    ----------
    source, positions
        A valve mesh and the loaded positions of its nodes ``(N_source, 3)``.
    target
        Another mesh of a valve with the same leaflets (names): another mesh size, or a
        graft in place of a native leaflet.

    Raises
    ------
    MeshError
        If the two valves do not have the same leaflets, or the positions do not fit.
    """
    positions = np.asarray(positions, dtype=float)
    if positions.shape != (source.num_nodes, 3):
        raise MeshError(f"source positions have shape {positions.shape}; the source valve has "
                        f"{source.num_nodes} nodes")
    names = [p.name for p in source.leaflets]
    if sorted(names) != sorted(p.name for p in target.leaflets):
        raise MeshError(f"cannot carry a valve with leaflets {names} onto one with "
                        f"{[p.name for p in target.leaflets]}")
    out = np.full((target.num_nodes, 3), np.nan)
    for patch in target.leaflets:
        origin = source.leaflet(patch.name)
        tri, w = _locate(native_frame(patch), native_frame(origin), origin.triangles)
        corners = positions[origin.nodes[origin.triangles[tri]]]  # (n, 3, 3)
        out[patch.nodes] = np.einsum("nk,nki->ni", w, corners)
    return out
