"""The regurgitant orifice, drawn from the raster :func:`~valve_dolfinx.analysis.orifice_leak_map`
counted it on.

The orifice is the union of the raster's open and leak-channel pixels
(``diagnostics["open"] | diagnostics["channel"]``, row = y, pixel ``(iy, ix)``
spanning ``origin + [ix, ix + 1]·pixel`` in x).  :func:`orifice_rectangles`
turns it into rectangles (one per run of pixels along a row), exactly the
counted area, which the ventricular 3-D view and the 2-D figures draw.
"""

from __future__ import annotations

import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import to_rgba
from matplotlib.patches import Circle, Patch

from valve_dolfinx.plotting.style import (
    OKABE_ITO,
    ORIFICE_COLOUR,
    key_numbers,
    leaflet_colour,
    leaflet_label,
    new_figure,
    save_figure,
)

__all__ = ["ORIFICE_GID", "orifice_mask", "orifice_rectangles", "orifice_outline",
           "draw_orifice", "plot_orifice_map"]

#: ``gid`` of the artist that draws the orifice in a matplotlib figure
ORIFICE_GID = "regurgitant_orifice"
_DEAD_END_COLOUR = OKABE_ITO["yellow"]


def orifice_mask(diagnostics: dict) -> np.ndarray:
    """The ``n × n`` pixels counted in the regurgitant orifice area."""
    return np.asarray(diagnostics["open"], bool) | np.asarray(diagnostics["channel"], bool)


def orifice_rectangles(diagnostics: dict, mask: np.ndarray | None = None) -> np.ndarray:
    """Corners ``(k, 4, 2)`` (mm, counter-clockwise) of the orifice's row runs of pixels."""
    mask = orifice_mask(diagnostics) if mask is None else np.asarray(mask, bool)
    origin, pixel = float(diagnostics["origin_mm"]), float(diagnostics["pixel_mm"])
    padded = np.pad(mask, ((0, 0), (1, 1))).astype(np.int8)
    step = np.diff(padded, axis=1)
    rows, starts = np.nonzero(step == 1)
    rows_end, ends = np.nonzero(step == -1)  # one past the run, in pixel units
    order, order_end = np.lexsort((starts, rows)), np.lexsort((ends, rows_end))
    rows, starts, ends = rows[order], starts[order], ends[order_end]
    x0, x1 = origin + starts * pixel, origin + ends * pixel
    y0, y1 = origin + rows * pixel, origin + (rows + 1) * pixel
    return np.stack([np.stack([x0, y0], -1), np.stack([x1, y0], -1),
                     np.stack([x1, y1], -1), np.stack([x0, y1], -1)], axis=1)


def orifice_outline(diagnostics: dict) -> list[np.ndarray]:
    """Polylines ``(k, 2)`` (mm) around the orifice, midway between its pixels and the others.

    For drawing only: it cuts the pixels' corners, so the area it encloses is
    not exactly the counted one (:func:`orifice_rectangles` is).
    """
    from contourpy import contour_generator

    mask = np.pad(orifice_mask(diagnostics), 1).astype(float)
    origin, pixel = float(diagnostics["origin_mm"]), float(diagnostics["pixel_mm"])
    centres = origin + (np.arange(mask.shape[0]) - 0.5) * pixel
    return [line for line in contour_generator(centres, centres, mask).lines(0.5)
            if len(line) > 1]


def draw_orifice(ax, diagnostics: dict, *, label: str | None = "regurgitant orifice",
                 zorder: float = 5) -> PolyCollection | None:
    """Fill the orifice on a 2-D axes in mm, outlined (``None`` if the orifice is empty)."""
    rects = orifice_rectangles(diagnostics)
    if len(rects) == 0:
        return None
    patches = PolyCollection(rects, facecolors=ORIFICE_COLOUR, edgecolors="none",
                             zorder=zorder, label=label)
    patches.set_gid(ORIFICE_GID)
    ax.add_collection(patches)
    ax.add_collection(LineCollection(orifice_outline(diagnostics), colors="black",
                                     linewidths=0.8, zorder=zorder))
    return patches


def plot_orifice_map(diagnostics: dict, valve, path=None, *, title: str = "",
                     result=None):
    """The orifice raster seen along the axis: leaflet footprints, orifice, dead ends.

    ``valve`` gives the leaflets' colours and labels (in the order of
    ``diagnostics["cover"]``); ``result`` (a case result or coaptation result),
    if given, puts its key numbers in the title.  Returns the figure; writes
    it to ``path`` if given.
    """
    cover = np.asarray(diagnostics["cover"], bool)
    in_disk = np.asarray(diagnostics["in_disk"], bool)
    n = cover.shape[1]
    origin, pixel = float(diagnostics["origin_mm"]), float(diagnostics["pixel_mm"])
    lo, hi = origin, origin + n * pixel
    rgba = np.ones((n, n, 4))
    rgba[in_disk] = (0.93, 0.93, 0.93, 1.0)
    patches = list(valve.leaflets)
    for i, patch in enumerate(patches):
        colour = np.array(to_rgba(leaflet_colour(patch, i)))
        rgba[cover[i] & in_disk] = 0.45 * colour + 0.55 * np.ones(4)  # light tint
    overlap = (cover.sum(axis=0) > 1) & in_disk
    rgba[overlap] = (0.62, 0.62, 0.62, 1.0)
    rgba[np.asarray(diagnostics["dead_end"], bool)] = to_rgba(_DEAD_END_COLOUR)
    fig = new_figure(8.6, 6.4)
    ax = fig.add_subplot()
    ax.imshow(rgba, origin="lower", extent=(lo, hi, lo, hi), interpolation="nearest")
    draw_orifice(ax, diagnostics)
    ax.add_patch(Circle((0.0, 0.0), float(diagnostics["radius_mm"]), fill=False, color="0.3",
                        lw=1.0))
    area = float(orifice_mask(diagnostics).sum() * pixel * pixel)
    handles = [Patch(color=0.45 * np.array(to_rgba(leaflet_colour(p, i))) + 0.55,
                     label=leaflet_label(p) + " covers") for i, p in enumerate(patches)]
    handles += [Patch(color="0.62", label="two leaflets, touching"),
                Patch(color="0.93", label="gap below the threshold (sealed)"),
                Patch(color=ORIFICE_COLOUR, label=f"regurgitant orifice {area:.2f} mm²"),
                Patch(color=_DEAD_END_COLOUR, label="pocket closed further along")]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8,
              frameon=False)
    ax.set(xlabel="x (mm)", ylabel="y (mm)", aspect="equal", xlim=(lo, hi), ylim=(lo, hi))
    ax.grid(alpha=0.25)
    heading = title or "regurgitant orifice, seen along the axis from the aorta"
    numbers = key_numbers(result) if result is not None else f"orifice {area:.2f} mm²"
    ax.set_title(f"{heading}\n{numbers} (pixel {pixel:g} mm)", fontsize=10)
    return save_figure(fig, path)

