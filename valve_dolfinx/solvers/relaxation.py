"""Dynamic relaxation to the loaded equilibrium: explicit, no Newton (SPEC §4 alternative).

The static equilibrium ``R(u) = 0`` (internal − pressure − contact forces, the
same residual as :class:`~valve_dolfinx.solvers.dynamics.DampedDynamicsSolver`
at rest) is reached by integrating fictitious dynamics ``M·ü = −R(u)``
explicitly (semi-implicit Euler), with the inertia-based step control of FIRE
(Bitzek et al., Phys Rev Lett 97:170201, 2006): the velocity is steered towards
the force, the step grows while the power ``−R·u̇`` stays positive, and the
motion is quenched (velocities zeroed, step halved) as soon as it turns
negative.  This is the dynamic relaxation used for form finding of cables and
membranes (Barnes 1999, Int J Space Struct 14:89), with FIRE's quench in place
of plain kinetic damping.

Fictitious masses.  Each node's mass is the Gershgorin bound of its rows of the
stiffness ``∂R/∂u`` (membrane and bending; sum of absolute values over the
displacement columns), so that a unit step is stable for every node whatever
its tissue: the pericardial graft, hundreds of times stiffer than the native
leaflet, simply gets heavier nodes (SPEC §4: scale to the stiffness, not to one
global constant).  Two additions keep the explicit update stable where the
stiffness jumps between mass updates:

* a floor from the tissue's small-strain stiffness on the initial mesh
  (``2·k·ℓ²/(4A)`` per triangle and vertex, ℓ the opposite edge, the diagonal
  bound of a P1 Laplacian), because a slack (wrinkled) membrane has no
  stiffness until it becomes taut, and then all of it at once;
* a constant contact allowance ``contact_mass`` (mN/mm) instead of the contact
  Jacobian: the turning of a contact force where a node passes close to a
  triangle edge gives Jacobian entries ``f/d`` that are unbounded as ``d → 0``
  (measured 6e6 mN/mm on the three-leaflet valve), and would freeze the node.

Masses, damping and step are numerical devices: a state where the iteration
stops has ``R(u) = 0`` to ``residual_tolerance`` whatever they were (tested
against the BDF2 dynamics and against the exact equilibrium of a stretched
sheet in tests/test_relaxation.py).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from valve_dolfinx._compat import MPI, PETSc, dolfinx
from valve_dolfinx.exceptions import MeshError, check_range
from valve_dolfinx.geometry.distributed import node_to_dof
from valve_dolfinx.solvers.dynamics import DampedDynamicsSolver, DynamicsReport

__all__ = ["RelaxationParameters", "DynamicRelaxationSolver"]

log = logging.getLogger(__name__)

# FIRE constants (Bitzek et al. 2006): steps of positive power before the step may grow,
# growth and cut factors, initial steering and its decay
_FIRE_DELAY = 5
_FIRE_GROW, _FIRE_CUT = 1.1, 0.5
_FIRE_ALPHA0, _FIRE_ALPHA_DECAY = 0.1, 0.99
#: the largest step in units of the Gershgorin-stable step (semi-implicit Euler is stable
#: below 2 when every node's mass bounds its stiffness rows)
_DT_MAX = 1.0
_DT_MIN = 0.02


@dataclass
class RelaxationParameters:
    """Iteration control of the dynamic relaxation (units: mm, mN).

    Attributes
    ----------
    residual_tolerance
        Converged when the static residual (max-norm over free nodes, mN) is below
        this **and** no node moved more than the dynamics' ``stop_increment_mm`` in
        the last iteration.  Default: a tenth of the dynamics' equilibrium test.
    max_step_mm
        Largest nodal motion per iteration (mm): the contact search sees every
        node approach a surface (it follows penetrations up to
        ``penetration_depth``).
    mass_update_interval
        Iterations between two updates of the nodal masses (one Jacobian assembly).
    contact_mass
        Mass allowance per node for contact (mN/mm, in units of a unit step): a few
        times the contact stiffness, plus the crossing barrier if one is used.
    max_iterations
        Iteration limit; the wall-clock limit is the dynamics' ``wall_time_limit_s``.
    history_interval
        Iterations between two rows of the history (and progress reports).
    quench_per_body
        Apply FIRE's power test, step and steering to each leaflet (cell tag)
        separately: a node chattering where a contact force switches triangles
        (the triple point) then quenches its own leaflet only, and the heavy,
        slowly swinging graft keeps its momentum (docs/closure.md).  False: one
        test for the whole valve.
    ramp_iterations
        Iterations over which the pressure rises to its full value (the
        dynamics' smooth step); 0 applies it in full from the first iteration.
        Contact makes the equilibrium path-dependent: leaflets slammed shut by
        the full pressure can settle with a free edge caught on the wrong side
        of a neighbour (docs/closure.md).
    finish_start, finish_interval
        From iteration ``finish_start`` on, every ``finish_interval`` iterations,
        try to finish with Newton's method (below); 0 never tries.  The explicit
        iteration is slow where the valve has a soft mode: a slack, oversized
        pericardial free edge held by bending and contact alone is ~1e6 times
        softer than the graft's in-plane stiffness that sets its nodes' masses,
        and it creeps for tens of thousands of iterations (docs/closure.md,
        "Session 9").  Cases the relaxation settles before ``finish_start`` never
        meet it.
    finish_residual_mN
        Try a finish only when the relaxation's residual (max-norm) is below this:
        far from the equilibrium the contact arrangement still changes.
    finish_max_steps, finish_shift, finish_step_mm, finish_max_motion_mm
        The finish is pseudo-transient continuation: steps
        ``(K + μ·M) Δu = −R`` with the consistent tangent K (membrane, bending,
        contact) and the relaxation's diagonal masses M, μ starting at
        ``finish_shift`` and following the residual (switched evolution
        relaxation, ``μ ← μ·|R_new|/|R_old|``), at most ``finish_step_mm`` of
        nodal motion per step, at most ``finish_max_steps`` steps.  It is
        accepted only if the residual falls below ``residual_tolerance``, no node
        moved further than ``finish_max_motion_mm`` from where the relaxation
        stood and the mid-surfaces do not cross more than there; otherwise the
        relaxation goes on from where it was.  An accepted finish becomes the
        state that self-contacts take their side from; the run ends there if the
        residual with those sides is below the dynamics' ``equilibrium_tolerance``
        (else the relaxation goes on from it, at rest).
    """

    residual_tolerance: float = 5e-3
    max_step_mm: float = 0.02
    mass_update_interval: int = 25
    contact_mass: float = 40.0
    max_iterations: int = 200000
    history_interval: int = 50
    quench_per_body: bool = True
    ramp_iterations: int = 0
    finish_start: int = 5000
    finish_interval: int = 1000
    finish_residual_mN: float = 1.0
    finish_max_steps: int = 100
    finish_shift: float = 1e-6
    finish_step_mm: float = 0.05
    finish_max_motion_mm: float = 0.5

    def __post_init__(self) -> None:
        check_range("residual_tolerance", self.residual_tolerance, 0.0, 10.0, low_open=True,
                    unit="mN")
        check_range("max_step_mm", self.max_step_mm, 0.0, 1.0, low_open=True, unit="mm",
                    hint="keep it below the contact penetration depth")
        check_range("mass_update_interval", self.mass_update_interval, 1, 1e6)
        check_range("contact_mass", self.contact_mass, 0.0, 1e9, unit="mN/mm")
        check_range("max_iterations", self.max_iterations, 1, 1e9)
        check_range("history_interval", self.history_interval, 1, 1e9)
        check_range("ramp_iterations", self.ramp_iterations, 0, 1e9,
                    hint="0 applies the full pressure from the first iteration")
        check_range("finish_start", self.finish_start, 0, 1e9, hint="0 never tries a finish")
        check_range("finish_interval", self.finish_interval, 1, 1e9)
        check_range("finish_residual_mN", self.finish_residual_mN, 0.0, 1e6, low_open=True,
                    unit="mN")
        check_range("finish_max_steps", self.finish_max_steps, 1, 1e6)
        check_range("finish_shift", self.finish_shift, 0.0, 1e3, low_open=True,
                    hint="the first step's mass shift: 1e-6 is nearly Newton on the valve")
        check_range("finish_step_mm", self.finish_step_mm, 0.0, 1.0, low_open=True, unit="mm",
                    hint="keep it below the contact penetration depth")
        check_range("finish_max_motion_mm", self.finish_max_motion_mm, 0.0, 100.0,
                    low_open=True, unit="mm")

    def to_dict(self) -> dict:
        return asdict(self)


class _FireState:
    """FIRE step and steering of each body (Bitzek et al. 2006)."""

    def __init__(self, n_bodies: int):
        self.n = n_bodies
        self.dt = np.full(n_bodies, 0.5 * _DT_MAX)
        self.alpha = np.full(n_bodies, _FIRE_ALPHA0)
        self.positive = np.zeros(n_bodies, dtype=np.int64)

    def update(self, power: np.ndarray) -> np.ndarray:
        """Advance with each body's power ``R·u̇``; return which bodies are quenched."""
        quench = power <= 0.0
        self.positive = np.where(quench, 0, self.positive + 1)
        grow = ~quench & (self.positive > _FIRE_DELAY)
        self.dt = np.where(grow, np.minimum(self.dt * _FIRE_GROW, _DT_MAX), self.dt)
        self.alpha = np.where(grow, self.alpha * _FIRE_ALPHA_DECAY, self.alpha)
        self.dt = np.where(quench, np.maximum(self.dt * _FIRE_CUT, _DT_MIN), self.dt)
        self.alpha = np.where(quench, _FIRE_ALPHA0, self.alpha)
        return quench


class DynamicRelaxationSolver(DampedDynamicsSolver):
    """Explicit dynamic relaxation of the same model, hooks and conditions (see module doc).

    Takes the arguments of :class:`DampedDynamicsSolver` (whose residual, Jacobian,
    hooks and fixed dofs it reuses; its mass, damping and time stepping are not
    used) plus ``relaxation``.  The pressure is applied in full from the start.
    """

    def __init__(self, *args, relaxation: RelaxationParameters | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.relaxation = relaxation or RelaxationParameters()

    # --- fictitious masses ------------------------------------------------------------
    def _mass_floor(self) -> np.ndarray:
        """Owned nodes' small-strain stiffness bound ``Σ 2·k·ℓ²/(4A)`` on the initial mesh."""
        mesh = self.model.domain.mesh
        tags = self.model.domain.cell_tags
        x = mesh.geometry.x
        n_cells = mesh.topology.index_map(mesh.topology.dim).size_local  # owned cells only
        cells = mesh.geometry.dofmaps[0][:n_cells]
        k = np.zeros(n_cells)
        for tag, value in self.stiffness.items():
            owned = tags.indices[(tags.values == tag) & (tags.indices < n_cells)]
            k[owned] = value
        p = x[cells]
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        acc = dolfinx.fem.Function(self.W)
        arr = acc.x.array.reshape(-1, 6)
        block = node_to_dof(self.W)
        for a in range(3):
            opposite = np.sum((p[:, (a + 2) % 3] - p[:, (a + 1) % 3]) ** 2, axis=1)
            np.add.at(arr[:, 0], block[cells[:, a]], 2.0 * k * opposite / (4.0 * area))
        acc.x.scatter_reverse(dolfinx.la.InsertMode.add)
        n_owned = self.W.dofmap.index_map.size_local
        return acc.x.array.reshape(-1, 6)[:n_owned, 0].copy()

    def _gershgorin(self, X, Xdot, t: float) -> np.ndarray:
        """Owned nodes' largest absolute row sum of ∂R/∂u without the contact hooks."""
        hooks = [h for h in self.hooks if getattr(h, "stiffness_in_nodal_mass", True)]
        self.ijacobian(None, t, X, Xdot, 0.0, self.J_mat, self.J_mat, hooks=hooks)
        indptr, indices, data = self.J_mat.getValuesCSR()
        rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
        displacement_col = (indices % 6) < 3
        sums = np.bincount(rows[displacement_col], weights=np.abs(data[displacement_col]),
                           minlength=len(indptr) - 1)
        return sums.reshape(-1, 6)[:, 3:].max(axis=1)  # momentum rows 3-5

    def _masses(self, X, Xdot, t: float, floor: np.ndarray) -> np.ndarray:
        m = np.maximum(self._gershgorin(X, Xdot, t), floor) + self.relaxation.contact_mass
        m[m <= 0.0] = 1.0  # fixed nodes (no force) on an unloaded, uncontacted sheet
        return m

    def _bodies(self) -> np.ndarray:
        """Owned nodes' body (index of their leaflet's cell tag): FIRE quenches each alone."""
        mesh = self.model.domain.mesh
        tags = self.model.domain.cell_tags
        all_tags = np.unique(np.concatenate(self.model.domain.comm.allgather(tags.values)))
        block = node_to_dof(self.W)
        cells = mesh.geometry.dofmaps[0]
        body = np.zeros(len(self.U.x.array) // 6, dtype=np.int64)
        for a in range(3):  # every owned node lies in some local (owned or ghost) cell
            body[block[cells[tags.indices, a]]] = np.searchsorted(all_tags, tags.values)
        return body[:self.W.dofmap.index_map.size_local]

    @staticmethod
    def _per_body(comm, body: np.ndarray, values: np.ndarray, n_bodies: int) -> np.ndarray:
        """Sum of nodal ``values`` per body over all ranks."""
        return comm.allreduce(np.bincount(body, weights=values, minlength=n_bodies), op=MPI.SUM)

    # --- the Newton (pseudo-transient continuation) finish ----------------------------
    def _finish_due(self, it: int, fmax: float, ramping: bool) -> bool:
        q = self.relaxation
        return (q.finish_start > 0 and not ramping and it >= q.finish_start
                and (it - q.finish_start) % q.finish_interval == 0
                and fmax < q.finish_residual_mN)

    def _mass_shift(self, X: PETSc.Vec, masses: np.ndarray) -> tuple[np.ndarray, ...]:
        """CSR of the shift ``M`` (each owned node's mass on its momentum rows' displacement
        columns; fixed dofs left out): (row pointer, columns, values, rows)."""
        rows = (X.getOwnershipRange()[0] + 6 * np.arange(len(masses))[:, None]
                + np.arange(3, 6)).ravel()
        values = np.repeat(masses, 3)
        free = ~np.isin(rows, self._bc_rows)
        rows, values = rows[free].astype(PETSc.IntType), values[free]
        indptr = np.arange(len(rows) + 1, dtype=PETSc.IntType)
        return indptr, (rows - 3).astype(PETSc.IntType), values, rows

    def _newton_finish(self, X: PETSc.Vec, Xdot: PETSc.Vec, t: float, masses: np.ndarray,
                       deadline: float) -> tuple[bool, str, float]:
        """Pseudo-transient continuation from the relaxation's state ``X`` (positions, zero
        velocities); see :class:`RelaxationParameters`.  On success ``X`` is the equilibrium;
        otherwise ``X`` is restored.  Returns (accepted, what happened, last residual)."""
        q, comm = self.relaxation, self.model.domain.comm
        start = X.copy()
        F, dX = X.duplicate(), X.duplicate()
        ksp = self._static_ksp()
        indptr, cols, shift, rows = self._mass_shift(X, masses)
        mu, mu_min = q.finish_shift, 1e-3 * q.finish_shift
        switched = [h for h in self.hooks if getattr(h, "forces_only", False)]
        for hook in switched:  # Newton needs the contact Jacobian
            hook.forces_only = False
        ok, why, fmax, steps = False, "", float("nan"), 0
        try:
            self.ifunction(None, t, X, Xdot, F)
            crossing0 = self._crossing()
            norm, fmax = F.norm(), F.norm(PETSc.NormType.INFINITY)
            while fmax >= q.residual_tolerance:
                if steps == q.finish_max_steps:
                    why = f"{steps} steps did not converge (residual {fmax:.3g} mN)"
                    break
                if comm.allreduce(time.perf_counter() > deadline, op=MPI.LOR):
                    why = "out of wall-clock time"
                    break
                self.ijacobian(None, t, X, Xdot, 0.0, self.J_mat, self.J_mat)
                self.J_mat.setValuesIJV(indptr, cols, mu * shift, addv=PETSc.InsertMode.ADD,
                                        rowmap=rows)
                self.J_mat.assemble()
                ksp.setOperators(self.J_mat)
                ksp.solve(F, dX)
                if ksp.getConvergedReason() < 0:
                    why = f"the linear solve failed ({ksp.getConvergedReason()})"
                    break
                step = self._largest_node_motion(dX.array_r.reshape(-1, 6)[:, :3])
                X.axpy(-min(1.0, q.finish_step_mm / max(step, 1e-300)), dX)
                steps += 1
                self.ifunction(None, t, X, Xdot, F)
                new, fmax = F.norm(), F.norm(PETSc.NormType.INFINITY)
                if not np.isfinite(new):
                    why = "the residual became non-finite"
                    break
                mu = min(max(mu * new / norm, mu_min), 1e3)  # switched evolution relaxation
                norm = new
            if not why:
                motion = self._largest_node_motion(
                    (X.array_r - start.array_r).reshape(-1, 6)[:, :3])
                crossing = self._crossing()
                if motion > q.finish_max_motion_mm:
                    why = f"it moved a node {motion:.3g} mm"
                elif crossing > max(crossing0, 0.0) + 1e-3:
                    why = f"it crossed surfaces by {crossing:.3g} mm"
                else:
                    ok, why = True, (f"{steps} Newton steps to residual {fmax:.2e} mN, "
                                     f"largest motion {motion:.3g} mm")
        except (PETSc.Error, MeshError) as err:  # MeshError: non-finite positions
            why = f"{type(err).__name__}: {err}"
        finally:
            for hook in switched:
                hook.forces_only = True
        if not ok:
            X.array[:] = start.array_r
        return ok, why, fmax

    # --- the run ------------------------------------------------------------------------
    def solve(self, progress: Callable[[dict], None] | None = None) -> DynamicsReport:
        """Relax until converged or out of iterations/time; never raises on divergence.

        The final state is copied into ``model.u`` whatever happened; the report
        (``steps`` = iterations, ``time`` = pseudo-time in stable steps) says
        whether it is the equilibrium and, if not, where it stopped.  The hooks
        evaluate forces only (no Jacobian blocks) while it runs.
        """
        switched = [h for h in self.hooks if hasattr(h, "forces_only") and not h.forces_only]
        for hook in switched:
            hook.forces_only = True
        try:
            return self._relax(progress)
        finally:
            for hook in switched:
                hook.forces_only = False

    def _relax(self, progress: Callable[[dict], None] | None) -> DynamicsReport:
        p, q = self.params, self.relaxation
        self._progress = progress
        comm = self.model.domain.comm
        t0 = time.perf_counter()
        r = self.report = DynamicsReport()
        X, Xdot, t_full = self._at_rest(0.0)
        F = X.duplicate()
        x = X.array.reshape(-1, 6)
        floor = self._mass_floor()
        v = np.zeros((len(x), 3))
        body = self._bodies() if q.quench_per_body else np.zeros(len(x), dtype=np.int64)
        fire = _FireState(comm.allreduce(int(body.max(initial=-1)) + 1, op=MPI.MAX))
        pseudo_time, masses = 0.0, None
        watch_start = self.coupling.displacements(self.U)[self.watch_nodes]
        fmax = step = float("nan")

        def record(iteration: int, t_now: float, step: float, fmax: float) -> None:
            """Accept the state in X and add a history row."""
            nonlocal watch_start
            self._set_state(t_now, X, Xdot)
            self._accept_state()
            watched = self.coupling.displacements(self.U)[self.watch_nodes]
            increment = float(np.max(np.linalg.norm(watched - watch_start, axis=1), initial=0.0))
            watch_start = watched
            r.steps, r.time, r.last_dt, r.last_increment_mm = iteration, pseudo_time, \
                float(fire.dt.min()), increment
            self._record({"step": iteration, "time": pseudo_time, "dt": r.last_dt,
                          "increment_mm": increment, "max_increment_mm": step,
                          "pressure": self._load(t_now), "residual_mN": fmax})

        for it in range(q.max_iterations):
            # the dynamics' smooth-step ramp, over ramp_iterations instead of ramp_time
            ramping = it < q.ramp_iterations
            t_now = p.ramp_time * it / q.ramp_iterations if ramping else t_full
            self.ifunction(None, t_now, X, Xdot, F)
            f = -F.array_r.reshape(-1, 6)[:, 3:]
            if it % q.mass_update_interval == 0:
                masses = self._masses(X, Xdot, t_full, floor)
            fmax = comm.allreduce(float(np.max(np.abs(f), initial=0.0)), op=MPI.MAX)
            if not np.isfinite(fmax):
                r.reason = f"the residual became non-finite at iteration {it}"
                break
            if self._finish_due(it, fmax, ramping):
                r.static_finish_attempts += 1
                deadline = t0 + p.wall_time_limit_s
                finished, how, residual = self._newton_finish(X, Xdot, t_full, masses, deadline)
                log.info("Newton finish at iteration %d %s: %s", it,
                         "accepted" if finished else "refused", how)
                if finished:
                    # accepting the state moves the self-contact sides to it (they come from
                    # the last accepted state): the equilibrium must hold with them too, to
                    # the dynamics' equilibrium test
                    record(it, t_now, 0.0, residual)
                    resided = self.equilibrium_residual(t_full)
                    if resided < p.equilibrium_tolerance:
                        r.static_finished = r.converged = True
                        r.reason = (f"dynamic relaxation, Newton finish at iteration {it}: "
                                    f"{how} ({resided:.2e} mN with the contact sides of the "
                                    "finished state)")
                        break
                    log.info("the finished state has residual %.3g mN with its own contact "
                             "sides: the relaxation goes on from it", resided)
                    v[:] = 0.0
                    continue  # the forces of this iteration belong to the state before it
            quenched = fire.update(self._per_body(comm, body, np.sum(f * v, axis=1), fire.n))
            dt = fire.dt[body][:, None]
            x[:, :3] -= np.where(quenched[body][:, None], 0.5 * dt * v, 0.0)
            v[quenched[body]] = 0.0
            acceleration = f / masses[:, None]
            v += dt * acceleration
            # steer each body's velocity towards its force (FIRE mixing)
            v_norm = np.sqrt(self._per_body(comm, body, np.sum(v * v, axis=1), fire.n))
            a_norm = np.sqrt(self._per_body(comm, body, np.sum(acceleration**2, axis=1), fire.n))
            ratio = np.divide(v_norm, a_norm, out=np.zeros_like(v_norm), where=a_norm > 0.0)
            alpha = np.where(a_norm > 0.0, fire.alpha, 0.0)
            v = (1.0 - alpha[body][:, None]) * v + (alpha * ratio)[body][:, None] * acceleration
            motion = dt * v
            step = self._largest_node_motion(motion)
            if step > q.max_step_mm:
                scale = q.max_step_mm / step
                motion *= scale
                v *= scale
                step = q.max_step_mm
            x[:, :3] += motion
            pseudo_time += float(fire.dt.min())
            done = not ramping and fmax < q.residual_tolerance and step < p.stop_increment_mm
            out_of_time = time.perf_counter() - t0 > p.wall_time_limit_s
            if done or out_of_time or (it + 1) % q.history_interval == 0:
                record(it + 1, t_now, step, fmax)
            if done:
                r.converged = True
                r.reason = (f"dynamic relaxation: static residual {fmax:.2e} mN < "
                            f"{q.residual_tolerance:g} mN and largest motion {step:.1e} mm < "
                            f"{p.stop_increment_mm:g} mm at iteration {it + 1}")
                break
            if out_of_time:
                r.reason = (f"wall-clock limit {p.wall_time_limit_s:g} s reached at iteration "
                            f"{it + 1} (static residual {fmax:.3g} mN, last motion "
                            f"{step:.3g} mm)")
                break
        else:
            r.reason = (f"no equilibrium after max_iterations = {q.max_iterations} iterations "
                        f"(static residual {fmax:.3g} mN, last motion {step:.3g} mm)")
        self._set_state(t_full, X, Xdot)
        self._copy_displacement()
        r.equilibrium_residual = self.equilibrium_residual()
        r.wall_time_s = time.perf_counter() - t0
        log.info("dynamic relaxation: %s; %d iterations, |R_static|_inf = %.3g mN, %.1f s",
                 "converged" if r.converged else "NOT converged", r.steps,
                 r.equilibrium_residual, r.wall_time_s)
        return r
