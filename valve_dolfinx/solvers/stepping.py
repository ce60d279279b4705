"""What the two paths to the loaded equilibrium share: a PETSc TS run over hooked forces.

:class:`~valve_dolfinx.solvers.pseudo_transient.PseudoTransientSolver` (the default path)
and :class:`~valve_dolfinx.solvers.dynamics.DampedDynamicsSolver` (the cross-check) both
integrate an implicit system ``F(t, U, U̇) = 0`` with PETSc TS: the membrane's forms plus
the forces of the hooks (contact, bending) made from the state's :class:`NodalCoupling`.
They differ in their state (``u``, or ``(u, v)``), their integrator and step control, and
what ends a run converged.  :class:`SteppingSolver` holds the rest, once:

* the set-up: state and rate, hooks, watched nodes, the residual vector, a TS with its
  options under a prefix of its own and every callback wrapped by one
  :class:`~valve_dolfinx.solvers.callbacks.CallbackGuard`;
* the run (:meth:`SteppingSolver.solve`): it never raises because the solve failed; the
  final state is the state's whatever happened, and the report says where and why the
  run stopped;
* what every accepted step does: take the TS's solution, measure the nodes' motion, tell
  the hooks the state is accepted, keep a history row with the hooks' diagnostics and
  report it to the progress callback;
* the failure reasons: a step below its floor, the wall-clock limit, an error, a TS that
  stopped on its own budget -- each saying where the run was.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable, Sequence

import numpy as np

from valve_dolfinx._compat import PETSc, dolfinx
from valve_dolfinx.exceptions import DegenerateGeometryError, MeshError
from valve_dolfinx.mechanics.membrane import MembraneModel
from valve_dolfinx.solvers.callbacks import CallbackGuard
from valve_dolfinx.solvers.nodal import NodalCoupling, NodalLayout
from valve_dolfinx.solvers.report import SolveReport

__all__ = ["SteppingSolver", "StepFloorStop"]

log = logging.getLogger(__name__)
fem = dolfinx.fem
fem_petsc = dolfinx.fem.petsc

# numbers the TS options prefixes of all runs: options set for one run never reach another
_RUNS = itertools.count(1)


class StepFloorStop(RuntimeError):
    """Raised from a TS callback to end a run whose step fell below its floor."""


class SteppingSolver:
    """Base of the two solvers: a TS run of ``state`` under the model's forms and hooks.

    A subclass builds its forms and Jacobian matrix (``J_mat``) and defines the TS
    callbacks ``ifunction``, ``ijacobian``, ``_post_step``, ``_make_ts`` (from
    :meth:`_new_ts`) and :meth:`_new_report`; the hooks ``_start_run``, ``_finish_run``
    and ``_log_summary`` default to nothing.

    Parameters
    ----------
    model
        The membrane.
    params
        The subclass's settings (with ``wall_time_limit_s``).
    target_pressure
        The full pressure (kPa).
    state, rate
        The TS's unknown and its time derivative (functions on one space).
    layout
        Where forces and displacements sit in the state's blocks (None: the state is the
        displacement).
    hooks
        Factories ``make(coupling) -> hook`` of extra forces, called with the
        :class:`NodalCoupling` of the state; a hook has ``add_residual(state, b)``,
        ``add_jacobian(state, A)`` and optionally ``accept_state(state)`` and
        ``diagnostics()``.
    watch_nodes
        Mesh node ids whose motion per step is recorded (the middle of each leaflet's
        free edge).
    """

    #: prefix of the TS's PETSc options (the run's number and ``_`` follow)
    OPTIONS_PREFIX = "valve_ts"
    #: what the log calls the solver
    TITLE = "time stepping"
    #: symbols of the time and of its step in reasons, and their unit (with its space)
    TIME, STEP, UNIT = "t", "dt", ""

    def __init__(self, model: MembraneModel, params, target_pressure: float,
                 state: fem.Function, rate: fem.Function, layout: NodalLayout | None,
                 hooks: Sequence[Callable[[NodalCoupling], object]] = (),
                 watch_nodes: Sequence[int] = ()):
        self.model = model
        self.params = params
        self.target_pressure = float(target_pressure)
        self.state, self.rate = state, rate
        space = state.function_space
        self.shift = fem.Constant(model.domain.mesh, PETSc.ScalarType(0.0))
        self.coupling = NodalCoupling(space) if layout is None else NodalCoupling(space, layout)
        self.hooks = [make(self.coupling) for make in hooks]
        self.watch_nodes = np.asarray(watch_nodes, dtype=np.int64)
        self.F_vec = fem_petsc.create_vector(space)
        self.report = self._new_report()
        self._progress: Callable[[dict], None] | None = None

    # --- what a subclass defines ---------------------------------------------------------
    def _new_report(self) -> SolveReport:
        raise NotImplementedError

    def _make_ts(self) -> PETSc.TS:
        raise NotImplementedError

    def _start_run(self) -> None:
        """Called before ``TS.solve``, with its errors counted as the run's."""

    def _finish_run(self) -> None:
        """Called once the state holds the run's final solution."""

    def _log_summary(self) -> None:
        """Log how the run went."""

    # --- the state ---------------------------------------------------------------------
    def _copy_state(self, X: PETSc.Vec, Xdot: PETSc.Vec | None) -> None:
        """Put PETSc's iterate into ``state`` and ``rate`` (rate zero without ``Xdot``)."""
        X.copy(self.state.x.petsc_vec)
        self.state.x.scatter_forward()
        if Xdot is None:
            self.rate.x.array[:] = 0.0
        else:
            Xdot.copy(self.rate.x.petsc_vec)
            self.rate.x.scatter_forward()

    def _take_solution(self, ts: PETSc.TS) -> None:
        """Put the TS's current solution into ``state``."""
        self.state.x.petsc_vec.array[:] = ts.getSolution().array_r
        self.state.x.scatter_forward()

    def _node_motion(self) -> tuple[np.ndarray, np.ndarray]:
        """The nodal displacements ``(N, 3)`` of ``state`` and each node's distance from
        where it was at the last accepted step."""
        displacement = self.coupling.displacements(self.state)
        return displacement, np.linalg.norm(displacement - self._last_displacement, axis=1)

    def accept_state(self) -> None:
        """Tell the hooks that ``state`` is accepted (contact sides, driving forces)."""
        for hook in self.hooks:
            accept = getattr(hook, "accept_state", None)
            if accept is not None:
                accept(self.state)

    # --- the TS ------------------------------------------------------------------------
    def _new_ts(self, options: dict, dt: float, max_time: float, max_steps: int
                ) -> PETSc.TS:
        """A TS with ``options`` under a prefix of its own, the guarded callbacks
        (``ifunction``, ``ijacobian``, ``_post_step``), first step ``dt`` and the budgets;
        the caller adds its own and calls ``setFromOptions``."""
        prefix = f"{self.OPTIONS_PREFIX}{next(_RUNS)}_"
        ts = PETSc.TS().create(self.model.domain.comm)
        ts.setOptionsPrefix(prefix)
        opts = PETSc.Options()
        for key, value in options.items():
            opts[f"{prefix}{key}"] = value
        guard = self._guard
        ts.setIFunction(guard.wrap(self.ifunction), self.F_vec)
        ts.setIJacobian(guard.wrap(self.ijacobian), self.J_mat)
        ts.setTime(0.0)
        ts.setTimeStep(dt)
        ts.setMaxTime(max_time)
        ts.setMaxSteps(max_steps)
        ts.setExactFinalTime(PETSc.TS.ExactFinalTime.MATCHSTEP)
        ts.setPostStep(guard.wrap(self._post_step))
        return ts

    def _where(self, ts: PETSc.TS) -> str:
        """Where the run is: step, time and time step."""
        return (f"at step {ts.getStepNumber()}, {self.TIME} = {ts.getTime():.4g}{self.UNIT}, "
                f"{self.STEP} = {ts.getTimeStep():.3g}{self.UNIT}")

    def _check_step_floor(self, ts: PETSc.TS | None, dt_min: float) -> None:
        """End the run (:class:`StepFloorStop`) when the TS's step is below ``dt_min``:
        failed Newton solves keep halving it, and below the floor the run has stalled."""
        if ts is None or ts.getTimeStep() >= dt_min:
            return
        residual = self.report.residual_mN
        last = (f"; static residual {residual:.3g} mN at the last accepted step"
                if np.isfinite(residual) else "")
        self.report.reason = (f"{self.STEP} fell below its floor {dt_min:g}{self.UNIT} "
                              f"{self._where(ts)} (Newton kept failing{last})")
        raise StepFloorStop(self.report.reason)

    def _end(self, ts: PETSc.TS, reason: str, converged: bool = False) -> None:
        """End the run after this step, with ``reason``."""
        self.report.converged, self.report.reason = converged, reason
        ts.setConvergedReason(PETSc.TS.ConvergedReason.CONVERGED_USER)

    def _out_of_time(self, ts: PETSc.TS, state: str) -> bool:
        """End the run if it has used its wall-clock limit; ``state`` says how far it got."""
        limit = self.params.wall_time_limit_s
        if time.perf_counter() - self._t0 <= limit:
            return False
        self._end(ts, f"wall-clock limit {limit:g} s reached {self._where(ts)}: {state}")
        return True

    def _count_step(self, ts: PETSc.TS) -> None:
        """Count an accepted step and its Newton iterations in the report."""
        r = self.report
        r.steps = ts.getStepNumber()
        r.time = ts.getTime()
        r.newton_iterations += ts.getSNES().getIterationNumber()

    def _keep_row(self, entry: dict) -> None:
        """Add the hooks' diagnostics to a history row, keep it and report it."""
        for hook in self.hooks:
            diag = getattr(hook, "diagnostics", None)
            if diag is not None:
                entry.update(diag())
        self.report.history.append(entry)
        if self._progress is not None:
            self._progress(entry)

    # --- the run -----------------------------------------------------------------------
    def solve(self, progress: Callable[[dict], None] | None = None) -> SolveReport:
        """Step to the static equilibrium; never raises because the solve failed.

        ``state`` holds the final state whatever happened; the report says whether it is
        the equilibrium and, if not, where and why it stopped.  ``progress`` is called
        with each accepted step's history row.
        """
        self._progress = progress
        self._guard = CallbackGuard(stops=(StepFloorStop, DegenerateGeometryError))
        self._t0 = time.perf_counter()
        self.report = self._new_report()
        self._last_displacement = self.coupling.displacements(self.state)
        ts = self._make_ts()
        X = self.state.x.petsc_vec.copy()
        ts.setSolution(X)  # the final state, should the run end at its start
        try:
            self._start_run()
            with self._guard:  # a signal waits for the next callback
                ts.solve(X)
        except (PETSc.Error, MeshError, DegenerateGeometryError, StepFloorStop) as err:
            # an interrupt or an error in a callback is not a failed solve (reraise raises
            # it); a collapsed triangle at an accepted state is
            where = self._where(ts)
            err = self._guard.reraise(where) or err
            if not self.report.reason:
                self.report.reason = (f"PETSc error {err.ierr} {where}"
                                      if isinstance(err, PETSc.Error)
                                      else f"{type(err).__name__} {where}: {err}")
            log.error("%s failed: %s", self.TITLE, self.report.reason)
        self.report.count_rejections(ts)
        self._take_solution(ts)
        self._finish_run()
        if not self.report.converged and not self.report.reason:
            self.report.reason = (
                f"TS stopped ({ts.getConvergedReason()}) after {ts.getStepNumber()} steps "
                f"(max_steps = {ts.getMaxSteps()}), {self.TIME} = {ts.getTime():.4g}"
                f"{self.UNIT}: static residual {self.report.residual_mN:.3g} mN")
        self.report.wall_time_s = time.perf_counter() - self._t0
        ts.destroy()
        X.destroy()
        self._log_summary()
        return self.report
