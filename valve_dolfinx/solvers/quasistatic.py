"""Quasi-static equilibrium by load continuation with PETSc SNES.

The pressure is ramped from 0 to its target in load steps whose size adapts
to how hard Newton's method (PETSc SNES) worked: a step that needs few
iterations lets the next one grow, a failed step is retried at half the size.

Regularisation.  An unstressed membrane has no stiffness normal to itself,
so the very first Newton step from a stress-free or slack state can be
singular.  Optionally each load step adds a pseudo-transient viscous term
``η·M·(u − u_prev)`` (M the lumped reference-area matrix, u_prev the previous
converged state): the step then solves a well-posed problem.  The term
vanishes at a steady state only, so after the ramp the solver removes it and
re-solves (η → 0 through decades) to return the true equilibrium; the report
gives the residual of the *unregularised* system, and says ``converged=False``
(with the reason in ``message``) if that last, unregularised solve fails.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import ufl

from valve_dolfinx._compat import MPI, PETSc, dolfinx
from valve_dolfinx.exceptions import SolverError, check_range
from valve_dolfinx.membrane import MembraneModel
from valve_dolfinx.solvers.assembly import AssembledSystem, Hook

__all__ = ["ContinuationParameters", "SolveReport", "QuasiStaticSolver", "default_snes_options"]

log = logging.getLogger(__name__)
fem = dolfinx.fem
fem_petsc = dolfinx.fem.petsc


def default_snes_options() -> dict:
    """Full Newton steps (no line search: the merit-function searches stall on wrinkling
    switches) and a direct (MUMPS) linear solve; robustness comes from the load stepping."""
    return {
        "snes_type": "newtonls",
        "snes_linesearch_type": "basic",
        "snes_rtol": 1e-9,
        "snes_atol": 1e-8,
        "snes_stol": 0.0,
        "snes_max_it": 30,
        "ksp_type": "preonly",
        "pc_type": "lu",
        "pc_factor_mat_solver_type": "mumps",
    }


@dataclass
class ContinuationParameters:
    """Load-step control (load factors in [0, 1]).

    ``viscosity`` is the regularisation η relative to the membrane stiffness:
    η = viscosity · max(t·c·λmax(M)) / h², h the mean edge length (0 = off).
    """

    initial_step: float = 0.25
    min_step: float = 1e-4
    max_step: float = 1.0
    grow: float = 1.5
    shrink: float = 0.5
    easy_iterations: int = 8
    viscosity: float = 0.0

    def __post_init__(self) -> None:
        check_range("initial_step", self.initial_step, 0.0, 1.0, low_open=True)
        check_range("min_step", self.min_step, 0.0, self.initial_step, low_open=True)
        check_range("max_step", self.max_step, self.initial_step, 1.0)
        check_range("grow", self.grow, 1.0, 10.0)
        check_range("shrink", self.shrink, 0.01, 0.99)
        check_range("viscosity", self.viscosity, 0.0, 1e6)


@dataclass
class SolveReport:
    """Outcome of :meth:`QuasiStaticSolver.solve`.

    ``converged`` is True only if the full load was reached *and* the unregularised
    system was solved; otherwise ``message`` says why.  ``residual_norm`` is ‖R‖₂ of
    the unregularised system at the returned state.
    """

    converged: bool
    load_factor: float
    load_steps: int = 0
    failed_steps: int = 0
    newton_iterations: int = 0
    residual_norm: float = float("nan")
    wall_time_s: float = 0.0
    history: list[dict] = field(default_factory=list)
    message: str = ""


class QuasiStaticSolver:
    """Ramp a :class:`MembraneModel`'s pressure to ``target_pressure`` (kPa) and solve.

    Parameters
    ----------
    model
        The membrane model; its ``u`` holds the solution (and the initial guess).
    bcs
        Dirichlet conditions on ``model.V``.
    target_pressure
        Final pressure (kPa).
    hooks
        Extra residual/Jacobian contributions (e.g. contact).
    continuation, snes_options
        Load-step control and PETSc options (merged over
        :func:`default_snes_options`; set under a unique prefix).
    """

    _count = 0

    def __init__(self, model: MembraneModel, bcs: Sequence, target_pressure: float, *,
                 hooks: Sequence[Hook] = (), continuation: ContinuationParameters | None = None,
                 snes_options: dict | None = None):
        self.model = model
        self.target_pressure = float(target_pressure)
        self.continuation = continuation or ContinuationParameters()
        self.u_prev = fem.Function(model.V, name="previous_state")
        self.u_prev.x.array[:] = model.u.x.array
        self.eta = fem.Constant(model.domain.mesh, dolfinx.default_scalar_type(0.0))
        residual = model.residual()
        if self.continuation.viscosity > 0:
            v = ufl.TestFunction(model.V)
            residual = residual + self.eta * _lumped_viscous(model, v, self.u_prev)
        self.system = AssembledSystem(residual, model.jacobian(residual), model.u, bcs, hooks)
        self.bcs = list(bcs)
        self.eta_ref = self.continuation.viscosity * _stiffness_per_area(model)

        QuasiStaticSolver._count += 1
        prefix = f"valve_qs{QuasiStaticSolver._count}_"
        self.snes = PETSc.SNES().create(model.domain.comm)
        self.snes.setOptionsPrefix(prefix)
        opts = PETSc.Options()
        for key, value in {**default_snes_options(), **(snes_options or {})}.items():
            opts[f"{prefix}{key}"] = value
        self.snes.setFromOptions()
        self.snes.setFunction(self.system.residual, self.system.b)
        self.snes.setJacobian(self.system.jacobian, self.system.A)

    def _accept(self) -> None:
        """Tell the hooks a load step was accepted (contact sides and driving forces)."""
        for hook in self.system.hooks:
            accept = getattr(hook, "accept_state", None)
            if accept is not None:
                accept(self.model.u)

    def _newton(self) -> tuple[bool, int]:
        for bc in self.bcs:
            bc.set(self.model.u.x.array)
        x = self.system.x
        self.model.u.x.petsc_vec.copy(x)
        self.snes.solve(None, x)
        its = self.snes.getIterationNumber()
        ok = self.snes.getConvergedReason() > 0 and np.isfinite(self.snes.getFunctionNorm())
        if ok:
            x.copy(self.model.u.x.petsc_vec)
            self.model.u.x.scatter_forward()
        return ok, its

    def solve(self, on_step: Callable[[float, float], None] | None = None) -> SolveReport:
        """Run the continuation; ``on_step(load_factor, pressure)`` after each accepted step."""
        c = self.continuation
        t0 = time.perf_counter()
        report = SolveReport(converged=False, load_factor=0.0)
        lam, step = 0.0, c.initial_step
        u = self.model.u
        saved = u.x.array.copy()
        self.eta.value = self.eta_ref
        while lam < 1.0 - 1e-14:
            trial = min(1.0, lam + step)
            self.model.pressure.value = trial * self.target_pressure
            saved[:] = u.x.array
            ok, its = self._newton()
            report.newton_iterations += its
            if ok:
                lam = trial
                report.load_steps += 1
                self.u_prev.x.array[:] = u.x.array
                self._accept()
                report.history.append({"load_factor": lam, "pressure": trial * self.target_pressure,
                                       "newton_iterations": its})
                if on_step is not None:
                    on_step(lam, lam * self.target_pressure)
                if its <= c.easy_iterations:
                    step = min(c.max_step, step * c.grow)
            else:
                u.x.array[:] = saved
                report.failed_steps += 1
                step *= c.shrink
                log.debug("load step to %.4g failed (reason %d), retrying with step %.3g",
                          trial, self.snes.getConvergedReason(), step)
                if step < c.min_step:
                    report.load_factor = lam
                    report.residual_norm = self.system.residual_norm()
                    report.message = (
                        f"load continuation stalled at load factor {lam:.4g} "
                        f"(p = {lam * self.target_pressure:.4g} kPa): Newton failed with reason "
                        f"{self.snes.getConvergedReason()} at step {step / c.shrink:.3g} and "
                        f"min_step = {c.min_step:g}")
                    report.wall_time_s = time.perf_counter() - t0
                    raise SolverError(report.message)
        report.load_factor = lam
        failure = self._remove_regularisation(report) if self.eta_ref > 0 else ""
        self.eta.value = 0.0
        # the residual of the true (unregularised) problem, whatever happened above
        report.residual_norm = self.system.residual_norm()
        report.converged = not failure
        report.message = failure
        report.wall_time_s = time.perf_counter() - t0
        if failure:
            log.warning("quasi-static solve NOT converged: %s", failure)
        log.info("quasi-static solve: %d load steps (%d failed), %d Newton iterations, "
                 "|R| = %.3g, %.2f s", report.load_steps, report.failed_steps,
                 report.newton_iterations, report.residual_norm, report.wall_time_s)
        return report

    def _remove_regularisation(self, report: SolveReport) -> str:
        """Pseudo-time steps at full load with η decreasing by decades, ending at η = 0.

        Returns ``""`` once the unregularised system is solved, else why it was not: the
        state is then the last converged *regularised* one, not an equilibrium.
        """
        eta = self.eta_ref
        u = self.model.u
        saved = u.x.array.copy()
        attempts, reason, eta_kept = 40, 0, eta
        for _ in range(attempts):
            eta = 0.0 if eta < 1e-8 * max(self.eta_ref, 1e-300) else eta
            self.eta.value = eta
            saved[:] = u.x.array
            ok, its = self._newton()
            report.newton_iterations += its
            if ok:
                self.u_prev.x.array[:] = u.x.array
                self._accept()
                if eta == 0.0:
                    return ""
                eta_kept = eta
                eta *= 0.1
            else:
                u.x.array[:] = saved
                reason = self.snes.getConvergedReason()
                if eta == 0.0:
                    eta = 1e-6 * self.eta_ref
                else:
                    eta *= 3.0
        return (f"could not remove the viscous regularisation: the unregularised Newton solve "
                f"at full load did not converge in {attempts} attempts (last SNES reason "
                f"{reason}); the state kept is the equilibrium of the regularised problem with "
                f"eta = {eta_kept:.3g} kPa/mm ({eta_kept / self.eta_ref:.2g} × the ramp's value), "
                "not of the true problem")


def _lumped_viscous(model: MembraneModel, v, u_prev):
    dxv = ufl.Measure("dx", domain=model.domain.mesh,
                      metadata={"quadrature_rule": "vertex", "quadrature_degree": 1})
    return ufl.inner(model.u - u_prev, v) * model.area_factor() * dxv


def _stiffness_per_area(model: MembraneModel) -> float:
    """max(t·c·λmax) / h² (kPa/mm): a stiffness per area and per displacement."""
    k = max(m.stiffness_scale for m in model.materials.values())
    return k / mean_edge_length(model.domain.mesh) ** 2


def mean_edge_length(mesh) -> float:
    """Mean length of the mesh's edges (over all ranks)."""
    mesh.topology.create_entities(1)
    mesh.topology.create_connectivity(1, mesh.topology.dim)
    n_edges = mesh.topology.index_map(1).size_local
    h = mesh.h(1, np.arange(n_edges, dtype=np.int32))
    total = mesh.comm.allreduce(float(np.sum(h)), op=MPI.SUM)
    count = mesh.comm.allreduce(n_edges, op=MPI.SUM)
    return total / count
