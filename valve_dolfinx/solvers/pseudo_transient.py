"""Pseudo-transient continuation to the loaded static equilibrium (SPEC §4).

The static equilibrium ``R(u) = 0`` (internal − pressure − contact − bending
forces, full diastolic pressure) of membranes that have no stiffness normal to
themselves when unstressed is reached by integrating, in a pseudo-time τ,

    M·du/dτ + R(u) = 0

with implicit (backward) Euler steps, PETSc TS (``beuler``) and Newton's
method (SNES) in every step.  The step Δτ follows the residual (switched
evolution relaxation, Mulder & van Leer 1985; Kelley & Keyes 1998):

    Δτ_{n+1} = Δτ_n · clip(c·‖R_{n-1}‖₂ / ‖R_n‖₂, 1/g, g),

(c = :data:`INCREMENT`, g = :data:`GROWTH_LIMIT`) so that far from the equilibrium the
mass term ``M/Δτ`` regularises the singular tangent, and near it Δτ → ∞ turns the steps
into Newton's method on the static problem.  Δτ is also limited so that no node moves further than
:data:`MAX_STEP_MOTION_MM` in one step, and every Newton update is scaled so that
no node moves further than :data:`NEWTON_MOTION_MM` between two contact
evaluations (a line-search pre-check), which keeps nodes from tunnelling
through a surface.  A step's Newton solve ends once its residual has fallen by
:data:`NEWTON_RTOL`; it fails, and the step is retried with half the Δτ, also at an iterate
that collapses a contact triangle, whose residual is NaN
(:func:`~valve_dolfinx.solvers.assembly.assemble_residual`).  An update that reverses the
previous one, within a solve or from the last update of the previous accepted step, is damped
(:data:`NEWTON_REVERSAL_DAMPING`).

**The mass is in force units.**  ``M`` is diagonal (vertex quadrature) with
nodal entries ``p·A_i/L`` (A_i the nodal reference area, p the target pressure,
L = ``mass_length_mm``): at Δτ = 1 an unbalanced node under its full pressure
force moves about L, whatever tissue it belongs to.  A mass scaled by each
tissue's in-plane stiffness lets the slack pericardial graft's soft modes
(held only by bending and contact) settle about 10⁶ times slower than its stiff
ones; a mass in force units treats soft and stiff modes alike.

**What is frozen within a step.**  The hooks' ``accept_state`` is called after
every accepted step: contact sides (the side a node approaches a triangle from)
and the contact law's driving force (the nodal pressure force) are those of the
last accepted state during the next step, so the contact Jacobian is exact and
Newton converges quadratically.  At a steady state the accepted and the current
state coincide, so the equilibrium is the SPEC's.

**Convergence.**  A run converges when the static residual at the accepted
state — evaluated with contact sides and driving forces of that state —
satisfies ``‖R‖∞ < residual_tolerance`` (mN) over the free degrees of freedom.
Otherwise it stops ``converged = False`` at the step, wall-time or Δτ-floor
(:data:`DT_MIN`) limit, or at a start with a collapsed contact triangle, with the
reason.  Mass, ``L`` and the step control are numerical devices: the equilibrium does
not depend on them (tested).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

import numpy as np
import ufl

from valve_dolfinx._compat import MPI, PETSc, dolfinx
from valve_dolfinx.mechanics.membrane import MembraneModel
from valve_dolfinx.solvers.assembly import (
    Laps,
    assemble_jacobian,
    assemble_residual,
    owned_bc_dofs,
)
from valve_dolfinx.solvers.callbacks import NewtonCycleStop, NewtonReversalDamping
from valve_dolfinx.solvers.contact_hook import cut_to_free_fraction
from valve_dolfinx.solvers.nodal import BlockPattern, NodalCoupling
from valve_dolfinx.solvers.parameters import PseudoTransientParameters
from valve_dolfinx.solvers.report import SolveReport
from valve_dolfinx.solvers.stepping import SteppingSolver

__all__ = ["PseudoTransientSolver"]

log = logging.getLogger(__name__)
fem = dolfinx.fem

#: first pseudo-time step (dimensionless): a node under its full pressure force moves
#: about 0.05·L in it
DT_INITIAL = 0.05
#: pseudo-time step below which the run has stalled (its Newton solves kept failing, and a
#: failed step is retried with half the Δτ)
DT_MIN = 1e-8
#: factor c on the residual ratio of switched evolution relaxation (PETSc's
#: ``-ts_pseudo_increment``): Δτ still grows by it while the residual stalls
INCREMENT = 1.2
#: largest factor by which Δτ grows or shrinks from one step to the next
GROWTH_LIMIT = 3.0
#: the next Δτ is shortened so that no node is expected to move further than this in one
#: step (mm)
MAX_STEP_MOTION_MM = 0.5
#: largest nodal motion of one Newton update (mm): contact is evaluated at every Newton
#: iterate, and a shorter motion than its penetration window keeps nodes from tunnelling
NEWTON_MOTION_MM = 0.1
#: Newton iterations per step (``snes_max_it``; ``petsc_options`` may set another)
NEWTON_MAX_IT = 12
#: relative reduction of the step's residual that ends its Newton solve (``snes_rtol``)
NEWTON_RTOL = 0.05
#: a Newton solve whose residual norms repeat every second or third iteration to this
#: relative tolerance has settled into a cycle and ends as failed at once, not at
#: NEWTON_MAX_IT; the step is retried from its start, so the path does not change
NEWTON_CYCLE_TOLERANCE = 1e-3
#: factor on a Newton update that points back along the previous one (cosine below -0.9:
#: the iterates jump to and fro across a kink of the residual, such as the relaxed
#: membrane energy's taut/wrinkled switch), so that the iterate lands between the two sides
NEWTON_REVERSAL_DAMPING = 0.5


class PseudoTransientSolver(SteppingSolver):
    """Static equilibrium of a :class:`MembraneModel` with hooks and Dirichlet conditions.

    What it shares with the damped dynamics (set-up, the run, history, failure reasons) is
    :class:`~valve_dolfinx.solvers.stepping.SteppingSolver`'s.

    Parameters
    ----------
    model
        The membrane; ``model.u`` (the solver's ``state`` and ``u``) is the starting
        displacement on entry and the final one on return (on the fixed dofs it must hold
        their values).
    bcs
        Dirichlet conditions on ``model.V``.
    target_pressure
        The pressure (kPa), applied in full from the first step.
    params
        Settings (tolerance, numerical mass, budgets); the step control's numbers are
        the module's constants.
    hooks
        Factories ``make(coupling) -> hook`` of extra forces (contact, bending),
        called with the :class:`NodalCoupling` of ``model.V``; a hook has
        ``add_residual(u, b)``, ``add_jacobian(u, A)`` and optionally
        ``accept_state(u)`` and ``diagnostics()``.
    watch_nodes
        Mesh node ids whose motion per step is recorded (the middle of each
        leaflet's free edge).
    """

    OPTIONS_PREFIX = "valve_ptc"
    TITLE = "pseudo-transient continuation"
    TIME, STEP, UNIT = "τ", "Δτ", ""

    def __init__(self, model: MembraneModel, bcs: Sequence[fem.DirichletBC],
                 target_pressure: float, params: PseudoTransientParameters | None = None,
                 hooks: Sequence[Callable[[NodalCoupling], object]] = (),
                 watch_nodes: Sequence[int] = ()):
        rate = fem.Function(model.V, name="displacement_rate")
        super().__init__(model, params or PseudoTransientParameters(), target_pressure,
                         model.u, rate, None, hooks, watch_nodes)
        self.bcs = list(bcs)
        # nodal mass p·A/L in force units: the same for every tissue
        scale = max(abs(self.target_pressure), 1e-12) / self.params.mass_length_mm
        self.mass_scale = fem.Constant(model.domain.mesh, PETSc.ScalarType(scale))
        self.F_form, self.J_form = self._forms()
        self.J_mat = self._create_jacobian()
        # one process: the Jacobian's pattern grows once per assembly, before it
        self._pattern = BlockPattern(self.coupling) if self.coupling.comm.size == 1 else None
        self._bc_local, self._bc_rows = owned_bc_dofs(model.V, self.bcs)
        self._laps = Laps()

    @property
    def u(self) -> fem.Function:
        """The displacement: ``model.u``, the time stepper's state."""
        return self.state

    def _new_report(self) -> SolveReport:
        return SolveReport(residual_tolerance_mN=self.params.residual_tolerance)

    # --- forms -------------------------------------------------------------------------
    def _forms(self):
        model = self.model
        v = ufl.TestFunction(model.V)
        du = ufl.TrialFunction(model.V)
        dxv = ufl.Measure("dx", domain=model.domain.mesh,
                          metadata={"quadrature_rule": "vertex", "quadrature_degree": 1})
        dA = model.area_factor()
        residual = model.residual(v)
        F = self.mass_scale * ufl.inner(self.rate, v) * dA * dxv + residual
        J = (ufl.derivative(residual, model.u, du)
             + self.shift * self.mass_scale * ufl.inner(du, v) * dA * dxv)
        return fem.form(F), fem.form(J)

    def _create_jacobian(self) -> PETSc.Mat:
        """The Jacobian's matrix: the form's sparsity plus the node couplings the hooks
        declare (``coupled_nodes()``, e.g. the bending stencil), so that inserting them
        does not reallocate the matrix.  Contact pairs, which change, add entries: on one
        process the blocks a hook announces (``jacobian_couplings(u)``) are put in the
        pattern in one step before each assembly (:class:`BlockPattern`)."""
        pattern = fem.create_sparsity_pattern(self.J_form)
        imap = self.model.V.dofmap.index_map
        for hook in self.hooks:
            coupled = getattr(hook, "coupled_nodes", None)
            if coupled is None:
                continue
            rows, cols = coupled()
            local = [imap.global_to_local(self.coupling.block_of_node[n]) for n in (rows, cols)]
            keep = (local[0] >= 0) & (local[1] >= 0)  # columns off this rank's halo: malloc
            rows, cols = local[0][keep], local[1][keep]
            order = np.argsort(rows, kind="stable")
            rows, cols = rows[order], cols[order]
            starts = np.flatnonzero(np.concatenate([[True], rows[1:] != rows[:-1], [True]]))
            for a, b in zip(starts[:-1], starts[1:], strict=True):
                pattern.insert(rows[a:a + 1].astype(np.int32), cols[a:b].astype(np.int32))
        pattern.finalize()
        J = dolfinx.cpp.la.petsc.create_matrix(self.model.domain.comm, pattern, "baij")
        J.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        return J

    # --- PETSc callbacks ---------------------------------------------------------------
    def ifunction(self, ts, t, X, Xdot, F) -> None:
        self._check_step_floor(ts, DT_MIN)
        self._laps.start()
        self._copy_state(X, Xdot)
        # a Newton iterate that collapses a triangle fails its solve; an accepted state raises
        assemble_residual(F, self.F_form, self.state, self.hooks, self.bcs, X, self._laps,
                          trial=ts is not None)

    def ijacobian(self, ts, t, X, Xdot, a, J, P) -> None:
        self._laps.start()
        self._copy_state(X, Xdot)
        if self._pattern is not None:  # the blocks the hooks will add, in the pattern at once
            for hook in self.hooks:
                couplings = getattr(hook, "jacobian_couplings", None)
                if couplings is not None:
                    if self._pattern.include(J, *couplings(self.state)) and ts is not None:
                        # a BAIJ preallocation leaves the matrix's nonzero state as it was:
                        # without a reset the LU would reuse the old pattern's analysis
                        ts.getSNES().getKSP().getPC().reset()
                    self._laps(hook.timing_name)
        self.shift.value = a
        assemble_jacobian(J, self.J_form, self.state, self.hooks, self.bcs, self._bc_rows,
                          self._laps)

    def _limit_update(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """Line-search pre-check: scale the Newton update so that no node moves further
        than :data:`NEWTON_MOTION_MM`, damp it if it reverses the previous one
        (:data:`NEWTON_REVERSAL_DAMPING`), and cut it to the part along which no surface
        meets another (:func:`~valve_dolfinx.solvers.contact_hook.cut_to_free_fraction`)."""
        motion = self._largest_node_motion(y.array_r)
        if motion > NEWTON_MOTION_MM:
            y.scale(NEWTON_MOTION_MM / motion)
        self._reversals(self._snes.getIterationNumber(), y)
        cut_to_free_fraction(self.hooks, x, y)

    def _largest_node_motion(self, owned: np.ndarray) -> float:
        local = owned.reshape(-1, 3)
        value = float(np.max(np.linalg.norm(local, axis=1), initial=0.0))
        return self.model.domain.comm.allreduce(value, op=MPI.MAX)

    # --- static residual -----------------------------------------------------------------
    def static_residual(self) -> tuple[float, float]:
        """(‖R‖∞, ‖R‖₂) of the static residual at ``model.u`` (mN), over the free dofs."""
        X = self.state.x.petsc_vec.copy()
        F = X.duplicate()
        self.ifunction(None, 0.0, X, None, F)
        with F.localForm() as f_local:
            f_local.array[self._bc_local] = 0.0
        norms = F.norm(PETSc.NormType.INFINITY), F.norm(PETSc.NormType.NORM_2)
        X.destroy()
        F.destroy()
        return float(norms[0]), float(norms[1])

    # --- the run -------------------------------------------------------------------------
    def _make_ts(self) -> PETSc.TS:
        p = self.params
        options = {
            "ts_type": "beuler",
            "ts_adapt_type": "none",
            "ts_max_snes_failures": -1,
            "ts_max_step_rejections": -1,
            "ts_adapt_scale_solve_failed": 0.5,
            "snes_type": "newtonls",
            "snes_linesearch_type": "basic",
            "snes_max_it": NEWTON_MAX_IT,
            "snes_rtol": NEWTON_RTOL,
            "snes_atol": 0.2 * p.residual_tolerance,
            "snes_stol": 0.0,
            "snes_divergence_tolerance": -1,
            "ksp_type": "preonly",
            "pc_type": "lu",
            "pc_factor_mat_solver_type": "mumps",
        }
        ts = self._new_ts({**options, **p.petsc_options}, DT_INITIAL, 1e300, p.max_steps)
        ts.setFromOptions()
        self._ts, self._snes = ts, ts.getSNES()
        self._cycles = NewtonCycleStop(NEWTON_CYCLE_TOLERANCE)
        self._reversals = NewtonReversalDamping(NEWTON_REVERSAL_DAMPING)
        ts.getSNES().setLineSearchPreCheck(self._guard.wrap(self._limit_update))
        ts.getSNES().setMonitor(self._guard.wrap(self._cycles))
        return ts

    def _start_run(self) -> None:
        self.model.pressure.value = self.target_pressure
        self._laps = Laps()
        _, self._r_prev = self.static_residual()

    def _post_step(self, ts: PETSc.TS) -> None:
        p, r = self.params, self.report
        self._laps.start()
        dt = ts.getTimeStep()
        self._take_solution(ts)
        self._last_displacement, step = self._node_motion()
        motion = float(np.max(step, initial=0.0))
        watched = float(np.max(step[self.watch_nodes], initial=0.0))
        solved_pressure = float(self.model.pressure.value)
        self.accept_state()  # contact sides and driving forces of this state
        self._reversals.carry_over()  # a cycle across steps is damped as one within a solve
        self._laps("post_step")  # the static residual's assembly keeps its own laps
        r_inf, r_two = self.static_residual()
        self._count_step(ts)
        r.residual_mN = r_inf
        self._keep_row({"step": r.steps, "pseudo_time": r.time, "dt": dt,
                        "pressure_kpa": solved_pressure,
                        "residual_mN": r_inf, "residual_l2_mN": r_two, "max_motion_mm": motion,
                        "watched_motion_mm": watched,
                        "newton_iterations": ts.getSNES().getIterationNumber(),
                        "rejected_steps": ts.getStepRejections()})
        self._laps("post_step")
        if r_inf < p.residual_tolerance:
            self._end(ts, f"static residual {r_inf:.3g} mN < {p.residual_tolerance:g} mN after "
                          f"{r.steps} pseudo-time steps, {r.newton_iterations} Newton iterations",
                      converged=True)
            return
        if self._out_of_time(ts, f"static residual {r_inf:.3g} mN"):
            return
        # switched evolution relaxation, bounded growth, bounded nodal motion
        ratio = INCREMENT * self._r_prev / r_two if r_two > 0 else GROWTH_LIMIT
        new_dt = dt * min(max(ratio, 1.0 / GROWTH_LIMIT), GROWTH_LIMIT)
        if motion > 0.0:
            new_dt = min(new_dt, dt * MAX_STEP_MOTION_MM / motion)
        self._r_prev = r_two
        ts.setTimeStep(max(new_dt, DT_MIN))

    def _finish_run(self) -> None:
        self.report.timings = dict(self._laps.seconds)

    def _log_summary(self) -> None:
        r = self.report
        log.info("pseudo-transient continuation: %s (%s; %.1f s; %d Newton iterations in "
                 "%d failed solves, %d of which ended in a cycle; %d reversing Newton "
                 "updates damped, %d of them a step's first)",
                 "converged" if r.converged else "NOT converged", r.reason, r.wall_time_s,
                 r.rejected_newton_iterations, r.rejected_steps,
                 self._cycles.stopped, self._reversals.damped, self._reversals.damped_first)
