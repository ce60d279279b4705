"""Contact as a residual/Jacobian hook of the finite element solve (SPEC §5).

At every residual evaluation the hook gathers the nodal positions of the
whole surface (:class:`~valve_dolfinx.solvers.nodal.NodalCoupling`),
evaluates the contact models for the nodes this rank owns, and adds
``−f_contact`` to the residual (contact forces are external forces) and
``−∂f_contact/∂x`` to the Jacobian.  The residual's evaluation computes
forces only; the Jacobian's, at the same positions, adds the blocks to the
contact rows the residual's found (a Newton solve evaluates its residual at
every iterate, its Jacobian at all but the last).

Driving force.  The law's force scale is the nodal pressure force
``f_ext`` (SPEC §5).  Two treatments (``lag_driving_force``):

* ``True`` (pseudo-transient continuation): ``f_ext`` of the last *accepted*
  step, scaled by the current pressure.  Within a step it is a constant, so
  the contact Jacobian is exact and Newton quadratic; at a steady state the
  accepted and current states coincide, so the equilibrium is the SPEC's.
* ``False`` (BDF2 dynamics): ``f_ext`` of the current positions.  The
  Jacobian has the turning of the contact direction under a fixed ``f_ext``
  but not the change of ``f_ext`` itself with the surface, so Newton
  converges fast but not quite quadratically once contact is active.

Guard.  With a :class:`~valve_dolfinx.contact.guard.SurfaceGuard` the hook also adds the
guard's barrier (its gradient to the residual, its Hessian to the Jacobian) in the rows of
the nodes this rank owns that no Dirichlet condition holds, and :func:`cut_to_free_fraction`
shortens every Newton update to the part along which no surface meets another.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from valve_dolfinx._compat import MPI, PETSc, dolfinx
from valve_dolfinx.contact.guard import SurfaceGuard
from valve_dolfinx.solvers.nodal import NodalCoupling, pressure_nodal_forces

__all__ = ["ContactHook", "cut_to_free_fraction"]

log = logging.getLogger(__name__)


class ContactHook:
    """Adds the forces of contact models (surface–surface, rigid planes) to a solve.

    Parameters
    ----------
    coupling
        Node ↔ PETSc index map of the assembled system.
    models
        Objects with ``evaluate(x, f_ext, nodes) -> ContactResult`` and
        optionally ``update_history(x)``.
    pressure_triangles
        ``(M, 3)`` node ids of the loaded surface, oriented like the pressure
        form (normal ``(x1−x0)×(x2−x0)``).
    pressure
        The pressure constant of the model (kPa), read at each evaluation.
    pressure_side
        Sign of the pressure force relative to the triangle normal.
    lag_driving_force
        Freeze the driving force within a step (see the module docstring).
    fixed_nodes
        Nodes held by Dirichlet conditions: never contacting nodes, no guard rows.
    guard
        The barrier that keeps every surface from passing through another, or None.
    """

    #: name of this hook's share in a solver's timings
    timing_name = "contact"

    def __init__(self, coupling: NodalCoupling, models: Sequence, pressure_triangles: np.ndarray,
                 pressure: dolfinx.fem.Constant, pressure_side: float, *,
                 lag_driving_force: bool = True, fixed_nodes: np.ndarray | None = None,
                 guard: SurfaceGuard | None = None):
        self.coupling = coupling
        self.guard = guard
        # nodes held by Dirichlet conditions (the attachment) are never contacting nodes;
        # their triangles still are contact surfaces
        fixed = np.empty(0, dtype=np.int64) if fixed_nodes is None else np.asarray(fixed_nodes)
        self.contact_nodes = np.setdiff1d(coupling.owned_nodes, fixed)
        self._guard_rows = np.zeros(coupling.num_nodes, dtype=bool)
        self._guard_rows[self.contact_nodes] = True
        self.lag_driving_force = bool(lag_driving_force)
        self.models = list(models)
        self.triangles = np.asarray(pressure_triangles, dtype=np.int64)
        self.pressure = pressure
        self.side = float(pressure_side)
        self._key: np.ndarray | None = None
        self._has_jacobian = False
        self._results: list = []
        self._merged: tuple | None = None  # (results, their merged blocks)
        self._unit_forces: np.ndarray | None = None  # pressure forces per kPa, accepted state

    def _evaluate(self, state: dolfinx.fem.Function, jacobian: bool) -> list:
        """The models' results at ``state``: forces only, or with the Jacobian blocks.

        A solver evaluates its residual at every state and its Jacobian at most of them:
        the residual's evaluation computes no blocks, and the Jacobian's at the same state
        adds them to it (the surface contact keeps its rows)."""
        x = self.coupling.positions(state)
        p = float(self.pressure.value)
        if (self._key is not None and self._pressure_key == p and np.array_equal(x, self._key)
                and (self._has_jacobian or not jacobian)):
            return self._results
        if self._unit_forces is None or not self.lag_driving_force:
            self._unit_forces = pressure_nodal_forces(x, self.triangles, 1.0, self.side)
        f_ext = p * self._unit_forces
        nodes = self.contact_nodes
        self._results = [m.evaluate(x, f_ext, nodes, jacobian=jacobian) for m in self.models]
        self._key, self._pressure_key, self._has_jacobian = x, p, jacobian
        return self._results

    def _guard_gradient(self) -> np.ndarray | None:
        """The guard's energy gradient at the positions last evaluated (:meth:`_evaluate`)
        in this rank's rows (zero elsewhere)."""
        if self.guard is None:
            return None
        gradient = self.guard.gradient(self._key)
        if gradient is None:
            return None
        return np.where(self._guard_rows[:, None], gradient, 0.0)

    def add_residual(self, state: dolfinx.fem.Function, b: PETSc.Vec) -> None:
        for result in self._evaluate(state, jacobian=False):
            self.coupling.add_forces(b, result.forces, scale=-1.0)
        gradient = self._guard_gradient()
        if gradient is not None:
            self.coupling.add_forces(b, gradient)

    def _merged_blocks(self, state: dolfinx.fem.Function) -> list[tuple]:
        """Each model's Jacobian blocks at ``state``, summed per (row, column) node pair
        (:meth:`NodalCoupling.merge_blocks`)."""
        results = self._evaluate(state, jacobian=True)
        if self._merged is None or self._merged[0] is not results:
            merged = [self.coupling.merge_blocks(r.jac_rows, r.jac_cols, -r.jac_blocks)
                      for r in results]
            if self.guard is not None:  # (summed per node pair by the library already)
                merged.append(self.guard.hessian_blocks(self._key, self._guard_rows))
            self._merged = (results, merged)
        return self._merged[1]

    def jacobian_couplings(self, state: dolfinx.fem.Function) -> tuple[np.ndarray, np.ndarray]:
        """(row nodes, column nodes) of the blocks :meth:`add_jacobian` adds at ``state``,
        for the matrix's pattern (:class:`~valve_dolfinx.solvers.nodal.BlockPattern`)."""
        merged = self._merged_blocks(state)
        return (np.concatenate([m[0] for m in merged] or [np.empty(0, np.int64)]),
                np.concatenate([m[1] for m in merged] or [np.empty(0, np.int64)]))

    def add_jacobian(self, state: dolfinx.fem.Function, A: PETSc.Mat) -> None:
        for rows, cols, blocks in self._merged_blocks(state):
            self.coupling.add_merged_blocks(A, rows, cols, blocks)

    def accept_state(self, state: dolfinx.fem.Function) -> None:
        """Record an accepted (time/load) step: sides and driving forces come from it."""
        x = self.coupling.positions(state)
        if self.lag_driving_force:  # (otherwise every evaluation computes its own)
            self._unit_forces = pressure_nodal_forces(x, self.triangles, 1.0, self.side)
        self._key = None
        for m in self.models:
            update = getattr(m, "update_history", None)
            if update is not None:
                update(x)

    def contact_forces(self, state: dolfinx.fem.Function) -> np.ndarray:
        """(N, 3) total contact force on every node (summed over ranks), e.g. for output."""
        local = sum(r.forces for r in self._evaluate(state, jacobian=False))
        if isinstance(local, int):
            local = np.zeros((self.coupling.num_nodes, 3))
        gradient = self._guard_gradient()
        if gradient is not None:
            local = local - gradient
        return self.coupling.comm.allreduce(local, op=MPI.SUM)

    def diagnostics(self) -> dict:
        """Active contacts, penetration (mm) and total contact force (mN), over all ranks.

        ``max_penetration_mm`` is how far mid-surfaces have passed through each
        other (SPEC §5's d < 0 for zero-thickness sheets); ``max_layer_overlap_mm``
        the overlap of the contact layers of thickness ``ContactParameters.thickness``
        (the law's own d < 0), which is unavoidable where leaflets are sewn
        together at the commissures.
        """
        comm = self.coupling.comm
        n = sum(r.n_active for r in self._results)
        pen = max((r.max_penetration for r in self._results), default=0.0)
        force = sum(r.total_force for r in self._results)
        crossing = max((r.max_crossing for r in self._results), default=0.0)
        out = {"contacts": comm.allreduce(n, op=MPI.SUM),
               "max_penetration_mm": comm.allreduce(crossing, op=MPI.MAX),
               "max_layer_overlap_mm": comm.allreduce(pen, op=MPI.MAX),
               "contact_force_mN": comm.allreduce(force, op=MPI.SUM)}
        if self.guard is not None and self._key is not None:  # (every rank has every pair)
            pairs = self.guard.pairs(self._key)
            out["guard_pairs"] = pairs.count
            out["guard_min_distance_mm"] = pairs.min_distance
        return out

    def free_fraction(self, x: PETSc.Vec, y: PETSc.Vec) -> float:
        """Largest fraction of the Newton update ``x → x − y`` along which no surface meets
        another (1 without a guard); the same number on every rank."""
        if self.guard is None:
            return 1.0
        start = self.coupling.reference_positions + self.coupling.vector_displacements(x)
        end = start - self.coupling.vector_displacements(y)
        return self.coupling.comm.allreduce(self.guard.free_fraction(start, end), op=MPI.MIN)


def cut_to_free_fraction(hooks: Sequence, x: PETSc.Vec, y: PETSc.Vec) -> float:
    """Scale the Newton update ``y`` (the step is ``x − y``) to the fraction of it along
    which no guarded surface meets another; the fraction applied."""
    fraction = min((hook.free_fraction(x, y) for hook in hooks
                    if hasattr(hook, "free_fraction")), default=1.0)
    if fraction < 1.0:
        y.scale(fraction)
    return fraction
