"""Figures of a sizing study, drawn from its recommendations (the worst case per graft).

* :func:`plot_coaptation_vs_width`: the worst-case minimum native coaptation height
  against graft width, one curve per graft height, with a bar up to the best member
  (the spread), and the target (the normal valve's, per member) as a line or band;
  grafts not sound in every member hollow.
* :func:`plot_sizing_map`: the W × H grid as a heat map of the same worst case, each
  cell with its spread, its margin over the target and why it is not competent (its
  ``competence_reason``; with several members, how many leak, intersect or did not
  converge); the recommended (or best) graft framed.
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

import numpy as np
from matplotlib import colormaps
from matplotlib.patches import Rectangle

from valve_dolfinx.plotting.style import OKABE_ITO, SEQUENTIAL_CMAP, new_figure, save_figure
from valve_dolfinx.result import INTERSECTION_REASON, margin_text

if TYPE_CHECKING:
    from valve_dolfinx.study.recommend import CellSummary, Recommendation

__all__ = ["plot_coaptation_vs_width", "plot_sizing_map", "plot_nomogram", "plot_case_panel",
           "PANEL_IMAGES"]

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
    fig = new_figure(7.5, 5.0)
    ax = fig.add_subplot()
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
                   label=f"target {targets[0]:.2f} mm ({rec.target_source})")
    elif targets:
        ax.axhspan(targets[0], targets[-1], color=_TARGET_COLOUR, alpha=0.15, lw=0,
                   label=f"targets {targets[0]:.2f}–{targets[-1]:.2f} mm ({rec.target_source})")
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
    ax.legend(fontsize=8, loc="best")
    ax.set_title(_title(rec, "Minimum coaptation height of the native leaflets", title),
                 fontsize=11)
    return save_figure(fig, path, dpi=130)


def _cell_lines(cell: CellSummary, n: int) -> list[str]:
    value = _worst(cell)
    lines = [f"{value:.2f} mm" if math.isfinite(value) else "no result"]
    if n > 1 and cell.spread_mm is not None:
        lines.append(f"spread {cell.spread_mm:.2f} mm")
    if cell.margin_mm is not None:
        lines.append(f"margin {margin_text(cell.margin_mm, signed=True)} mm")
    if n == 1:  # why it is not competent, as its result.json says (where leaflets intersect
        # is too long for a cell: how many pairs)
        for why in cell.reasons.values():
            lines += [f"intersects: {cell.most_intersecting_pairs} pairs"
                      if part.startswith(INTERSECTION_REASON) else part
                      for part in (why or "not competent").split("; ")]
        return lines + (["missing"] if cell.missing else [])
    for what, members in (("leaks", cell.leaking), ("intersects", cell.intersecting),
                          ("not converged", cell.unconverged), ("missing", cell.missing)):
        if members:
            lines.append(f"{what} {len(members)}/{n}")
    return lines


def plot_sizing_map(rec: Recommendation, path: Path | None = None, *, title: str = ""):
    """The W × H grid coloured by the worst-case minimum coaptation height; each cell with
    its spread over the members, its margin over the target and its failures.

    Cells that are not competent (in some member) are hatched; the recommended cell is
    framed, or, when there is none, the best one, labelled as short of the target."""
    cells = rec.cells
    widths = sorted({c.width_pct for c in cells})
    heights = sorted({c.height_pct for c in cells})
    if not cells:
        fig = new_figure(5, 3)
        ax = fig.add_subplot()
        ax.text(0.5, 0.5, "no graft case finished yet", ha="center", va="center")
        ax.set_axis_off()
        return save_figure(fig, path, dpi=100)
    n = len(rec.members)
    grid = np.full((len(heights), len(widths)), np.nan)
    for c in cells:
        grid[heights.index(c.height_pct), widths.index(c.width_pct)] = _worst(c)
    width_in = 1.5 * len(widths) + 3.2
    fig = new_figure(width_in, (1.1 if n == 1 else 1.35) * len(heights) + 2.4)
    ax = fig.add_subplot()
    cmap = colormaps[SEQUENTIAL_CMAP].with_extremes(bad="0.85")
    targets = _targets(rec)
    # the colour range takes in the targets, so that their marks lie on the bar
    values = [*grid[np.isfinite(grid)], *targets]
    limits = (min(values), max(values)) if values else (None, None)
    image = ax.imshow(np.ma.masked_invalid(grid), origin="lower", cmap=cmap, aspect="auto",
                      vmin=limits[0], vmax=limits[1])
    bar = fig.colorbar(image, ax=ax)
    bar.set_label("worst-case minimum coaptation height (mm)" if n > 1 else
                  "minimum coaptation height (mm)")
    note = "vermillion hatched: not competent (leaks, intersects or not converged)"
    if n > 1:
        note += " in some member"
    for t in targets:
        bar.ax.axhline(t, color="k", lw=2.5)
    if targets:
        span = (f"{targets[0]:.2f} mm" if len(targets) == 1
                else f"{targets[0]:.2f}–{targets[-1]:.2f} mm")
        note += f"; black line{'s' if len(targets) > 1 else ''} on the colour bar: target {span}"
    finite = grid[np.isfinite(grid)]
    middle = 0.5 * (finite.min() + finite.max()) if finite.size else 0.0
    framed = rec.recommended or rec.best
    for c in cells:
        i, j = heights.index(c.height_pct), widths.index(c.width_pct)
        value = grid[i, j]
        colour = "white" if math.isfinite(value) and value < middle else "black"
        ax.text(j, i, "\n".join(_cell_lines(c, n)), ha="center", va="center",
                fontsize=8 if n == 1 else 7, color=colour,
                fontweight="bold" if c.incompetent else "normal")
        if c.incompetent:
            ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec=_LEAK_COLOUR,
                                   lw=2.5, hatch="//", alpha=0.8))
        if c.label == framed:
            for edge, width in (("black", 5.0), ("white", 2.0)):  # seen on any colour
                ax.add_patch(Rectangle((j - 0.45, i - 0.45), 0.9, 0.9, fill=False,
                                       ec=edge, lw=width))
    ax.set_xticks(range(len(widths)), [f"+{w:g}" for w in widths])
    ax.set_yticks(range(len(heights)), [f"+{h:g}" for h in heights])
    ax.set_xlabel("graft width enlargement W (%)")
    ax.set_ylabel("graft height enlargement H (%)")
    if rec.recommended:
        note += f"\nblack-and-white frame: recommended {rec.recommended}"
    elif rec.best:
        note += f"\nblack-and-white frame: best {rec.best}, short of the target"
    if n > 1:
        note += ("\nper cell: the lowest member's height, the spread over the members and the "
                 "least margin over the member's target")
    # a narrow grid's figure takes the notes on more lines (about 13 characters an inch)
    note = "\n".join(textwrap.fill(line, int(13 * width_in)) for line in note.split("\n"))
    ax.set_title(_title(rec, "Graft sizing map", title) + f"\n{note}", fontsize=9)
    return save_figure(fig, path, dpi=130)


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

    A diameter where no graft on the grid qualifies is shaded, with the best graft's
    enlargements hollow and its margin (negative: its shortfall) in vermillion; under each
    diameter, the normal valve's minimum coaptation height (the target) and whether it
    is competent."""
    d = np.array([r["root_loaded_diameter_mm"] for r in rows], dtype=float)
    ok = np.array([bool(r["recommended"]) for r in rows], dtype=bool)

    def column(key: str) -> np.ndarray:
        return np.array([np.nan if r[key] is None else r[key] for r in rows], dtype=float)

    fig = new_figure(7.5, 8.0)
    top, low, notes = fig.subplots(3, 1, gridspec_kw={"height_ratios": [3, 2, 0.55]})
    low.sharex(top)
    step = min(np.diff(d)) if len(d) > 1 else 1.0
    for ax in (top, low):
        for x in d[~ok]:
            ax.axvspan(x - step / 2, x + step / 2, color="0.88", lw=0)
        ax.grid(alpha=0.3)
    series = (("graft_width_pct", "best_width_pct", "width W", "o", OKABE_ITO["blue"], -1),
              ("graft_height_pct", "best_height_pct", "height H", "s", OKABE_ITO["orange"], 1))
    highest = 0.0
    for key, best_key, label, marker, colour, side in series:
        y, best = column(key), column(best_key)
        x = d + side * 0.04 * step  # W and H side by side where they are equal
        if ok.any():
            top.plot(x[ok], y[ok], "-", marker=marker, color=colour, ms=8, lw=1.5,
                     label=f"recommended {label}")
        if (~ok).any():
            top.plot(x[~ok], best[~ok], marker, mfc="white", mec=colour, mew=1.8, ms=8,
                     ls="none", label=f"best {label} (grey: no graft qualifies)")
        highest = np.nanmax([highest, *y[ok], *best[~ok]])
    for r, x in zip(rows, d, strict=True):
        name = r["recommended"] or (f"best {r['best']}" if r["best"] else "")
        if name:
            top.annotate(name, (x, 0), xytext=(0, 4), textcoords="offset points",
                         xycoords=("data", "axes fraction"), ha="center", fontsize=8,
                         color="black" if r["recommended"] else "0.4")
    top.set_ylabel("graft enlargement over\nthe native leaflet (%)")
    top.set_ylim(-0.3 * highest - 3, 1.45 * highest + 3)  # room for the names and legend
    top.legend(fontsize=8, loc="upper left", ncol=2)
    top.tick_params(labelbottom=False)
    margin = np.where(ok, column("margin_mm"), -column("shortfall_mm"))
    for where, colour, label in (
            (ok, OKABE_ITO["bluish_green"], "margin over the target in every member"),
            (~ok, OKABE_ITO["vermillion"], "no graft qualifies: the best one's margin "
             "(if positive, it fails to converge or seal)")):
        if where.any():
            low.bar(d[where], margin[where], width=step / 2, color=colour, label=label)
    for x, m in zip(d, margin, strict=True):
        if math.isfinite(m):
            low.annotate(margin_text(m, signed=True), (x, m),
                         xytext=(0, 3 if m >= 0 else -3), textcoords="offset points",
                         ha="center", va="bottom" if m >= 0 else "top", fontsize=8)
    low.axhline(0.0, color="k", lw=1.0)
    finite = margin[np.isfinite(margin)]
    lo, hi = min(0.0, *finite), max(0.0, *finite)
    span = (hi - lo) or 0.1
    low.set_ylim(lo - 0.2 * span, hi + 0.7 * span)  # room for the numbers and legend
    low.set_ylabel("margin (mm)")
    low.set_xlabel("loaded root diameter at 80 mmHg (mm)")
    low.set_xticks(d, [f"{x:g}" + _normal_words(r) for x, r in zip(d, rows, strict=True)])
    for label in low.get_xticklabels():
        label.set_fontsize(8)
    low.legend(fontsize=8, loc="upper left")
    notes.set_axis_off()
    notes.text(0.0, 1.0, footnote, fontsize=7, va="top", ha="left", wrap=True,
               transform=notes.transAxes)
    fig.suptitle(title, fontsize=11)
    return save_figure(fig, path, dpi=130)


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
