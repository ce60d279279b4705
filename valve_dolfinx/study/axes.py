"""Study axes: settings a study varies beside the graft's width and height (SPEC §7).

An axis is a case-configuration key (dotted, as ``--set`` takes it:
``root.loaded_diameter_mm``, ``native.bending_modulus_kpa``) and the values it takes.  It
is of one of two kinds:

* a **comparison** axis (``--vary KEY=V1,V2``, ``[study] vary``): each value is a
  study of its own, with its own table, maps and recommendation;
* an **uncertainty** axis (``--uncertain KEY=V1,V2``, ``[study] uncertain``): the
  values are what is not known; together with the numerical paths they are the
  *members* of every cell, and the recommendation is taken over all of them.

Each value is checked by building the case configuration with it, so a bad key
or value is named before anything is computed; the values are kept as the
configuration holds them (``21`` becomes ``21.0``, ``none`` becomes ``None``),
which is also how duplicates are recognised.

Nothing here imports DOLFINx.
"""

from __future__ import annotations

import difflib
import json
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from valve_dolfinx.config import (
    RENAMED,
    WALL_CLOCK_KEY,
    CaseConfig,
    check_key,
    config_from_dict,
    get_dotted,
    parse_value,
    set_dotted,
    setting_keys,
)
from valve_dolfinx.exceptions import ParameterError

__all__ = [
    "COMPARISON",
    "UNCERTAINTY",
    "PATH_KEY",
    "StudyAxis",
    "value_text",
    "axis_label",
    "parse_axis_option",
    "axis_table",
    "check_axis_values",
    "check_axes",
]

COMPARISON = "comparison"
UNCERTAINTY = "uncertainty"
#: the column (and folder-name key) of a case's numerical path
PATH_KEY = "path"
#: case settings a study sets itself, and the option that sets them
_GRID_KEYS = {"graft.width_pct": "--widths (study.widths)",
              "graft.height_pct": "--heights (study.heights)"}
_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]")


@dataclass(frozen=True)
class StudyAxis:
    """One axis of a study: a case-configuration key, its values and its kind."""

    key: str
    values: tuple[Any, ...]
    kind: str

    @property
    def is_comparison(self) -> bool:
        return self.kind == COMPARISON


def value_text(value: Any) -> str:
    """A value as folder names, labels and tables spell it (filesystem-safe):
    ``21.0`` -> ``21``, ``None`` -> ``none``, ``True`` -> ``true``."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    return _UNSAFE.sub("_", str(value))


def axis_label(values: Iterable[tuple[str, Any]]) -> str:
    """``key=value, key=value`` of axis values ("" for none)."""
    return ", ".join(f"{key}={value_text(value)}" for key, value in values)


def _split(option: str, key: str, values: Any) -> list[Any]:
    """Raw values: a list as it is; a string as the command line spells it (commas
    separate, each part read as a TOML value or a bare word); a scalar as one value."""
    if isinstance(values, str):
        return [parse_value(part) for part in values.split(",") if part.strip()]
    if isinstance(values, list | tuple):
        return list(values)
    if isinstance(values, Mapping):
        raise ParameterError(f"{option} {key}: give a list of values, e.g. {key} = [1, 2]")
    return [values]


def parse_axis_option(option: str, text: str) -> tuple[str, list[Any]]:
    """``("KEY", [V1, V2])`` from the command line's ``KEY=V1,V2``.

    Raises
    ------
    ParameterError
        If there is no ``=`` or no value.
    """
    key, sep, values = text.partition("=")
    key = key.strip()
    example = f"e.g. {option} root.loaded_diameter_mm=20,21,22"
    if not sep or not key:
        raise ParameterError(f"{option} {text!r}: give KEY=V1,V2,... with KEY a case setting "
                             f"as --set takes it, {example}")
    raw = _split(option, key, values)
    if not raw:
        raise ParameterError(f"{option} {key}: no value given; list the values after '=', "
                             f"{example}")
    return key, raw


def axis_table(option: str, table: Any) -> dict[str, list[Any]]:
    """``{"section.key": [values]}`` from a ``[study]`` table's ``vary``/``uncertain``
    (dotted keys, or nested tables ``{root = {loaded_diameter_mm = [20, 21]}}``)."""
    if not isinstance(table, Mapping):
        raise ParameterError(f"{option} must be a table of settings and their values, e.g. "
                             f'{option} = {{"root.loaded_diameter_mm" = [20, 21, 22]}}')
    flat: dict[str, list[Any]] = {}
    for key, value in table.items():
        if isinstance(value, Mapping):
            for sub, values in axis_table(option, value).items():
                flat[f"{key}.{sub}"] = values
        else:
            flat[str(key)] = _split(option, str(key), value)
    return flat


def _check_key(option: str, key: str) -> None:
    """Raise unless ``key`` names one setting of the case configuration an axis may set."""
    if key in _GRID_KEYS:
        raise ParameterError(f"{option} {key}: the graft size is the study's grid; give it with "
                             f"{_GRID_KEYS[key]}")
    if key == PATH_KEY:
        raise ParameterError(f"{option} path: the numerical paths are set with --paths N "
                             "(study.paths)")
    if key in RENAMED:
        check_key(key, source=option)
    if key == WALL_CLOCK_KEY:  # the settings hash leaves it out: its values would share a case
        raise ParameterError(f"{option} {key}: a wall-clock limit bounds how long a case may "
                             "run, not what it computes, so it is not an axis (its values "
                             "would share one case folder); give one limit with "
                             "--wall-time-limit (study.wall_time_limit) or --set")
    defaults = CaseConfig().to_dict()
    try:
        default = get_dotted(defaults, key)
    except KeyError:
        known = setting_keys(defaults)
        close = difflib.get_close_matches(key, known, n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise ParameterError(f"{option} {key}: unknown key{hint}; give a case setting as --set "
                             "takes it (`valve-dolfinx config` prints every key)") from None
    if isinstance(default, Mapping):
        raise ParameterError(f"{option} {key}: names a table of settings, not one setting; "
                             f"give one of its keys, e.g. {key}.{next(iter(default), 'key')}")


def _text(value: Any) -> str:
    """A value as the user gave it (``0.0``, ``21``, ``"bdf2"``), for messages."""
    if isinstance(value, str):
        return json.dumps(value)
    return repr(value) if isinstance(value, float) else value_text(value)


def check_axis_values(option: str, key: str, values: Any, base: Mapping) -> tuple[Any, ...]:
    """The values of one axis, validated and as the case configuration holds them.

    Parameters
    ----------
    option
        How the user spelled the axis (``--vary``, ``study.uncertain``), for messages.
    key
        The dotted case-configuration key.
    values
        The values (a list, or the command line's comma-separated text).
    base
        The study's case settings (``CaseConfig.to_dict()`` layout, any subset), into
        which each value is set to check it.

    Raises
    ------
    ParameterError
        Naming the option, the key and the value: an unknown key, a key that names a
        table or the grid, no value, a value the configuration rejects (wrong type, out
        of range) and a value given twice.
    """
    _check_key(option, key)
    raw = _split(option, key, values)
    if not raw:
        raise ParameterError(f"{option} {key}: no value given; list at least one")
    kept: list[Any] = []
    for item in raw:
        if isinstance(item, Mapping | list | tuple):
            raise ParameterError(f"{option} {key}: {item!r} is not a single value")
        data = json.loads(json.dumps(base))
        set_dotted(data, key, item)
        config = config_from_dict(data, source=f"{option} {key}={_text(item)}")
        value = get_dotted(config.to_dict(), key)
        if isinstance(value, float) and not math.isfinite(value):
            raise ParameterError(f"{option} {key}={_text(item)}: give a finite number")
        if value in kept:
            raise ParameterError(f"{option} {key}: {_text(item)} is given twice (the same "
                                 f"value as an earlier one, {value_text(value)}); list each "
                                 "value once")
        kept.append(value)
    return tuple(kept)


def check_axes(vary: Mapping[str, Any], uncertain: Mapping[str, Any], base: Mapping,
               fixed: Mapping[str, str]) -> tuple[StudyAxis, ...]:
    """The comparison axes (``vary``), then the uncertainty axes (``uncertain``), checked.

    Parameters
    ----------
    vary, uncertain
        ``{"section.key": values}``.
    base
        The study's case settings with which each value is checked.
    fixed
        Keys that something else sets, with what sets them (``--set``, ``--mesh-size``, a
        numerical path): an axis may not set them too.

    Raises
    ------
    ParameterError
        As :func:`check_axis_values`, and for a key that is both varied and uncertain or
        is also set by what ``fixed`` names.
    """
    axes = []
    for option, kind, table in (("vary", COMPARISON, vary), ("uncertain", UNCERTAINTY,
                                                             uncertain)):
        for key, values in table.items():
            if key in vary and key in uncertain:
                raise ParameterError(f"{key} is both varied (vary) and uncertain (uncertain): "
                                     "an axis is one or the other; keep one")
            if key in fixed:
                raise ParameterError(f"{option} {key}: it is also set by {fixed[key]}; an "
                                     "axis sets it for every case: drop one of them")
            axes.append(StudyAxis(key, check_axis_values(option, key, values, base), kind))
    return tuple(axes)
