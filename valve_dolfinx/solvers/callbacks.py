"""PETSc callbacks: one guard for all of them, and Newton solves that cycle.

PETSc calls the solvers' Python callbacks (residual, Jacobian, line-search pre-check,
initial guess, monitor, post-step) from C.  An exception raised in one comes back from
``TS.solve`` as a ``PETSc.Error`` (code 101) that has lost it, and reads like a solve
that failed.  :class:`CallbackGuard` wraps every callback a solver hands to PETSc and
records the first exception of any kind; the solver calls :meth:`CallbackGuard.reraise`
once ``TS.solve`` has returned.  A solver's own way of ending a run from a callback (a
step below its floor) stays a failed solve with its reason; an interrupt is raised again
as itself (the command ends with 130 or 143 and records nothing); any other exception is
a :class:`~valve_dolfinx.exceptions.SolverError` that names it, never ``converged: false``.
Around ``TS.solve`` the guard holds SIGINT and SIGTERM back to the entry of the next
callback (:func:`~valve_dolfinx.interrupts.deferred_signals`), where it records them.

A Newton solve whose iterates have settled into a cycle (the residual norms repeat
every second or third iteration) cannot converge any more, but it runs on to
``snes_max_it`` before the time stepper retries the step with a shorter one.
:class:`NewtonCycleStop`, an SNES monitor, ends it as diverged as soon as the cycle
shows; :class:`NewtonReversalDamping`, part of the line-search pre-check, damps the
update that would start a two-cycle (which turns some of them into three-cycles: an
update, the reversing one halved, the rest of the way back).
"""

from __future__ import annotations

import contextlib
import functools
import logging
from collections import deque
from collections.abc import Callable

from valve_dolfinx._compat import PETSc
from valve_dolfinx.exceptions import SolverError
from valve_dolfinx.interrupts import deferred_signals, raise_pending

__all__ = ["CallbackGuard", "NewtonCycleStop", "NewtonReversalDamping"]

log = logging.getLogger(__name__)


class CallbackGuard(contextlib.AbstractContextManager):
    """Wraps a solver's PETSc callbacks; :meth:`reraise` deals with what one of them raised.

    Parameters
    ----------
    stops
        The exception types the solver raises in a callback to end a run that failed
        (reported by the solver with its reason, not raised again).

    Use ``with guard: ts.solve(X)`` (signals wait for the next callback) and call
    :meth:`reraise` after ``TS.solve``, whether it raised or not.
    """

    def __init__(self, stops: tuple[type[BaseException], ...] = ()) -> None:
        self.stops = tuple(stops)
        self.caught: BaseException | None = None
        self.callback = ""
        self._signals: contextlib.AbstractContextManager | None = None

    def wrap(self, callback: Callable) -> Callable:
        # a monitor is an object: its class names it
        name = getattr(callback, "__name__", type(callback).__name__)

        @functools.wraps(callback)
        def guarded(*args, **kwargs):
            try:
                raise_pending()  # a signal that arrived while PETSc ran C code
                return callback(*args, **kwargs)
            except BaseException as err:
                if self.caught is None:
                    self.caught, self.callback = err, name
                raise

        return guarded

    def __enter__(self) -> CallbackGuard:
        self._signals = deferred_signals()
        self._signals.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        signals, self._signals = self._signals, None
        signals.__exit__(*exc)

    def reraise(self, where: str) -> BaseException | None:
        """Raise what a callback raised (and forget it): an interrupt or ``SystemExit`` as
        it is, another exception as a ``SolverError`` naming it and ``where`` the solve
        was.  Return one of the ``stops`` (for the solver's reason), or None when no
        callback raised."""
        err, self.caught = self.caught, None
        if err is None or isinstance(err, self.stops):
            return err
        if not isinstance(err, Exception):
            raise err
        log.debug("the PETSc callback %s raised", self.callback, exc_info=err)
        message = " ".join(str(err).split()) or "(no message)"
        raise SolverError(f"{type(err).__name__} in the solver's callback {self.callback} "
                          f"{where}: {message}") from err


class NewtonCycleStop:
    """SNES monitor that ends a Newton solve caught in a cycle of period 2 or 3 as diverged.

    At iteration ``k ≥ 2p`` the solve has cycled with period ``p`` when the last ``p``
    residual norms each repeat the one ``p`` iterations earlier (the norms after the
    first update, ``r_1 … r_k``, are compared),
    ``|r_{k−j} − r_{k−j−p}| ≤ tolerance·r_{k−j}`` for ``j = 0 … p−1``, and the
    convergence test has not stopped it.  The reason is then ``DIVERGED_DTOL`` (PETSc has
    none for a cycle); the time stepper treats it as any failed solve and retries the step
    from its start, so where a failed solve stops does not change the path.  PETSc calls
    the monitors after the convergence test of an iteration and stops on the reason they
    leave.  A solve that converges is never cut, so the path and the result are those
    without the monitor.  The residual norm is global, so every rank decides alike.

    Parameters
    ----------
    tolerance
        Relative repetition of the norms that counts as a cycle; 0 disables it.
    """

    #: cycle lengths looked for
    PERIODS = (2, 3)

    def __init__(self, tolerance: float) -> None:
        self.tolerance = float(tolerance)
        # the last norms of this solve after its first update: two of the longest periods
        self.norms: deque[float] = deque(maxlen=2 * max(self.PERIODS))
        #: solves ended by a cycle (reported by the solver's log)
        self.stopped = 0

    def _cycled(self, period: int) -> bool:
        r, tol = self.norms, self.tolerance
        return len(r) >= 2 * period and all(
            abs(r[-1 - j] - r[-1 - j - period]) <= tol * r[-1 - j] for j in range(period))

    def __call__(self, snes: PETSc.SNES, its: int, fnorm: float) -> None:
        if its == 0:
            self.norms.clear()
            return
        self.norms.append(float(fnorm))
        if self.tolerance <= 0.0 or snes.getConvergedReason() != 0:
            return
        if any(self._cycled(p) for p in self.PERIODS):
            snes.setConvergedReason(PETSc.SNES.ConvergedReason.DIVERGED_DTOL)
            self.stopped += 1


#: An update counts as reversing the previous one when the cosine of their angle is below
#: minus this.
REVERSAL_COSINE = 0.9


class NewtonReversalDamping:
    """Line-search pre-check step that damps a Newton update reversing the previous one.

    Where the residual has a kink at the solution (its Jacobian jumps, as the relaxed
    membrane energy's tangent does between taut and wrinkled) Newton's method jumps to
    and fro across it, each update nearly the negative of the one before.  Call it with
    the SNES iteration number and the update ``y`` of every iteration: from the second
    iteration of a solve on, an update whose cosine with the previous one is below
    ``-REVERSAL_COSINE`` is scaled by ``factor``, so that the iterate lands between the
    two sides of the cycle.  On Newton's exact two-cycle of ``f(x) = arctan x``
    (``x₀ → −x₀ → x₀``) ``factor = 1/2`` lands on the root.  The dot products are global,
    so every rank decides alike; ``factor = 1`` disables it.

    The same cycle runs across solves when each ends after one update (a pseudo-time
    step whose solve stops at a loose tolerance): after :meth:`carry_over` the next
    solve's first update is compared with this solve's last one.  A time stepper calls
    it after every accepted step, so a step retried after a failed solve starts
    undamped.
    """

    def __init__(self, factor: float) -> None:
        self.factor = float(factor)
        self.previous: PETSc.Vec | None = None
        self._carried = False
        #: updates damped (reported by the solver's log), and of those the first
        #: updates of a solve
        self.damped = 0
        self.damped_first = 0

    def carry_over(self) -> None:
        """Compare the first update of the next solve with the last update of this one."""
        self._carried = True

    def __call__(self, iteration: int, y: PETSc.Vec) -> None:
        previous = self.previous
        compare = iteration >= 1 or self._carried
        if iteration == 0:
            self._carried = False
        if self.factor < 1.0 and compare and previous is not None:
            scale = y.norm() * previous.norm()
            if scale > 0.0 and y.dot(previous) < -REVERSAL_COSINE * scale:
                y.scale(self.factor)
                self.damped += 1
                self.damped_first += iteration == 0
        if previous is None:
            self.previous = previous = y.duplicate()
        y.copy(previous)
