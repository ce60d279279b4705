"""Newton solves that cycle: ending them, damping the update that starts one
(valve_dolfinx.solvers.callbacks).

Newton's method on f(x) = arctan x has an exact two-cycle: from x₀ with
2x₀ = (1 + x₀²)·arctan x₀ (x₀ = 1.39174520027...) the iterates alternate between x₀
and −x₀ for ever; from |x₀| < x₀* they converge to 0, beyond it they diverge.
"""

from __future__ import annotations

import math

import pytest
from scipy.optimize import brentq

from valve_dolfinx._compat import PETSc
from valve_dolfinx.solvers.callbacks import NewtonCycleStop, NewtonReversalDamping

#: the two-cycle's point, from 2x = (1 + x²) arctan x
CYCLE = brentq(lambda x: 2.0 * x - (1.0 + x * x) * math.atan(x), 1.0, 2.0, xtol=1e-15)


def newton_on_arctan(x0: float, monitor=None, max_it: int = 30, damping=None):
    """(converged reason, iterations, residual norms) of PETSc's Newton method on arctan;
    ``damping`` (a :class:`NewtonReversalDamping`) as the line search's pre-check."""
    return newton_1d(math.atan, lambda x: 1.0 / (1.0 + x * x), x0, monitor, max_it, damping)


#: a three-cycle 1 → −2 → 3 → 1 of Newton's method on f(x) = x with a kinked tangent:
#: the slope s at x sends x to x − x/s
THREE_CYCLE_SLOPES = {1.0: 1.0 / 3.0, -2.0: 0.4, 3.0: 1.5}


def three_cycle_slope(x: float) -> float:
    return THREE_CYCLE_SLOPES[min(THREE_CYCLE_SLOPES, key=lambda p: abs(p - x))]


def newton_1d(f, df, x0: float, monitor=None, max_it: int = 30, damping=None):
    """PETSc's Newton method (basic line search) on the scalar equation f(x) = 0 with the
    tangent df."""
    snes = PETSc.SNES().create(PETSc.COMM_SELF)
    x = PETSc.Vec().createSeq(1, comm=PETSc.COMM_SELF)
    r = x.duplicate()
    J = PETSc.Mat().createDense((1, 1), comm=PETSc.COMM_SELF)
    J.setUp()

    def residual(snes, X, R):
        R[0] = f(X[0])
        R.assemble()

    def jacobian(snes, X, A, P):
        P[0, 0] = df(X[0])
        P.assemble()

    snes.setFunction(residual, r)
    snes.setJacobian(jacobian, J)
    snes.setType("newtonls")
    snes.getLineSearch().setType("basic")
    snes.getKSP().setType("preonly")
    snes.getKSP().getPC().setType("lu")
    snes.setTolerances(rtol=1e-10, atol=1e-14, stol=0.0, max_it=max_it)
    norms = []
    snes.setMonitor(lambda s, its, fnorm: norms.append(fnorm))
    if monitor is not None:
        snes.setMonitor(monitor)
    if damping is not None:
        snes.setLineSearchPreCheck(lambda X, Y: damping(snes.getIterationNumber(), Y))
    x[0] = x0
    x.assemble()
    snes.solve(None, x)
    result = snes.getConvergedReason(), snes.getIterationNumber(), norms
    for obj in (snes, x, r, J):
        obj.destroy()
    return result


def test_the_cycle_point_cycles_without_the_monitor():
    reason, its, norms = newton_on_arctan(CYCLE, max_it=30)
    assert reason == PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT and its == 30
    # the norms repeat: |arctan(±x₀)| = arctan x₀ (round-off lets the cycle drift slowly)
    assert norms[3] == pytest.approx(math.atan(CYCLE), rel=1e-9)


def test_a_cycling_solve_ends_at_the_fourth_iteration():
    stop = NewtonCycleStop(1e-3)
    reason, its, _ = newton_on_arctan(CYCLE, monitor=stop, max_it=30)
    assert reason < 0 and its == 4
    assert stop.stopped == 1


def test_a_three_cycle_ends_at_the_sixth_iteration():
    """Norms 1, 2, 3, 1, 2, 3, ...: a period-2 test never sees it; after the first update
    two whole periods (iterations 1-6) show it."""
    def plain_run():
        return newton_1d(lambda x: x, three_cycle_slope, 1.0, max_it=12)

    reason, its, norms = plain_run()
    assert reason == PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT and its == 12
    assert norms[:7] == pytest.approx([1.0, 2.0, 3.0, 1.0, 2.0, 3.0, 1.0])
    stop = NewtonCycleStop(1e-3)
    reason, its, _ = newton_1d(lambda x: x, three_cycle_slope, 1.0, monitor=stop, max_it=12)
    assert reason < 0 and its == 6
    assert stop.stopped == 1


@pytest.mark.parametrize("x0", [0.5, 1.2, -1.35])
def test_a_converging_solve_is_not_touched(x0):
    """Inside the cycle the iterates converge (slowly near it): same iterations, same
    norms with and without the monitor."""
    stop = NewtonCycleStop(1e-3)
    plain = newton_on_arctan(x0)
    watched = newton_on_arctan(x0, monitor=stop)
    assert plain[0] > 0 and watched[0] == plain[0]
    assert watched[1] == plain[1] and watched[2] == plain[2]
    assert stop.stopped == 0


def test_tolerance_zero_disables_it():
    stop = NewtonCycleStop(0.0)
    reason, its, _ = newton_on_arctan(CYCLE, monitor=stop, max_it=10)
    assert reason == PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT and its == 10


def test_halving_the_reversing_update_lands_the_cycle_on_the_root():
    """x₀ → −x₀ is Newton's first update; the second, +2x₀, reverses it and is halved:
    the iterate lands on 0, the root."""
    damping = NewtonReversalDamping(0.5)
    reason, its, norms = newton_on_arctan(CYCLE, damping=damping, max_it=30)
    assert reason > 0 and its == 2 and norms[-1] < 1e-14
    assert damping.damped == 1


def test_damping_rescues_a_start_beyond_the_cycle():
    """From |x₀| > x₀* plain Newton on arctan diverges; the damped one converges."""
    _, _, plain = newton_on_arctan(1.5, max_it=4)
    assert all(b > a for a, b in zip(plain[:-1], plain[1:], strict=True))  # |arctan x_k| grows
    damping = NewtonReversalDamping(0.5)
    reason, _, norms = newton_on_arctan(1.5, damping=damping, max_it=30)
    assert reason > 0 and norms[-1] < 1e-14 and damping.damped >= 1


def test_damping_factor_one_disables_it():
    damping = NewtonReversalDamping(1.0)
    reason, its, _ = newton_on_arctan(CYCLE, damping=damping, max_it=10)
    assert reason == PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT and its == 10
    assert damping.damped == 0


def test_a_cycle_across_solves_is_damped_after_carry_over():
    """Solves of one update each (a pseudo-time step ending at a loose tolerance): from x₀
    the first lands on −x₀, the second would land back on x₀.  Carried over, the second
    solve's first update (+2x₀) reverses the first solve's last (−2x₀) and is halved: it
    lands on the root."""
    damping = NewtonReversalDamping(0.5)
    _, _, first = newton_on_arctan(CYCLE, damping=damping, max_it=1)
    assert first[-1] == pytest.approx(math.atan(CYCLE), rel=1e-9)  # on −x₀
    damping.carry_over()
    _, _, second = newton_on_arctan(-CYCLE, damping=damping, max_it=1)
    assert second[-1] < 1e-14
    assert damping.damped == damping.damped_first == 1


def test_without_carry_over_a_solves_first_update_is_never_damped():
    """A step retried after a failed solve starts undamped: the cycle across solves goes on."""
    damping = NewtonReversalDamping(0.5)
    newton_on_arctan(CYCLE, damping=damping, max_it=1)
    _, _, second = newton_on_arctan(-CYCLE, damping=damping, max_it=1)
    assert second[-1] == pytest.approx(math.atan(CYCLE), rel=1e-9)  # back on x₀
    damping.carry_over()
    newton_on_arctan(CYCLE, damping=damping, max_it=1)  # the carry-over is used here
    _, _, fourth = newton_on_arctan(-CYCLE, damping=damping, max_it=1)
    assert fourth[-1] == pytest.approx(math.atan(CYCLE), rel=1e-9)
    assert damping.damped == 1
