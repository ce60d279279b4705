r"""Edge-to-edge contact of the leaflets' free edges ("scissors" contact).

Node-to-surface contact cannot stop two *edges* that cross like the blades of
scissors: the crossing point lies between nodes, and no node comes within
reach of the other sheet.  That is how the free edges of closing leaflets meet
at the valve centre and along the seams, and without edge contact one
leaflet's free edge slips over its neighbour's and its belly follows.

For two segments ``a = (a₀, a₁)`` and ``b = (b₀, b₁)`` whose closest points
``p = a₀ + s·(a₁ - a₀)`` and ``q = b₀ + t·(b₁ - b₀)`` are interior to both
(``0 < s, t < 1``), ``p - q`` is parallel to the common normal
``c = (a₁ - a₀) × (b₁ - b₀)/|…|`` and

.. math::

    d = σ\, c\cdot(p - q) - t_c

is a signed distance, continuous through zero; ``σ = ±1`` is the side the
pair was on when it was last far apart (:meth:`EdgeContact.update_history`),
so a pair that has crossed has ``d < 0``.  The SPEC §5 law (same parameters
as the surface contact) pushes ``p`` along ``n = σc`` with ``f(d, F)``, ``F``
the pressure force at ``p`` pushing it towards ``b``; the force is split over
the four nodes with ``B = [1-s, s, -(1-t), -t]``.

Rows appear and vanish smoothly: a presence factor fades each pair in as its
closest points move in from the segment ends (over ``blend_distance`` of
arc length) and out before the cut-off, so the residual is continuous.  The
Jacobian is exact (distance, turning of ``c``, sliding of ``s`` and ``t``,
the driving force turning with ``n``, the presence), checked against finite
differences in ``tests/test_contact_edges.py``.
"""

from __future__ import annotations

import logging

import numpy as np

from valve_dolfinx.contact.law import (
    ContactParameters,
    contact_force_slope_in_F,
    law_force,
)
from valve_dolfinx.contact.linearisation import skew
from valve_dolfinx.contact.results import ContactResult
from valve_dolfinx.exceptions import MeshError

__all__ = ["EdgeContact", "closest_points_on_lines"]

log = logging.getLogger(__name__)

#: Segments closer to parallel than this (sin of the angle) have no scissors contact.
_PARALLEL = 1e-6


def closest_points_on_lines(a0, a1, b0, b1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Parameters ``(s, t)`` of the closest points of the *lines* through segment pairs.

    Also returns ``sin`` of the angle between the lines; where it is (nearly)
    zero the parameters are meaningless.
    """
    da, db, r = a1 - a0, b1 - b0, a0 - b0
    a = np.einsum("ij,ij->i", da, da)
    b = np.einsum("ij,ij->i", da, db)
    e = np.einsum("ij,ij->i", db, db)
    c = np.einsum("ij,ij->i", da, r)
    f = np.einsum("ij,ij->i", db, r)
    denom = a * e - b * b
    safe = np.where(denom > 0.0, denom, 1.0)
    s = (b * f - c * e) / safe
    t = (a * f - b * c) / safe
    sin = np.sqrt(np.maximum(denom, 0.0) / np.maximum(a * e, 1e-300))
    return s, t, sin


def _ramp(x: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Smoothstep ``0 → 1`` over ``[0, width]`` and its derivative."""
    xi = np.clip(x / width, 0.0, 1.0)
    return xi * xi * (3.0 - 2.0 * xi), np.where((xi > 0) & (xi < 1), 6.0 * xi * (1 - xi) / width,
                                                0.0)


class EdgeContact:
    """Scissors contact between the segments of polylines (the leaflets' free edges).

    Parameters
    ----------
    segments
        ``(E, 2)`` node ids of the edge segments.
    num_nodes
        Number of nodes of the positions passed to :meth:`evaluate`.
    params
        Contact law parameters (shared with the surface contact).
    reference, exclusion_radius
        ``(N, 3)`` node positions in a stress-free placement and a distance
        (mm): segments closer than that in the reference never contact (the
        neighbouring segments of one polyline meet at an angle, and at the
        tip of a leaflet's V the two halves of its free edge are within reach
        of each other without crossing).
    """

    def __init__(self, segments: np.ndarray, num_nodes: int,
                 params: ContactParameters | None = None, *,
                 reference: np.ndarray | None = None, exclusion_radius: float = 0.0) -> None:
        segments = np.asarray(segments, dtype=np.int64).reshape(-1, 2)
        if segments.size and (segments.min() < 0 or segments.max() >= num_nodes):
            raise MeshError(f"edge segment node ids must lie in [0, {num_nodes})")
        self.segments = segments
        self.num_nodes = int(num_nodes)
        self.params = ContactParameters() if params is None else params
        i, j = np.triu_indices(len(segments), k=1)
        share = (segments[i, :, None] == segments[j, None, :]).any(axis=(1, 2))
        keep = ~share
        if reference is not None and exclusion_radius > 0.0:
            ref = np.asarray(reference, dtype=float)
            ends_i, ends_j = ref[segments[i]], ref[segments[j]]
            s, t, sin = closest_points_on_lines(ends_i[:, 0], ends_i[:, 1], ends_j[:, 0],
                                                ends_j[:, 1])
            s, t = np.clip(s, 0, 1), np.clip(t, 0, 1)
            p = ends_i[:, 0] + s[:, None] * (ends_i[:, 1] - ends_i[:, 0])
            q = ends_j[:, 0] + t[:, None] * (ends_j[:, 1] - ends_j[:, 0])
            near = np.linalg.norm(p - q, axis=1) < exclusion_radius
            near |= np.min(np.linalg.norm(ends_i[:, :, None] - ends_j[:, None], axis=3),
                           axis=(1, 2)) < exclusion_radius
            keep &= ~near
        #: candidate pairs of segment ids
        self.pairs = np.stack([i[keep], j[keep]], axis=1)
        self._side = np.zeros(len(self.pairs))

    def _geometry(self, x: np.ndarray):
        a, b = self.segments[self.pairs[:, 0]], self.segments[self.pairs[:, 1]]
        a0, a1, b0, b1 = x[a[:, 0]], x[a[:, 1]], x[b[:, 0]], x[b[:, 1]]
        s, t, sin = closest_points_on_lines(a0, a1, b0, b1)
        da, db = a1 - a0, b1 - b0
        r = (a0 + s[:, None] * da) - (b0 + t[:, None] * db)
        N = np.cross(da, db)
        c = N / np.maximum(np.linalg.norm(N, axis=1), 1e-300)[:, None]
        return a, b, s, t, sin, r, c

    def update_history(self, x: np.ndarray) -> None:
        """Record the side of every pair that is not close to contact at an accepted state."""
        _, _, s, t, sin, r, c = self._geometry(np.asarray(x, dtype=float))
        gap = np.einsum("ij,ij->i", r, c)
        far = (np.abs(gap) > 2.0 * (self.params.thickness + self.params.cutoff)) | (self._side == 0)
        far |= (s <= 0) | (s >= 1) | (t <= 0) | (t >= 1) | (sin < _PARALLEL)
        self._side = np.where(far, np.where(gap < 0.0, -1.0, 1.0), self._side)

    def evaluate(self, x: np.ndarray, f_ext: np.ndarray, nodes: np.ndarray | None = None,
                 jacobian: bool = True) -> ContactResult:
        """Forces of the pairs whose first segment starts at one of ``nodes`` (default: all;
        ``jacobian`` is accepted for a uniform interface, the blocks are always computed)."""
        x = np.asarray(x, dtype=float)
        p = self.params
        if not np.any(self._side):
            self.update_history(x)
        a, b, s, t, sin, r, c = self._geometry(x)
        sigma = self._side
        d = sigma * np.einsum("ij,ij->i", r, c) - p.thickness
        da = x[a[:, 1]] - x[a[:, 0]]
        db = x[b[:, 1]] - x[b[:, 0]]
        la, lb = np.linalg.norm(da, axis=1), np.linalg.norm(db, axis=1)
        eps = p.blend_distance
        end_a, end_b = np.minimum(s, 1 - s) * la, np.minimum(t, 1 - t) * lb
        candidate = (sin > _PARALLEL) & (end_a > 0) & (end_b > 0) & (d < p.cutoff) \
            & (d > -p.penetration_depth)
        if nodes is not None:
            mine = np.zeros(self.num_nodes, dtype=bool)
            mine[np.asarray(nodes, dtype=np.int64)] = True
            candidate &= mine[a[:, 0]]
        k = np.flatnonzero(candidate)
        if len(k) == 0:
            return ContactResult.empty(self.num_nodes)
        a, b, s, t, r, c, d, sigma = a[k], b[k], s[k], t[k], r[k], c[k], d[k], sigma[k]
        da, db, la, lb, end_a, end_b = da[k], db[k], la[k], lb[k], end_a[k], end_b[k]
        n = sigma[:, None] * c
        f_a = (1 - s)[:, None] * f_ext[a[:, 0]] + s[:, None] * f_ext[a[:, 1]]
        F_raw = -np.einsum("ij,ij->i", f_a, n)
        F = np.maximum(F_raw, p.min_driving_force)
        f, dfdd = law_force(d, F, p)
        dfdF = np.where(F_raw > p.min_driving_force,
                        contact_force_slope_in_F(d, F, p.stiffness, p.cutoff, p.taper), 0.0)
        pa, dpa = _ramp(end_a, eps)
        pb, dpb = _ramp(end_b, eps)
        pc, dpc = _ramp(p.cutoff - d, eps) if p.taper > 0 else (np.ones(len(k)), np.zeros(len(k)))
        presence = pa * pb * pc
        phi = presence * f
        ids = np.concatenate([a, b], axis=1)                                  # (A, 4)
        B = np.stack([1 - s, s, -(1 - t), -t], axis=1)
        forces = np.zeros((self.num_nodes, 3))
        contributions = B[:, :, None] * (phi[:, None] * n)[:, None, :]
        for axis in range(3):
            forces[:, axis] = np.bincount(ids.ravel(), contributions[:, :, axis].ravel(),
                                          minlength=self.num_nodes)

        # --- derivatives over the four nodes [a0, a1, b0, b1] ---------------------------------
        count = len(k)
        grad_d = B[:, :, None] * n[:, None, :]                               # exact (envelope)
        # turning of c: N = da × db, dN = d(da) × db + da × d(db)
        Nlen = np.linalg.norm(np.cross(da, db), axis=1)
        P = np.eye(3) - c[:, :, None] * c[:, None, :]
        dN = np.stack([skew(db), -skew(db), -skew(da), skew(da)], axis=1)    # (A, 4, 3, 3)
        dn = sigma[:, None, None, None] * np.einsum("aij,amjl->amil", P, dN) \
            / Nlen[:, None, None, None]
        # sliding: the closest-point conditions da·r = 0, db·r = 0 give ds, dt
        coef_w = np.stack([1 - s, s, -(1 - t), -t], axis=1)                   # r at fixed s, t
        rhs1 = -(coef_w[:, :, None] * da[:, None, :])
        rhs1[:, 0] += r
        rhs1[:, 1] -= r
        rhs2 = -(coef_w[:, :, None] * db[:, None, :])
        rhs2[:, 2] += r
        rhs2[:, 3] -= r
        m11, m12 = la**2, -np.einsum("ij,ij->i", da, db)
        m21, m22 = -m12, -lb**2
        det = m11 * m22 - m12 * m21
        ds = (m22[:, None, None] * rhs1 - m12[:, None, None] * rhs2) / det[:, None, None]
        dt = (-m21[:, None, None] * rhs1 + m11[:, None, None] * rhs2) / det[:, None, None]
        # driving force F = -f_a·n with f_a = (1-s) f0 + s f1 (f_ext frozen)
        df_a = f_ext[a[:, 1]] - f_ext[a[:, 0]]
        grad_F = -(np.einsum("ij,ij->i", df_a, n)[:, None, None] * ds
                   + np.einsum("amil,ai->aml", dn, f_a))
        # presence: end distances min(s, 1-s)·ℓ and the cut-off fade
        ua, ub = da / la[:, None], db / lb[:, None]
        grad_la = np.zeros((count, 4, 3))
        grad_la[:, 0], grad_la[:, 1] = -ua, ua
        grad_lb = np.zeros((count, 4, 3))
        grad_lb[:, 2], grad_lb[:, 3] = -ub, ub
        sa = np.where(s < 0.5, 1.0, -1.0)
        sb = np.where(t < 0.5, 1.0, -1.0)
        grad_end_a = sa[:, None, None] * ds * la[:, None, None] \
            + np.minimum(s, 1 - s)[:, None, None] * grad_la
        grad_end_b = sb[:, None, None] * dt * lb[:, None, None] \
            + np.minimum(t, 1 - t)[:, None, None] * grad_lb
        grad_presence = ((dpa * pb * pc)[:, None, None] * grad_end_a
                         + (pa * dpb * pc)[:, None, None] * grad_end_b
                         - (pa * pb * dpc)[:, None, None] * grad_d)
        grad_phi = presence[:, None, None] * (dfdd[:, None, None] * grad_d
                                              + dfdF[:, None, None] * grad_F) \
            + f[:, None, None] * grad_presence
        grad_B = np.stack([-ds, ds, dt, -dt], axis=1)                         # (A, 4r, 4m, 3)
        blocks = (B[:, :, None, None, None] * n[:, None, None, :, None]
                  * grad_phi[:, None, :, None, :])
        blocks += B[:, :, None, None, None] * phi[:, None, None, None, None] * dn[:, None]
        blocks += phi[:, None, None, None, None] * n[:, None, None, :, None] \
            * grad_B[:, :, :, None, :]
        rows = np.repeat(ids, 4, axis=1).ravel()
        cols = np.tile(ids, (1, 4)).ravel()
        active = phi > 0.0
        return ContactResult(forces=forces, jac_rows=rows, jac_cols=cols,
                             jac_blocks=blocks.reshape(-1, 3, 3), n_active=int(active.sum()),
                             max_penetration=float(np.max(-d[active], initial=0.0)),
                             total_force=float(phi.sum()),
                             pairs=np.stack([a[active, 0], -1 - b[active, 0]], axis=1),
                             max_crossing=float(np.max(-(d[active] + self.params.thickness),
                                                       initial=0.0)))
