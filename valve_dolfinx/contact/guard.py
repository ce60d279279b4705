"""A barrier that keeps every leaflet from passing through another or through itself.

The contact law (SPEC §5, :mod:`valve_dolfinx.contact.law`) balances the part of the
pressure that drives a node into a surface: it rests coapting sheets ``thickness`` apart.
It does not answer an elastic force — a stiff graft bending, a wrinkle, a free edge pulled
taut beside a commissure — and it sees only node–triangle pairs, so such a force can fold
a leaflet through its neighbour or through itself between its nodes.  The guard closes
that gap with the IPC Toolkit (``ipctk``), whose geometry is exact and complete:

* **Barrier.**  One collision surface holds every leaflet; the library lists every
  vertex–triangle, edge–edge, edge–vertex and vertex–vertex pair closer than the reach
  ``d̂`` (``contact.guard_distance_mm``), leaving out pairs that share a vertex, and adds
  the energy ``κ Σ w b(d)`` with the clamped log barrier
  ``b(d) = −(d − d̂)² ln(d/d̂)`` and ``w`` each pair's share of the surface's area
  (``κ``: ``contact.guard_stiffness_mn_per_mm3``).  The barrier grows without bound as ``d → 0``:
  it resists any force, not only the pressure's.  Its reach is shorter than the rest
  gap of the contact law, so coapting leaflets at rest are outside it and the law alone
  sets their gap and the coaptation heights; the guard acts where the law gives way.
  The collision set is the library's standard one with area weighting (every
  vertex–triangle and edge–edge pair by its closest features), not its improved max
  approximation, whose gradient was measured to jump under motions of micrometres where
  two surfaces come within a few micrometres (docs/numerics.md); the energy's exact
  gradient and Hessian go into the residual and the Jacobian.
* **Steps that cannot cross.**  A barrier holds only if no step jumps over it.  Every
  Newton update is cut to its collision-free fraction (the library's continuous
  collision detection, additive CCD with its conservative rescaling), so a state the
  solver reaches from an intersection-free start is intersection-free.
* **Start.**  A state that already intersects cannot be repaired by a barrier (it holds
  the crossing).  :meth:`SurfaceGuard.intersects` tells the caller so, who starts from
  the unloaded valve instead.

The guard has no exclusions beyond the library's (pairs sharing a vertex): a graft fold
is held apart like two leaflets.  Where two leaflets are sewn together at a commissure
they share the seam's nodes, so the pairs at the seam share a vertex and are left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SurfaceGuard", "GuardPairs"]


def _ipctk():
    import ipctk

    ipctk.set_num_threads(1)  # one thread per MPI rank: ranks already share the cores
    return ipctk


@dataclass(frozen=True)
class GuardPairs:
    """The guard's state at one set of positions (for diagnostics and outputs)."""

    #: pairs inside the reach
    count: int
    #: closest distance of any pair inside the reach (mm; inf without pairs)
    min_distance: float


class SurfaceGuard:
    """Barrier energy, its derivatives and collision-free steps on a triangle surface.

    Parameters
    ----------
    rest_positions
        ``(N, 3)`` positions of the unloaded surface (mm): the pairs' area weights.
    triangles
        ``(M, 3)`` node ids of every leaflet's triangles.
    distance
        The barrier's reach ``d̂`` (mm).
    stiffness
        ``κ`` (mN/mm³): the energy per unit area of a pair at distance ``d`` is
        ``κ b(d)`` (mJ/mm² with ``b`` in mm²).
    """

    def __init__(self, rest_positions: np.ndarray, triangles: np.ndarray, *,
                 distance: float, stiffness: float):
        ipctk = _ipctk()
        self._ipctk = ipctk
        faces = np.asfortranarray(triangles, dtype=np.int32)
        self.mesh = ipctk.CollisionMesh(np.asfortranarray(rest_positions, dtype=float),
                                        ipctk.edges(faces), faces)
        self.distance = float(distance)
        self.potential = ipctk.BarrierPotential(self.distance, float(stiffness))
        self._key: tuple[np.ndarray, object] | None = None

    def _collisions(self, x: np.ndarray):
        """The library's collision set at ``x`` (kept for the last positions asked)."""
        if self._key is not None and np.array_equal(x, self._key[0]):
            return self._key[1]
        ipctk = self._ipctk
        collisions = ipctk.NormalCollisions()
        collisions.use_area_weighting = True  # before build: it sets the pairs' weights
        collisions.collision_set_type = \
            ipctk.NormalCollisions.CollisionSetType.IPC
        collisions.build(self.mesh, np.asfortranarray(x), self.distance)
        self._key = (np.array(x, copy=True), collisions)
        return collisions

    def energy(self, x: np.ndarray) -> float:
        """Barrier energy at ``x`` (mJ; ``inf`` when a pair touches)."""
        collisions = self._collisions(x)
        return float(self.potential(collisions, self.mesh, np.asfortranarray(x))) \
            if len(collisions) else 0.0

    def gradient(self, x: np.ndarray) -> np.ndarray | None:
        """``(N, 3)`` gradient of the energy at ``x`` (mN; minus the guard's forces), or
        None when no pair is inside the reach."""
        collisions = self._collisions(x)
        if not len(collisions):
            return None
        return self.potential.gradient(collisions, self.mesh,
                                       np.asfortranarray(x)).reshape(-1, 3)

    def hessian_blocks(self, x: np.ndarray, rows: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row nodes, column nodes, ``(K, 3, 3)`` blocks) of the energy's Hessian at ``x``
        in the node rows where ``rows`` (a boolean mask over the nodes) is true."""
        collisions = self._collisions(x)
        if not len(collisions):
            empty = np.empty(0, dtype=np.int64)
            return empty, empty, np.empty((0, 3, 3))
        hessian = self.potential.hessian(collisions, self.mesh, np.asfortranarray(x))
        blocks = hessian.tocsr().tobsr(blocksize=(3, 3))
        blocks.sort_indices()
        row = np.repeat(np.arange(blocks.shape[0] // 3), np.diff(blocks.indptr))
        keep = rows[row]
        return row[keep], blocks.indices.astype(np.int64)[keep], blocks.data[keep]

    def pairs(self, x: np.ndarray) -> GuardPairs:
        """How many pairs are inside the reach at ``x`` and how close the closest is."""
        collisions = self._collisions(x)
        if not len(collisions):
            return GuardPairs(0, float("inf"))
        squared = collisions.compute_minimum_distance(self.mesh, np.asfortranarray(x))
        return GuardPairs(len(collisions), float(np.sqrt(squared)))

    def free_fraction(self, x0: np.ndarray, x1: np.ndarray) -> float:
        """Largest fraction in ``[0, 1]`` of the straight step ``x0 → x1`` along which no
        pair meets (the library's CCD, conservatively rescaled).

        Two points of the surface approach each other by at most twice the largest nodal
        motion of the step, and at ``x0`` every pair is at least the reach apart or inside
        the collision set: a step whose motion is below half of the closer of the two
        cannot close any gap, and is whole without a CCD."""
        motion = float(np.sqrt(np.max(np.sum((x1 - x0) ** 2, axis=1), initial=0.0)))
        if 2.0 * motion < min(self.distance, self.pairs(x0).min_distance):
            return 1.0
        ipctk = self._ipctk
        return float(ipctk.compute_collision_free_stepsize(
            self.mesh, np.asfortranarray(x0), np.asfortranarray(x1), 0.0, ipctk.LBVH(),
            ipctk.AdditiveCCD()))

    def intersects(self, x: np.ndarray) -> bool:
        """Whether the surface at ``x`` passes through itself anywhere."""
        return bool(self._ipctk.has_intersections(self.mesh, np.asfortranarray(x)))
