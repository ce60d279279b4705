"""Figures on the flat (stress-free) leaflets: the mesh with its fibres, the coaptation map.

:func:`plot_coaptation_map` draws the coaptation region on each flat leaflet
outline with its height profile below it.
"""

from __future__ import annotations

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from valve_dolfinx.plotting.style import (
    COAPTATION_COLOUR,
    OKABE_ITO,
    key_numbers,
    leaflet_colour,
    leaflet_label,
    new_figure,
    save_figure,
)

__all__ = ["leaflet_outline", "plot_flat_leaflet", "plot_coaptation_map"]

_MARK_COLOUR = OKABE_ITO["vermillion"]


def leaflet_outline(patch) -> np.ndarray:
    """Closed flat outline ``(k, 2)``: attachment chain, then the free edge back to the start."""
    chain = np.concatenate([patch.attachment, patch.free_edge[::-1]])
    if chain[0] != chain[-1]:
        chain = np.append(chain, chain[0])
    return patch.flat[chain]


def plot_flat_leaflet(points: np.ndarray, triangles: np.ndarray, path=None, *,
                      title: str = "", fibres: np.ndarray | None = None,
                      outline: np.ndarray | None = None):
    """The flat leaflet triangulation (mm), optionally with fibre directions per cell.

    Returns the figure; writes it to ``path`` if given.
    """
    fig = new_figure(8.0, 5.4)
    ax = fig.add_subplot()
    ax.triplot(points[:, 0], points[:, 1], triangles, lw=0.4, color="0.45")
    if fibres is not None:
        c = points[triangles].mean(axis=1)
        step = max(1, len(c) // 400)
        ax.quiver(c[::step, 0], c[::step, 1], fibres[::step, 0], fibres[::step, 1],
                  color=OKABE_ITO["vermillion"], pivot="mid", scale=45, width=0.002,
                  headwidth=0, headlength=0, headaxislength=0, label="fibre direction")
        ax.legend(loc="lower right")
    if outline is not None:
        ax.plot(outline[:, 0], outline[:, 1], color="k", lw=1.2)
    ax.set_aspect("equal")
    ax.set_xlabel("x across the leaflet (mm)")
    ax.set_ylabel("height above the nadir (mm)")
    ax.grid(alpha=0.2)
    ax.set_title(title or f"flat leaflet: {len(points)} nodes, {len(triangles)} triangles")
    return save_figure(fig, path)


def _draw_leaflet(ax, patch, colour: str, gap: np.ndarray, threshold: float) -> None:
    flat = patch.flat
    ax.triplot(flat[:, 0], flat[:, 1], patch.triangles, lw=0.2, color="0.8", zorder=1)
    if gap.min() <= threshold:
        ax.tricontourf(flat[:, 0], flat[:, 1], patch.triangles, gap,
                       levels=[min(gap.min(), 0.0) - 1.0, threshold],
                       colors=[COAPTATION_COLOUR], alpha=0.6, zorder=2)
    outline = leaflet_outline(patch)
    ax.plot(outline[:, 0], outline[:, 1], color=colour, lw=1.6, zorder=3)
    fe = flat[patch.free_edge]
    ax.plot(fe[:, 0], fe[:, 1], color=colour, lw=3.5, zorder=3)


def plot_coaptation_map(coaptation, valve, path=None, *, title: str = "", result=None):
    """Coaptation region on the flat outline of each leaflet, with its height profile.

    Top row: each leaflet's flat (reference) outline in its colour --
    attachment edge thin, free edge thick -- with the region
    ``gap <= threshold`` filled.  Bottom row: the coaptation height profile
    ``h(x)`` along the free edge, the minimum on each side of the midline and
    the central value, with the nodulus tip (if ``nodulus_length_mm > 0``)
    shaded.  All panels share one length scale.  The title carries the key
    numbers of ``result`` (a case result; by default those of ``coaptation``).
    Returns the figure; writes it to ``path`` if given.
    """
    patches = [p for p in valve.leaflets if p.name in coaptation.leaflets]
    index = {p.name: i for i, p in enumerate(valve.leaflets)}
    xlim = max(np.abs(p.flat[:, 0]).max() for p in patches) * 1.05
    ylo = min(p.flat[:, 1].min() for p in patches) - 0.5
    yhi = max(p.flat[:, 1].max() for p in patches) + 0.5
    hmax = max(max(lc.height_mm.max() for lc in coaptation.leaflets.values()), 1.0) * 1.15
    aspect = (yhi - ylo) / (2 * xlim)  # of each outline panel
    fig = new_figure(4.8 * len(patches), 4.2 * aspect + 2.4 + 1.5)
    axes = fig.subplots(2, len(patches), squeeze=False,
                        gridspec_kw={"height_ratios": [4.2 * aspect, 2.4]})
    for k, patch in enumerate(patches):
        lc = coaptation.leaflets[patch.name]
        colour = leaflet_colour(patch, index[patch.name])
        ax = axes[0, k]
        _draw_leaflet(ax, patch, colour, lc.node_gap_mm, coaptation.threshold_mm)
        ax.set(xlim=(-xlim, xlim), ylim=(ylo, yhi), aspect="equal", xlabel="x (mm)",
               title=f"{leaflet_label(patch)}: coapted {lc.area_mm2:.1f} mm² "
                     f"(leaflet {lc.reference_area_mm2:.1f} mm² flat)")
        ax.title.set_color(colour if patch.is_graft else "k")
        ax.title.set_fontsize(10)
        if k == 0:
            ax.set_ylabel("y above the nadir (mm)")
        bx = axes[1, k]
        bx.plot(lc.x_mm, lc.height_mm, color=colour, lw=1.8)
        tip = 0.5 * lc.nodulus_length_mm
        if tip > 0.0:
            bx.axvspan(lc.midline_mm - tip, lc.midline_mm + tip, color="0.85", zorder=0)
        for side, value in (("left", lc.min_height_left_mm), ("right", lc.min_height_right_mm)):
            bx.plot([lc.min_height_x(side)], [value], "v", color=_MARK_COLOUR, ms=7)
            # each side's label outwards of its marker: the two minima may sit a nodulus apart
            away = -1 if side == "left" else 1
            bx.annotate(f"{value:.2f}", (lc.min_height_x(side), value), xytext=(6 * away, -9),
                        textcoords="offset points", ha="right" if away < 0 else "left",
                        va="top", fontsize=8, color=_MARK_COLOUR)
        bx.plot([lc.midline_mm], [lc.central_height_mm], "o", color="k", ms=5)
        bx.annotate(f"{lc.central_height_mm:.2f}", (lc.midline_mm, lc.central_height_mm),
                    xytext=(0, 7), textcoords="offset points", ha="center", fontsize=8)
        bx.set(xlim=(-xlim, xlim), ylim=(-0.25 * hmax, hmax), xlabel="x along the free edge (mm)")
        if k == 0:
            bx.set_ylabel("coaptation height (mm)")
        bx.axhline(0.0, color="0.6", lw=0.6)
        bx.grid(alpha=0.3)
    handles = [Patch(color=COAPTATION_COLOUR, alpha=0.6,
                     label=f"coapted: gap ≤ {coaptation.threshold_mm:g} mm to another leaflet"),
               Line2D([], [], color="0.3", lw=3.5, label="free edge (thick), attachment (thin)"),
               Line2D([], [], ls="", marker="v", color=_MARK_COLOUR,
                      label="minimum height each side of the midline (mm)"),
               Line2D([], [], ls="", marker="o", color="k", label="central height (mm)")]
    if any(coaptation.leaflets[p.name].nodulus_length_mm > 0 for p in patches):
        handles.append(Patch(color="0.85", label="nodulus tip (left out of the minima)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8.5,
               frameon=False)
    heading = (title + ": " if title else "") + "coaptation on the flat leaflets"
    fig.suptitle(f"{heading}\n{key_numbers(result if result is not None else coaptation)}",
                 fontsize=11)
    return save_figure(fig, path)
