"""Damped dynamics to the loaded equilibrium: PETSc TS, BDF2, adaptive steps (SPEC §4).

The membrane is driven to its static equilibrium under the diastolic pressure
by integrating

    ρ·ü + c·u̇ + R(u) = 0,   R = internal − pressure − contact forces,

written as a first-order system in the state U = (u, v) (a P1 field with 6
components per node):

    u̇ − v = 0,
    ρ·v̇ + c·v + R(u) = 0,

with lumped (vertex-quadrature) mass and damping, implicit second-order BDF
(``TSBDF``, order 2) and adaptive step control on the local truncation error of
the displacement only (absolute target :data:`ERROR_TOLERANCE_MM`, 0.01 mm as in
the reference method; velocities are not error-controlled).  The pressure is
ramped smoothly over :data:`RAMP_TIME_S`.  The run stops when the displacement
increment of the watched nodes (the middle of each leaflet's free edge) over
one accepted step falls below ``stop_increment_mm`` (1e-5 mm) once the full
load is on, and the static residual is below :data:`EQUILIBRIUM_TOLERANCE_MN`.

Mass and damping are numerical devices: a steady state of the system has
v = 0 and R(u) = 0 whatever ρ and c are, so the equilibrium does not depend on
them (tested).  They are scaled per tissue to its stiffness,
``c = (k_tissue/k_ref)^β · k_ref·τ/L²`` and ``ρ = c·(m·τ)`` (τ = ``relaxation_time``,
β = :data:`STIFFNESS_EXPONENT`, L = :data:`LENGTH_SCALE_MM`, m = :data:`MASS_RATIO`), with
``k = t·c_Fung·λmax(M)`` (:attr:`FungMaterial.stiffness_scale`), so that the
pericardial graft -- hundreds of times stiffer in-plane than the native
leaflet -- is not integrated with the native leaflet's time scale (SPEC §4).
This is the cross-check of the default path
(:mod:`~valve_dolfinx.solvers.pseudo_transient`), which reaches the same static
equilibrium without a physical time scale.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

import numpy as np
import ufl

from valve_dolfinx._compat import PETSc, dolfinx
from valve_dolfinx.exceptions import DegenerateGeometryError
from valve_dolfinx.geometry.distributed import node_to_dof
from valve_dolfinx.mechanics.membrane import MembraneModel
from valve_dolfinx.solvers.assembly import assemble_jacobian, assemble_residual, owned_bc_dofs
from valve_dolfinx.solvers.contact_hook import cut_to_free_fraction
from valve_dolfinx.solvers.nodal import NodalCoupling, NodalLayout
from valve_dolfinx.solvers.parameters import DynamicsParameters
from valve_dolfinx.solvers.report import DynamicsReport
from valve_dolfinx.solvers.stepping import SteppingSolver

__all__ = ["DampedDynamicsSolver", "STATE_LAYOUT"]

log = logging.getLogger(__name__)
fem = dolfinx.fem
fem_petsc = dolfinx.fem.petsc

#: forces act on the momentum rows (components 3-5), depend on the displacement (0-2)
STATE_LAYOUT = NodalLayout(block_size=6, row_offset=3, col_offset=0)

#: mass time scale over τ: ``ρ = c·MASS_RATIO·τ`` (small: over-damped)
MASS_RATIO = 0.05
#: L (mm) in the stiffness-per-area estimate k/L² of the damping
LENGTH_SCALE_MM = 10.0
#: β in ``c ∝ (k_tissue/k_ref)^β`` (1: damping proportional to each tissue's stiffness)
STIFFNESS_EXPONENT = 1.0
#: duration (s) of the smooth-step pressure ramp
RAMP_TIME_S = 1.0
#: first time step (s)
DT_INITIAL_S = 1e-3
#: time step (s) below which the run has stalled
DT_MIN_S = 1e-8
#: largest time step (s)
DT_MAX_S = 50.0
#: simulated time limit (s)
T_MAX_S = 1e5
#: local truncation error target of the displacement (mm; the reference method's 0.01 mm)
ERROR_TOLERANCE_MM = 0.01
#: largest nodal displacement per step (mm): the next step is shortened so that no node
#: moves further, which keeps nodes from tunnelling through a surface between two contact
#: evaluations (the contact search only sees penetrations shallower than its window)
MAX_INCREMENT_MM = 0.1
#: convergence also needs the static residual (internal − pressure − contact forces at
#: rest), max-norm over the free nodes, below this (mN): small increments alone can also
#: mean a stalled, tiny time step
EQUILIBRIUM_TOLERANCE_MN = 0.05
#: limit on time steps (accepted + rejected)
MAX_STEPS = 20000
#: Newton iterations per step before the step is retried smaller
NEWTON_MAX_IT = 20


class DampedDynamicsSolver(SteppingSolver):
    """BDF2 damped dynamics of a :class:`MembraneModel` with hooks (contact) and fixed dofs.

    What it shares with the pseudo-transient continuation (set-up, the run, history,
    failure reasons) is :class:`~valve_dolfinx.solvers.stepping.SteppingSolver`'s; its
    ``state`` is ``U = (u, v)``.

    Parameters
    ----------
    model
        The membrane (its ``u`` receives the final displacement).
    bcs
        Dirichlet conditions on ``model.V`` (or its components): which
        displacement components are fixed; they keep their initial value and
        their velocity is zero.
    initial_displacement
        Function on ``model.V``: the starting placement (also the value kept on
        the fixed dofs).
    target_pressure
        Final pressure (kPa).
    stiffness
        ``{cell tag: k_tissue}`` (mN/mm) for the mass/damping scaling.
    watch_nodes
        Mesh node ids whose increments decide convergence.
    params
        Settings (damping time scale, convergence, wall-clock limit).
    hooks
        Factories ``make(coupling) -> hook`` (contact), called with the
        :class:`NodalCoupling` of the state space.
    """

    OPTIONS_PREFIX = "valve_dyn"
    TITLE = "damped dynamics"
    TIME, STEP, UNIT = "t", "dt", " s"

    def __init__(self, model: MembraneModel, bcs: Sequence[fem.DirichletBC],
                 initial_displacement: fem.Function, target_pressure: float,
                 stiffness: dict[int, float], watch_nodes: Sequence[int],
                 params: DynamicsParameters | None = None,
                 hooks: Sequence[Callable[[NodalCoupling], object]] = ()):
        self.W = fem.functionspace(model.domain.mesh, ("Lagrange", 1, (6,)))
        super().__init__(model, params or DynamicsParameters(), target_pressure,
                         fem.Function(self.W, name="state"),
                         fem.Function(self.W, name="state_rate"), STATE_LAYOUT, hooks,
                         watch_nodes)
        # the P1 spaces V (3 components) and W (6) number their nodes independently
        self._w_of_v = np.empty(len(model.u.x.array) // 3, dtype=np.int64)
        self._w_of_v[node_to_dof(model.V)] = node_to_dof(self.W)
        # initial state (u0, 0) and the fixed values
        U_arr = self.state.x.array.reshape(-1, 6)
        U_arr[self._w_of_v, :3] = initial_displacement.x.array.reshape(-1, 3)
        U_arr[:, 3:] = 0.0
        self.state.x.scatter_forward()
        self.bcs = self._state_bcs(bcs)

        self.stiffness = dict(stiffness)
        self.damping, self.mass = self._coefficients(stiffness)
        self.G_form, self.J_form = self._forms()
        self.J_mat = fem_petsc.create_matrix(self.J_form)
        self.J_mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        _, self._bc_rows = owned_bc_dofs(self.W, self.bcs)

    def _new_report(self) -> DynamicsReport:
        return DynamicsReport(residual_tolerance_mN=EQUILIBRIUM_TOLERANCE_MN)

    # --- setup -------------------------------------------------------------------
    def _state_bcs(self, bcs: Sequence[fem.DirichletBC]) -> list[fem.DirichletBC]:
        """Fix (u_c, v_c) of the state wherever a condition on V fixes u_c."""
        fixed = np.concatenate([bc.dof_indices()[0] for bc in bcs] or [np.empty(0, np.int32)])
        blocks, comps = self._w_of_v[fixed // 3], fixed % 3
        out = []
        for c in range(3):
            nodes = np.unique(blocks[comps == c])
            for comp in (c, c + 3):  # displacement keeps its value, velocity is zero
                Wc, to_parent = self.W.sub(comp).collapse()
                to_parent = np.asarray(to_parent).ravel()  # 0.11 returns [array]
                child = np.full(len(self.state.x.array), -1, dtype=np.int64)
                child[to_parent] = np.arange(len(to_parent))
                parent = (6 * nodes + comp).astype(np.int32)
                g = fem.Function(Wc)
                g.x.array[:] = self.state.x.array[to_parent]
                out.append(fem.dirichletbc(g, [parent, child[parent].astype(np.int32)],
                                           self.W.sub(comp)))
        return out

    def _coefficients(self, stiffness: dict[int, float]) -> tuple[dict, dict]:
        p = self.params
        k_ref = min(stiffness.values())
        damping, mass = {}, {}
        for tag, k in stiffness.items():
            c = (k / k_ref) ** STIFFNESS_EXPONENT * k_ref * p.relaxation_time / LENGTH_SCALE_MM**2
            damping[tag] = c
            mass[tag] = c * MASS_RATIO * p.relaxation_time
        return damping, mass

    def _forms(self):
        model = self.model
        U, Udot = self.state, self.rate
        u = ufl.as_vector([U[i] for i in range(3)])
        v = ufl.as_vector([U[i] for i in range(3, 6)])
        udot = ufl.as_vector([Udot[i] for i in range(3)])
        vdot = ufl.as_vector([Udot[i] for i in range(3, 6)])
        w = ufl.TestFunction(self.W)
        w_u = ufl.as_vector([w[i] for i in range(3)])
        w_v = ufl.as_vector([w[i] for i in range(3, 6)])
        dA = model.area_factor()
        dxv = ufl.Measure("dx", domain=model.domain.mesh, subdomain_data=model.domain.cell_tags,
                          metadata={"quadrature_rule": "vertex", "quadrature_degree": 1})
        inertial = sum(
            (self.damping[tag] * ufl.inner(udot - v, w_u)
             + ufl.inner(self.mass[tag] * vdot + self.damping[tag] * v, w_v)) * dA * dxv(tag)
            for tag in self.damping)
        G = inertial + model.residual(w_v, u=u)
        dU = ufl.TrialFunction(self.W)
        J = ufl.derivative(G, U, dU) + self.shift * ufl.derivative(G, Udot, dU)
        return fem.form(G), fem.form(J)

    # --- PETSc TS callbacks ------------------------------------------------------------
    def _load(self, t: float) -> float:
        xi = min(1.0, max(0.0, t / RAMP_TIME_S))
        return self.target_pressure * xi * xi * (3.0 - 2.0 * xi)

    def _set_state(self, t: float, X: PETSc.Vec, Xdot: PETSc.Vec) -> None:
        self.model.pressure.value = self._load(t)
        self._copy_state(X, Xdot)

    def ifunction(self, ts, t, X, Xdot, F) -> None:
        self._check_step_floor(ts, DT_MIN_S)
        self._set_state(t, X, Xdot)
        # a Newton iterate that collapses a triangle fails its solve; an accepted state raises
        assemble_residual(F, self.G_form, self.state, self.hooks, self.bcs, X,
                          trial=ts is not None)

    def ijacobian(self, ts, t, X, Xdot, a, J, P) -> None:
        self._set_state(t, X, Xdot)
        self.shift.value = a
        assemble_jacobian(J, self.J_form, self.state, self.hooks, self.bcs, self._bc_rows)

    # --- the run -------------------------------------------------------------------
    def _make_ts(self) -> PETSc.TS:
        options = {
            "ts_type": "bdf",
            "ts_bdf_order": 2,
            "ts_adapt_type": "basic",
            "ts_adapt_dt_min": DT_MIN_S,
            "ts_adapt_dt_max": DT_MAX_S,
            "ts_adapt_clip": "0.1,4.0",
            "ts_max_snes_failures": -1,
            "ts_max_step_rejections": -1,
            "snes_type": "newtonls",
            # backtracking: a node in a crease of a crumpled (wrinkled) sheet makes the
            # full Newton step cycle between two states; halving it breaks the cycle
            "snes_linesearch_type": "bt",
            "snes_max_it": NEWTON_MAX_IT,
            # residuals are forces (mN); nodal pressure forces are ~1-10 mN, and 1e-2 mN
            # moves a node by 1e-3 mm against the contact stiffness (10 mN/mm): the path
            # needs no more, and the equilibrium test (EQUILIBRIUM_TOLERANCE_MN) is separate.
            # PETSc's stol ends Newton when round-off (huge shift at tiny dt) stalls |F|.
            "snes_rtol": 1e-4,
            "snes_atol": 1e-2,
            "snes_stol": 1e-12,
            # The LU factorisation took half the time of a step: it is refreshed every
            # 10th Newton iteration, across time steps, and GMRES preconditioned by it
            # solves each Newton system with the current Jacobian.
            "snes_lag_preconditioner": 10,
            "snes_lag_preconditioner_persists": True,
            "ksp_type": "gmres",
            # modified Gram-Schmidt: with PETSc's default (classical, VecMDot/VecMAXPY) two
            # runs of the same case differ in the last bits; with it runs are bit-reproducible
            "ksp_gmres_modifiedgramschmidt": True,
            "ksp_rtol": 1e-8,
            "pc_type": "lu",
            "pc_factor_mat_solver_type": "mumps",
        }
        ts = self._new_ts(options, DT_INITIAL_S, T_MAX_S, MAX_STEPS)
        atol = self.F_vec.duplicate()
        with atol.localForm() as a_local:
            arr = a_local.array.reshape(-1, 6)
            arr[:, :3] = ERROR_TOLERANCE_MM
            arr[:, 3:] = 1e30  # velocities are not error-controlled
        ts.setTolerances(rtol=0.0, atol=atol)
        ts.setFromOptions()
        ts.getSNES().setLineSearchPreCheck(self._guard.wrap(self._cut_update))
        return ts

    def _cut_update(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """Line-search pre-check: no Newton update carries a surface through another
        (:func:`~valve_dolfinx.solvers.contact_hook.cut_to_free_fraction`)."""
        cut_to_free_fraction(self.hooks, x, y)

    def _start_run(self) -> None:
        self._t_prev = 0.0

    def _post_step(self, ts: PETSc.TS) -> None:
        p = self.params
        t = ts.getTime()
        dt = ts.getTimeStep()
        step_dt = t - self._t_prev
        self._take_solution(ts)
        displacement, step = self._node_motion()
        largest = float(np.max(step))
        if largest > MAX_INCREMENT_MM and step_dt > DT_MIN_S:
            # a node moved further than the contact search can follow: redo the step shorter
            ts.rollBack()
            ts.setTimeStep(max(DT_MIN_S, 0.8 * step_dt * MAX_INCREMENT_MM / largest))
            self.report.rejected_for_motion += 1
            return
        self._last_displacement = displacement
        self._t_prev = t
        increment = float(np.max(step[self.watch_nodes]))
        if largest > 0.5 * MAX_INCREMENT_MM:  # keep the next step's motion bounded
            ts.setTimeStep(min(dt, step_dt * MAX_INCREMENT_MM / largest))
        self.accept_state()
        self._count_step(ts)
        self._keep_row({"step": self.report.steps, "time": t, "dt": dt,
                        "increment_mm": increment, "max_increment_mm": largest,
                        "pressure": self._load(t)})
        if (t >= RAMP_TIME_S and increment < p.stop_increment_mm
                and self.equilibrium_residual(t) < EQUILIBRIUM_TOLERANCE_MN):
            self._end(ts, f"increment {increment:.2e} mm < {p.stop_increment_mm:g} mm and "
                          f"static residual < {EQUILIBRIUM_TOLERANCE_MN:g} mN at t = {t:.4g} s",
                      converged=True)
            return
        if self._out_of_time(ts, f"increment {increment:.3g} mm"):
            return
        if dt <= DT_MIN_S * (1 + 1e-9):
            self._end(ts, f"time step fell to the floor {DT_MIN_S:g} s at t = {t:.4g} s, "
                          f"step {self.report.steps}, increment {increment:.3g} mm")

    def _finish_run(self) -> None:
        """Copy the displacement into ``model.u`` and take the static residual there."""
        u = self.model.u.x.array.reshape(-1, 3)
        u[:] = self.state.x.array.reshape(-1, 6)[self._w_of_v, :3]
        self.model.u.x.scatter_forward()
        try:
            self.report.residual_mN = self.equilibrium_residual()
        except DegenerateGeometryError:  # the state the reason names: no residual (NaN)
            pass

    def _log_summary(self) -> None:
        r = self.report
        log.info("damped dynamics: %s; %d steps (%d rejected, %d redone for their motion), "
                 "%d Newton its, t = %.4g s, |R_static|_inf = %.3g mN, %.1f s",
                 "converged" if r.converged else "NOT converged",
                 r.steps, r.rejected_steps, r.rejected_for_motion,
                 r.newton_iterations, r.time, r.residual_mN, r.wall_time_s)

    def _at_rest(self, t: float | None = None) -> tuple[PETSc.Vec, PETSc.Vec, float]:
        """The current state with velocities and rates zero, and the time of full load."""
        X = self.state.x.petsc_vec.copy()
        X.array.reshape(-1, 6)[:, 3:] = 0.0
        Xdot = X.duplicate()
        Xdot.set(0.0)
        t_full = max(RAMP_TIME_S, self.report.time if t is None else t)
        return X, Xdot, t_full

    def equilibrium_residual(self, t: float | None = None) -> float:
        """max |R(u)| (mN) over free nodes at full pressure, velocities and rates set to 0."""
        saved_U = self.state.x.array.copy()
        X, Xdot, t_full = self._at_rest(t)
        F = self.F_vec.duplicate()
        self.ifunction(None, t_full, X, Xdot, F)
        value = F.norm(PETSc.NormType.INFINITY)
        self.state.x.array[:] = saved_U
        self.state.x.scatter_forward()
        return float(value)
