"""The two paths to the loaded equilibrium: pseudo-transient continuation (the default,
:mod:`valve_dolfinx.solvers.pseudo_transient`) and damped BDF2 dynamics (the cross-check,
:mod:`valve_dolfinx.solvers.dynamics`).

Checks: PTC lands on the exact equilibrium of a sheet held at a homogeneous stretch
(serially and under ``mpirun -n 2``); its equilibrium does not depend on the numerical mass
or the first pseudo-time step; two runs are identical bit for bit; BDF2 reaches the same
equilibrium; bad parameters are refused by name.
"""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.geometry.verification import flat_sheet_domain
from valve_dolfinx.materials import NATIVE_LEAFLET, FungMaterial
from valve_dolfinx.mechanics.membrane import MembraneModel
from valve_dolfinx.solvers import pseudo_transient
from valve_dolfinx.solvers.dynamics import DampedDynamicsSolver
from valve_dolfinx.solvers.parameters import DynamicsParameters, PseudoTransientParameters
from valve_dolfinx.solvers.pseudo_transient import PseudoTransientSolver

LX, LY = 4.0, 3.0
ISO = FungMaterial.isotropic(c=9.7, a=20.0, b=0.0, thickness=0.5)


def clamp_all_edges(model, value: dolfinx.fem.Function | None = None):
    mesh = model.domain.mesh
    edges = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda X: np.full(X.shape[1], True))
    g = value if value is not None else dolfinx.fem.Function(model.V)
    return dolfinx.fem.dirichletbc(g, dolfinx.fem.locate_dofs_topological(model.V, 1, edges))


def max_over_ranks(comm, values: np.ndarray) -> float:
    return comm.allreduce(float(np.max(np.abs(values), initial=0.0)), op=MPI.MAX)


def stretched_sheet(comm=MPI.COMM_SELF, **params):
    """Flat native-leaflet sheet (fibres at 30°) whose boundary is held at a homogeneous
    stretch, no pressure: the exact equilibrium is that stretch everywhere (patch test).  The
    interior starts 0.05 mm away from it, in and out of plane.  (Without pressure the mass
    p·A/L is nil and the pseudo-time steps are Newton's; the taut sheet needs no more.)"""
    domain = flat_sheet_domain(LX, LY, 8, 6, fibre_angle_deg=30.0, comm=comm)
    model = MembraneModel(domain, {1: NATIVE_LEAFLET})
    stretch = np.diag([0.12, 0.2, 0.0])
    exact = dolfinx.fem.Function(model.V)
    exact.interpolate(lambda X: stretch @ X)
    bc = clamp_all_edges(model, exact)
    model.u.interpolate(lambda X: stretch @ X + 0.05 * np.sin(np.pi * X[0] / LX)
                        * np.sin(np.pi * X[1] / LY) * np.array([[1.0], [-0.5], [2.0]]))
    solver = PseudoTransientSolver(model, [bc], 0.0, PseudoTransientParameters(**params))
    report = solver.solve()
    return report, max_over_ranks(comm, model.u.x.array - exact.x.array)


def slack_sheet():
    """A 4 mm square clamped on its edges whose stress-free reference is 10 % larger (slack
    everywhere, a singular tangent at the start), inflated by 2 kPa into a taut dome."""
    domain = flat_sheet_domain(4.0, 4.0, 8, 8, comm=MPI.COMM_SELF)
    domain.reference.x.array[:] *= 0.9
    model = MembraneModel(domain, {1: ISO})
    return model, clamp_all_edges(model)


def ptc_slack_sheet(**params) -> tuple[np.ndarray, object]:
    model, bc = slack_sheet()
    params.setdefault("residual_tolerance", 1e-9)
    report = PseudoTransientSolver(model, [bc], 2.0, PseudoTransientParameters(**params)).solve()
    assert report.converged, report.reason
    return model.u.x.array.copy(), report


@pytest.fixture(scope="module")
def slack_equilibrium():
    return ptc_slack_sheet()


def test_ptc_lands_on_the_exact_equilibrium_of_a_stretched_sheet():
    """The residual tolerance 1e-9 mN against nodal stiffnesses of ~1e2 mN/mm bounds the
    error by ~1e-11 mm; Newton's last iterations are quadratic, so it is round-off."""
    report, error = stretched_sheet(residual_tolerance=1e-9)
    assert report.converged, report.reason
    assert report.residual_mN < 1e-9
    assert error < 1e-10
    assert report.history and {"residual_mN", "dt", "max_motion_mm"} <= set(report.history[-1])


@pytest.mark.mpi
def test_ptc_lands_on_the_exact_equilibrium_in_parallel():
    """Distributed over the ranks (owned rows, ghosted nodes, MUMPS): the same exact state."""
    report, error = stretched_sheet(MPI.COMM_WORLD, residual_tolerance=1e-9)
    assert report.converged, report.reason
    assert error < 1e-10


@pytest.mark.parametrize("mass_length_mm, dt_initial", [(4.0, None), (0.25, None),
                                                        (None, 1.0)])
def test_ptc_equilibrium_does_not_depend_on_mass_or_first_step(slack_equilibrium, monkeypatch,
                                                               mass_length_mm, dt_initial):
    """Mass × 1/4 and × 4 (mass_length_mm × 4 and / 4), a first step 20 × longer: other
    paths (5-21 pseudo-time steps), the same equilibrium to 1e-10 mm (measured 1e-11 mm)."""
    reference, base = slack_equilibrium
    if dt_initial is not None:
        monkeypatch.setattr(pseudo_transient, "DT_INITIAL", dt_initial)
    change = {} if mass_length_mm is None else {"mass_length_mm": mass_length_mm}
    other, report = ptc_slack_sheet(**change)
    assert report.steps != base.steps          # the path did change
    assert np.max(np.abs(other - reference)) < 1e-10


def test_two_ptc_runs_are_identical_bit_for_bit(slack_equilibrium):
    reference, base = slack_equilibrium
    again, report = ptc_slack_sheet()
    assert np.array_equal(again, reference)
    assert [e["residual_mN"] for e in report.history] == [e["residual_mN"] for e in base.history]


def test_bdf2_reaches_the_ptc_equilibrium(slack_equilibrium):
    """Damped BDF2 dynamics from the same slack start, pressure ramped over 1 s, stopped by its
    own test (watched increment < 1e-5 mm and static residual < 0.05 mN): the PTC state to
    1e-4 mm (measured 3.7e-6 mm, residual 5e-5 mN)."""
    reference, _ = slack_equilibrium
    model, bc = slack_sheet()
    centre = int(np.argmin(np.linalg.norm(model.domain.mesh.geometry.x - [2.0, 2.0, 0.0],
                                          axis=1)))
    solver = DampedDynamicsSolver(model, [bc], dolfinx.fem.Function(model.V), 2.0,
                                  {1: ISO.stiffness_scale}, [centre])
    report = solver.solve()
    assert report.converged, report.reason
    assert report.residual_mN < 0.05
    assert np.max(np.abs(model.u.x.array - reference)) < 1e-4


@pytest.mark.parametrize("path", ["ptc", "bdf2"])
def test_interrupt_stops_the_solve_instead_of_failing_it(path):
    """A Ctrl-C inside a solve (here raised by the progress callback, which PETSc calls from
    the post-step) comes out of ``solve`` as KeyboardInterrupt: PETSc turns an exception in
    a callback into an error, and without the guard the solve would report an unconverged
    case and a study would go on to the next one."""
    model, bc = slack_sheet()
    if path == "ptc":
        solver = PseudoTransientSolver(model, [bc], 2.0, PseudoTransientParameters())
    else:
        solver = DampedDynamicsSolver(model, [bc], dolfinx.fem.Function(model.V), 2.0,
                                      {1: ISO.stiffness_scale}, [0])
    calls = []

    def interrupt(entry):
        calls.append(entry)
        if len(calls) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        solver.solve(progress=interrupt)
    assert len(calls) == 2


@pytest.mark.parametrize("bad", [
    {"residual_tolerance": 0.0}, {"mass_length_mm": -1.0}, {"mass_length_mm": float("nan")},
    {"coarse_mesh_mm": 3.0}, {"max_steps": 0}, {"wall_time_limit_s": -1.0}])
def test_ptc_parameters_name_the_bad_one(bad):
    (name, _), = bad.items()
    with pytest.raises(ParameterError, match=name):
        PseudoTransientParameters(**bad)


def test_dynamics_parameters_name_the_bad_one():
    with pytest.raises(ParameterError, match="relaxation_time"):
        DynamicsParameters(relaxation_time=0.0)
    with pytest.raises(ParameterError, match="stop_increment_mm"):
        DynamicsParameters(stop_increment_mm=-1e-5)
