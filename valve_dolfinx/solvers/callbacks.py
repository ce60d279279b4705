"""PETSc callbacks: letting an interrupt through, and Newton solves that cycle.

PETSc calls the solvers' Python callbacks (residual, Jacobian, post-step) from C.  An
exception raised in one comes back from ``TS.solve`` as a ``PETSc.Error`` (code 101),
which the solvers report as a failed solve.  A Ctrl-C or a ``SystemExit`` is not a
failed solve: :class:`InterruptGuard` records it in the callback and the solver raises
it again once ``TS.solve`` has returned, so an interrupted study stops (exit status 130)
instead of recording the interrupted case as unconverged.

A Newton solve whose iterates have settled into a cycle (the residual norms repeat
every second or third iteration) cannot converge any more, but it runs on to
``snes_max_it`` before the time stepper retries the step with a shorter one.
:class:`NewtonCycleStop`, an SNES monitor, ends it as diverged as soon as the cycle
shows; :class:`NewtonReversalDamping`, part of the line-search pre-check, damps the
update that would start a two-cycle (which turns some of them into three-cycles: an
update, the reversing one halved, the rest of the way back).
"""

from __future__ import annotations

import functools
from collections import deque
from collections.abc import Callable

from valve_dolfinx._compat import PETSc

__all__ = ["InterruptGuard", "NewtonCycleStop", "NewtonReversalDamping"]


class InterruptGuard:
    """Wraps callbacks; :meth:`reraise` raises the interrupt one of them caught."""

    def __init__(self) -> None:
        self.caught: BaseException | None = None

    def wrap(self, callback: Callable) -> Callable:
        @functools.wraps(callback)
        def guarded(*args, **kwargs):
            try:
                return callback(*args, **kwargs)
            except (KeyboardInterrupt, SystemExit) as interrupt:
                self.caught = interrupt
                raise

        return guarded

    def reraise(self) -> None:
        """Raise the caught interrupt, if there is one (and forget it)."""
        interrupt, self.caught = self.caught, None
        if interrupt is not None:
            raise interrupt


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
