"""Named errors with messages that say what was wrong and how to fix it, and the CLI's exit codes.

Every error class carries the exit code the command line ends with when it
reaches ``valve-dolfinx``; :func:`exit_code` maps any exception to one.  Each kind
of output problem has its own class and code, the same in every command that writes
files (:func:`valve_dolfinx.io.check_output_folder` raises them before any computation).
"""

from __future__ import annotations

import math
import signal
from enum import IntEnum

__all__ = [
    "ExitCode",
    "NextRoundError",
    "ValveError",
    "ParameterError",
    "ConfigurationError",
    "MeshError",
    "InputFileError",
    "SolverError",
    "DegenerateGeometryError",
    "OutputConflictError",
    "OutputNotFolderError",
    "OutputNotWritableError",
    "StudyIncompleteError",
    "Interrupted",
    "check_range",
    "exit_code",
]


class ExitCode(IntEnum):
    """Exit status of ``valve-dolfinx``."""

    OK = 0
    INTERNAL = 1  #: an unexpected error (a bug): rerun with -v and report the traceback
    USAGE = 2  #: a bad command line, configuration or parameter value
    NOT_CONVERGED = 3  #: the case ran but did not converge (results written, converged: false)
    INPUT = 4  #: an input or output file is missing, unreadable or not what it should be
    SOLVER = 5  #: a solver failed, or raised in one of its callbacks; no result
    OUTPUT_CONFLICT = 6  #: the output folder holds another case's results; nothing computed
    OUTPUT_NOT_FOLDER = 7  #: the output path, or a folder above it, is a file
    OUTPUT_NOT_WRITABLE = 8  #: the output folder cannot be created or written
    STUDY_INCOMPLETE = 9  #: a study's case failed, is damaged, stale, not run or running: no answer
    NEXT_ROUND = 10  #: ``report`` wrote the study's next round: run its cases, report again
    INTERRUPTED = 130  #: Ctrl-C (SIGINT): 128 + 2; nothing unfinished is recorded
    TERMINATED = 143  #: SIGTERM (kill, a batch system's time limit): 128 + 15


class ValveError(Exception):
    """Base class of the package's errors."""

    exit_code = ExitCode.INTERNAL


class ParameterError(ValveError, ValueError):
    """A parameter is outside its allowed range (a ``ValueError``)."""

    exit_code = ExitCode.USAGE


class ConfigurationError(ParameterError):
    """A configuration file cannot be parsed, or holds an unknown key or a bad value."""


class MeshError(ValveError, ValueError):
    """A mesh (built, loaded or passed in) is unusable: broken, degenerate or inconsistent."""

    exit_code = ExitCode.INPUT


class InputFileError(ValveError, OSError):
    """A file the run needs is missing or is not what it should be."""

    exit_code = ExitCode.INPUT


class SolverError(ValveError, RuntimeError):
    """A nonlinear or time-stepping solve failed; the message says where and with what residual."""

    exit_code = ExitCode.SOLVER


class DegenerateGeometryError(SolverError):
    """A state of a solve has a collapsed (zero-area) triangle: it is outside the domain of the
    residual.  The solvers retry a step whose Newton iterate collapses a triangle with a
    shorter one, and end the run as failed when an accepted state has one."""


class OutputConflictError(ValveError, FileExistsError):
    """The output folder holds another case's results (``--force`` overwrites them)."""

    exit_code = ExitCode.OUTPUT_CONFLICT


class OutputNotFolderError(ValveError, NotADirectoryError):
    """The output path, or a folder above it, is a file."""

    exit_code = ExitCode.OUTPUT_NOT_FOLDER


class OutputNotWritableError(ValveError, PermissionError):
    """The output folder cannot be created or written (permissions, a read-only file system)."""

    exit_code = ExitCode.OUTPUT_NOT_WRITABLE


class StudyIncompleteError(ValveError):
    """A study has cases without a result that counts (failed, damaged, stale, not run, in
    progress in another process): it has no answer, and its report lists them."""

    exit_code = ExitCode.STUDY_INCOMPLETE


class NextRoundError(ValveError):
    """``report`` decided the study's next round (an answer to confirm, an adaptive
    design's cases) and wrote it: the answer printed is not final until its cases are run."""

    exit_code = ExitCode.NEXT_ROUND


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived (:mod:`valve_dolfinx.interrupts`); exit status 128 + signal.

    A ``KeyboardInterrupt``, so nothing that catches ``Exception`` (a study recording a
    failed case, a figure that could not be drawn) swallows it.
    """

    def __init__(self, signum: int = signal.SIGINT) -> None:
        self.signum = int(signum)
        super().__init__(signal.Signals(self.signum).name)


def exit_code(err: BaseException) -> int:
    """The exit status for ``err`` reaching the command line."""
    if isinstance(err, KeyboardInterrupt):
        return 128 + getattr(err, "signum", signal.SIGINT)
    if isinstance(err, ValveError):
        return err.exit_code
    if isinstance(err, OSError):
        return ExitCode.INPUT
    if isinstance(err, ValueError):
        return ExitCode.USAGE
    if type(err).__module__.startswith("petsc4py"):
        return ExitCode.SOLVER
    return ExitCode.INTERNAL


def check_range(
    name: str,
    value: float,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    unit: str = "",
    hint: str = "",
    low_hint: str = "",
    high_hint: str = "",
) -> float:
    """Return ``float(value)`` or raise :class:`ParameterError` naming ``name`` and the range.

    NaN, infinities and non-numbers are always rejected.  The message ends with
    the reason for the bound that was crossed (``low_hint`` below the range,
    ``high_hint`` above it), else with ``hint``.
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, got {value!r}") from None
    lo = "-inf" if low is None else f"{low:g}"
    hi = "inf" if high is None else f"{high:g}"
    bracket = "(" if low_open else "["
    allowed = f"{bracket}{lo}, {hi}]" + (f" {unit}" if unit else "")
    reason = None
    if not math.isfinite(v):
        reason = hint
    elif low is not None and (v <= low if low_open else v < low):
        reason = low_hint or hint
    elif high is not None and v > high:
        reason = high_hint or hint
    if reason is not None:
        msg = f"{name} = {value!r} is outside the allowed range {allowed}"
        if reason:
            msg += f"; {reason}"
        raise ParameterError(msg)
    return v
