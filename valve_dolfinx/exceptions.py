"""Named errors with messages that say what was wrong and how to fix it."""

from __future__ import annotations

import math

__all__ = [
    "ValveError",
    "ParameterError",
    "MeshError",
    "SolverError",
    "check_range",
]


class ValveError(Exception):
    """Base class of the package's errors."""


class ParameterError(ValveError, ValueError):
    """A parameter is outside its allowed range (a ``ValueError``)."""


class MeshError(ValveError, ValueError):
    """A mesh (built, loaded or passed in) is unusable: broken, degenerate or inconsistent."""


class SolverError(ValveError, RuntimeError):
    """A nonlinear or time-stepping solve failed; the message says where and with what residual."""


def check_range(
    name: str,
    value: float,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    unit: str = "",
    hint: str = "",
) -> float:
    """Return ``float(value)`` or raise :class:`ParameterError` naming ``name`` and the range.

    NaN, infinities and non-numbers are always rejected.
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, got {value!r}") from None
    lo = "-inf" if low is None else f"{low:g}"
    hi = "inf" if high is None else f"{high:g}"
    bracket = "(" if low_open else "["
    allowed = f"{bracket}{lo}, {hi}]" + (f" {unit}" if unit else "")
    bad = not math.isfinite(v)
    if low is not None:
        bad |= v <= low if low_open else v < low
    if high is not None:
        bad |= v > high
    if bad:
        msg = f"{name} = {value!r} is outside the allowed range {allowed}"
        if hint:
            msg += f"; {hint}"
        raise ParameterError(msg)
    return v
