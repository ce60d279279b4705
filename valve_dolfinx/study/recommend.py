"""The sizing recommendation from a study table (SPEC §7).

Rule: among the graft cases that converged and are competent (regurgitant
orifice 0), take those whose minimum native coaptation height reaches the
target -- the normal valve's minimum coaptation height, or a threshold the
user gives -- and recommend the smallest of them by flat graft area, which is
the native area times ``(1 + W)(1 + H)`` (ties: narrower, then lower).  If no
case qualifies, report the best case (largest minimum coaptation height,
preferring converged and competent cases) and by how much it falls short.

A single number hides how sharp the optimum is, so the recommendation also
lists how much the figure of merit changes from the chosen cell to each of its
grid neighbours, and the largest and median change between neighbouring cells
over the whole grid.  It also names the other sound grafts whose figure lies within
the model's path resolution of the target (:data:`PATH_RESOLUTION_MM`): a margin
smaller than that does not tell them apart.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import asdict, dataclass, field

__all__ = ["Recommendation", "recommend", "flat_area_ratio"]

FIGURE = "min_coaptation_height_mm"

#: Differences of the figure of merit below this (mm) are within the model's path
#: resolution at the default 0.8 mm mesh: the same graft on another numerical path (round-off
#: of another CPU, another step control, another initial placement) comes to rest up to
#: about this much higher or lower in most cells (docs/numerics.md §7, "Resolution").
PATH_RESOLUTION_MM = 0.3


def flat_area_ratio(row: dict) -> float:
    """Flat graft area over the native leaflet's, (1 + W)(1 + H)."""
    return (1 + row["graft_width_pct"] / 100) * (1 + row["graft_height_pct"] / 100)


def _value(row: dict | None) -> float:
    v = None if row is None else row.get(FIGURE)
    return float(v) if isinstance(v, int | float) and math.isfinite(v) else math.nan


def _size_order(row: dict) -> tuple[float, float, float]:
    """Smallest flat area first; ties: narrower, then lower."""
    return flat_area_ratio(row), row["graft_width_pct"], row["graft_height_pct"]


def _label(row: dict) -> str:
    return f"W{row['graft_width_pct']:g}/H{row['graft_height_pct']:g}"


def _sound(row: dict) -> bool:
    return bool(row.get("converged")) and bool(row.get("competent")) and not math.isnan(
        _value(row))


def _quality(row: dict) -> str:
    """``converged and competent``, or why a case is not sound (its competence reason)."""
    if _sound(row):
        return "converged and competent"
    if row.get("competence_reason"):
        return f"not competent: {row['competence_reason']}"
    return "not converged" if not row.get("converged") else "not competent"


@dataclass
class Recommendation:
    """Outcome of :func:`recommend` (all heights in mm).

    ``recommended`` is the chosen case's name (None if no case qualifies);
    ``best`` the case closest to the target when none does, with ``shortfall_mm``.
    ``neighbours`` maps each grid neighbour of the chosen (or best) cell to the
    change of the figure of merit from that cell.  ``near_target`` maps the other
    converged, sealed grafts whose figure lies within ``resolution_mm`` of the target
    to their figure (smallest flat area first).
    """

    target_mm: float | None
    target_source: str
    recommended: str | None = None
    recommended_height_mm: float | None = None
    recommended_area_ratio: float | None = None
    best: str | None = None
    best_height_mm: float | None = None
    best_is_sound: bool = False
    shortfall_mm: float | None = None
    neighbours: dict[str, float] = field(default_factory=dict)
    max_neighbour_step_mm: float | None = None
    median_neighbour_step_mm: float | None = None
    qualifying: list[str] = field(default_factory=list)
    resolution_mm: float = PATH_RESOLUTION_MM
    near_target: dict[str, float] = field(default_factory=dict)
    text: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def _grid_neighbours(grafts: list[dict]) -> dict[tuple[float, float], list[tuple[float, float]]]:
    widths = sorted({r["graft_width_pct"] for r in grafts})
    heights = sorted({r["graft_height_pct"] for r in grafts})
    out = {}
    for i, w in enumerate(widths):
        for j, h in enumerate(heights):
            cells = [(i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)]
            out[(w, h)] = [(widths[a], heights[b]) for a, b in cells
                           if 0 <= a < len(widths) and 0 <= b < len(heights)]
    return out


def _steps(grafts: list[dict]) -> tuple[float | None, float | None]:
    """Largest and median |change| of the figure between neighbouring grid cells."""
    by_size = {(r["graft_width_pct"], r["graft_height_pct"]): _value(r) for r in grafts}
    steps = []
    for (w, h), cells in _grid_neighbours(grafts).items():
        for other in cells:
            if other > (w, h):  # each pair once
                d = by_size.get(other, math.nan) - by_size.get((w, h), math.nan)
                if math.isfinite(d):
                    steps.append(abs(d))
    if not steps:
        return None, None
    return max(steps), statistics.median(steps)


def recommend(rows: list[dict], target_mm: float | None = None,
              resolution_mm: float = PATH_RESOLUTION_MM) -> Recommendation:
    """The smallest sound graft that reaches the target coaptation, or the best and its shortfall.

    Parameters
    ----------
    rows
        Study rows (:func:`valve_dolfinx.study.table.case_rows`): ``graft_width_pct``
        and ``graft_height_pct`` (None for the normal valve), ``converged``,
        ``competent`` and ``min_coaptation_height_mm``.
    target_mm
        Minimum coaptation height to reach; None takes the normal valve's (which
        then has to have converged).
    resolution_mm
        Differences of the figure below this are read as within the model's path
        resolution: the sound grafts within it of the target are named beside the choice.
    """
    normal = next((r for r in rows if r.get("graft_width_pct") is None), None)
    grafts = [r for r in rows if r.get("graft_width_pct") is not None]
    if target_mm is not None:
        rec = Recommendation(float(target_mm), "given threshold (--target-coaptation)")
    elif normal is not None and normal.get("converged") and math.isfinite(_value(normal)):
        rec = Recommendation(_value(normal), "the normal valve's minimum coaptation height")
    else:
        why = ("was not run" if normal is None else "did not converge"
               if normal.get("status", "finished") == "finished" else f"is {normal['status']}")
        rec = Recommendation(None, f"none: the normal valve {why}; give --target-coaptation")

    qualifying = []
    if rec.target_mm is not None:
        qualifying = [r for r in grafts if _sound(r) and _value(r) >= rec.target_mm]
    qualifying.sort(key=_size_order)
    rec.qualifying = [_label(r) for r in qualifying]
    rec.max_neighbour_step_mm, rec.median_neighbour_step_mm = _steps(grafts)
    lines = []
    if qualifying:
        chosen = qualifying[0]
        rec.recommended, rec.recommended_height_mm = _label(chosen), _value(chosen)
        rec.recommended_area_ratio = flat_area_ratio(chosen)
        lines.append(
            f"Recommended graft: **{rec.recommended}** (+{chosen['graft_width_pct']:g} % "
            f"width, +{chosen['graft_height_pct']:g} % height; flat area "
            f"{rec.recommended_area_ratio:.3f} × native), the smallest graft on the grid that "
            f"converged, seals and reaches the target minimum coaptation height "
            f"{rec.target_mm:.2f} mm ({rec.target_source}): {rec.recommended_height_mm:.2f} mm.")
        if len(qualifying) > 1:
            lines.append(f"{len(qualifying)} grafts qualify: {', '.join(rec.qualifying)}.")
        centre = chosen
    else:
        pool = ([r for r in grafts if _sound(r)]
                or [r for r in grafts if r.get("converged") and math.isfinite(_value(r))]
                or [r for r in grafts if math.isfinite(_value(r))])
        centre = max(pool, key=_value) if pool else None
        if centre is None:
            lines.append("No graft case has a minimum coaptation height: nothing to recommend.")
        else:
            rec.best, rec.best_height_mm = _label(centre), _value(centre)
            rec.best_is_sound = _sound(centre)
            quality = _quality(centre)
            if rec.target_mm is None:
                lines.append(f"No target ({rec.target_source}). The best graft is "
                             f"**{rec.best}** ({quality}): {rec.best_height_mm:.2f} mm.")
            else:
                rec.shortfall_mm = rec.target_mm - rec.best_height_mm
                # a shortfall that rounds to 0.00 mm is shown to the digit where it shows
                digits = 2 if not 0.0 < rec.shortfall_mm < 0.005 else max(
                    3, 1 - math.floor(math.log10(rec.shortfall_mm)))
                short = (f"{rec.shortfall_mm:.{digits}f} mm short" if rec.shortfall_mm > 0.0
                         else "which reaches the target, but the case does not qualify")
                lines.append(
                    f"No graft on the grid converges, seals and reaches the target minimum "
                    f"coaptation height {rec.target_mm:.{digits}f} mm ({rec.target_source}). "
                    f"The best is **{rec.best}** ({quality}) with "
                    f"{rec.best_height_mm:.{digits}f} mm, {short}.")
    if rec.target_mm is not None:
        rec.resolution_mm = float(resolution_mm)
        near = [r for r in grafts if _sound(r) and r is not centre
                and abs(_value(r) - rec.target_mm) < rec.resolution_mm]
        near.sort(key=_size_order)
        rec.near_target = {_label(r): _value(r) for r in near}
        listed = (", ".join(f"{k} {v:.2f} mm" for k, v in rec.near_target.items())
                  if near else "none")
        lines.append(f"Differences below {rec.resolution_mm:.2g} mm are within the model's "
                     f"path resolution at the default mesh (docs/numerics.md §7, "
                     f"\"Resolution\"); the other converged, sealed grafts that close to "
                     f"the target: {listed}.")
    if centre is not None:
        by_size = {(r["graft_width_pct"], r["graft_height_pct"]): r for r in grafts}
        here = _value(centre)
        for size in _grid_neighbours(grafts)[(centre["graft_width_pct"],
                                              centre["graft_height_pct"])]:
            other = by_size.get(size)
            if other is not None and math.isfinite(_value(other) - here):
                rec.neighbours[_label(other)] = _value(other) - here
        if rec.neighbours:
            moves = ", ".join(f"{k} {v:+.2f} mm" for k, v in rec.neighbours.items())
            lines.append(f"From {_label(centre)}, the neighbouring grid cells change the minimum "
                         f"coaptation height by {moves}.")
    if rec.max_neighbour_step_mm is not None:
        lines.append(f"Across the grid, neighbouring cells differ by up to "
                     f"{rec.max_neighbour_step_mm:.2f} mm (median "
                     f"{rec.median_neighbour_step_mm:.2f} mm).")
    rec.text = " ".join(lines)
    return rec
