"""Contact inside the finite element solve: two pressed membranes, and MPI consistency."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.contact import ContactParameters, SurfaceContact
from valve_dolfinx.geometry.verification import membrane_domain_from_arrays
from valve_dolfinx.materials import FungMaterial
from valve_dolfinx.membrane import MembraneModel
from valve_dolfinx.solvers.contact_hook import ContactHook
from valve_dolfinx.solvers.nodal import NodalCoupling, pressure_nodal_forces
from valve_dolfinx.solvers.quasistatic import ContinuationParameters, QuasiStaticSolver

#: Soft isotropic Fung membrane: the sheets balloon into each other at 2 kPa.
SOFT = FungMaterial.isotropic(c=20.0, a=5.0, thickness=0.2, name="soft")
SIDE, CELLS, GAP = 6.0, 12, 1.0


def two_sheets(comm):
    """Two clamped squares 1 mm apart, normals facing each other (tags 1 and 2)."""
    if comm.rank != 0:
        return membrane_domain_from_arrays(comm, None, None, None, None, None), None
    def grid(n, z):
        u = np.linspace(0.0, SIDE, n + 1)
        X, Y = np.meshgrid(u, u, indexing="ij")
        idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
        a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
        c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
        cells = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])  # normal +z
        return np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], axis=1), cells

    # different resolutions, so that no node meets another node head-on
    low_points, lower = grid(CELLS, 0.0)
    up_points, upper = grid(CELLS + 1, GAP)
    upper = upper[:, ::-1] + len(low_points)                                      # normal -z
    points = np.concatenate([low_points, up_points])
    cells = np.concatenate([lower, upper])
    tags = np.repeat([1, 2], [len(lower), len(upper)]).astype(np.int32)
    # reference charts: the flat (x, ±y) coordinates, an isometric copy of each sheet whose
    # chart normal F1 × F2 is the cell's normal (the pressure side)
    frames = np.concatenate([
        np.tile(np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]), (len(lower), 1, 1)),
        np.tile(np.array([[1.0, 0.0], [0.0, -1.0], [0.0, 0.0]]), (len(upper), 1, 1))])
    fibres = np.tile([1.0, 0.0], (len(cells), 1))
    domain = membrane_domain_from_arrays(comm, points, cells, tags, frames, fibres)
    return domain, (points, cells, tags)


def clamp_boundary(model):
    V = model.V
    x = V.tabulate_dof_coordinates()
    on_edge = np.isclose(x[:, 0], 0) | np.isclose(x[:, 0], SIDE) \
        | np.isclose(x[:, 1], 0) | np.isclose(x[:, 1], SIDE)
    dofs = np.flatnonzero(on_edge).astype(np.int32)
    return dolfinx.fem.dirichletbc(dolfinx.fem.Function(V), dofs)


@pytest.fixture(scope="module")
def pressed_sheets():
    comm = MPI.COMM_SELF
    domain, (points, cells, tags) = two_sheets(comm)
    model = MembraneModel(domain, {1: SOFT, 2: SOFT}, pressure_side=1.0)
    coupling = NodalCoupling(model.V)
    params = ContactParameters()                       # the SPEC law: k = 10 mN/mm, h = 0.1 mm
    contact = SurfaceContact(cells, len(points), params, triangle_body=tags)
    hook = ContactHook(coupling, [contact], cells, model.pressure, 1.0)
    solver = QuasiStaticSolver(model, [clamp_boundary(model)], 2.0, hooks=[hook],
                               continuation=ContinuationParameters(viscosity=1e-3))
    report = solver.solve()
    x = coupling.positions(model.u)
    return report, hook, x, cells, tags, coupling, model


def test_pressed_membranes_converge_without_penetration(pressed_sheets):
    report, hook, x, cells, tags, *_ = pressed_sheets
    # nodal pressure forces are p·h² ≈ 0.5 mN; the residual left by the lagged driving
    # force (updated once per load step) is far below that
    assert report.converged and report.residual_norm < 1e-3
    diag = hook.diagnostics()
    assert diag["contacts"] > 20                          # a real contact patch formed
    assert diag["max_penetration_mm"] < 0.01
    lower = np.unique(cells[tags == 1])
    upper = np.unique(cells[tags == 2])
    # the sheets never cross: every upper node stays above the lower sheet's nodes near it
    centre = np.argmin(np.linalg.norm(x[lower, :2] - SIDE / 2, axis=1))
    above = np.argmin(np.linalg.norm(x[upper, :2] - x[lower[centre], :2], axis=1))
    assert x[upper[above], 2] > x[lower[centre], 2]
    # both ballooned well past the mid-plane they meet at
    assert x[lower[centre], 2] > 0.4 and x[upper[above], 2] < 0.6


def test_contact_reactions_balance_the_pressure_on_the_flat_patch(pressed_sheets):
    """Inside a flat contact patch the membrane carries no normal load: contact = pressure."""
    report, hook, x, cells, tags, coupling, model = pressed_sheets
    forces = hook.contact_forces(model.u)
    assert np.allclose(forces.sum(axis=0), 0.0, atol=1e-9)          # action = reaction
    pressure = pressure_nodal_forces(x, cells, 2.0, 1.0)
    lower_cells = cells[tags == 1]
    lower = np.unique(lower_cells)
    # the patch interior: lower-sheet nodes in contact whose triangles are all in contact,
    # peeled twice (at the patch rim the membrane's kink adds a line load; one ring of
    # triangles spreads the reactions of the other sheet's nodes)
    inner = np.zeros(len(x), dtype=bool)
    inner[lower[-forces[lower, 2] > 0.0]] = True
    for _ in range(2):
        inner[np.unique(lower_cells[~inner[lower_cells].all(axis=1)])] = False
    patch = np.flatnonzero(inner)
    assert len(patch) >= 20
    assert -forces[patch, 2].sum() == pytest.approx(pressure[patch, 2].sum(), rel=0.01)


@pytest.mark.mpi
def test_contact_forces_in_parallel_match_serial():
    """The hook on a distributed mesh gives the serial forces (to round-off)."""
    comm = MPI.COMM_WORLD
    domain, arrays = two_sheets(comm)
    points, cells, tags = comm.bcast(arrays)
    model = MembraneModel(domain, {1: SOFT, 2: SOFT}, pressure_side=1.0)

    def bulge(X):  # the sheets dome towards each other until they overlap by 0.05 mm
        shape = np.sin(np.pi * X[0] / SIDE) * np.sin(np.pi * X[1] / SIDE)
        dz = np.where(X[2] < 0.5 * GAP, 0.525, -0.525) * shape
        return np.stack([0.0 * X[0], 0.02 * shape, dz])

    model.u.interpolate(bulge)
    model.pressure.value = 2.0
    coupling = NodalCoupling(model.V)
    params = ContactParameters(penetration_depth=0.2)
    contact = SurfaceContact(cells, len(points), params, triangle_body=tags)
    hook = ContactHook(coupling, [contact], cells, model.pressure, 1.0)
    parallel = hook.contact_forces(model.u)
    x = coupling.positions(model.u)
    serial = SurfaceContact(cells, len(points), params, triangle_body=tags).evaluate(
        x, pressure_nodal_forces(x, cells, 2.0, 1.0)).forces
    assert np.abs(serial).max() > 1.0
    np.testing.assert_allclose(parallel, serial, rtol=0, atol=1e-10 * np.abs(serial).max())
