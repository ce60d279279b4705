"""Figures of a sizing study, drawn from its recommendations (the worst case per graft).

* :func:`plot_coaptation_vs_width`: the worst-case minimum native coaptation height
  against graft width, one curve per graft height, with a bar up to the best member
  (the spread), and the target (the normal valve's, per member) as a line or band;
  grafts not sound in every member hollow.
* :func:`plot_sizing_map`: the answer over W × H: contours of the predicted worst-case
  margin, the sealing boundary, the band of qualifying sizes, the answer and the highest
  size, with the solved cells marked.
* :func:`plot_nomogram`: the recommended graft and its margin against the loaded root
  diameter (:mod:`valve_dolfinx.study.nomogram`).
* :func:`plot_case_panel`: the figure-style panel of one case (ventricular view,
  two axial cuts, coaptation region on the flat outline), assembled from the
  pictures ``run`` wrote into the case folder.

Each returns the figure and writes it to ``path`` if given.
"""

from __future__ import annotations

import logging
import math
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib
import numpy as np
from matplotlib.ticker import FuncFormatter, MaxNLocator

from valve_dolfinx.plotting.style import OKABE_ITO, new_figure, save_figure
from valve_dolfinx.result import margin_text

if TYPE_CHECKING:
    from valve_dolfinx.sizing import CellSummary, Recommendation

__all__ = ["plot_coaptation_vs_width", "plot_sizing_map", "sizing_map_key", "plot_nomogram",
           "plot_case_panel", "PANEL_IMAGES", "MIN_PRINT_PT"]

log = logging.getLogger(__name__)

#: the pictures of a case folder that make its panel, with their captions
PANEL_IMAGES = (("closed_valve_ventricular.png", "closed valve seen from the ventricle"),
                ("cut_planes.png", "axial cuts"),
                ("coaptation_map.png", "coaptation region on the flat leaflets"))


#: one colour per graft height (Okabe-Ito, black kept for the normal valve)
_CURVE_COLOURS = tuple(OKABE_ITO[k] for k in ("blue", "orange", "bluish_green", "reddish_purple",
                                              "sky_blue", "vermillion", "yellow"))
_TARGET_COLOUR = OKABE_ITO["vermillion"]
_LEAK_COLOUR = OKABE_ITO["vermillion"]


def _targets(rec: Recommendation) -> list[float]:
    return sorted({t for t in rec.targets_mm.values() if t is not None})


def _worst(cell: CellSummary) -> float:
    return math.nan if cell.worst_height_mm is None else cell.worst_height_mm


def _title(rec: Recommendation, what: str, title: str) -> str:
    """``what``, and on a second line the comparison values and the members' worst case."""
    n = len(rec.members)
    worst = f"worst case over {n} members" if n > 1 else ""
    more = ", ".join(p for p in (title, worst) if p)
    return f"{what}\n{more}" if more else what


def plot_coaptation_vs_width(rec: Recommendation, path: Path | None = None, *,
                             title: str = ""):
    """Worst-case minimum coaptation height against graft width, one curve per graft height;
    a bar up to the best member shows the spread."""
    cells = rec.cells
    heights = sorted({c.height_pct for c in cells})
    widths = sorted({c.width_pct for c in cells})
    step = min(np.diff(widths)) if len(widths) > 1 else 10.0
    fig = new_figure(9.5, 5.0, layout=None)  # the axes placed by hand, the key beside them
    ax = fig.add_axes((0.08, 0.11, 0.58, 0.78))
    for k, h in enumerate(heights):
        colour = _CURVE_COLOURS[k % len(_CURVE_COLOURS)]
        curve = sorted((c for c in cells if c.height_pct == h), key=lambda c: c.width_pct)
        # heights side by side within a width, so that their bars do not hide each other
        shift = step * 0.06 * (k - (len(heights) - 1) / 2) if len(rec.members) > 1 else 0.0
        w = np.array([c.width_pct for c in curve]) + shift
        y = np.array([_worst(c) for c in curve])
        spread = np.array([c.spread_mm if c.spread_mm is not None else 0.0 for c in curve])
        sound = np.array([c.sound for c in curve], dtype=bool)
        ax.plot(w, y, "-", color=colour, lw=1.5, label=f"H +{h:g} %")
        if len(rec.members) > 1:
            ax.errorbar(w, y, yerr=[np.zeros_like(spread), spread], fmt="none", ecolor=colour,
                        elinewidth=1.2, capsize=3)
        ax.plot(w[sound], y[sound], "o", color=colour, ms=7)
        ax.plot(w[~sound], y[~sound], "o", mfc="white", mec=colour, mew=1.8, ms=7)
    targets = _targets(rec)
    if len(targets) == 1:
        ax.axhline(targets[0], color=_TARGET_COLOUR, ls="--", lw=1.2,
                   label=textwrap.fill(f"target {targets[0]:.2f} mm ({rec.target_source})", 30))
    elif targets:
        ax.axhspan(targets[0], targets[-1], color=_TARGET_COLOUR, alpha=0.15, lw=0,
                   label=textwrap.fill(f"targets {targets[0]:.2f}–{targets[-1]:.2f} mm "
                                       f"({rec.target_source})", 30))
    ax.plot([], [], "o", mfc="white", mec="0.3", label="not competent"
            + (" in some member" if len(rec.members) > 1 else ""))
    if len(rec.members) > 1:
        ax.errorbar([], [], yerr=[], fmt="none", ecolor="0.3", capsize=3,
                    label="bar: up to the best member (spread)")
    ax.set_xlabel("graft width enlargement W (%)")
    ax.set_ylabel("minimum native coaptation height (mm)")
    if widths:
        ax.set_xticks(widths)
    ax.grid(alpha=0.3)
    # the key beside the plot: inside it, it would cover some cell's point
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    ax.set_title(_title(rec, "Minimum coaptation height of the native leaflets", title),
                 fontsize=11)
    return save_figure(fig, path, dpi=130)


#: the sizing map's default size (inches)
_MAP_SIZE_IN = (8.6, 7.4)
#: the smallest text of a figure drawn at its print size (points)
MIN_PRINT_PT = 7.5
#: the diverging colour map of a margin over the target (blue above, red below)
_MARGIN_CMAP = "RdBu"


#: label directions around a point: (dx, dy, ha, va), in order of preference
_AROUND = ((0, -1, "center", "top"), (0, 1, "center", "bottom"), (1, 0, "left", "center"),
           (-1, 0, "right", "center"), (1, -1, "left", "top"), (-1, -1, "right", "top"),
           (1, 1, "left", "bottom"), (-1, 1, "right", "bottom"))
#: how far from its point a label may go, in multiples of its gap (beyond the first, a thin
#: line leads back to the point)
_REACH = (1.0, 2.2, 3.6, 5.0)


def _label_box(label, renderer):
    """The display box of an annotation's text and its background (not its leader line)."""
    from matplotlib.text import Text

    label.update_positions(renderer)
    patch = label.get_bbox_patch()
    pad = 0.0 if patch is None else patch.get_boxstyle().pad * label.get_fontsize()
    return Text.get_window_extent(label, renderer).padded(
        pad * label.get_figure(root=True).dpi / 72.0)


def _overflow(ax, box, taken, renderer) -> float:
    """How far a label's ``box`` (display units) leaves the axes or covers a ``taken`` box
    (0: it fits)."""
    frame = ax.get_window_extent(renderer)
    out = (max(0.0, frame.x0 - box.x0) + max(0.0, box.x1 - frame.x1)
           + max(0.0, frame.y0 - box.y0) + max(0.0, box.y1 - frame.y1))
    for other in taken:
        w = min(box.x1, other.x1) - max(box.x0, other.x0)
        h = min(box.y1, other.y1) - max(box.y0, other.y0)
        if w > 0 and h > 0:
            out += min(w, h)
    return out


def _place(ax, label, gap: float, taken: list, renderer) -> None:
    """Put the annotation ``label`` beside its point, the nearest of :data:`_REACH` times
    ``gap`` points away and on the first side of :data:`_AROUND` where it stays inside the
    axes and covers no ``taken`` box (else where it overflows least); its box joins
    ``taken``, and a label set off from its point gets a thin line back to it."""
    best = None
    for reach in _REACH:
        for dx, dy, ha, va in _AROUND:
            label.xyann = (dx * gap * reach, dy * gap * reach)
            label.set_horizontalalignment(ha)
            label.set_verticalalignment(va)
            cost = _overflow(ax, _label_box(label, renderer), taken, renderer)
            if best is None or cost < best[0]:
                best = (cost, reach, (dx, dy, ha, va))
            if cost == 0.0:
                break
        if best[0] == 0.0:
            break
    _, reach, (dx, dy, ha, va) = best
    label.xyann = (dx * gap * reach, dy * gap * reach)
    label.set_horizontalalignment(ha)
    label.set_verticalalignment(va)
    label.arrow_patch.set_visible(reach > 1.0)
    taken.append(_label_box(label, renderer))


def _label(ax, text: str, xy, gap: float, **kw):
    """An annotation of point ``xy`` to be placed by :func:`_place` (``gap``: points from the
    point's centre), with the line that leads back to it when set off."""
    label = ax.annotate(text, xy, xytext=(0, 0), textcoords="offset points", zorder=6,
                        annotation_clip=False,
                        arrowprops=dict(arrowstyle="-", color="0.2", lw=0.6, shrinkA=0,
                                        shrinkB=max(gap - 1.5, 0.0)), **kw)
    label.set_in_layout(False)
    return label, gap


def _marker_box(ax, xy, size_pt: float, renderer):
    """The display box of a marker of ``size_pt`` points at data point ``xy``."""
    from matplotlib.transforms import Bbox

    x, y = ax.transData.transform(xy)
    half = 0.4 * size_pt * ax.get_figure(root=True).dpi / 72.0  # the mark, not its corners
    return Bbox.from_extents(x - half, y - half, x + half, y + half)


def _solved_cells(ax, rec: Recommendation, pt) -> list:
    """The solved cells on a sizing map: filled where sound in every member, a cross where
    not; returns each cell's label of its worst-case height (mm), with its gap, to be
    placed."""
    labels = []
    for c in rec.cells:
        value = _worst(c)
        if c.sound:
            marker = dict(marker="o", mfc="black", mec="white")
        elif c.unconverged or c.incompetent:
            marker = dict(marker="X", mfc=_LEAK_COLOUR, mec="black")
        else:  # sound where solved, not solved in every member (an adaptive design's)
            marker = dict(marker="o", mfc="white", mec="black")
        ax.plot(c.width_pct, c.height_pct, ms=pt(8), mew=1.0, ls="none", zorder=4, **marker)
        if math.isfinite(value):
            labels.append(_label(ax, f"{value:.2f}", (c.width_pct, c.height_pct),
                                 pt(8) / 2 + 1.5, fontsize=pt(8),
                                 bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none",
                                           alpha=0.7)))
    return labels


def _margin_contours(fig, ax, answer, pt, scale: float, caption: bool) -> None:
    """The answer's lattice on a sizing map: filled contours of the predicted worst-case
    margin with their colour bar, its 0 line solid and the tolerance's dashed, the sealing
    boundary dash-dotted with the side that does not seal hatched, and the band of
    qualifying sizes outlined in green."""
    lattice = answer.lattice
    w, h = np.meshgrid(lattice.widths_pct, lattice.heights_pct)
    margin = lattice.worst_margin_mm
    reach = max(float(np.abs(margin).max()), 0.05)
    levels = np.linspace(-reach, reach, 21)
    filled = ax.contourf(w, h, margin, levels=levels, cmap=_MARGIN_CMAP, extend="both")
    # a map printed small keeps its width for the plane: the colour bar goes below it
    bar = fig.colorbar(filled, ax=ax, shrink=0.9, aspect=20 if scale >= 1 else 40,
                       location="right" if scale >= 1 else "bottom")
    if caption:  # else the key says it
        bar.set_label(_COLOURS, fontsize=pt(10))
    bar.set_ticks(levels[::4], labels=[f"{v:+.2f}" for v in levels[::4]])
    bar.ax.tick_params(labelsize=pt(10))
    steps = ax.contour(w, h, margin, levels=levels[::4], colors="0.3", linewidths=0.6)
    ax.clabel(steps, fmt="%.2f", fontsize=pt(8))
    tol = answer.tolerance_mm
    ax.contour(w, h, margin, levels=[0.0], colors="black", linewidths=2.0)
    ax.contour(w, h, margin, levels=[-tol], colors="black", linewidths=1.5,
               linestyles="--")
    threshold = answer.seal_threshold
    if lattice.seal_probability.min() < threshold <= lattice.seal_probability.max():
        ax.contour(w, h, lattice.seal_probability, levels=[threshold], colors="black",
                   linewidths=1.8, linestyles="-.")
    with matplotlib.rc_context({"hatch.color": "0.25", "hatch.linewidth": 0.6}):
        ax.contourf(w, h, lattice.seal_probability, levels=[0.0, threshold],
                    colors=["0.5"], alpha=0.3, hatches=["//"])
    if lattice.qualifies.any():
        ax.contour(w, h, lattice.qualifies.astype(float), levels=[0.5],
                   colors=OKABE_ITO["bluish_green"], linewidths=3.0)


def _answer_marks(ax, answer, pt) -> tuple[list, list]:
    """The answer (star) and the highest size (triangle) on a sizing map; returns their
    labels, to be placed, and their marks (data point, size in points)."""
    labels, marks = [], []
    if answer.size is not None:
        ax.plot(*answer.size, marker="*", ms=pt(20), mfc="white", mec="black", mew=1.5,
                ls="none", zorder=5)
        marks.append((tuple(answer.size), pt(20)))
        labels.append(_label(ax, f"answer {answer.size.label}", answer.size,
                             pt(20) / 2 + 2, fontsize=pt(10), fontweight="bold",
                             bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="black")))
    if answer.highest is not None:
        ax.plot(*answer.highest, marker="^", ms=pt(11), mfc="white", mec="black", mew=1.2,
                ls="none", zorder=5)
        marks.append((tuple(answer.highest), pt(11)))
        labels.append(_label(ax, f"highest {answer.highest.label}", answer.highest,
                             pt(11) / 2 + 2, fontsize=pt(9),
                             bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="0.4")))
    return labels, marks


def _size_axes(ax, rec: Recommendation, pt, caption: bool) -> None:
    """A sizing map's axes: ticks at the grid's sizes (plain ticks over the range for an
    adaptive design's), limits about the solved cells, the axes' names (short on a map
    drawn for a page, whose key has the long ones)."""
    grid = [c for c in rec.cells if not c.confirmation]
    widths = sorted({c.width_pct for c in grid})
    heights = sorted({c.height_pct for c in grid})
    if widths and all(not c.missing for c in grid):  # ticks at the grid's sizes
        ax.set_xticks(widths, [f"+{x:g}" for x in widths])
        ax.set_yticks(heights, [f"+{y:g}" for y in heights])
    elif widths:  # an adaptive design's sizes: plain ticks over the range
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_locator(MaxNLocator(6, integer=True))
            axis.set_major_formatter(FuncFormatter(lambda v, _: f"+{v:g}"))
    if widths:
        pad_w = 0.04 * ((widths[-1] - widths[0]) or 10)
        pad_h = 0.04 * ((heights[-1] - heights[0]) or 10)
        ax.set_xlim(widths[0] - pad_w, widths[-1] + pad_w)
        ax.set_ylim(heights[0] - 3 * pad_h, heights[-1] + 2 * pad_h)
    ax.tick_params(labelsize=pt(10))
    ax.set_xlabel("graft width enlargement W (%)" if caption else "W (%)", fontsize=pt(11))
    ax.set_ylabel("graft height enlargement H (%)" if caption else "H (%)", fontsize=pt(11))


#: what the sizing map's colours show
_COLOURS = "predicted worst-case margin over the target (mm)"


def sizing_map_key(rec: Recommendation, *, names: bool = False) -> str:
    """What the lines and marks of :func:`plot_sizing_map` mean, in a sentence or two;
    ``names`` adds what its axes and colours are (a map drawn without its caption)."""
    answer = rec.answer
    lines = []
    if names:
        lines.append("W, H: the graft's width and height enlargements over the native leaflet "
                     f"(%); colours: the {_COLOURS}.")
    if answer.lattice is not None:
        lines.append(f"Solid: the target; dashed: the tolerance, −{answer.tolerance_mm:.2f} mm; "
                     f"dash-dotted: probability of sealing {answer.seal_threshold:g} in every "
                     "member, grey hatched below it; green: the band of sizes that qualify; "
                     "star: the answer; triangle: the highest predicted coaptation.")
    partial = any(c.missing and not (c.unconverged or c.incompetent) for c in rec.cells)
    lines.append("Solved cells: dot sound in every member, "
                 + ("ring sound in the members solved (not all), " if partial else "")
                 + "cross not sealed or not converged in some member; number: worst-case "
                 "minimum coaptation height (mm) over the members solved.")
    return " ".join(lines)


def plot_sizing_map(rec: Recommendation, path: Path | None = None, *, title: str = "",
                    size_in: tuple[float, float] = _MAP_SIZE_IN, caption: bool = True,
                    dpi: int = 130):
    """The answer's sizing map over W × H (:mod:`valve_dolfinx.sizing.answer`).

    Filled contours of the predicted worst-case margin over the target (mm; its 0 line
    solid, the tolerance's line dashed), the sealing boundary (the probability
    threshold, dash-dotted, the side that does not seal hatched), the band of qualifying
    sizes outlined in green, the answer (star) and the highest size (triangle), and the
    solved cells with their worst-case heights.  Without a surface, the solved cells
    alone.  Every label is placed beside its point where it stays inside the axes and
    covers no other label or mark.  ``size_in`` is the figure's size (inches): drawn
    smaller than the default (to be printed at that size, as on the plan's page), its
    texts shrink with it down to :data:`MIN_PRINT_PT`.  ``caption`` false leaves out the
    title and the key (:func:`sizing_map_key`), for a page that prints them itself."""
    answer = rec.answer
    lattice = answer.lattice
    scale = size_in[0] / _MAP_SIZE_IN[0]

    def pt(size: float) -> float:
        return max(MIN_PRINT_PT, size * scale)

    fig = new_figure(*size_in)
    ax = fig.add_subplot()
    labels = []  # (annotation, gap in points), placed once the layout is settled
    marks = []  # (data point, size in points): what a label may not cover
    if lattice is not None:
        _margin_contours(fig, ax, answer, pt, scale, caption)
        labels, marks = _answer_marks(ax, answer, pt)
    marks += [((c.width_pct, c.height_pct), pt(8)) for c in rec.cells]
    labels += _solved_cells(ax, rec, pt)
    _size_axes(ax, rec, pt, caption)
    if caption:
        key = answer.text.split(". ")[0] + ". " if lattice is None else ""
        chars = int(100 * scale * 9 / pt(9))
        ax.set_title(_title(rec, "Graft sizing map", title) + "\n"
                     + textwrap.fill(key + sizing_map_key(rec), chars), fontsize=pt(9))
    fig.draw_without_rendering()  # settle the layout, then place the labels in it
    fig.set_layout_engine("none")
    renderer = fig.canvas.get_renderer()
    taken = [_marker_box(ax, xy, size, renderer) for xy, size in marks]
    for label, gap in labels:
        _place(ax, label, gap, taken, renderer)
    return save_figure(fig, path, dpi=dpi)


def _normal_words(row: dict) -> str:
    """The normal valve under a nomogram's diameter: its minimum coaptation height, and
    whether it leaks (then the target it sets is no standard for a repair)."""
    height = row.get("normal_min_coaptation_mm")
    if height is None:
        return ""
    leaks = "" if row.get("normal_competent") in (True, None) else "\nnot competent"
    return f"\nnormal\n{height:.2f} mm{leaks}"


def plot_nomogram(rows: Sequence[dict], path: Path | None = None, *, title: str,
                  footnote: str):
    """Recommended graft enlargements (top) and margin (bottom) against the loaded root
    diameter; ``rows`` are :func:`valve_dolfinx.study.nomogram.nomogram_rows`.

    Bars about the recommended enlargements span the band of sizes that also qualify.  A
    diameter without a graft is shaded, with the closest size's enlargements hollow and its
    margin (negative: its shortfall) in vermillion; an answer read from the surface and not
    solved in every member (its confirmations spent) says so under its name, its margin
    bar hatched; under each diameter, the normal valve's minimum coaptation height (the
    target) and whether it is competent."""
    d = np.array([r["root_loaded_diameter_mm"] for r in rows], dtype=float)
    ok = np.array([bool(r["recommended"]) for r in rows], dtype=bool)
    fig = new_figure(7.5, 8.0)
    top, low, notes = fig.subplots(3, 1, gridspec_kw={"height_ratios": [3, 2, 0.55]})
    low.sharex(top)
    step = min(np.diff(d)) if len(d) > 1 else 1.0
    for ax in (top, low):
        for x in d[~ok]:
            ax.axvspan(x - step / 2, x + step / 2, color="0.88", lw=0)
        ax.grid(alpha=0.3)
    _nomogram_sizes(top, rows, d, ok, step)
    _nomogram_margins(low, rows, d, ok, step)
    notes.set_axis_off()
    notes.text(0.0, 1.0, footnote, fontsize=7, va="top", ha="left", wrap=True,
               transform=notes.transAxes)
    fig.suptitle(title, fontsize=11)
    return save_figure(fig, path, dpi=130)


def _column(rows: Sequence[dict], key: str) -> np.ndarray:
    """A nomogram column as floats (None: NaN)."""
    return np.array([np.nan if r[key] is None else r[key] for r in rows], dtype=float)


def _nomogram_sizes(top, rows: Sequence[dict], d: np.ndarray, ok: np.ndarray,
                    step: float) -> None:
    """The nomogram's upper panel: the recommended W and H per diameter ``d`` with the
    band that also qualifies, the closest size's hollow where no graft qualifies (``ok``
    false), and each diameter's graft named at the bottom."""
    series = (("graft_width_pct", "best_width_pct", "width W", "o", OKABE_ITO["blue"], -1),
              ("graft_height_pct", "best_height_pct", "height H", "s", OKABE_ITO["orange"], 1))
    highest = 0.0
    for key, best_key, label, marker, colour, side in series:
        y, best = _column(rows, key), _column(rows, best_key)
        x = d + side * 0.04 * step  # W and H side by side where they are equal
        if ok.any():
            top.plot(x[ok], y[ok], "-", marker=marker, color=colour, ms=8, lw=1.5,
                     label=f"recommended {label}")
            what = key.split("_")[1]
            low_end = _column(rows, f"band_{what}_min_pct")
            high_end = _column(rows, f"band_{what}_max_pct")
            top.errorbar(x[ok], y[ok], yerr=[y[ok] - low_end[ok], high_end[ok] - y[ok]],
                         fmt="none", ecolor=colour, elinewidth=5, alpha=0.35,
                         label=f"band of {label} that also qualify")
        if (~ok).any():
            top.plot(x[~ok], best[~ok], marker, mfc="white", mec=colour, mew=1.8, ms=8,
                     ls="none", label=f"closest {label} (grey: no graft)")
        highest = np.nanmax([highest, *y[ok], *best[~ok]])
    for r, x in zip(rows, d, strict=True):
        name = r["recommended"] or (f"closest {r['best']}" if r["best"] else "")
        if r["recommended"] and r.get("solved") is False:
            name += "\nnot solved"  # read from the surface, its confirmations spent
        if name:
            top.annotate(name, (x, 0), xytext=(0, 4), textcoords="offset points",
                         xycoords=("data", "axes fraction"), ha="center", fontsize=8,
                         color="black" if r["recommended"] else "0.4")
    top.set_ylabel("graft enlargement over\nthe native leaflet (%)")
    top.set_ylim(-0.3 * highest - 3, 1.45 * highest + 3)  # room for the names and legend
    top.legend(fontsize=8, loc="upper left", ncol=2)
    top.tick_params(labelbottom=False)


def _nomogram_margins(low, rows: Sequence[dict], d: np.ndarray, ok: np.ndarray,
                      step: float) -> None:
    """The nomogram's lower panel: the answer's margin per diameter ``d`` (where no graft
    qualifies, the closest size's shortfall, negative), the tolerance, and under each
    diameter the normal valve's minimum coaptation height."""
    margin = np.where(ok, _column(rows, "margin_mm"), -_column(rows, "shortfall_mm"))
    unsolved = ok & np.array([r.get("solved") is False for r in rows], dtype=bool)
    for where, colour, hatch, label in (
            (ok & ~unsolved, OKABE_ITO["bluish_green"], None,
             "the answer's predicted worst-case margin"),
            (unsolved, "white", "///", "the same, the answer not solved in every member"),
            (~ok, OKABE_ITO["vermillion"], None, "no graft: the closest size's margin "
             "(if positive, it does not seal)")):
        if where.any():
            low.bar(d[where], margin[where], width=step / 2, color=colour, label=label,
                    hatch=hatch, edgecolor=OKABE_ITO["bluish_green"] if hatch else None)
    for x, m in zip(d, margin, strict=True):
        if math.isfinite(m):  # above the bar, or above the zero line over a negative one
            low.annotate(margin_text(m, signed=True), (x, max(m, 0.0)), xytext=(0, 3),
                         textcoords="offset points", ha="center", va="bottom", fontsize=8)
    low.axhline(0.0, color="k", lw=1.0)
    tolerance = _column(rows, "tolerance_mm")
    if np.isfinite(tolerance).any():
        tol = float(np.nanmax(tolerance))
        low.axhline(-tol, color="k", lw=1.0, ls="--", label=f"the tolerance, −{tol:.2f} mm")
        margin_floor = -tol
    else:
        margin_floor = 0.0
    finite = margin[np.isfinite(margin)]
    lo, hi = min([margin_floor, *finite]), max([0.0, *finite])
    span = (hi - lo) or 0.1
    low.set_ylim(lo - 0.2 * span, hi + 0.7 * span)  # room for the numbers and legend
    low.set_ylabel("margin (mm)")
    low.set_xlabel("loaded root diameter at 80 mmHg (mm)")
    low.set_xticks(d, [f"{x:g}" + _normal_words(r) for x, r in zip(d, rows, strict=True)])
    for label in low.get_xticklabels():
        label.set_fontsize(8)
    low.legend(fontsize=8, loc="upper left")


def plot_case_panel(case_folder: Path, path: Path | None = None, *, title: str = ""):
    """One case's ventricular view, axial cuts and coaptation map side by side.

    Returns None (and draws nothing) if the case folder holds none of the pictures.
    """
    images = [(case_folder / name, caption) for name, caption in PANEL_IMAGES
              if (case_folder / name).is_file()]
    if not images:
        log.debug("no pictures in %s: no panel drawn", case_folder)
        return None
    import matplotlib.image as mpimg

    pictures = [(mpimg.imread(p), caption) for p, caption in images]
    # rows of equal width: the valve view and the cuts side by side, the flat map below
    rows = [pictures[:2], pictures[2:]] if len(pictures) == 3 else [pictures]
    width, caption_h, title_h = 12.0, 0.3, 0.45 if title else 0.0
    heights = [width / sum(img.shape[1] / img.shape[0] for img, _ in row) for row in rows]
    total = title_h + sum(h + caption_h for h in heights)
    fig = new_figure(width, total, layout=None)
    top = total - title_h
    for row, h in zip(rows, heights, strict=True):
        left = 0.0
        top -= h + caption_h
        for img, caption in row:
            w = h * img.shape[1] / img.shape[0]
            ax = fig.add_axes((left / width, top / total, w / width, h / total))
            ax.imshow(img)
            ax.set_axis_off()
            ax.set_title(caption, fontsize=10)
            left += w
    if title:
        fig.suptitle(title, y=1.0 - 0.2 * title_h / total, fontsize=13)
    return save_figure(fig, path, dpi=200)
