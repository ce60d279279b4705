"""The strain-rate (Kelvin–Voigt) damping of the damped dynamics: it vanishes at rest and for
rigid motions, and its power for a uniform stretching rate is η·Ė:Ė·area (closed form)."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.geometry.verification import flat_sheet_domain
from valve_dolfinx.materials import NATIVE_LEAFLET
from valve_dolfinx.membrane import MembraneModel
from valve_dolfinx.solvers.dynamics import DampedDynamicsSolver, DynamicsParameters

LX, LY = 4.0, 3.0


def residual_with_velocity(tau_v: float, velocity) -> tuple[np.ndarray, np.ndarray]:
    """Momentum rows of the residual at u = 0, rates 0, velocity v(x); and the nodal v."""
    domain = flat_sheet_domain(LX, LY, 4, 3, comm=MPI.COMM_SELF)
    model = MembraneModel(domain, {1: NATIVE_LEAFLET})
    u0 = dolfinx.fem.Function(model.V)
    k = NATIVE_LEAFLET.stiffness_scale
    solver = DampedDynamicsSolver(model, [], u0, 0.0, {1: k}, [0],
                                  DynamicsParameters(strain_rate_damping_time=tau_v))
    x = domain.mesh.geometry.x
    state = solver.U.x.array.reshape(-1, 6)
    v = np.array([velocity(p) for p in x])
    state[:, 3:] = v  # P1: geometry node i is dof block i on a serial mesh
    X = solver.U.x.petsc_vec.copy()
    Xdot = X.duplicate()
    Xdot.set(0.0)
    F = X.duplicate()
    solver.ifunction(None, 0.0, X, Xdot, F)
    return F.array.reshape(-1, 6)[:, 3:].copy(), v


def test_viscosity_vanishes_at_rest_and_for_rigid_motion():
    rest, _ = residual_with_velocity(0.5, lambda p: np.zeros(3))
    assert np.max(np.abs(rest)) < 1e-12
    omega, c = np.array([0.3, -0.2, 0.5]), np.array([1.0, 2.0, -0.5])
    rigid = lambda p: c + np.cross(omega, p)  # noqa: E731
    with_visc, _ = residual_with_velocity(0.5, rigid)
    without, _ = residual_with_velocity(0.0, rigid)
    np.testing.assert_allclose(with_visc, without, atol=1e-10)


@pytest.mark.parametrize("tau_v", [0.1, 0.5])
def test_viscous_power_of_a_uniform_stretching_rate(tau_v):
    stretch = lambda p: np.array([p[0], 0.0, 0.0])  # noqa: E731  Ė11 = 1 s⁻¹
    with_visc, v = residual_with_velocity(tau_v, stretch)
    without, _ = residual_with_velocity(0.0, stretch)
    power = float(np.sum((with_visc - without) * v))
    eta = tau_v * NATIVE_LEAFLET.stiffness_scale
    assert power == pytest.approx(eta * 1.0 * LX * LY, rel=1e-10)


def test_newton_stops_on_a_tiny_update_whatever_the_residual():
    """Where the residual is discontinuous (a node in a crease of a folded sheet switching
    triangles) Newton cycles between two states ~1e-5 mm apart; an update that moves no node
    by more than ``newton_step_tolerance_mm`` ends the iteration as converged."""
    from valve_dolfinx._compat import PETSc

    domain = flat_sheet_domain(LX, LY, 4, 3, comm=MPI.COMM_SELF)
    model = MembraneModel(domain, {1: NATIVE_LEAFLET})
    solver = DampedDynamicsSolver(model, [], dolfinx.fem.Function(model.V), 0.0,
                                  {1: NATIVE_LEAFLET.stiffness_scale}, [0],
                                  DynamicsParameters(newton_step_tolerance_mm=1e-4))
    reason = PETSc.SNES.ConvergedReason
    snes = PETSc.SNES().create(MPI.COMM_SELF)
    snes.setTolerances(rtol=1e-6, atol=1e-4, max_it=20)
    X = solver.U.x.petsc_vec.copy()
    snes.setSolution(X)
    assert solver._newton_converged(snes, 0, (0.0, 0.0, 1000.0)) == reason.ITERATING
    X.array[6 * 2 + 1] += 5e-5            # one node's displacement: 5e-5 mm < 1e-4 mm
    X.array[6 * 3 + 4] += 1.0             # a velocity does not count
    assert solver._newton_converged(snes, 1, (0.0, 0.0, 0.5)) == reason.CONVERGED_SNORM_RELATIVE
    X.array[6 * 2 + 1] += 2e-4            # 2e-4 mm: keep iterating
    assert solver._newton_converged(snes, 2, (0.0, 0.0, 0.5)) == reason.ITERATING
    assert solver._newton_converged(snes, 3, (0.0, 0.0, 5e-4)) == reason.CONVERGED_FNORM_RELATIVE
    assert solver._newton_converged(snes, 4, (0.0, 0.0, 5e-5)) == reason.CONVERGED_FNORM_ABS
    X.array[6 * 2 + 1] += 1.0
    assert solver._newton_converged(snes, 20, (0.0, 0.0, 0.5)) == reason.DIVERGED_MAX_IT


def test_newton_step_tolerance_must_stay_below_the_truncation_error_target():
    from valve_dolfinx.exceptions import ParameterError

    with pytest.raises(ParameterError, match="newton_step_tolerance_mm"):
        DynamicsParameters(newton_step_tolerance_mm=0.005, error_tolerance_mm=0.01)


def _stretched_sheet(params: DynamicsParameters, solver_class=DampedDynamicsSolver,
                     comm=MPI.COMM_SELF, **options):
    """Flat sheet whose boundary is held at a homogeneous stretch (no pressure): the exact
    equilibrium is that stretch everywhere (patch test); the interior starts away from it
    (the solver holds the fixed dofs at their starting values, so the bump vanishes there)."""
    domain = flat_sheet_domain(LX, LY, 8, 6, fibre_angle_deg=30.0, comm=comm)
    model = MembraneModel(domain, {1: NATIVE_LEAFLET})
    stretch = np.diag([0.12, 0.2, 0.0])

    def homogeneous(X):
        return stretch @ X

    exact = dolfinx.fem.Function(model.V)
    exact.interpolate(homogeneous)
    boundary = dolfinx.mesh.locate_entities_boundary(domain.mesh, 1,
                                                     lambda X: np.full(X.shape[1], True))
    bc = dolfinx.fem.dirichletbc(exact, dolfinx.fem.locate_dofs_topological(model.V, 1, boundary))
    start = dolfinx.fem.Function(model.V)
    start.interpolate(lambda X: homogeneous(X) + 0.05 * np.sin(np.pi * X[0] / LX)
                      * np.sin(np.pi * X[1] / LY) * np.array([[1.0], [-0.5], [2.0]]))
    centre = int(np.argmin(np.linalg.norm(domain.mesh.geometry.x - [LX / 2, LY / 2, 0], axis=1)))
    solver = solver_class(model, [bc], start, 0.0, {1: NATIVE_LEAFLET.stiffness_scale},
                          [centre], params, **options)
    report = solver.solve()
    error = comm.allreduce(float(np.max(np.abs(model.u.x.array - exact.x.array))), op=MPI.MAX)
    return report, error


def test_static_finish_lands_on_the_exact_equilibrium():
    """Once the motion is slow, Newton on the static equilibrium ends the run at the exact
    (homogeneous) state; the plain dynamics reach the same state, in more steps."""
    base = dict(ramp_time=0.01, dt_initial=1e-3)
    finished, error = _stretched_sheet(DynamicsParameters(static_finish_increment_mm=1e-3,
                                                          **base))
    assert finished.converged and finished.static_finished, finished.reason
    assert "static" in finished.reason
    # static residual < 0.1 × equilibrium_tolerance = 5e-3 mN against a membrane stiffness of
    # ~1e2 mN/mm per node: a few 1e-5 mm at most
    assert error < 1e-5
    plain, plain_error = _stretched_sheet(DynamicsParameters(static_finish_increment_mm=0.0,
                                                            **base))
    assert plain.converged and not plain.static_finished, plain.reason
    assert plain_error < 1e-3  # at rest to the increment criterion, not to round-off
    assert finished.steps < plain.steps


def test_static_finish_that_moves_too_far_is_rejected():
    """A finish may not move any node further than ``static_finish_max_motion_mm`` (it could
    have jumped through a contact surface): an attempt while the sheet still moves is refused
    and the dynamics go on (a state already at rest passes without moving anything)."""
    report, error = _stretched_sheet(DynamicsParameters(
        ramp_time=0.01, dt_initial=1e-3, static_finish_increment_mm=1.0,
        static_finish_interval=1, static_finish_max_motion_mm=1e-9))
    assert report.static_finish_attempts >= 2  # the first, right after the ramp, was refused
    assert report.history[0].get("static_finish") is None
    assert report.converged, report.reason
    assert error < 1e-3


def test_dynamic_relaxation_lands_on_the_exact_equilibrium():
    """Explicit relaxation (no Newton, no damping) reaches the same exact homogeneous state.
    The error is bounded by residual / (softest stiffness of the sheet, ~35 mN/mm): a few
    1e-4 mm at the default tolerance (5e-3 mN), a few 1e-6 mm at 1e-4 mN."""
    from valve_dolfinx.solvers.relaxation import DynamicRelaxationSolver, RelaxationParameters

    report, error = _stretched_sheet(DynamicsParameters(), DynamicRelaxationSolver)
    assert report.converged, report.reason
    assert "relaxation" in report.reason
    assert report.equilibrium_residual < 5e-3
    assert error < 5e-4
    tight, tight_error = _stretched_sheet(
        DynamicsParameters(), DynamicRelaxationSolver,
        relaxation=RelaxationParameters(residual_tolerance=1e-4))
    assert tight.converged, tight.reason
    assert tight_error < 1e-5
    assert report.history and {"residual_mN", "increment_mm"} <= set(report.history[-1])
    # with the load ramped over 2000 iterations it may only stop after the ramp
    ramped, ramped_error = _stretched_sheet(
        DynamicsParameters(), DynamicRelaxationSolver,
        relaxation=RelaxationParameters(ramp_iterations=2000))
    assert ramped.converged and ramped.steps > 2000, ramped.reason
    assert ramped_error < 5e-4


def test_relaxation_newton_finish_lands_on_the_exact_equilibrium():
    """From a state the relaxation has brought near the equilibrium, the Newton
    (pseudo-transient continuation) finish ends the run on the exact homogeneous state, in
    fewer iterations than the relaxation alone; a finish that would move a node further than
    ``finish_max_motion_mm`` is refused and the relaxation goes on to the same state."""
    from valve_dolfinx.solvers.relaxation import DynamicRelaxationSolver, RelaxationParameters

    early = dict(finish_start=20, finish_interval=20, finish_residual_mN=1e3)
    plain, _ = _stretched_sheet(DynamicsParameters(), DynamicRelaxationSolver,
                                relaxation=RelaxationParameters(finish_start=0))
    assert plain.converged and plain.static_finish_attempts == 0, plain.reason
    finished, error = _stretched_sheet(DynamicsParameters(), DynamicRelaxationSolver,
                                       relaxation=RelaxationParameters(**early))
    assert finished.converged and finished.static_finished, finished.reason
    assert "Newton finish" in finished.reason
    assert finished.steps < plain.steps
    # residual < 5e-3 mN against the sheet's softest stiffness (~35 mN/mm): < 1.5e-4 mm, and
    # Newton's last step converges quadratically
    assert finished.equilibrium_residual < 5e-3
    assert error < 1e-5
    refused, refused_error = _stretched_sheet(
        DynamicsParameters(), DynamicRelaxationSolver,
        relaxation=RelaxationParameters(**early, finish_max_motion_mm=1e-9))
    assert refused.static_finish_attempts >= 1 and not refused.static_finished
    assert refused.converged and "Newton" not in refused.reason, refused.reason
    assert refused_error < 5e-4


@pytest.mark.mpi
def test_relaxation_newton_finish_in_parallel():
    """The finish distributed over the ranks (mass shift on owned rows, MUMPS, collective
    tests) lands on the same exact equilibrium."""
    from valve_dolfinx.solvers.relaxation import DynamicRelaxationSolver, RelaxationParameters

    finished, error = _stretched_sheet(
        DynamicsParameters(), DynamicRelaxationSolver, comm=MPI.COMM_WORLD,
        relaxation=RelaxationParameters(finish_start=20, finish_interval=20,
                                        finish_residual_mN=1e3))
    assert finished.converged and finished.static_finished, finished.reason
    assert error < 1e-5


def test_dynamic_relaxation_out_of_iterations_says_where():
    from valve_dolfinx.solvers.relaxation import DynamicRelaxationSolver, RelaxationParameters

    report, error = _stretched_sheet(DynamicsParameters(), DynamicRelaxationSolver,
                                     relaxation=RelaxationParameters(max_iterations=5))
    assert not report.converged
    assert "max_iterations = 5" in report.reason and "residual" in report.reason
    assert report.equilibrium_residual > 0.05  # stopped far from the equilibrium
    assert error > 1e-3


def test_relaxation_parameters_name_the_bad_one():
    from valve_dolfinx.exceptions import ParameterError
    from valve_dolfinx.solvers.relaxation import RelaxationParameters

    with pytest.raises(ParameterError, match="max_step_mm"):
        RelaxationParameters(max_step_mm=-0.1)
    with pytest.raises(ParameterError, match="residual_tolerance"):
        RelaxationParameters(residual_tolerance=0.0)
    with pytest.raises(ParameterError, match="finish_step_mm"):
        RelaxationParameters(finish_step_mm=0.0)
    with pytest.raises(ParameterError, match="finish_start"):
        RelaxationParameters(finish_start=-1)
