"""The guard (valve_dolfinx.contact.guard): its barrier's derivatives, its collision-free
steps, its view of intersections, and, inside the finite element solve, a sheet that the
contact law does not hold but the guard does.

The derivatives are checked against central differences of the guard's own energy, the
step fractions against the closed-form time at which two parallel sheets meet, and the
solve against the independent intersection check (:mod:`valve_dolfinx.analysis.intersection`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_contact_fe import SIDE, SOFT, clamp_boundary, two_sheets

from valve_dolfinx._compat import MPI
from valve_dolfinx.analysis.intersection import find_intersections
from valve_dolfinx.contact import ContactParameters, SurfaceContact
from valve_dolfinx.contact.guard import SurfaceGuard
from valve_dolfinx.mechanics.membrane import MembraneModel
from valve_dolfinx.solvers.contact_hook import ContactHook
from valve_dolfinx.solvers.parameters import PseudoTransientParameters
from valve_dolfinx.solvers.pseudo_transient import PseudoTransientSolver

DHAT, KAPPA = 0.1, 1000.0


def sheet(n: int, side: float, z: float, shift=(0.0, 0.0), flip: bool = False):
    """A flat square of ``n × n`` cells at height ``z`` (points, triangles)."""
    u = np.linspace(0.0, side, n + 1)
    X, Y = np.meshgrid(u + shift[0], u + shift[1], indexing="ij")
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), \
        idx[:-1, 1:].ravel()
    cells = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], axis=1), \
        (cells[:, ::-1] if flip else cells)


def two_parallel_sheets(gap: float):
    """Two 2 mm squares ``gap`` apart, the upper one shifted so no node faces a node."""
    low, low_cells = sheet(4, 2.0, 0.0)
    up, up_cells = sheet(5, 1.6, gap, shift=(0.17, 0.23), flip=True)
    return np.concatenate([low, up]), np.concatenate([low_cells, up_cells + len(low)]), \
        np.arange(len(low), len(low) + len(up))


@pytest.fixture(scope="module")
def close_sheets():
    points, cells, upper = two_parallel_sheets(0.06)
    rng = np.random.default_rng(3)
    x = points + rng.uniform(-0.01, 0.01, points.shape)  # no symmetry to hide an error
    return SurfaceGuard(points, cells, distance=DHAT, stiffness=KAPPA), x, upper


def test_gradient_is_the_derivative_of_the_energy(close_sheets):
    guard, x, upper = close_sheets
    g = guard.gradient(x)
    assert g is not None and np.abs(g).max() > 0
    h = 1e-7
    for node in (upper[7], upper[20], 5):
        for i in range(3):
            xp, xm = x.copy(), x.copy()
            xp[node, i] += h
            xm[node, i] -= h
            fd = (guard.energy(xp) - guard.energy(xm)) / (2 * h)
            assert g[node, i] == pytest.approx(fd, rel=1e-4, abs=1e-6 * np.abs(g).max())


def test_hessian_blocks_are_the_derivative_of_the_gradient(close_sheets):
    guard, x, upper = close_sheets
    rows = np.zeros(len(x), dtype=bool)
    rows[upper[::2]] = True  # a rank's rows only
    r, c, blocks = guard.hessian_blocks(x, rows)
    assert len(r) and rows[r].all()
    H = {(int(a), int(b)): blk for a, b, blk in zip(r, c, blocks, strict=True)}
    h = 1e-7
    for node in (upper[8], upper[20]):
        for j in range(3):
            xp, xm = x.copy(), x.copy()
            xp[node, j] += h
            xm[node, j] -= h
            column = (guard.gradient(xp) - guard.gradient(xm)) / (2 * h)
            for row in np.flatnonzero(rows):
                expected = column[row]
                got = H.get((int(row), int(node)), np.zeros((3, 3)))[:, j]
                assert got == pytest.approx(expected, rel=1e-4,
                                            abs=1e-6 * np.abs(blocks).max())


def test_sheets_outside_the_reach_feel_nothing():
    points, cells, _ = two_parallel_sheets(1.5 * DHAT)
    guard = SurfaceGuard(points, cells, distance=DHAT, stiffness=KAPPA)
    assert guard.gradient(points) is None
    assert guard.energy(points) == 0.0
    assert guard.pairs(points).count == 0


def test_the_guard_pushes_the_sheets_apart_along_their_normal(close_sheets):
    guard, x, upper = close_sheets
    g = guard.gradient(x)
    lower = np.setdiff1d(np.arange(len(x)), upper)
    # the forces (−g) push the upper sheet up and the lower one down, and balance
    assert -g[upper, 2].sum() > 0 and -g[lower, 2].sum() < 0
    assert np.abs(g.sum(axis=0)).max() < 1e-9 * np.abs(g).max() * len(x)


@pytest.mark.parametrize("gap, travel", [(0.3, 0.5), (0.3, 0.2), (0.05, 1.0)])
def test_a_step_stops_before_the_sheets_meet(gap, travel):
    """The upper sheet moves down by ``travel``: it meets the lower one at the fraction
    gap/travel of the step, so the collision-free fraction is below it (the library
    rescales conservatively, to at least half of it) or 1 when they never meet."""
    points, cells, upper = two_parallel_sheets(gap)
    guard = SurfaceGuard(points, cells, distance=DHAT, stiffness=KAPPA)
    end = points.copy()
    end[upper, 2] -= travel
    fraction = guard.free_fraction(points, end)
    meet = gap / travel
    if meet >= 1.0:
        assert fraction == 1.0
    else:
        assert 0.5 * meet <= fraction < meet
        assert not guard.intersects(points + fraction * (end - points))


def test_intersections_as_the_independent_check_sees_them():
    points, cells, upper = two_parallel_sheets(0.3)
    guard = SurfaceGuard(points, cells, distance=DHAT, stiffness=KAPPA)
    tags = np.where(np.isin(cells[:, 0], upper), 2, 1)
    tilted = points.copy()
    tilted[upper, 2] += 0.8 * (tilted[upper, 0] - 1.0)  # the upper sheet tilted through
    for x in (points, tilted):
        assert guard.intersects(x) == (find_intersections(x, cells, tags).count > 0)
    assert guard.intersects(tilted)


# --- inside the solve --------------------------------------------------------------------
#: the contact law on its own terms (thickness 0, no crossing barrier), whose force answers
#: the pressure of the nodes it is given and nothing else
LAW = ContactParameters(thickness=0.0, crossing_stiffness=0.0, penetration_depth=0.2,
                        blend_distance=0.01)
#: 20 kPa on nodal areas of 0.25 mm² is 5 mN a node, 0.5 mm of penalty (10 mN/mm) behind a
#: triangle: past the law's 0.2 mm window, where a node counts as on the other side
PRESSURE = 20.0


def press_unanswered(guarded: bool):
    """Two ballooning sheets pressed together where the law's driving force counts only the
    lower sheet's pressure: the upper sheet's push is a force the law does not answer, as
    an elastic one would be."""
    comm = MPI.COMM_SELF
    domain, (points, cells, tags) = two_sheets(comm)
    model = MembraneModel(domain, {1: SOFT, 2: SOFT}, pressure_side=1.0)
    law = SurfaceContact(cells, len(points), LAW, triangle_body=tags)
    guard = SurfaceGuard(points, cells, distance=DHAT, stiffness=KAPPA) if guarded else None
    hook = lambda coupling: ContactHook(coupling, [law], cells[tags == 1], model.pressure,  # noqa: E731
                                        1.0, guard=guard)
    solver = PseudoTransientSolver(model, [clamp_boundary(model)], PRESSURE,
                                   PseudoTransientParameters(wall_time_limit_s=120.0),
                                   hooks=[hook])
    report = solver.solve()
    x = solver.coupling.positions(model.u)
    return report, find_intersections(x, cells, tags), solver.hooks[0].diagnostics()


def test_a_push_the_law_does_not_answer_goes_through_without_the_guard():
    report, crossings, _ = press_unanswered(guarded=False)
    assert report.converged and crossings.count > 0


def test_the_guard_holds_a_push_the_law_does_not_answer():
    report, crossings, diag = press_unanswered(guarded=True)
    assert report.converged, report.reason
    assert crossings.count == 0
    # the guard carries the upper sheet's pressure inside its reach, apart
    assert diag["guard_pairs"] > 0 and 0.0 < diag["guard_min_distance_mm"] < DHAT


def test_a_start_whose_leaflets_intersect_is_refused_for_the_unloaded_valve():
    """A barrier would hold a crossing it starts from: the closure starts unloaded and the
    result's start says why."""
    from valve_dolfinx.case import solve_case
    from valve_dolfinx.config import CaseConfig
    from valve_dolfinx.geometry.transfer import ValveState
    from valve_dolfinx.geometry.valve import build_valve

    config = CaseConfig()
    config = replace(config, geometry=replace(config.geometry, mesh_size=2.0))
    valve = build_valve(config.geometry)
    crossed = valve.points.copy()
    first = np.unique(valve.cells[valve.cell_tags == valve.leaflets[0].tag])
    free = np.setdiff1d(first, valve.attachment_nodes())
    crossed[free, :2] *= -1.0  # the first leaflet's free nodes swung through the axis
    tags = valve.cell_tags
    assert find_intersections(crossed, valve.cells, tags).count > 0
    state = solve_case(config, MPI.COMM_SELF, valve=valve,
                       start=ValveState(valve, crossed, "a crossed valve"))
    assert state.report.start["from"] == "the unloaded valve"
    assert "a crossed valve" in state.report.start["refused"]
    assert state.report.converged


def test_sheets_pressed_under_the_law_rest_outside_the_guards_reach():
    """The valve's contact (the law with its 0.25 mm thickness, and the guard) on two sheets
    pressed by 2 kPa: the law rests them about its thickness apart, beyond the guard's
    shorter reach, so at rest the guard has no pair and the law alone sets the gap."""
    import ipctk

    comm = MPI.COMM_SELF
    domain, (points, cells, tags) = two_sheets(comm, 16)
    model = MembraneModel(domain, {1: SOFT, 2: SOFT}, pressure_side=1.0)
    params = ContactParameters()
    law = SurfaceContact(cells, len(points), params, triangle_body=tags)
    guard = SurfaceGuard(points, cells, distance=params.guard_distance,
                         stiffness=params.guard_stiffness)
    hook = lambda coupling: ContactHook(coupling, [law], cells, model.pressure, 1.0,  # noqa: E731
                                        guard=guard)
    solver = PseudoTransientSolver(model, [clamp_boundary(model)], 2.0,
                                   PseudoTransientParameters(residual_tolerance=1e-6),
                                   hooks=[hook])
    report = solver.solve()
    assert report.converged, report.reason
    x = solver.coupling.positions(model.u)
    upper = np.unique(cells[tags == 2])
    centre = upper[np.argmin(np.linalg.norm(x[upper, :2] - SIDE / 2, axis=1))]
    gap = min(np.sqrt(ipctk.point_triangle_distance(x[centre], *x[t]))  # (squared)
              for t in cells[tags == 1])
    assert params.thickness <= gap < 1.1 * params.thickness
    assert solver.hooks[0].diagnostics()["guard_pairs"] == 0
