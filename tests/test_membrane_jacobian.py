"""Taylor test of the assembled membrane Jacobian, follower pressure included (SPEC §4).

For a residual R with Jacobian J, a state u and a direction δu,

    r0(ε) = ‖R(u + ε δu) − R(u)‖            = O(ε),
    r1(ε) = ‖R(u + ε δu) − R(u) − ε J(u) δu‖ = O(ε²)

if (and only if, generically) J is the derivative of R.  Halving ε must divide r1 by 4:
an observed order of 2.  The follower pressure makes J non-symmetric; leaving its
linearisation out (the negative control below) drops the order of r1 to 1, which shows the
test can fail.  The states are chosen inside one branch of the tension-field relaxation
(all cells taut, or all wrinkled), where the energy is smooth, and the increments ε·δu are
far too small to switch a cell between branches.
"""

from __future__ import annotations

import numpy as np
import ufl

from valve_dolfinx._compat import MPI, PETSc, dolfinx
from valve_dolfinx.geometry.verification import flat_sheet_domain, sphere_domain
from valve_dolfinx.materials import NATIVE_LEAFLET
from valve_dolfinx.mechanics.membrane import MembraneModel

EPS = 1e-3 * 0.5 ** np.arange(6)


def _assemble_residual(form) -> np.ndarray:
    b = dolfinx.fem.petsc.assemble_vector(form)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    out = b.array.copy()
    b.destroy()
    return out


def taylor_remainders(model: MembraneModel, jacobian, du: np.ndarray) -> np.ndarray:
    """(r0, r1) for each ε in EPS, at the model's current state, along ``du``."""
    F = dolfinx.fem.form(model.residual())
    A = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(jacobian))
    A.assemble()
    d, Jd = A.createVecs()
    d.array[:] = du
    A.mult(d, Jd)
    u0 = model.u.x.array.copy()
    R0 = _assemble_residual(F)
    out = []
    for eps in EPS:
        model.u.x.array[:] = u0 + eps * du
        dR = _assemble_residual(F) - R0
        out.append((np.linalg.norm(dR), np.linalg.norm(dR - eps * Jd.array)))
    model.u.x.array[:] = u0
    for obj in (A, d, Jd):
        obj.destroy()
    return np.array(out)


def orders(r: np.ndarray) -> np.ndarray:
    return np.log2(r[:-1] / r[1:])


def _principal_stresses(model):
    return np.linalg.eigvalsh(model.cell_fields()["stress"].x.array.reshape(-1, 2, 2))


def _without_pressure_linearisation(model):
    """The Jacobian of the internal forces only (a wrong tangent: the negative control)."""
    v = ufl.TestFunction(model.V)
    return ufl.derivative(model.internal_work(v), model.u, ufl.TrialFunction(model.V))


def test_jacobian_taylor_inflated_sphere():
    """Anisotropic native leaflet on a curved mesh, inflated by 8 % and perturbed, at 80 mmHg."""
    rng = np.random.default_rng(3)
    domain = sphere_domain(10.0, 2.5, comm=MPI.COMM_SELF)
    model = MembraneModel(domain, {1: NATIVE_LEAFLET})
    model.pressure.value = 10.666
    x = domain.mesh.geometry.x
    model.u.x.array[:] = (0.08 * x + 0.01 * rng.uniform(-1, 1, x.shape)).ravel()
    assert _principal_stresses(model).min() > 1.0  # taut everywhere (kPa)
    du = rng.uniform(-1, 1, x.shape).ravel()

    r = taylor_remainders(model, model.jacobian(), du)
    assert np.all(np.abs(orders(r[:, 0]) - 1) < 0.05)
    assert np.all(np.abs(orders(r[:, 1]) - 2) < 0.05)
    assert r[-1, 1] < 1e-3 * r[-1, 0]

    wrong = taylor_remainders(model, _without_pressure_linearisation(model), du)
    assert orders(wrong[:, 1])[-1] < 1.2  # first order only: the test sees a wrong tangent


def test_jacobian_taylor_wrinkled_sheet():
    """A sheet stretched 15 % along x, compressed 15 % along y (fibres at 60°) and bulged:
    every cell wrinkled, under 2 kPa of follower pressure."""
    rng = np.random.default_rng(5)
    domain = flat_sheet_domain(4.0, 3.0, 6, 4, fibre_angle_deg=60.0, comm=MPI.COMM_SELF)
    model = MembraneModel(domain, {1: NATIVE_LEAFLET})
    model.pressure.value = 2.0
    x = domain.mesh.geometry.x
    u = np.stack([0.15 * x[:, 0], -0.15 * x[:, 1],
                  0.1 * np.sin(np.pi * x[:, 0] / 4) * np.sin(np.pi * x[:, 1] / 3)], axis=1)
    model.u.x.array[:] = (u + 0.01 * rng.uniform(-1, 1, x.shape)).ravel()
    # wrinkled branch in every cell: principal strains of opposite signs, and no stress
    # along the compressed principal strain direction n2
    fields = model.cell_fields()
    strain = fields["strain"].x.array.reshape(-1, 2, 2)
    stress = fields["stress"].x.array.reshape(-1, 2, 2)
    lam, vec = np.linalg.eigh(strain)
    assert np.all(lam[:, 0] < -0.1) and np.all(lam[:, 1] > 0.1)
    n2 = vec[:, :, 0]
    assert np.max(np.abs(np.einsum("ci,cij,cj->c", n2, stress, n2))) < 1e-9 * np.abs(stress).max()
    du = rng.uniform(-1, 1, x.shape).ravel()

    r = taylor_remainders(model, model.jacobian(), du)
    assert np.all(np.abs(orders(r[:, 0]) - 1) < 0.05)
    assert np.all(np.abs(orders(r[:, 1]) - 2) < 0.05)

