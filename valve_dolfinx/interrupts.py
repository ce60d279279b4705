"""SIGINT and SIGTERM as an exception, held back while PETSc runs the solvers' callbacks.

Under :func:`interrupt_on_signals` (the command line runs every command in it) SIGINT
(Ctrl-C) and SIGTERM (``kill``, a batch system's time limit) raise
:class:`~valve_dolfinx.exceptions.Interrupted` wherever they arrive, and the command ends
with status 128 + the signal number (130, 143).  An interrupted case is never a result:
the exception passes every ``except Exception``, and a command that received a signal
writes no ``result.json`` and commits no study case afterwards (:func:`check_not_interrupted`).

Python runs a signal handler between two bytecodes of whatever Python code runs next.
Inside ``TS.solve`` that is one of the solver's callbacks, called from C: PETSc turns an
exception raised there into an error code, and one raised before the callback has entered
its own ``try`` is lost.  So inside :func:`deferred_signals` the handlers only note the
signal; :func:`raise_pending`, called first thing in every guarded callback
(:class:`~valve_dolfinx.solvers.callbacks.CallbackGuard`), runs the handler there, where
the guard records what it raises, and leaving the block runs it at the latest.
Signals that are ignored (``SIG_IGN``) or left to the operating system (``SIG_DFL``) are
not touched.  Gmsh installs C handlers of its own when it starts: :func:`reclaim_signals`
gives the signals back to Python.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator

from valve_dolfinx.exceptions import Interrupted

__all__ = ["SIGNALS", "interrupt_on_signals", "deferred_signals", "raise_pending",
           "check_not_interrupted", "reclaim_signals"]

#: the signals that end a command cleanly
SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _State:
    """What the handlers of this process have seen."""

    #: the first signal received under :func:`interrupt_on_signals`, or None
    received: int | None = None
    #: a signal noted inside :func:`deferred_signals` and not handled yet, with the
    #: handler it was held back from
    pending: tuple[int, Callable] | None = None
    #: the handlers held back inside :func:`deferred_signals`, by signal
    held: dict[int, Callable] = {}
    deferring = False


def _interrupt(signum: int, frame) -> None:
    """The handler of :func:`interrupt_on_signals`."""
    if _State.received is None:
        _State.received = signum
    raise Interrupted(signum)


def _note(signum: int, frame) -> None:
    """The handler inside :func:`deferred_signals`: remember the signal, raise nothing."""
    if _State.pending is None:
        _State.pending = (signum, _State.held[signum])


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def interrupt_on_signals() -> Iterator[None]:
    """Within the block SIGINT and SIGTERM raise ``Interrupted`` (main thread only)."""
    saved = {}
    if _main_thread():
        for signum in SIGNALS:
            if signal.getsignal(signum) is not signal.SIG_IGN:
                saved[signum] = signal.signal(signum, _interrupt)
    _State.received = None
    try:
        yield
    finally:
        for signum, handler in saved.items():
            signal.signal(signum, handler)
        _State.received = None


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    """Within the block the Python handlers of SIGINT and SIGTERM only note the signal;
    :func:`raise_pending` runs the held-back handler, and leaving the block does."""
    if _State.deferring or not _main_thread():
        yield
        return
    _State.held = {}
    for signum in SIGNALS:
        handler = signal.getsignal(signum)
        if callable(handler):
            _State.held[signum] = handler
            signal.signal(signum, _note)
    _State.deferring = True
    try:
        yield
    finally:
        _State.deferring = False
        for signum, handler in _State.held.items():
            signal.signal(signum, handler)
        raise_pending()


def raise_pending() -> None:
    """Run the handler of a signal noted inside :func:`deferred_signals`, if one arrived
    (it raises ``Interrupted``, or ``KeyboardInterrupt`` under Python's own handler)."""
    pending, _State.pending = _State.pending, None
    if pending is not None:
        signum, handler = pending
        handler(signum, None)


def reclaim_signals() -> None:
    """Give SIGINT and SIGTERM back to their Python handlers after a library that installed
    C handlers of its own (Gmsh's ``initialize``); main thread only."""
    if _main_thread():
        for signum in SIGNALS:
            handler = signal.getsignal(signum)
            if handler is not None:
                signal.signal(signum, handler)


def check_not_interrupted() -> None:
    """Raise ``Interrupted`` if this command has received a signal: call it before
    writing anything that says a case finished."""
    if _State.received is not None:
        raise Interrupted(_State.received)
