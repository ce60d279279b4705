"""Edge-to-edge contact of the leaflets' free edges.

Node-to-surface contact cannot stop two *edges* that cross like the blades of
scissors: the crossing point lies between nodes, and no node comes within the
cut-off of the other sheet.  That is exactly how three closing leaflets meet
at the valve centre -- their free edges converge on the axis -- and without
edge contact they pass through each other there.  This module treats the
free-edge segments: for every pair of segments (of different leaflets, or of
one leaflet but not sharing a node) the closest points ``p = (1-s)·a0 + s·a1``
and ``q = (1-t)·b0 + t·b1`` define the distance ``d = |p - q|`` and the
direction ``n = (p - q)/d``; the SPEC §5 law (same parameters, taper and
driving force as the surface contact) pushes the segments apart along ``n``,
with the force split over the four nodes by the segment parameters.

Where the closest points are interior to both segments (the scissors case)
the direction is the common normal ``c = (a1 - a0)×(b1 - b0)/|…|`` and
``d = σ·c·(p - q)`` is a *signed* distance, continuous through zero; σ = ±1 is
the side the pair was on at the last accepted state (:meth:`update_history`),
so a pair that has crossed has ``d < 0`` (a penetration).  Elsewhere (an end
point involved) ``n = (p - q)/|p - q|``, and a pair whose direction has flipped
since the recorded state counts as crossed.

The Jacobian blocks are the exact ``d``-derivative with ``n``, ``s``, ``t``
and the driving force frozen (as for the surface contact):
``∂f_p/∂x_q = B_p B_q (∂f/∂d) n⊗n`` with ``B = [1-s, s, -(1-t), -t]``.
"""

from __future__ import annotations

import logging

import numpy as np

from valve_dolfinx.contact.law import ContactParameters, contact_force, driving_force
from valve_dolfinx.contact.model import ContactResult
from valve_dolfinx.exceptions import MeshError

__all__ = ["EdgeContact", "closest_points_on_segments"]

log = logging.getLogger(__name__)


def closest_points_on_segments(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray]:
    """Parameters ``(s, t)`` in [0, 1] of the closest points of segment pairs (vectorised).

    Minimises ``|a0 + s(a1 - a0) - b0 - t(b1 - b0)|`` (Ericson, *Real-Time
    Collision Detection*, §5.1.9); parallel segments take the first solution.
    """
    d1, d2, r = a1 - a0, b1 - b0, a0 - b0
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-14 * a * e, np.clip((b * f - c * e) / denom, 0.0, 1.0), 0.0)
        t = (b * s + f) / e
        s = np.where(t < 0.0, np.clip(-c / a, 0.0, 1.0), np.where(t > 1.0,
                                                                np.clip((b - c) / a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    return s, t


class EdgeContact:
    """Contact between the segments of given polylines (the leaflets' free edges).

    Parameters
    ----------
    segments
        ``(E, 2)`` node ids of the edge segments.
    num_nodes
        Number of nodes of the positions passed to :meth:`evaluate`.
    params
        Contact law parameters (shared with the surface contact).
    """

    def __init__(self, segments: np.ndarray, num_nodes: int,
                 params: ContactParameters = ContactParameters()) -> None:
        segments = np.asarray(segments, dtype=np.int64).reshape(-1, 2)
        if segments.size and (segments.min() < 0 or segments.max() >= num_nodes):
            raise MeshError(f"edge segment node ids must lie in [0, {num_nodes})")
        self.segments = segments
        self.num_nodes = int(num_nodes)
        self.params = params
        i, j = np.triu_indices(len(segments), k=1)
        share = (segments[i, :, None] == segments[j, None, :]).any(axis=(1, 2))
        #: candidate pairs: segments that share no node
        self.pairs = np.stack([i[~share], j[~share]], axis=1)
        self._history: np.ndarray | None = None

    def update_history(self, x: np.ndarray) -> None:
        """Record the side of every pair at an accepted state."""
        _, _, v, c = self._closest(x)
        self._history = (v, np.sign(np.einsum("ij,ij->i", v, c)))

    def _closest(self, x: np.ndarray):
        """Segment parameters, offsets p - q and unit common normals of all pairs."""
        a, b = self.segments[self.pairs[:, 0]], self.segments[self.pairs[:, 1]]
        s, t = closest_points_on_segments(x[a[:, 0]], x[a[:, 1]], x[b[:, 0]], x[b[:, 1]])
        da, db = x[a[:, 1]] - x[a[:, 0]], x[b[:, 1]] - x[b[:, 0]]
        p = x[a[:, 0]] + s[:, None] * da
        q = x[b[:, 0]] + t[:, None] * db
        c = np.cross(da, db)
        c /= np.maximum(np.linalg.norm(c, axis=1), 1e-300)[:, None]
        return s, t, p - q, c

    def evaluate(self, x: np.ndarray, f_ext: np.ndarray, nodes: np.ndarray | None = None
                 ) -> ContactResult:
        """Forces of the segment pairs whose first segment starts at one of ``nodes``."""
        p = self.params
        s, t, v, c = self._closest(x)
        dist = np.linalg.norm(v, axis=1)
        normal = v / np.maximum(dist, 1e-300)[:, None]
        d = dist.copy()
        vc = np.einsum("ij,ij->i", v, c)
        if self._history is not None:
            v_prev, side = self._history
            crossed = np.einsum("ij,ij->i", v, v_prev) < 0.0
            d[crossed] = -dist[crossed]
            normal[crossed] = -normal[crossed]
        else:
            side = np.sign(vc)
        # scissors: both closest points interior and the segments not parallel
        interior = (s > 1e-9) & (s < 1 - 1e-9) & (t > 1e-9) & (t < 1 - 1e-9) & (side != 0)
        d[interior] = side[interior] * vc[interior]
        normal[interior] = side[interior, None] * c[interior]
        d = d - p.thickness
        active = (d < p.cutoff) & (d > -p.penetration_depth)
        if nodes is not None:
            mine = np.zeros(self.num_nodes, dtype=bool)
            mine[np.asarray(nodes, dtype=np.int64)] = True
            active &= mine[self.segments[self.pairs[:, 0], 0]]
        idx = np.flatnonzero(active)
        if len(idx) == 0:
            return ContactResult.empty(self.num_nodes)
        a = self.segments[self.pairs[idx, 0]]
        b = self.segments[self.pairs[idx, 1]]
        s, t, n, d = s[idx], t[idx], normal[idx], d[idx]
        # driving force: the pressure load at the closest point of segment a pushing it
        # towards b (n points from b to a)
        f_a = (1 - s)[:, None] * f_ext[a[:, 0]] + s[:, None] * f_ext[a[:, 1]]
        F = driving_force(f_a, n, p)
        f, dfdd = contact_force(d, F, p.stiffness, p.cutoff, p.taper)
        on = f > 0
        a, b, s, t, n, f, dfdd, d = (arr[on] for arr in (a, b, s, t, n, f, dfdd, d))
        ids = np.concatenate([a, b], axis=1)  # (A, 4)
        B = np.stack([1 - s, s, -(1 - t), -t], axis=1)
        contributions = B[:, :, None] * (f[:, None] * n)[:, None, :]
        forces = np.stack([np.bincount(ids.ravel(), contributions[:, :, i].ravel(),
                                       minlength=self.num_nodes) for i in range(3)], axis=1)
        nn = dfdd[:, None, None] * n[:, :, None] * n[:, None, :]
        blocks = (B[:, :, None] * B[:, None, :])[:, :, :, None, None] * nn[:, None, None]
        rows = np.repeat(ids, 4, axis=1).ravel()
        cols = np.tile(ids, (1, 4)).ravel()
        return ContactResult(forces=forces, jac_rows=rows, jac_cols=cols,
                             jac_blocks=blocks.reshape(-1, 3, 3), n_active=int(on.sum()),
                             max_penetration=float(np.max(-d, initial=0.0)),
                             total_force=float(f.sum()),
                             pairs=np.stack([a[:, 0], -1 - b[:, 0]], axis=1))
