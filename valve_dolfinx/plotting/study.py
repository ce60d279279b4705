"""Figures of a sizing study, drawn from the study table alone.

* :func:`plot_coaptation_vs_width`: minimum native coaptation height against graft
  width, one curve per graft height, the normal valve as a reference line;
  cases that are not competent hollow.
* :func:`plot_sizing_map`: the W × H grid as a heat map of the same figure, with
  the reason written where a case is not competent (``competence_reason``).
* :func:`plot_case_panel`: the figure-style panel of one case (ventricular view,
  two axial cuts, coaptation region on the flat outline), assembled from the
  pictures ``run`` wrote into the case folder.

Each returns the figure and writes it to ``path`` if given.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.patches import Rectangle

from valve_dolfinx.plotting.style import OKABE_ITO, SEQUENTIAL_CMAP, new_figure, save_figure

__all__ = ["plot_coaptation_vs_width", "plot_sizing_map", "plot_case_panel", "PANEL_IMAGES"]

log = logging.getLogger(__name__)

FIGURE = "min_coaptation_height_mm"
#: the pictures of a case folder that make its panel, with their captions
PANEL_IMAGES = (("closed_valve_ventricular.png", "closed valve seen from the ventricle"),
                ("cut_planes.png", "axial cuts"),
                ("coaptation_map.png", "coaptation region on the flat leaflets"))


#: one colour per graft height (Okabe-Ito, black kept for the normal valve)
_CURVE_COLOURS = tuple(OKABE_ITO[k] for k in ("blue", "orange", "bluish_green", "reddish_purple",
                                              "sky_blue", "vermillion", "yellow"))
_TARGET_COLOUR = OKABE_ITO["vermillion"]
_LEAK_COLOUR = OKABE_ITO["vermillion"]


def _num(value) -> float:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) \
        else math.nan


def _sound(row: dict) -> bool:
    return bool(row.get("converged")) and bool(row.get("competent"))


def plot_coaptation_vs_width(rows: list[dict], path: Path | None = None, *,
                             target_mm: float | None = None, title: str = ""):
    """Minimum coaptation height against graft width, one curve per graft height."""
    grafts = [r for r in rows if r.get("graft_width_pct") is not None]
    normal = next((r for r in rows if r.get("graft_width_pct") is None), None)
    heights = sorted({r["graft_height_pct"] for r in grafts})
    fig = new_figure(7.5, 5.0)
    ax = fig.add_subplot()
    for k, h in enumerate(heights):
        colour = _CURVE_COLOURS[k % len(_CURVE_COLOURS)]
        curve = sorted((r for r in grafts if r["graft_height_pct"] == h),
                       key=lambda r: r["graft_width_pct"])
        w = np.array([r["graft_width_pct"] for r in curve], dtype=float)
        y = np.array([_num(r.get(FIGURE)) for r in curve])
        sound = np.array([_sound(r) for r in curve], dtype=bool)
        ax.plot(w, y, "-", color=colour, lw=1.5, label=f"H +{h:g} %")
        ax.plot(w[sound], y[sound], "o", color=colour, ms=7)
        ax.plot(w[~sound], y[~sound], "o", mfc="white", mec=colour, mew=1.8, ms=7)
    if normal is not None and math.isfinite(_num(normal.get(FIGURE))):
        style = "-" if _sound(normal) else ":"
        ax.axhline(_num(normal[FIGURE]), color="k", ls=style, lw=1.2,
                   label=f"normal valve {_num(normal[FIGURE]):.2f} mm"
                   + ("" if _sound(normal) else " (not competent)"))
    if target_mm is not None:
        ax.axhline(target_mm, color=_TARGET_COLOUR, ls="--", lw=1.2,
                   label=f"target {target_mm:.2f} mm")
    ax.plot([], [], "o", mfc="white", mec="0.3",
            label="not competent (leaks, leaflets cross or not converged)")
    ax.set_xlabel("graft width enlargement W (%)")
    ax.set_ylabel("minimum native coaptation height (mm)")
    widths = sorted({r["graft_width_pct"] for r in grafts})
    if widths:
        ax.set_xticks(widths)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title or "Minimum coaptation height of the native leaflets")
    return save_figure(fig, path, dpi=130)


def plot_sizing_map(rows: list[dict], path: Path | None = None, *,
                    recommended: str | None = None, best: str | None = None,
                    title: str = ""):
    """The W × H grid coloured by minimum coaptation height; cells that are not competent
    hatched with the reason, failed and damaged cases marked.

    The ``recommended`` cell is framed; when there is none, the ``best`` one is, labelled
    as short of the target."""
    grafts = [r for r in rows if r.get("graft_width_pct") is not None]
    widths = sorted({r["graft_width_pct"] for r in grafts})
    heights = sorted({r["graft_height_pct"] for r in grafts})
    if not grafts:
        fig = new_figure(5, 3)
        ax = fig.add_subplot()
        ax.text(0.5, 0.5, "no graft case finished yet", ha="center", va="center")
        ax.set_axis_off()
        return save_figure(fig, path, dpi=100)
    grid = np.full((len(heights), len(widths)), np.nan)
    by_cell = {}
    for r in grafts:
        j, i = widths.index(r["graft_width_pct"]), heights.index(r["graft_height_pct"])
        grid[i, j] = _num(r.get(FIGURE))
        by_cell[(i, j)] = r
    fig = new_figure(1.4 * len(widths) + 3.2, 1.1 * len(heights) + 2.2)
    ax = fig.add_subplot()
    cmap = colormaps[SEQUENTIAL_CMAP].with_extremes(bad="0.85")
    normal = next((r for r in rows if r.get("graft_width_pct") is None), None)
    # the colour range takes in the normal valve, so that its mark lies on the bar
    values = [v for v in [*grid[np.isfinite(grid)],
                          _num(normal.get(FIGURE)) if normal is not None else math.nan]
              if math.isfinite(v)]
    limits = (min(values), max(values)) if values else (None, None)
    image = ax.imshow(np.ma.masked_invalid(grid), origin="lower", cmap=cmap, aspect="auto",
                      vmin=limits[0], vmax=limits[1])
    bar = fig.colorbar(image, ax=ax)
    bar.set_label("minimum coaptation height (mm)")
    note = "vermillion hatched: not competent (the cell says why)"
    if normal is not None and math.isfinite(_num(normal.get(FIGURE))):
        bar.ax.axhline(_num(normal[FIGURE]), color="k", lw=2.5)
        note += f"; black line on the colour bar: normal valve {_num(normal[FIGURE]):.2f} mm"
    finite = grid[np.isfinite(grid)]
    middle = 0.5 * (finite.min() + finite.max()) if finite.size else 0.0
    for (i, j), r in by_cell.items():
        value = grid[i, j]
        lines = [f"{value:.2f} mm" if math.isfinite(value) else "no result"]
        status = r.get("status", "finished")
        incompetent = status == "finished" and not r.get("competent")
        if status != "finished":  # failed, or damaged files
            lines.append(status)
        elif incompetent:  # why, as result.json says: leaks, crossing, not converged
            lines += (r.get("competence_reason") or "not competent").split("; ")
        colour = "white" if math.isfinite(value) and value < middle else "black"
        ax.text(j, i, "\n".join(lines), ha="center", va="center", fontsize=8, color=colour,
                fontweight="bold" if incompetent else "normal")
        if incompetent:
            ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec=_LEAK_COLOUR,
                                   lw=2.5, hatch="//", alpha=0.8))
        label = f"W{r['graft_width_pct']:g}/H{r['graft_height_pct']:g}"
        if label == (recommended or best):
            for colour, width in (("black", 5.0), ("white", 2.0)):  # seen on any colour
                ax.add_patch(Rectangle((j - 0.45, i - 0.45), 0.9, 0.9, fill=False,
                                       ec=colour, lw=width))
    ax.set_xticks(range(len(widths)), [f"+{w:g}" for w in widths])
    ax.set_yticks(range(len(heights)), [f"+{h:g}" for h in heights])
    ax.set_xlabel("graft width enlargement W (%)")
    ax.set_ylabel("graft height enlargement H (%)")
    if recommended:
        note += f"\nblack-and-white frame: recommended {recommended}"
    elif best:
        note += f"\nblack-and-white frame: best {best}, short of the target"
    ax.set_title((title or "Graft sizing map") + f"\n{note}", fontsize=10)
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
