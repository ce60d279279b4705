"""The graft sizing grid and the study settings (SPEC §7), validated before anything runs.

A study is the normal valve plus every graft of a width × height grid of
enlargements (per cent of the native leaflet), at every combination of the
values of its axes (:mod:`~valve_dolfinx.study.axes`) and along each of its
numerical paths (:mod:`~valve_dolfinx.study.paths`).  This module turns what a
user typed (command-line values, a ``[study]`` table of a TOML file, Python
arguments) into a validated :class:`StudySettings`; :meth:`StudySettings.layout`
enumerates its cases in a fixed order (:mod:`~valve_dolfinx.study.layout`), so
``--case-index I`` names the same case in every task of a job array.

Nothing here imports DOLFINx: a bad grid or axis is reported in a fraction of a
second, before any mesh is built.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Iterable
from dataclasses import InitVar, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from valve_dolfinx.config import (
    STUDY_TABLE,
    WALL_CLOCK_KEY,
    CaseConfig,
    apply_overrides,
    config_from_dict,
    get_dotted,
    read_config_file,
    set_dotted,
    setting_keys,
)
from valve_dolfinx.exceptions import ParameterError, check_range
from valve_dolfinx.geometry.outline import GRAFT_TOO_LARGE, GRAFT_TOO_SMALL, MAX_GRAFT_PCT
from valve_dolfinx.sizing.design import initial_design
from valve_dolfinx.study.axes import (
    COMPARISON,
    UNCERTAINTY,
    StudyAxis,
    axis_table,
    check_axes,
)
from valve_dolfinx.study.layout import (
    NORMAL_CASE,
    Point,
    Rounds,
    StudyCase,
    StudyLayout,
    case_name,
    study_layout,
)
from valve_dolfinx.study.paths import START_FROM_NORMAL, study_paths

__all__ = [
    "STUDY_WIDTHS_PCT",
    "STUDY_HEIGHTS_PCT",
    "TARGET_COAPTATION_MAX_MM",
    "DEFAULT_PANEL_CASES",
    "NORMAL_CASE",
    "StudyCase",
    "StudySettings",
    "case_name",
    "parse_percentages",
    "load_study_toml",
]

log = logging.getLogger(__name__)

#: The published study grid (SPEC §1, §7): graft width and height enlargements in per cent
STUDY_WIDTHS_PCT = (0.0, 7.0, 14.0, 21.0, 27.0)
STUDY_HEIGHTS_PCT = (0.0, 13.0, 27.0, 40.0)
#: the designs of a study: every graft of the grid, or rounds chosen by the surface
GRID, ADAPTIVE = "grid", "adaptive"
DESIGNS = (GRID, ADAPTIVE)
#: an adaptive study's default case budget (graft cases)
ADAPTIVE_BUDGET = 40
#: Cases drawn as figure panels besides the normal valve
DEFAULT_PANEL_CASES = ("W0_H0", "W7_H0", "W21_H27")
#: the range (mm) of a target minimum coaptation height, in every command: above 0, at
#: most this (a normal valve coapts 3-4 mm at its centre)
TARGET_COAPTATION_MAX_MM = 10.0
#: how messages name the case settings as what sets a key
_CASE_SETTINGS = "the case settings (--set or the configuration file)"


def _split_values(values: Iterable[Any]) -> list[Any]:
    """Flatten ``["0,7", "14"]`` into ``["0", "7", "14"]`` (commas or spaces separate)."""
    out: list[Any] = []
    for value in values:
        if isinstance(value, str):
            out += [part for part in value.replace(",", " ").split() if part]
        else:
            out.append(value)
    return out


def parse_percentages(option: str, values: Iterable[Any] | None, what: str) -> tuple[float, ...]:
    """Validated, sorted graft enlargements (per cent) from what the user gave.

    Parameters
    ----------
    option
        How the user spelled the parameter (``--widths``, ``study.heights``), for messages.
    values
        Numbers or strings; strings may hold several values separated by commas.
    what
        ``"width"`` or ``"height"``, for messages.

    Raises
    ------
    ParameterError
        On an empty list, a non-number, a value outside ``[0, MAX_GRAFT_PCT]`` or a
        duplicate; the message names the value and the allowed range.
    """
    allowed = f"[0, {MAX_GRAFT_PCT:g}] %"
    numbers = "0 7 14 21 27" if what == "width" else "0 13 27 40"
    example = (f"e.g. {option} {numbers}" if option.startswith("-")
               else f"e.g. {option} = [{numbers.replace(' ', ', ')}]")
    if isinstance(values, str | int | float):
        values = [values]
    raw = _split_values(values or [])
    if not raw:
        raise ParameterError(f"{option} is empty: give at least one graft {what} enlargement "
                             f"in per cent within {allowed}, {example}")
    seen: dict[float, Any] = {}
    for item in raw:
        if isinstance(item, bool):  # TOML true/false would pass float()
            item = str(item).lower()
        try:
            value = float(item)
        except (TypeError, ValueError):
            raise ParameterError(f"{option}: {item!r} is not a number; give graft {what} "
                                 f"enlargements in per cent within {allowed}, {example}") from None
        if not math.isfinite(value) or not 0.0 <= value <= MAX_GRAFT_PCT:
            reason = ("give a finite number" if math.isnan(value) else
                      GRAFT_TOO_LARGE if value > MAX_GRAFT_PCT else GRAFT_TOO_SMALL)
            raise ParameterError(f"{option}: {item!r} is outside the allowed range {allowed} "
                                 f"(graft {what} enlargement in per cent of the native "
                                 f"leaflet): {reason}")
        if value in seen:
            raise ParameterError(f"{option}: {item!r} is given twice (also as {seen[value]!r}); "
                                 f"list each graft {what} once, within {allowed}")
        seen[value] = item
    return tuple(sorted(seen))


@dataclass(frozen=True)
class StudySettings:
    """What a sizing study runs (the ``[study]`` section of a configuration file).

    Attributes
    ----------
    widths_pct, heights_pct
        Graft width and height enlargements (per cent); every combination is a case.
    include_normal
        Also run the normal valve (the reference of the recommendation and the plots).
    mesh_size_mm
        Target triangle edge length (mm); ``None`` keeps the case default.
    wall_time_limit_s
        Wall-clock limit of each case (s); ``None`` keeps the case default.  It is a
        numerical setting of the case, so it enters the configuration hash.
    target_coaptation_mm
        Minimum coaptation height a graft must reach; ``None`` takes the normal valve's.
    panel_cases
        Cases drawn as figure panels besides the normal valve.
    ranks_per_case
        MPI ranks that share one case (``mpirun -n N`` runs ``N / ranks_per_case``
        cases at a time).
    case
        Case settings applied to every case (the ``CaseConfig.to_dict()`` layout, nested
        tables for nested parameters; in a file, its top-level keys and tables).
    case_source
        How messages name where ``case`` came from (``--set``, the file); not kept.
    base_config
        The configuration every case starts from (:meth:`base_case`), validated once when
        the settings are made: ``case`` with the mesh size and the wall-clock limit.
    vary
        Comparison axes, ``{"table.key": values}`` (``--vary KEY=V1,V2``): a table, maps
        and a recommendation per value (per combination of the values of several axes).
    uncertain
        Uncertainty axes (``--uncertain KEY=V1,V2``): with the paths they make the members
        of every cell, and the recommendation holds in all of them.
    paths
        Numerical paths along which every graft is solved
        (:data:`valve_dolfinx.study.paths.PATHS`; always uncertainty).
    design
        ``"grid"``: every graft of the grid in every member; ``"adaptive"``: the grid's
        width and height range only, solved from a small initial design in rounds chosen
        by the fitted surface (:mod:`valve_dolfinx.sizing.design`).
    budget
        An adaptive study's most graft cases per comparison value (the normal valves not
        counted); it stops there, saying what is not settled.

    An axis key may not also be set by ``mesh_size_mm`` or ``wall_time_limit_s``, by a path
    of the study, or by ``case`` to anything but its default value.
    """

    widths_pct: tuple[float, ...] = STUDY_WIDTHS_PCT
    heights_pct: tuple[float, ...] = STUDY_HEIGHTS_PCT
    include_normal: bool = True
    mesh_size_mm: float | None = None
    wall_time_limit_s: float | None = None
    target_coaptation_mm: float | None = None
    panel_cases: tuple[str, ...] = DEFAULT_PANEL_CASES
    ranks_per_case: int = 1
    case: dict = field(default_factory=dict)
    vary: dict = field(default_factory=dict)
    uncertain: dict = field(default_factory=dict)
    paths: int = 1
    design: str = GRID
    budget: int = ADAPTIVE_BUDGET
    case_source: InitVar[str] = "study case settings"
    base_config: CaseConfig = field(init=False, repr=False, compare=False)

    def __post_init__(self, case_source: str) -> None:
        set_ = object.__setattr__  # frozen: normalise in place once
        set_(self, "widths_pct", parse_percentages("widths", self.widths_pct, "width"))
        set_(self, "heights_pct", parse_percentages("heights", self.heights_pct, "height"))
        if self.mesh_size_mm is not None:
            set_(self, "mesh_size_mm", check_range(
                "mesh_size", self.mesh_size_mm, 0.05, 2.5, unit="mm",
                hint="target triangle edge length; 0.8 mm is the default, 1.6-2.0 mm a "
                "quick coarse study"))
        if self.wall_time_limit_s is not None:
            set_(self, "wall_time_limit_s", check_range(
                "wall_time_limit", self.wall_time_limit_s, 0.0, 30 * 24 * 3600.0,
                low_open=True, unit="s", hint="the wall-clock limit of each case in seconds"))
        if self.target_coaptation_mm is not None:
            set_(self, "target_coaptation_mm", check_range(
                "target_coaptation", self.target_coaptation_mm, 0.0, TARGET_COAPTATION_MAX_MM,
                low_open=True,
                unit="mm", hint="a minimum coaptation height in mm; a normal valve coapts "
                "3-4 mm (omit it to use the normal valve's)"))
        ranks = self.ranks_per_case
        if isinstance(ranks, bool) or not isinstance(ranks, int) or ranks < 1:
            raise ParameterError(f"ranks_per_case = {ranks!r} must be a whole number >= 1 "
                                 "(MPI ranks that share one case)")
        if self.design not in DESIGNS:
            raise ParameterError(f"design = {self.design!r} is not one of "
                                 f"{', '.join(DESIGNS)}: 'grid' solves every graft of the "
                                 "grid, 'adaptive' (--adaptive) a design chosen in rounds")
        if self.adaptive and (len(self.widths_pct) < 2 or len(self.heights_pct) < 2):
            raise ParameterError(f"design = 'adaptive' needs a range of widths and of heights "
                                 f"to choose sizes in (widths {list(self.widths_pct)}, "
                                 f"heights {list(self.heights_pct)}): give at least two of "
                                 "each, or solve the sizes given with the full grid "
                                 "(--full-grid, design = 'grid')")
        budget = self.budget
        if isinstance(budget, bool) or not isinstance(budget, int) or budget < 1:
            raise ParameterError(f"budget = {budget!r} must be a whole number >= 1: the most "
                                 "graft cases an adaptive study solves (--budget)")
        panels = (self.panel_cases,) if isinstance(self.panel_cases, str) else self.panel_cases
        set_(self, "panel_cases", tuple(str(p) for p in panels))
        if not isinstance(self.case, dict):
            raise ParameterError("study.case must be a table of case-configuration overrides")
        set_(self, "base_config", config_from_dict(self.base_case(), source=case_source))
        vary, uncertain = axis_table("vary", self.vary), axis_table("uncertain", self.uncertain)
        axes = check_axes(vary, uncertain, self.base_case(), self._fixed_keys())
        set_(self, "vary", {a.key: a.values for a in axes if a.kind == COMPARISON})
        set_(self, "uncertain", {a.key: a.values for a in axes if a.kind == UNCERTAINTY})
        self._check_warm_starts()

    def _check_warm_starts(self) -> None:
        """Raise if a path that starts the grafts from the loaded normal valve meets a solver
        that cannot start from a loaded valve (BDF2 starts from the unloaded valve)."""
        warm = [p for p in study_paths(self.paths) if p.start == START_FROM_NORMAL]
        if not warm:
            return
        solvers = ({**self.vary, **self.uncertain}.get("solver.method")
                   or (self.base_config.solver,))
        if "bdf2" in solvers:
            raise ParameterError(f"solver.method = 'bdf2' with the numerical {warm[0].label}: that "
                                 "path starts every graft from the loaded normal valve, and a "
                                 "closure that starts from a loaded valve needs solver.method = "
                                 "'ptc' (BDF2 starts from the unloaded valve); every study "
                                 "takes path 1, so run the BDF2 cross-check case by case with "
                                 "`valve-dolfinx run --solver bdf2`")

    def base_case(self) -> dict:
        """The case settings every case starts from: ``case``, then the mesh size and the
        wall-clock limit (a new dict)."""
        data = json.loads(json.dumps(self.case))  # a deep copy
        if self.mesh_size_mm is not None:
            set_dotted(data, "geometry.mesh_size_mm", self.mesh_size_mm)
        if self.wall_time_limit_s is not None:
            set_dotted(data, WALL_CLOCK_KEY, self.wall_time_limit_s)
        return data

    def _fixed_keys(self) -> dict[str, str]:
        """The keys something other than an axis sets, with what sets them; raises if a path
        sets a key the case settings give another value."""
        given = self.base_config.to_dict()  # its mesh size and limit are fixed below
        defaults = CaseConfig().to_dict()
        fixed = {key: _CASE_SETTINGS for key in setting_keys(self.case)
                 if get_dotted(given, key) != get_dotted(defaults, key)}
        if self.mesh_size_mm is not None:
            fixed["geometry.mesh_size_mm"] = "--mesh-size (study.mesh_size)"
        if self.wall_time_limit_s is not None:
            fixed[WALL_CLOCK_KEY] = "--wall-time-limit (study.wall_time_limit)"
        by_paths = {}  # paths set the same keys to different values
        for path in study_paths(self.paths):
            for key in path.overrides:
                if key in fixed:
                    raise ParameterError(f"paths = {self.paths}: {path.label} sets {key}, "
                                         f"which {fixed[key]} sets too; drop it there, or "
                                         "use --paths 1")
                by_paths.setdefault(key, f"the numerical {path.label} (paths = {self.paths})")
        return {**fixed, **by_paths}

    # --- the cases ---------------------------------------------------------------------
    @property
    def axes(self) -> tuple[StudyAxis, ...]:
        """The comparison axes, then the uncertainty axes, in the order given."""
        return (*(StudyAxis(k, v, COMPARISON) for k, v in self.vary.items()),
                *(StudyAxis(k, v, UNCERTAINTY) for k, v in self.uncertain.items()))

    @property
    def adaptive(self) -> bool:
        return self.design == ADAPTIVE

    def initial_points(self) -> tuple[Point, ...]:
        """Round 0 of an adaptive study (:func:`valve_dolfinx.sizing.design.initial_design`
        over the grid's range, for every comparison value); none for a grid."""
        if not self.adaptive:
            return ()
        n_uncertain = math.prod(len(v) for v in self.uncertain.values())
        n_comparisons = math.prod(len(v) for v in self.vary.values())
        design = initial_design((self.widths_pct[0], self.widths_pct[-1]),
                                (self.heights_pct[0], self.heights_pct[-1]), n_uncertain,
                                self.paths)
        return tuple(Point(c, m, tuple(size)) for c in range(n_comparisons)
                     for m, size in design)

    def layout(self, rounds: Rounds = ()) -> StudyLayout:
        """Every case, its configuration and where it stands among the axes, with the
        rounds after round 0 ``rounds`` (:func:`valve_dolfinx.study.layout.read_rounds`;
        :func:`valve_dolfinx.study.layout.study_layout`)."""
        grid = ((), ()) if self.adaptive else (self.widths_pct, self.heights_pct)
        return study_layout(self.base_case(), self.axes, self.paths, *grid,
                            self.include_normal, (self.initial_points(), *rounds))

    def cases(self) -> list[StudyCase]:
        """Every case, in the fixed order that ``--case-index`` counts."""
        return list(self.layout().cases)

    def to_dict(self) -> dict:
        """The settings as given (``base_config`` is made from them)."""
        data = asdict(self)
        return {f.name: data[f.name] for f in fields(self) if f.init}

    @classmethod
    def from_dict(cls, data: dict, source: str = "study",
                  case_source: str = "study case settings") -> StudySettings:
        """Settings from a mapping (a TOML ``[study]`` table); unknown keys are rejected;
        ``case_source`` names the case settings' origin in their messages."""
        aliases = {"widths": "widths_pct", "heights": "heights_pct",
                   "mesh_size": "mesh_size_mm", "target_coaptation": "target_coaptation_mm",
                   "wall_time_limit": "wall_time_limit_s"}
        known = {f.name for f in fields(cls) if f.init}
        kw = {}
        for key, value in data.items():
            name = aliases.get(key, key)
            if name not in known:
                allowed = sorted(set(aliases) | known - set(aliases.values()))
                raise ParameterError(f"{source}: unknown key {key!r}; allowed keys are "
                                     f"{', '.join(allowed)}")
            kw[name] = value
        return cls(**kw, case_source=case_source)

    def replace(self, **changes: Any) -> StudySettings:
        """A copy with the given fields changed (``None`` values leave a field as it is)."""
        data = self.to_dict()
        data.update({k: v for k, v in changes.items() if v is not None})
        return StudySettings(**data)


def load_study_toml(path: str | Path, overrides: Iterable[str] = ()) -> StudySettings:
    """A sizing study's configuration file: the ``[study]`` table and the case settings.

    The file is a case configuration (the layout ``valve-dolfinx config`` prints, read
    by ``valve-dolfinx run --config`` too) with a ``[study]`` table for the grid; its
    case settings apply to every case, whose graft size the grid sets.  ``overrides``
    are ``table.key=value`` changes of the case settings (``--set``).  Example::

        [study]
        widths = [0, 7, 14, 21, 27]     # per cent
        heights = [0, 13, 27, 40]
        mesh_size = 0.8                 # mm
        panel_cases = ["W0_H0", "W7_H0", "W21_H27"]
        vary = {"native.bending_modulus_kpa" = [0, 200]}       # comparison axes
        uncertain = {"root.loaded_diameter_mm" = [20, 21, 22]}    # uncertainty axes
        paths = 2                       # numerical paths (uncertainty)
        design = "adaptive"             # or "grid" (the default): rounds chosen by the
        budget = 40                     # surface, at most this many graft cases

        [solver.pseudo_transient]       # the case settings of every case
        max_steps = 30000

    Raises
    ------
    ParameterError
        On an unknown key or a bad value, in ``[study]`` or in the case settings
        (named with its table), before anything runs.
    """
    data = read_config_file(path)
    study = data.pop(STUDY_TABLE, {})
    if not isinstance(study, dict):
        raise ParameterError(f"{path}: {STUDY_TABLE} must be a table ([study]) of the sweep "
                             "settings (widths, heights, mesh_size, ...)")
    if "case" in study:
        raise ParameterError(f"{path}: [study.case] is not read; write the case settings at "
                             "the top level of the file, in the layout `valve-dolfinx config` "
                             "prints (e.g. [solver.pseudo_transient] max_steps = 30000)")
    apply_overrides(data, overrides)
    return StudySettings.from_dict({**study, "case": data}, source=f"{path} [study]",
                                   case_source=str(path))
