"""The solved cells of a study: each graft's worst case over its members (SPEC §7).

A study solves every cell (a graft, at one value of each comparison axis) in
several *members*: the combinations of the uncertainty values and the numerical
paths.  The target in each member is the normal valve's minimum coaptation
height in that member (or a threshold the user gives).  Per graft, over its
members (:class:`CellSummary`):

* the worst (lowest) minimum coaptation height, the member where it occurs, and
  the spread (highest minus lowest);
* the members where the graft did not converge, leaks (regurgitant orifice area
  above 0) or has leaflets that intersect (an edge of the loaded surface through one of
  its triangles, as ``competent`` counts it);
* the margin: the least, over the members, of its height minus that member's
  target, and the member that sets it (the *limiting* member).

A cell *qualifies* when it converged, is competent and reaches the target in every
member.  These are the solved numbers as they are, shown in every report beside the
answer; the answer itself is read from the response surface fitted to them
(:mod:`valve_dolfinx.sizing.answer`).  :class:`GraftSize` is the one value type of a
graft's size, on the grid or off it (defined beside the leaflet's outline,
:mod:`valve_dolfinx.geometry.outline`).  Nothing here imports DOLFINx.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field

from valve_dolfinx.geometry.outline import GraftSize, flat_area_ratio
from valve_dolfinx.result import competence_text, leaflets_intersect

__all__ = ["FIGURE", "NORMAL_TARGET", "GraftSize", "CellSummary", "summarise_cells",
           "member_targets", "incompetent_normals", "flat_area_ratio", "cell_state"]

FIGURE = "min_coaptation_height_mm"
#: the normal valve's figure, as the target says where it comes from
NORMAL_TARGET = "the normal valve's minimum coaptation height"


def _number(row: Mapping | None, key: str) -> float:
    v = None if row is None else row.get(key)
    ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
    return float(v) if ok else math.nan


@dataclass
class CellSummary:
    """One graft over the members of its cell (heights in mm, members by label)."""

    width_pct: float
    height_pct: float
    members: list[str]
    heights_mm: dict[str, float] = field(default_factory=dict)
    margins_mm: dict[str, float] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)
    unconverged: list[str] = field(default_factory=list)
    leaking: list[str] = field(default_factory=list)
    intersecting: list[str] = field(default_factory=list)
    incompetent: list[str] = field(default_factory=list)
    #: why each member in ``incompetent`` is not competent (its ``competence_reason``)
    reasons: dict[str, str] = field(default_factory=dict)
    largest_orifice_mm2: float | None = None
    #: the most intersecting edge–triangle pairs of a member
    most_intersecting_pairs: int | None = None
    worst_height_mm: float | None = None
    worst_member: str | None = None
    spread_mm: float | None = None
    margin_mm: float | None = None
    limiting_member: str | None = None
    qualifies: bool = False
    #: solved to confirm an answer (a size off the grid)
    confirmation: bool = False

    @property
    def size(self) -> GraftSize:
        return GraftSize(self.width_pct, self.height_pct)

    @property
    def label(self) -> str:
        return self.size.label

    @property
    def area_ratio(self) -> float:
        return self.size.area_ratio

    @property
    def converged(self) -> bool:
        """Converged in every member (none missing)."""
        return not self.missing and not self.unconverged

    @property
    def sound(self) -> bool:
        """Converged and competent in every member (none missing)."""
        return self.converged and not self.incompetent

    def to_dict(self) -> dict:
        return {"graft": self.label, **asdict(self), "sound": self.sound}


def _summarise(width: float, height: float, rows: Mapping[str, Mapping | None],
               targets: Mapping[str, float | None]) -> CellSummary:
    cell = CellSummary(width, height, list(rows))
    for member, row in rows.items():
        if row is None:
            cell.missing.append(member)
            continue
        value = _number(row, FIGURE)
        cell.heights_mm[member] = value
        if not row.get("converged"):
            cell.unconverged.append(member)
        orifice = _number(row, "regurgitant_orifice_area_mm2")
        if orifice > 0:
            cell.leaking.append(member)
            cell.largest_orifice_mm2 = max(orifice, cell.largest_orifice_mm2 or 0.0)
        if leaflets_intersect(row):
            cell.intersecting.append(member)
            cell.most_intersecting_pairs = max(row["intersecting_pairs"],
                                               cell.most_intersecting_pairs or 0)
        if not row.get("competent"):
            cell.incompetent.append(member)
            cell.reasons[member] = row.get("competence_reason") or ""
        target = targets.get(member)
        if target is not None and math.isfinite(value):
            cell.margins_mm[member] = value - target
    finite = {m: v for m, v in cell.heights_mm.items() if math.isfinite(v)}
    if finite:
        cell.worst_member = min(finite, key=finite.get)
        cell.worst_height_mm = finite[cell.worst_member]
        cell.spread_mm = max(finite.values()) - cell.worst_height_mm
    if cell.margins_mm:
        cell.limiting_member = min(cell.margins_mm, key=cell.margins_mm.get)
        cell.margin_mm = cell.margins_mm[cell.limiting_member]
    complete = len(cell.margins_mm) == len(rows)  # every member has a figure and a target
    cell.qualifies = complete and cell.sound and cell.margin_mm >= 0
    return cell


def _as_tables(tables: Mapping[str, Sequence[Mapping]] | Sequence[Mapping]
               ) -> dict[str, Sequence[Mapping]]:
    return dict(tables) if isinstance(tables, Mapping) else {"": tables}


def member_targets(tables: Mapping[str, Sequence[Mapping]] | Sequence[Mapping],
                   target_mm: float | None = None) -> tuple[dict[str, float | None], str]:
    """The target of each member and where it comes from.

    ``target_mm`` if given; otherwise the figure of the member's normal valve (the row
    with ``graft_width_pct`` None) if it converged, else None.
    """
    tables = _as_tables(tables)
    if target_mm is not None:
        return dict.fromkeys(tables, float(target_mm)), "given threshold (--target-coaptation)"
    targets = {}
    for member, rows in tables.items():
        normal = next((r for r in rows if r.get("graft_width_pct") is None), None)
        value = _number(normal, FIGURE)
        ok = normal is not None and normal.get("converged") and math.isfinite(value)
        targets[member] = value if ok else None
    source = NORMAL_TARGET + (" in each member" if len(tables) > 1 else "")
    return targets, source


def incompetent_normals(tables: Mapping[str, Sequence[Mapping]] | Sequence[Mapping]
                        ) -> dict[str, str]:
    """``{member: competence_text}`` of the members whose normal valve is not competent."""
    out = {}
    for member, rows in _as_tables(tables).items():
        normal = next((r for r in rows if r.get("graft_width_pct") is None), None)
        if normal is not None and not normal.get("competent"):
            out[member] = competence_text(normal)
    return out


def summarise_cells(tables: Mapping[str, Sequence[Mapping]] | Sequence[Mapping],
                    targets: Mapping[str, float | None]) -> list[CellSummary]:
    """The worst case of every graft over the members (``{member: rows}``; a list of rows is
    one member), width by width, heights ascending."""
    tables = _as_tables(tables)
    sizes = sorted({(float(r["graft_width_pct"]), float(r["graft_height_pct"]))
                    for rows in tables.values() for r in rows
                    if r.get("graft_width_pct") is not None})
    by_member = {member: {(r["graft_width_pct"], r["graft_height_pct"]): r for r in rows
                          if r.get("graft_width_pct") is not None}
                 for member, rows in tables.items()}
    return [_summarise(w, h, {m: found.get((w, h)) for m, found in by_member.items()}, targets)
            for w, h in sizes]


def cell_state(cell: CellSummary) -> str:
    """How a graft fared over its members, in words ("converged and sealed in all 6
    members", "leaking in 2 of 6 members")."""
    n = len(cell.members)
    if n == 1:
        if cell.sound or cell.missing:
            return "converged and competent" if cell.sound else "not computed"
        why = next(iter(cell.reasons.values()), "") or (
            "not converged" if cell.unconverged else "")
        return f"not competent: {why}" if why else "not competent"
    if cell.sound:
        return f"converged and competent in all {n} members"
    parts = [f"{what} in {len(members)} of {n} members" for what, members in (
        ("not computed", cell.missing), ("not converged", cell.unconverged),
        ("leaking", cell.leaking), ("leaflets intersecting", cell.intersecting)) if members]
    return ", ".join(parts) or f"not sealed in {len(cell.incompetent)} of {n} members"
