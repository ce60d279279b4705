"""PETSc callbacks that let an interrupt through.

PETSc calls the solvers' Python callbacks (residual, Jacobian, post-step) from C.  An
exception raised in one comes back from ``TS.solve`` as a ``PETSc.Error`` (code 101),
which the solvers report as a failed solve.  A Ctrl-C or a ``SystemExit`` is not a
failed solve: :class:`InterruptGuard` records it in the callback and the solver raises
it again once ``TS.solve`` has returned, so an interrupted study stops (exit status 130)
instead of recording the interrupted case as unconverged.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

__all__ = ["InterruptGuard"]


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
