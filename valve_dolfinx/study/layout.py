"""The cases of a study and where each stands among its axes (SPEC §7).

A study's *slots* are every combination of

* a **comparison** value (one value of each ``vary`` axis),
* a **member**: one value of each ``uncertain`` axis and one numerical path,
* the normal valve or a graft size ``(W, H)``.

Each slot has a case configuration: the study's case settings, the slot's
axis values, its path's settings and the graft size; the normal valve's
configuration has every graft-only setting at its default
(:meth:`valve_dolfinx.config.CaseConfig.normal_valve`).  Slots whose
configuration (and start, below) is the same are **one case**, computed once:
the normal valve does not depend on the path, nor on any graft setting, so a
study runs it once per combination of the other axes' values.  A case is
named by its graft size and by the values it is fixed on, for instance
``W14_H13__root.loaded_diameter_mm=21__path=2``: an axis whose value does not
change the case (the path of the normal valve) is left out of the name, and
so is the first path (a plain sweep's folder names are ``normal`` and
``W14_H13``, and ``--paths 2`` reuses them for its first path).

A path may start its grafts from the loaded normal valve of the same member
(:data:`valve_dolfinx.study.paths.START_FROM_NORMAL`); the case then records
that source (``start_from``), and its identity (:func:`case_digest`) includes
the source's, so a changed source recomputes it.

Beside the grid, a study solves *points* added in rounds: a graft size in one member,
or in every member (the confirmation of an answer), of one comparison value.  An adaptive
study (:mod:`valve_dolfinx.sizing.design`) has no grid: its round 0 is its initial
design, and every later round is decided from the cases solved before it.  The rounds
after round 0 are listed in the study folder's :data:`ROUNDS_FILE`.

Order: the normal valves first, then the grid's grafts, each in slot order
(comparison values, then members, then W, then H, as given), then the points of each
round in the order they were added.  The case index (``--case-index``) is the position
in that order, so a round never renumbers the cases before it; a source always precedes
the cases that start from it.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from valve_dolfinx.config import (
    CaseConfig,
    canonical_hash,
    config_from_dict,
    set_dotted,
    settings_hash,
)
from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.sizing.answer import MemberTable
from valve_dolfinx.study.axes import PATH_KEY, StudyAxis, axis_label, value_text
from valve_dolfinx.study.paths import START_FROM_NORMAL, StudyPath, study_paths

__all__ = [
    "NORMAL_CASE",
    "ROUNDS_FILE",
    "Point",
    "read_rounds",
    "rounds_data",
    "StudyCase",
    "Member",
    "StudyLayout",
    "case_name",
    "case_digest",
    "study_layout",
    "layout_tables",
]

#: Name of the normal valve's case folder (before any axis values)
NORMAL_CASE = "normal"
#: the study folder's rounds of points after round 0 (``{"rounds": [[{"comparison": c,
#: "member": m or null, "size": [W, H]}, ...], ...]}``; member null: every member, the
#: confirmation of an answer), written by the sweep and by ``report``, read by every reader
ROUNDS_FILE = "rounds.json"

Size = tuple[float, float] | None
#: (comparison index, member index, graft size or None for the normal valve)
Slot = tuple[int, int, Size]


@dataclass(frozen=True)
class Point:
    """A graft size added to a study in a round: in one member (its index among the
    study's members) or, with ``member`` None, in every member (an answer's confirmation)
    of comparison value ``comparison``."""

    comparison: int
    member: int | None
    size: tuple[float, float]

    @property
    def confirms(self) -> bool:
        return self.member is None

    def to_dict(self) -> dict:
        return {"comparison": self.comparison, "member": self.member,
                "size": list(self.size)}

    @classmethod
    def from_dict(cls, data: Mapping) -> Point:
        member = data.get("member")
        return cls(int(data["comparison"]), None if member is None else int(member),
                   (float(data["size"][0]), float(data["size"][1])))

Rounds = Sequence[Sequence[Point]]


def case_name(width_pct: float | None, height_pct: float | None) -> str:
    """A case's name before its axis values: ``normal`` or ``W<width>_H<height>``.

    The same as :func:`valve_dolfinx.config.case_name` of the case's geometry.
    """
    if width_pct is None:
        return NORMAL_CASE
    return GraftSize(width_pct, height_pct).stem


def case_digest(config: Mapping[str, Any], start: str | None = None) -> str:
    """The identity of a case: its settings hash (:func:`valve_dolfinx.config.settings_hash`
    of ``CaseConfig.to_dict()``, the ``settings_hash`` of its ``result.json``), combined
    with its start's digest when it starts from another case's state.

    The wall-clock limits are not part of it: the resume check
    (:func:`valve_dolfinx.result.check_case`) recomputes a case that did not converge
    when its limit changes.
    """
    if start is None:
        return settings_hash(config)
    return canonical_hash({"settings": settings_hash(config), "start_from": start})


@dataclass(frozen=True)
class StudyCase:
    """One case of a study: the normal valve (``width_pct is None``) or a graft size.

    Attributes
    ----------
    index
        Position in the study's fixed order (``--case-index``).
    width_pct, height_pct
        Graft enlargements in per cent; ``None`` for the normal valve.
    name
        The case's folder name (default: :func:`case_name`).
    values
        ``((key, value), ...)``: the case's value of every axis, then of ``"path"`` (the
        path's number).  A tuple lists the values of an axis the case serves, being the
        same case for each of them (the normal valve on every path).
    start_from
        Name of the case whose loaded state this one starts from; ``None``: the unloaded
        valve.
    confirmation
        A size an answer proposed, solved in every member to confirm it.
    round
        The round that added it (0: the grid, or an adaptive study's initial design).
    """

    index: int
    width_pct: float | None
    height_pct: float | None
    name: str = ""
    values: tuple[tuple[str, Any], ...] = ()
    start_from: str | None = None
    confirmation: bool = False
    round: int = 0

    def __post_init__(self) -> None:
        if not self.name:
            object.__setattr__(self, "name", case_name(self.width_pct, self.height_pct))

    @property
    def is_normal(self) -> bool:
        return self.width_pct is None

    @property
    def size(self) -> Size:
        return None if self.width_pct is None else (self.width_pct, self.height_pct)

    @property
    def axis_values(self) -> dict[str, Any]:
        """``{key: value}`` of :attr:`values` (lists for the values of a served axis)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self.values}


@dataclass(frozen=True)
class Member:
    """One member of every cell: a value of each uncertainty axis and a numerical path.

    ``label`` names it in reports (``root.loaded_diameter_mm=21, path 2 (billowed)``); it is
    empty in a study with a single member.
    """

    values: tuple[tuple[str, Any], ...]
    path: StudyPath
    label: str


@dataclass(frozen=True)
class StudyLayout:
    """Every case of a study, its configuration, and which slot each case fills.

    Attributes
    ----------
    axes, paths
        The study's axes (comparison first) and numerical paths.
    comparisons
        ``((key, value), ...)`` per combination of the comparison values (one empty tuple
        when the study varies nothing).
    members
        The members of every cell, in order (uncertainty values, then path).
    sizes
        The graft sizes ``(W, H)`` of the grid, width by width (none in an adaptive study).
    rounds
        The points of every round, round 0 first (the grid's cases are not listed);
        :attr:`confirm` gives those solved in every member.
    cases
        Every case in the fixed order of ``--case-index``.
    configs, digests
        Each case's ``CaseConfig`` and identity (:func:`case_digest`), by name.
    slots
        ``(comparison index, member index, (W, H) or None) -> case name``.
    """

    axes: tuple[StudyAxis, ...]
    paths: tuple[StudyPath, ...]
    comparisons: tuple[tuple[tuple[str, Any], ...], ...]
    members: tuple[Member, ...]
    sizes: tuple[tuple[float, float], ...]
    cases: tuple[StudyCase, ...]
    configs: Mapping[str, CaseConfig] = field(repr=False)
    digests: Mapping[str, str] = field(repr=False)
    slots: Mapping[Slot, str] = field(repr=False)
    rounds: tuple[tuple[Point, ...], ...] = ()

    @property
    def confirm(self) -> dict[int, tuple[tuple[float, float], ...]]:
        """Per comparison index, the sizes its rounds solved in every member (the
        confirmations of its answer), in the order they were proposed."""
        out: dict[int, tuple[tuple[float, float], ...]] = {}
        for points in self.rounds:
            for p in points:
                if p.confirms and p.size not in out.get(p.comparison, ()):
                    out[p.comparison] = (*out.get(p.comparison, ()), p.size)
        return out

    @property
    def graft_cases(self) -> int:
        """The number of graft cases (the normal valves left out)."""
        return sum(not c.is_normal for c in self.cases)

    def case(self, name: str) -> StudyCase:
        return next(c for c in self.cases if c.name == name)

    def panel_cases(self, grafts: Sequence[str]) -> list[StudyCase]:
        """The cases whose figures the report's panels show: the first, in the study's
        order, of the normal valve and of each of ``grafts`` (``W0_H0``, whatever its
        member) that the study has."""
        first = {}
        for case in self.cases:
            first.setdefault(case_name(case.width_pct, case.height_pct), case)
        return [first[name] for name in dict.fromkeys([NORMAL_CASE, *grafts])
                if name in first]

    def select(self, indices: Sequence[int] | None) -> list[StudyCase]:
        """The cases with the given indices (all if ``None``); bad indices name the range."""
        if indices is None:
            return list(self.cases)
        n = len(self.cases)
        for i in indices:
            if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < n:
                raise ParameterError(f"case index {i!r} is outside the allowed range "
                                     f"[0, {n - 1}]: this study has {n} cases "
                                     "(`valve-dolfinx sweep --list` prints them)")
        return [self.cases[i] for i in dict.fromkeys(indices)]

    def comparison_label(self, index: int) -> str:
        """``key=value, ...`` of comparison ``index`` ("" when nothing is varied)."""
        return axis_label(self.comparisons[index])

    def member_cases(self, comparison: int) -> dict[str, dict[Size, str]]:
        """``{member label: {(W, H) or None: case name}}`` of one comparison value."""
        return {member.label: {size: name for (c, m, size), name in self.slots.items()
                               if c == comparison and m == index}
                for index, member in enumerate(self.members)}


def _product(axes: Sequence[StudyAxis]) -> list[tuple[tuple[str, Any], ...]]:
    return [tuple(zip([a.key for a in axes], combo, strict=True))
            for combo in itertools.product(*[a.values for a in axes])]


def _members(axes: Sequence[StudyAxis], paths: Sequence[StudyPath]) -> tuple[Member, ...]:
    members = []
    for values in _product(axes):
        for path in paths:
            parts = [axis_label(values)] if values else []
            if len(paths) > 1:
                parts.append(path.label)
            members.append(Member(values, path, ", ".join(parts)))
    return tuple(members)


def _slot_configs(base: Mapping, include_normal: bool, comparisons, members, sizes, rounds
                  ) -> tuple[dict[Slot, CaseConfig], dict[Slot, tuple[int, bool]]]:
    """The configuration of every slot (errors name the slot's axis values): the grid's, then
    each round's points in order (so that no round renumbers the cases before it); and the
    round and confirmation flag of every slot a round added."""
    configs: dict[Slot, CaseConfig] = {}
    plain: dict[tuple[int, int], CaseConfig] = {}
    for c, comparison in enumerate(comparisons):
        for m, member in enumerate(members):
            where = ", ".join(p for p in (axis_label(comparison + member.values),
                                          member.path.label) if p)
            data = json.loads(json.dumps(base))
            for key, value in (*comparison, *member.values, *member.path.overrides.items()):
                set_dotted(data, key, value)
            config = config_from_dict(data, source=f"study case settings at {where}")
            plain[(c, m)] = config
            try:
                if include_normal:
                    configs[(c, m, None)] = config.normal_valve()
                for size in sizes:
                    configs[(c, m, size)] = config.with_graft(*size)
            except ParameterError as err:
                raise ParameterError(f"study case settings at {where}: {err}") from None
    added: dict[Slot, tuple[int, bool]] = {}
    for number, points in enumerate(rounds):
        for point in points:
            if point.comparison >= len(comparisons):
                continue
            where = range(len(members)) if point.confirms else (point.member,)
            for m in where:
                slot = (point.comparison, m, point.size)
                if slot not in configs:
                    try:
                        configs[slot] = plain[(point.comparison, m)].with_graft(*point.size)
                    except ParameterError as err:
                        raise ParameterError(f"round {number} of the study: {err}") from None
                    added[slot] = (number, point.confirms)
    return configs, added


def _values(slots: Sequence[Slot], axes: Sequence[StudyAxis], comparisons, members
            ) -> tuple[tuple[str, Any], ...]:
    """A case's value of each axis and path over the slots it fills (a tuple when several)."""
    out = []
    for axis in axes:
        seen = [dict(comparisons[c] if axis.is_comparison else members[m].values)[axis.key]
                for c, m, _ in slots]
        kept = tuple(v for v in axis.values if v in seen)
        out.append((axis.key, kept[0] if len(kept) == 1 else kept))
    numbers = tuple(sorted({members[m].path.number for _, m, _ in slots}))
    out.append((PATH_KEY, numbers[0] if len(numbers) == 1 else numbers))
    return tuple(out)


def _name(size: Size, values: tuple[tuple[str, Any], ...]) -> str:
    parts = [case_name(*(size or (None, None)))]
    for key, value in values:
        if isinstance(value, tuple):
            continue
        if key == PATH_KEY:
            if value > 1:
                parts.append(f"{PATH_KEY}={value}")
        else:
            parts.append(f"{key}={value_text(value)}")
    return "__".join(parts)


def study_layout(base_case: Mapping, axes: Sequence[StudyAxis], paths: int,
                 widths_pct: Sequence[float], heights_pct: Sequence[float],
                 include_normal: bool = True, rounds: Rounds = ()) -> StudyLayout:
    """Enumerate a study's cases: build every slot's configuration, merge slots that are the
    same case, name the cases and order them (see the module docstring).

    ``base_case`` is the case settings every case starts from, ``axes`` the comparison and
    uncertainty axes, ``paths`` the number of numerical paths, and the grid's widths and
    heights the graft sizes (:meth:`valve_dolfinx.study.grid.StudySettings.layout` passes
    its own, checked; none for an adaptive study).  ``rounds`` adds, round by round, its
    :class:`Point` s: ordinary cases, named and identified as every other, after the
    grid's (points of a comparison value the study does not have are left out).

    Raises
    ------
    ParameterError
        Naming the axis values and path, if a combination gives a configuration the
        package rejects; and for a path that starts from the normal valve in a study
        without it.
    """
    axes = tuple(axes)
    paths = study_paths(paths)
    comparisons = tuple(_product([a for a in axes if a.is_comparison]))
    members = _members([a for a in axes if not a.is_comparison], paths)
    sizes = tuple((w, h) for w in widths_pct for h in heights_pct)
    rounds = tuple(tuple(p for p in points if p.comparison < len(comparisons))
                   for points in rounds)
    configs, added = _slot_configs(base_case, include_normal, comparisons, members, sizes,
                                   rounds)
    digests: dict[Slot, str] = {}
    for slot, config in configs.items():  # normal valves first: the grafts' sources
        if slot[2] is None:
            digests[slot] = case_digest(config.to_dict())
    for slot, config in configs.items():
        if slot[2] is not None:
            start = None
            if members[slot[1]].path.start == START_FROM_NORMAL:
                if not include_normal:
                    raise ParameterError(f"{members[slot[1]].path.label} starts its grafts "
                                         "from the normal valve: include_normal must be true")
                start = digests[(slot[0], slot[1], None)]
            digests[slot] = case_digest(config.to_dict(), start)
    groups: dict[str, list[Slot]] = {}
    for slot in digests:  # dicts keep the order: normal valves, then grafts, in slot order
        groups.setdefault(digests[slot], []).append(slot)
    names = {}
    for digest, slots in groups.items():
        names[digest] = _name(slots[0][2], _values(slots, axes, comparisons, members))
    repeated = {n for n in names.values() if list(names.values()).count(n) > 1}
    names = {d: f"{n}__{d[:8]}" if n in repeated else n for d, n in names.items()}
    cases = []
    for index, (digest, slots) in enumerate(groups.items()):
        c, m, size = slots[0]
        start = None
        if size is not None and members[m].path.start == START_FROM_NORMAL:
            start = names[digests[(c, m, None)]]
        number, confirms = added.get(slots[0], (0, False))
        cases.append(StudyCase(index, *(size or (None, None)), name=names[digest],
                               values=_values(slots, axes, comparisons, members),
                               start_from=start, confirmation=confirms, round=number))
    return StudyLayout(
        axes=axes, paths=paths, comparisons=comparisons, members=members, sizes=sizes,
        cases=tuple(cases),
        configs={names[d]: configs[slots[0]] for d, slots in groups.items()},
        digests={names[d]: d for d in groups},
        slots={slot: names[digests[slot]] for slot in digests}, rounds=rounds)


def layout_tables(layout: StudyLayout, comparison: int, rows: Sequence[Mapping]
                  ) -> list[MemberTable]:
    """The member tables of one comparison value of a study, from the rows at hand (a case
    not finished yet, damaged or stale is left out)."""
    by_name = {r["case"]: r for r in rows if r.get("status") not in ("damaged", "stale")}
    members = {m.label: m for m in layout.members}
    return [MemberTable(label, [by_name[name] for name in cases.values() if name in by_name],
                        comparison=layout.comparisons[comparison],
                        uncertain=members[label].values, path=members[label].path.number)
            for label, cases in layout.member_cases(comparison).items()]


def read_rounds(out) -> tuple[tuple[Point, ...], ...]:
    """The rounds after round 0 of the study folder ``out`` (:data:`ROUNDS_FILE`; none
    without one)."""
    path = Path(out) / ROUNDS_FILE
    if not path.is_file():
        return ()
    data = json.loads(path.read_text(encoding="utf-8"))
    return tuple(tuple(Point.from_dict(p) for p in points)
                 for points in data.get("rounds") or ())


def rounds_data(rounds: Rounds) -> dict:
    """What :data:`ROUNDS_FILE` holds for ``rounds`` (those after round 0)."""
    return {"rounds": [[p.to_dict() for p in points] for points in rounds]}
