"""Contact inside the finite element solve: two pressed membranes, a membrane folded onto
itself, Newton's convergence rate with contact active, and MPI consistency.

The solves take the closure's path: pseudo-transient continuation at the full pressure
(:class:`PseudoTransientSolver`) with the contact hook given as a factory of the solver's
:class:`NodalCoupling`, its driving force frozen at the last accepted step
(``lag_driving_force``) as in :mod:`valve_dolfinx.case`."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx._compat import MPI, PETSc, dolfinx
from valve_dolfinx.contact import ContactParameters, SurfaceContact
from valve_dolfinx.exceptions import DegenerateGeometryError
from valve_dolfinx.geometry.verification import membrane_domain_from_arrays, tangent_frames
from valve_dolfinx.materials import FungMaterial
from valve_dolfinx.mechanics.membrane import MembraneModel
from valve_dolfinx.solvers.contact_hook import ContactHook
from valve_dolfinx.solvers.nodal import NodalCoupling, pressure_nodal_forces
from valve_dolfinx.solvers.parameters import PseudoTransientParameters
from valve_dolfinx.solvers.pseudo_transient import DT_INITIAL, PseudoTransientSolver

#: Soft isotropic Fung membrane: the sheets balloon into each other at 2 kPa.
SOFT = FungMaterial.isotropic(c=20.0, a=5.0, thickness=0.2, name="soft")
SIDE, CELLS, GAP = 6.0, 12, 1.0
#: The SPEC §5 law (k = 10 mN/mm, h = 0.1 mm) on zero-thickness sheets: no contact layer and
#: no barrier against crossing mid-surfaces (the valve's, ContactParameters' defaults, add
#: both), a 0.2 mm penetration window and a 0.01 mm blending width.
SPEC_LAW = ContactParameters(thickness=0.0, crossing_stiffness=0.0, penetration_depth=0.2,
                             blend_distance=0.01)


def contact_hook(models, triangles, pressure):
    """The hook factory the solver calls with its coupling (the closure's settings)."""
    return lambda coupling: ContactHook(coupling, models, triangles, pressure, 1.0,
                                        lag_driving_force=True)


def two_sheets(comm, n: int = CELLS):
    """Two clamped squares 1 mm apart, ``n`` and ``n + 1`` cells a side, normals facing each
    other (tags 1 and 2)."""
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
    low_points, lower = grid(n, 0.0)
    up_points, upper = grid(n + 1, GAP)
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


class NewtonRecordingSolver(PseudoTransientSolver):
    """Records, per Newton solve (one per pseudo-time step try), the residual norm and the
    number of active contacts at each iterate."""

    def solve(self, progress=None):
        self.newton_histories: list[dict] = []
        return super().solve(progress)

    def _make_ts(self):
        ts = super()._make_ts()
        ts.getSNES().setMonitor(self._record)
        return ts

    def _record(self, snes, iteration, norm):
        if iteration == 0:
            self.newton_histories.append({"norms": [], "contacts": []})
        self.newton_histories[-1]["norms"].append(norm)
        self.newton_histories[-1]["contacts"].append(self.hooks[0].diagnostics()["contacts"])


@pytest.fixture(scope="module")
def pressed_sheets():
    """Each pseudo-time step's Newton solve is run to round-off (snes_rtol 1e-12) so that
    its convergence rate can be read; the run ends at ‖R‖∞ < 1e-10 mN."""
    comm = MPI.COMM_SELF
    domain, (points, cells, tags) = two_sheets(comm)
    model = MembraneModel(domain, {1: SOFT, 2: SOFT}, pressure_side=1.0)
    contact = SurfaceContact(cells, len(points), SPEC_LAW, triangle_body=tags)
    solver = NewtonRecordingSolver(
        model, [clamp_boundary(model)], 2.0,
        PseudoTransientParameters(residual_tolerance=1e-10,
                                  petsc_options={"snes_rtol": 1e-12, "snes_max_it": 30}),
        hooks=[contact_hook([contact], cells, model.pressure)])
    report = solver.solve()
    x = solver.coupling.positions(model.u)
    return (report, solver.hooks[0], x, cells, tags, solver.coupling, model,
            solver.newton_histories)


def test_pressed_membranes_converge_without_penetration(pressed_sheets):
    report, hook, x, cells, tags, *_ = pressed_sheets
    # the static residual with the driving force of the final state, against nodal pressure
    # forces of p·h² ≈ 0.5 mN
    assert report.converged and report.residual_mN < 1e-10, report.reason
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
    report, hook, x, cells, tags, coupling, model, _ = pressed_sheets
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


def test_newton_converges_quadratically_with_contact_active(pressed_sheets):
    """The contact Jacobian is exact (turning normal, sliding point, blending; the driving
    force frozen within a pseudo-time step), so Newton's method converges quadratically on
    the curved, ballooned contact patch.  Without the geometric terms (turning normal,
    sliding point) Newton converges linearly here (order 1.0 in all 14 such solves, 325
    Newton iterations instead of 52), which this test rejects.  The order is read from the
    last three norms of each Newton solve with the patch formed throughout, above 1e-12 mN
    (round-off is ~4e-14 mN here)."""
    *_, histories = pressed_sheets
    orders = []
    for history in histories:
        norms = np.array(history["norms"])
        if min(history["contacts"]) < 20 or norms[-1] > 1e-10:
            continue                          # contact not active throughout, or a failed try
        above = norms[norms > 1e-12]
        if len(above) < 3:
            continue
        e0, e1, e2 = above[-3:]
        orders.append(np.log(e2 / e1) / np.log(e1 / e0))
    assert len(orders) >= 4
    assert min(orders) > 1.5 and np.median(orders) > 1.8


#: an interior node of the lower sheet and its neighbour along x: the two triangles that
#: share their edge collapse when the node is moved onto the neighbour
NODE, NEIGHBOUR = 6 * (CELLS + 1) + 6, 7 * (CELLS + 1) + 6


def sheets_solver(comm, solver_class=PseudoTransientSolver, **params):
    """The two sheets' closure solver (default settings but ``params``), at rest."""
    domain, arrays = two_sheets(comm)
    points, cells, tags = comm.bcast(arrays)
    model = MembraneModel(domain, {1: SOFT, 2: SOFT}, pressure_side=1.0)
    contact = SurfaceContact(cells, len(points), SPEC_LAW, triangle_body=tags,
                             body_names={1: "the lower sheet"})
    return solver_class(model, [clamp_boundary(model)], 2.0,
                        PseudoTransientParameters(**params),
                        hooks=[contact_hook([contact], cells, model.pressure)])


def onto_neighbour(coupling, displacement: np.ndarray) -> np.ndarray:
    """``(3,)`` displacement of NODE that puts it where NEIGHBOUR is with the nodes'
    ``displacement`` ``(N, 3)``."""
    x0 = coupling.reference_positions
    return x0[NEIGHBOUR] + displacement[NEIGHBOUR] - x0[NODE]


@pytest.mark.mpi
def test_a_collapsed_triangle_fails_an_iterate_and_ends_a_run_from_an_accepted_state():
    """At a trial Newton iterate (``ifunction`` called by the time stepper) a collapsed
    contact triangle makes the residual NaN on every rank, which fails the Newton solve; at
    an accepted state (the static residual, the start of a run) it is the named error, and
    a run that starts there ends as failed, naming the triangles -- never a bug in a
    callback."""
    comm = MPI.COMM_WORLD
    solver = sheets_solver(comm)
    coupling, imap = solver.coupling, solver.model.V.dofmap.index_map
    target = onto_neighbour(coupling, coupling.displacements(solver.u))
    block = coupling.block_of_node[NODE] - imap.local_range[0]
    if 0 <= block < imap.size_local:  # the rank that owns NODE
        solver.u.x.array.reshape(-1, 3)[block] = target
    solver.u.x.scatter_forward()
    X = solver.u.x.petsc_vec.copy()
    Xdot, F = X.duplicate(), X.duplicate()
    Xdot.set(0.0)
    ts = PETSc.TS().create(comm)  # ifunction reads its step only
    ts.setTimeStep(0.05)
    solver.ifunction(ts, 0.0, X, Xdot, F)
    assert np.isnan(F.array_r).all()
    ts.destroy()
    with pytest.raises(DegenerateGeometryError, match=r"^2 collapsed .*triangle"):
        solver.static_residual()
    report = solver.solve()
    assert not report.converged and report.steps == 0
    assert report.reason.startswith("DegenerateGeometryError at step 0")
    assert f"(nodes {NODE}, {NEIGHBOUR}," in report.reason
    assert report.reason.endswith("of the lower sheet")


class CollapsingSolver(PseudoTransientSolver):
    """Its first Newton update moves NODE onto NEIGHBOUR; counts the NaN residuals (one
    process: the blocks are the vectors' indices)."""

    def solve(self, progress=None):
        self.collapse, self.nan_residuals = True, 0
        return super().solve(progress)

    def _limit_update(self, x, y):
        super()._limit_update(x, y)
        if self.collapse:  # the iterate x - y: NODE where NEIGHBOUR lands
            self.collapse = False
            iterate = (x.array_r - y.array_r).reshape(-1, 3)[self.coupling.block_of_node]
            target = onto_neighbour(self.coupling, iterate)
            rows = (3 * self.coupling.block_of_node[NODE] + np.arange(3)).astype(PETSc.IntType)
            y.setValues(rows, x.array_r[rows] - target)
            y.assemble()

    def ifunction(self, ts, t, X, Xdot, F):
        super().ifunction(ts, t, X, Xdot, F)
        self.nan_residuals += bool(np.isnan(F.array_r).any())


def test_a_newton_iterate_that_collapses_a_triangle_retries_its_step_shorter():
    """The first pseudo-time step's Newton solve meets a collapsed triangle at its first
    iterate: the solve fails and the step is retried with half the Δτ (DT_INITIAL), as
    after any failed solve, and the run goes on."""
    solver = sheets_solver(MPI.COMM_SELF, CollapsingSolver, max_steps=2)
    report = solver.solve()
    assert solver.nan_residuals == 1
    assert report.rejected_steps == 1 and report.steps == 2
    assert report.history[0]["dt"] == pytest.approx(0.5 * DT_INITIAL)


L_FOLD, W_FOLD, R_FOLD = 6.0, 6.0, 0.5


def hairpin_strip():
    """A 6 mm wide strip folded into a hairpin: two flat 6 mm halves 1 mm apart joined by a
    half-cylinder of radius 0.5 mm at x = 6.  Structured mesh over the strip's arc length s
    (13, 4 and 13 cells on the lower half, the fold and the upper half, so that the halves'
    nodes are staggered).  Returns points, triangles (normal into the gap on the flat halves,
    towards the fold's axis on the fold), part (0 lower, 1 fold, 2 upper) per triangle."""
    s = np.concatenate([np.linspace(0.0, L_FOLD, 13),
                        L_FOLD + np.linspace(0.0, np.pi * R_FOLD, 5)[1:],
                        L_FOLD + np.pi * R_FOLD + np.linspace(0.0, L_FOLD, 14)[1:]])
    y = np.linspace(0.0, W_FOLD, 13)
    S, Y = (a.ravel() for a in np.meshgrid(s, y, indexing="ij"))
    beyond = S - L_FOLD - np.pi * R_FOLD
    theta = np.clip((S - L_FOLD) / R_FOLD, 0.0, np.pi)
    x = np.where(S <= L_FOLD, S, np.where(beyond >= 0, L_FOLD - beyond,
                                          L_FOLD + R_FOLD * np.sin(theta)))
    z = np.where(S <= L_FOLD, 0.0, np.where(beyond >= 0, 2 * R_FOLD,
                                            R_FOLD * (1.0 - np.cos(theta))))
    idx = np.arange(len(S)).reshape(len(s), len(y))
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    cells = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    s_mid = S[cells].mean(axis=1)
    part = np.where(s_mid < L_FOLD, 0, np.where(s_mid < L_FOLD + np.pi * R_FOLD, 1, 2))
    return np.stack([x, Y, z], axis=1), cells, part


def height_of_surface_below(points, triangles, x):
    """z of the surface (triangles over x, y) under each point, by plain loops; nan off it."""
    out = np.full(len(points), np.nan)
    for i, p in enumerate(points):
        for t in triangles:
            (ax, ay, az), (bx, by, bz), (cx, cy, cz) = x[t]
            det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
            l1 = ((p[0] - ax) * (cy - ay) - (cx - ax) * (p[1] - ay)) / det
            l2 = ((bx - ax) * (p[1] - ay) - (p[0] - ax) * (by - ay)) / det
            if l1 >= 0.0 and l2 >= 0.0 and l1 + l2 <= 1.0:
                out[i] = az + l1 * (bz - az) + l2 * (cz - az)
                break
    return out


def test_membrane_folded_onto_itself_does_not_pass_through_itself():
    """Self-contact in the solve: one body (a single contact body, so only the topological
    neighbourhood is excluded), folded into a hairpin and pressed shut by 2 kPa.

    The fold's reference charts are flipped so that the pressure inflates the fold (keeping
    it taut) while it pushes the flat halves into each other.  Without contact the halves
    pass through each other by about 2.4 mm; with it, every node of each half stays on its
    own side of the other half, the halves touch (gap below h) and they carry a real load.
    """
    points, cells, part = hairpin_strip()
    frames, _ = tangent_frames(points, cells)
    frames[part == 1, :, 1] *= -1.0                     # fold: chart normal pointing outwards
    loaded = np.where((part == 1)[:, None], cells[:, ::-1], cells)  # pressure side = chart side
    domain = membrane_domain_from_arrays(MPI.COMM_SELF, points, cells,
                                         np.ones(len(cells), np.int32), frames,
                                         np.tile([1.0, 0.0], (len(cells), 1)))
    model = MembraneModel(domain, {1: SOFT}, pressure_side=1.0)
    dofs_x = model.V.tabulate_dof_coordinates()
    clamped = np.isclose(dofs_x[:, 0], 0.0) | np.isclose(dofs_x[:, 1], 0.0) \
        | np.isclose(dofs_x[:, 1], W_FOLD)
    bc = dolfinx.fem.dirichletbc(dolfinx.fem.Function(model.V),
                                 np.flatnonzero(clamped).astype(np.int32))
    contact = SurfaceContact(cells, len(points), SPEC_LAW)   # one body
    solver = PseudoTransientSolver(model, [bc], 2.0,
                                   PseudoTransientParameters(residual_tolerance=1e-6),
                                   hooks=[contact_hook([contact], loaded, model.pressure)])
    report = solver.solve()
    assert report.converged, report.reason
    x = solver.coupling.positions(model.u)
    diag = solver.hooks[0].diagnostics()
    assert diag["contacts"] > 50 and diag["max_penetration_mm"] < 0.01
    assert diag["contact_force_mN"] > 20.0            # of the ~140 mN pressure load on the halves
    lower, upper = np.unique(cells[part == 0]), np.unique(cells[part == 2])
    gap_up = x[upper, 2] - height_of_surface_below(x[upper], cells[part == 0], x)
    gap_down = height_of_surface_below(x[lower], cells[part == 2], x) - x[lower, 2]
    for gap in (gap_up, gap_down):
        over = np.isfinite(gap)
        assert over.sum() > 100
        assert np.all(gap[over] > 0.0)                 # on its own side: no crossing
        assert gap[over].min() < 0.1                   # and the halves do touch


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
    params = SPEC_LAW
    contact = SurfaceContact(cells, len(points), params, triangle_body=tags)
    hook = ContactHook(coupling, [contact], cells, model.pressure, 1.0)
    parallel = hook.contact_forces(model.u)
    x = coupling.positions(model.u)
    whole = SurfaceContact(cells, len(points), params, triangle_body=tags).evaluate(
        x, pressure_nodal_forces(x, cells, 2.0, 1.0))
    serial = whole.forces
    assert np.abs(serial).max() > 1.0
    np.testing.assert_allclose(parallel, serial, rtol=0, atol=1e-10 * np.abs(serial).max())
    # the diagnostics, reduced over the ranks, are the serial ones
    diag = hook.diagnostics()
    assert diag["contacts"] == whole.n_active > 20
    assert diag["contact_force_mN"] == pytest.approx(whole.total_force, rel=1e-10)
