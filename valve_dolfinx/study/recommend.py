"""The sizing recommendation: the worst case of each graft over its members (SPEC §7).

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

A graft **qualifies** when it converged, is competent (sealed, no intersection) and
reaches the target in every member: margin ≥ 0 with no member missing.  The
recommendation is the qualifying graft with the smallest flat area, which is the
native area times ``(1 + W)(1 + H)`` (ties: narrower, then lower).  If none
qualifies, the report says that no graft on the grid is robust and names the best
graft -- the largest margin among the grafts sound in every member (else
converged in every member, else any) -- and its shortfall.  A study of one member
is the special case: the worst case is the graft's only result.

A single number hides how sharp the optimum is, so the recommendation also
lists how much the worst-case figure changes from the chosen cell to each of its
grid neighbours, and the largest and median change between neighbouring cells.
How much the numerical path moves a cell is measured, not assumed: with two or
more paths it is part of the worst case and of the spread; a study of one path
says so.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from valve_dolfinx.result import competence_text, leaflets_intersect, margin_text, shortfall_digits

__all__ = ["CellSummary", "Recommendation", "recommend", "summarise_cells", "member_targets",
           "flat_area_ratio", "cell_state"]

FIGURE = "min_coaptation_height_mm"
#: the normal valve's figure, as the target says where it comes from
NORMAL_TARGET = "the normal valve's minimum coaptation height"


def flat_area_ratio(width_pct: float, height_pct: float) -> float:
    """Flat graft area over the native leaflet's, (1 + W)(1 + H)."""
    return (1 + width_pct / 100) * (1 + height_pct / 100)


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

    @property
    def label(self) -> str:
        return f"W{self.width_pct:g}/H{self.height_pct:g}"

    @property
    def area_ratio(self) -> float:
        return flat_area_ratio(self.width_pct, self.height_pct)

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


@dataclass
class Recommendation:
    """Outcome of :func:`recommend` (heights in mm; members by label, "" in a one-member study).

    ``recommended`` is the chosen graft (``W14/H13``; None if none qualifies), with its
    worst-case height, flat area, ``margin_mm``, the ``limiting_member`` and the spread of
    its heights over the members.  When none qualifies, ``best`` is the graft closest to
    qualifying, with its worst-case height and ``shortfall_mm`` (in ``limiting_member``).
    ``shortfall_mm`` is negative when the best graft reaches the target in every member but
    does not converge or seal in some.
    ``target_mm`` is the target when it is the same in every member (a given threshold,
    or a one-member study's normal valve), else None; ``targets_mm`` holds each member's.
    ``neighbours`` maps each grid neighbour of the chosen (or best) cell to the change of
    the worst-case figure from that cell.  ``cells`` is the worst case of every graft.
    """

    comparison: dict[str, Any]
    members: list[str]
    targets_mm: dict[str, float | None]
    target_mm: float | None
    target_source: str
    recommended: str | None = None
    recommended_height_mm: float | None = None
    recommended_area_ratio: float | None = None
    margin_mm: float | None = None
    limiting_member: str | None = None
    spread_mm: float | None = None
    best: str | None = None
    best_height_mm: float | None = None
    best_is_sound: bool = False
    shortfall_mm: float | None = None
    neighbours: dict[str, float] = field(default_factory=dict)
    max_neighbour_step_mm: float | None = None
    median_neighbour_step_mm: float | None = None
    qualifying: list[str] = field(default_factory=list)
    cells: list[CellSummary] = field(default_factory=list)
    #: members whose target is the height of a normal valve that is not competent, with why
    #: (``competence_text``): a target no sound valve set
    incompetent_targets: dict[str, str] = field(default_factory=dict)
    text: str = ""

    def cell(self, label: str | None) -> CellSummary | None:
        return next((c for c in self.cells if c.label == label), None)

    def to_dict(self) -> dict:
        data = asdict(self)
        data["cells"] = [c.to_dict() for c in self.cells]
        return data


def _neighbours(cells: Sequence[CellSummary]) -> dict[tuple[float, float], list]:
    widths = sorted({c.width_pct for c in cells})
    heights = sorted({c.height_pct for c in cells})
    out = {}
    for i, w in enumerate(widths):
        for j, h in enumerate(heights):
            around = [(i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)]
            out[(w, h)] = [(widths[a], heights[b]) for a, b in around
                           if 0 <= a < len(widths) and 0 <= b < len(heights)]
    return out


def _worst(cell: CellSummary | None) -> float:
    return math.nan if cell is None or cell.worst_height_mm is None else cell.worst_height_mm


def _sharpness(rec: Recommendation, centre: CellSummary | None) -> list[str]:
    """The neighbour changes of the worst-case figure, around ``centre`` and over the grid."""
    by_size = {(c.width_pct, c.height_pct): c for c in rec.cells}
    neighbours = _neighbours(rec.cells)
    steps = [abs(_worst(by_size.get(b)) - _worst(by_size.get(a)))
             for a, around in neighbours.items() for b in around if b > a]
    steps = [s for s in steps if math.isfinite(s)]
    if steps:
        rec.max_neighbour_step_mm, rec.median_neighbour_step_mm = max(steps), statistics.median(
            steps)
    lines = []
    if centre is not None:
        here = _worst(centre)
        for size in neighbours[(centre.width_pct, centre.height_pct)]:
            change = _worst(by_size.get(size)) - here
            if math.isfinite(change):
                rec.neighbours[by_size[size].label] = change
        if rec.neighbours:
            moves = ", ".join(f"{k} {v:+.2f} mm" for k, v in rec.neighbours.items())
            lines.append(f"From {centre.label}, the neighbouring grid cells change the "
                         f"{'worst-case ' if len(rec.members) > 1 else ''}minimum coaptation "
                         f"height by {moves}.")
    if steps:
        lines.append(f"Across the grid, neighbouring cells differ by up to "
                     f"{rec.max_neighbour_step_mm:.2f} mm (median "
                     f"{rec.median_neighbour_step_mm:.2f} mm).")
    return lines


def _member(label: str | None) -> str:
    return f"`{label}`" if label else "its member"


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


def _chosen_text(rec: Recommendation, chosen: CellSummary) -> str:
    head = (f"Recommended graft: **{chosen.label}** (+{chosen.width_pct:g} % width, "
            f"+{chosen.height_pct:g} % height; flat area {chosen.area_ratio:.3f} × native), "
            "the smallest graft on the grid that converged, seals and reaches the target "
            "minimum coaptation height")
    n = len(rec.members)
    if n == 1:
        return (f"{head} {rec.target_mm:.2f} mm ({rec.target_source}): "
                f"{chosen.worst_height_mm:.2f} mm, a margin of "
                f"{margin_text(chosen.margin_mm)} mm.")
    limit = chosen.limiting_member
    return (f"{head} ({rec.target_source}) in every one of its {n} members: margin "
            f"{margin_text(chosen.margin_mm)} mm, limited by {_member(limit)} "
            f"({chosen.heights_mm[limit]:.2f} mm against {rec.targets_mm[limit]:.2f} mm); over "
            f"its members its minimum coaptation height spans {chosen.worst_height_mm:.2f}"
            f"–{chosen.worst_height_mm + chosen.spread_mm:.2f} mm.")


def _best_text(rec: Recommendation, best: CellSummary | None) -> str:
    n = len(rec.members)
    missing_target = [m for m, t in rec.targets_mm.items() if t is None]
    if best is None:
        return "No graft case has a minimum coaptation height: nothing to recommend."
    if missing_target:
        where = "" if n == 1 else f" in {len(missing_target)} of {n} members"
        return (f"No target ({rec.target_source}{where}: the normal valve was not run or did "
                f"not converge; give --target-coaptation). The best graft is **{best.label}** "
                f"({cell_state(best)}): {best.worst_height_mm:.2f} mm at worst.")
    short = rec.shortfall_mm
    d = shortfall_digits(abs(short))
    limit = best.limiting_member
    if short <= 0:  # high enough everywhere, but not sound
        where = "" if n == 1 else " in every member"
        return (f"No graft on the grid {'is robust' if n > 1 else 'qualifies'}: none "
                f"converges, seals and reaches the target minimum coaptation height "
                f"({rec.target_source}){' in every one of its members' if n > 1 else ''}. "
                f"The best is **{best.label}** ({cell_state(best)}); its height reaches the "
                f"target{where} (margin {-short:.{d}f} mm).")
    if n == 1:
        return (f"No graft on the grid converges, seals and reaches the target minimum "
                f"coaptation height {rec.target_mm:.{d}f} mm ({rec.target_source}). The best "
                f"is **{best.label}** ({cell_state(best)}) with {best.worst_height_mm:.{d}f} mm, "
                f"{short:.{d}f} mm short.")
    return (f"No graft on the grid is robust: none converges, seals and reaches the target "
            f"minimum coaptation height ({rec.target_source}) in every one of its {n} members. "
            f"The best is **{best.label}** ({cell_state(best)}), {short:.{d}f} mm short in "
            f"{_member(limit)} ({best.heights_mm[limit]:.{d}f} mm against "
            f"{rec.targets_mm[limit]:.{d}f} mm).")


def _incompetent_normals(tables: Mapping[str, Sequence[Mapping]]) -> dict[str, str]:
    """``{member: competence_text}`` of the members whose normal valve is not competent."""
    out = {}
    for member, rows in tables.items():
        normal = next((r for r in rows if r.get("graft_width_pct") is None), None)
        if normal is not None and not normal.get("competent"):
            out[member] = competence_text(normal)
    return out


def _incompetent_text(rec: Recommendation) -> list[str]:
    """The sentence that says a target comes from a normal valve that is not competent."""
    if not rec.incompetent_targets:
        return []
    which = "; ".join(f"{_member(m)}: {why}" if m else why
                      for m, why in rec.incompetent_targets.items())
    return [f"Caution: the target is the height of a normal valve that is not competent "
            f"({which}), not that of a sound valve; give --target-coaptation to measure the "
            "grafts against a height of your choice."]


def _best(cells: Sequence[CellSummary]) -> CellSummary | None:
    """The graft closest to qualifying: sound everywhere, else converged everywhere, else any;
    then the largest margin (the largest worst-case height without a target)."""
    pool = ([c for c in cells if c.sound and c.worst_height_mm is not None]
            or [c for c in cells if c.converged and c.worst_height_mm is not None]
            or [c for c in cells if c.worst_height_mm is not None])
    if not pool:
        return None
    if all(c.margin_mm is not None and not c.missing for c in pool):
        return max(pool, key=lambda c: c.margin_mm)
    return max(pool, key=lambda c: c.worst_height_mm)


def recommend(tables: Mapping[str, Sequence[Mapping]] | Sequence[Mapping],
              target_mm: float | None = None, *, comparison: Mapping[str, Any] | None = None,
              n_paths: int = 1) -> Recommendation:
    """The smallest graft that qualifies in every member, or the statement that none does.

    Parameters
    ----------
    tables
        ``{member label: rows}``, the rows of each member (the normal valve and the
        grafts: ``graft_width_pct`` and ``graft_height_pct`` (None for the normal valve),
        ``converged``, ``competent``, ``min_coaptation_height_mm``,
        ``regurgitant_orifice_area_mm2``, ``intersecting_pairs``);
        a plain list of rows is a study of one member.
    target_mm
        Minimum coaptation height to reach in every member; None takes each member's
        normal valve's (which then has to have converged).
    comparison
        The comparison values these members share (for the report), e.g.
        ``{"bending_modulus_kpa": 0.0}``.
    n_paths
        Numerical paths among the members; with one, the text says the path was not
        varied.
    """
    tables = _as_tables(tables)
    targets, source = member_targets(tables, target_mm)
    same = {t for t in targets.values()}
    rec = Recommendation(dict(comparison or {}), list(tables), targets,
                         next(iter(same)) if len(same) == 1 else None, source)
    rec.cells = summarise_cells(tables, targets)
    qualifying = sorted((c for c in rec.cells if c.qualifies),
                        key=lambda c: (c.area_ratio, c.width_pct, c.height_pct))
    rec.qualifying = [c.label for c in qualifying]
    if qualifying:
        centre = qualifying[0]
        rec.recommended, rec.recommended_height_mm = centre.label, centre.worst_height_mm
        rec.recommended_area_ratio, rec.margin_mm = centre.area_ratio, centre.margin_mm
        rec.limiting_member, rec.spread_mm = centre.limiting_member, centre.spread_mm
        lines = [_chosen_text(rec, centre)]
        if len(qualifying) > 1:
            lines.append(f"{len(qualifying)} grafts qualify: {', '.join(rec.qualifying)}.")
    else:
        centre = _best(rec.cells)
        if centre is not None:
            rec.best, rec.best_height_mm = centre.label, centre.worst_height_mm
            rec.best_is_sound, rec.limiting_member = centre.sound, centre.limiting_member
            rec.spread_mm = centre.spread_mm
            if centre.margin_mm is not None and None not in targets.values():
                rec.shortfall_mm = -centre.margin_mm
        lines = [_best_text(rec, centre)]
    if target_mm is None:
        rec.incompetent_targets = _incompetent_normals(tables)
        lines += _incompetent_text(rec)
    if centre is not None and n_paths == 1:
        lines.append("Each cell was solved along one numerical path; `--paths 2` solves it "
                     "along a second one too and takes the worse (docs/study.md, \"Paths\").")
    lines += _sharpness(rec, centre)
    rec.text = " ".join(lines)
    return rec
