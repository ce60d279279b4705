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
