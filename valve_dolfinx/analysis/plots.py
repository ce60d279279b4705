"""Figures of the coaptation analysis (matplotlib, Agg backend).

:func:`plot_coaptation_map` draws the coaptation region on each flat leaflet
outline with its height profile; :func:`plot_orifice_map` draws the
regurgitant orifice raster.  Each writes one PNG and returns its path.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from valve_dolfinx.analysis.coaptation import CoaptationResult
from valve_dolfinx.geometry.valve import LeafletPatch, ValveMesh

__all__ = ["plot_coaptation_map", "plot_orifice_map", "leaflet_outline"]

log = logging.getLogger(__name__)

_REGION_COLOUR = "#c0392b"
_GRAFT_COLOUR = "#5b8fd9"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def leaflet_outline(patch: LeafletPatch) -> np.ndarray:
    """Closed flat outline ``(k, 2)``: attachment chain, then the free edge back to the start."""
    chain = np.concatenate([patch.attachment, patch.free_edge[::-1]])
    if chain[0] != chain[-1]:
        chain = np.append(chain, chain[0])
    return patch.flat[chain]


def _draw_leaflet(ax, patch: LeafletPatch, gap: np.ndarray, threshold: float) -> None:
    flat = patch.flat
    ax.triplot(flat[:, 0], flat[:, 1], patch.triangles, lw=0.2, color="0.8", zorder=1)
    if gap.min() <= threshold:
        ax.tricontourf(flat[:, 0], flat[:, 1], patch.triangles, gap,
                       levels=[min(gap.min(), 0.0) - 1.0, threshold],
                       colors=[_REGION_COLOUR], alpha=0.75, zorder=2)
    outline = leaflet_outline(patch)
    colour = _GRAFT_COLOUR if patch.is_graft else "k"
    ax.plot(outline[:, 0], outline[:, 1], color=colour, lw=1.2, zorder=3)
    fe = flat[patch.free_edge]
    ax.plot(fe[:, 0], fe[:, 1], color=colour, lw=2.5, zorder=3)


def plot_coaptation_map(result: CoaptationResult, valve: ValveMesh, path: str | Path) -> Path:
    """Coaptation region on the flat outline of each leaflet, with its height profile.

    Top row: each leaflet's flat (reference) outline -- attachment edge thin,
    free edge thick -- with the region ``gap <= threshold`` filled.  Bottom
    row: the coaptation height profile ``h(x)`` along the free edge, the
    minimum on each side of the midline and the central value, with the
    nodulus tip (if ``nodulus_length_mm > 0``, see :mod:`.coaptation`) shaded.
    All panels share one length scale; the graft is drawn in blue and labelled.
    """
    plt = _pyplot()
    path = Path(path)
    patches = [p for p in valve.leaflets if p.name in result.leaflets]
    fig, axes = plt.subplots(2, len(patches), figsize=(4.6 * len(patches), 6.8),
                             gridspec_kw={"height_ratios": [2.2, 1]}, squeeze=False,
                             constrained_layout=True)
    xlim = max(np.abs(p.flat[:, 0]).max() for p in patches) * 1.05
    ylo = min(p.flat[:, 1].min() for p in patches) - 0.5
    yhi = max(p.flat[:, 1].max() for p in patches) + 0.5
    hmax = max(max(lc.height_mm.max() for lc in result.leaflets.values()), 1.0) * 1.15
    for k, patch in enumerate(patches):
        lc = result.leaflets[patch.name]
        label = patch.name.replace("_", "-") + (" (graft)" if patch.is_graft else "")
        ax = axes[0, k]
        _draw_leaflet(ax, patch, lc.node_gap_mm, result.threshold_mm)
        ax.set(xlim=(-xlim, xlim), ylim=(ylo, yhi), aspect="equal", xlabel="x (mm)",
               title=f"{label}\ncoapted area {lc.area_mm2:.1f} mm² "
                     f"(flat {lc.reference_area_mm2:.1f} mm²)")
        ax.title.set_color(_GRAFT_COLOUR if patch.is_graft else "k")
        if k == 0:
            ax.set_ylabel("y above nadir (mm)")
        bx = axes[1, k]
        bx.plot(lc.x_mm, lc.height_mm, color=_GRAFT_COLOUR if patch.is_graft else "k", lw=1.3)
        tip = 0.5 * lc.nodulus_length_mm
        if tip > 0.0:
            bx.axvspan(lc.midline_mm - tip, lc.midline_mm + tip, color="0.85", zorder=0,
                       label=f"nodulus {lc.nodulus_length_mm:g} mm "
                             f"(raw min {lc.min_height_raw_mm:.2f} mm)")
        for side, value in (("left", lc.min_height_left_mm), ("right", lc.min_height_right_mm)):
            bx.plot([lc.min_height_x(side)], [value], "v", color=_REGION_COLOUR, ms=5,
                    label=f"min {side} {value:.2f} mm")
        bx.plot([lc.midline_mm], [lc.central_height_mm], "o", color=_REGION_COLOUR,
                label=f"central {lc.central_height_mm:.2f} mm")
        bx.set(xlim=(-xlim, xlim), ylim=(0, hmax), xlabel="x along free edge (mm)")
        if k == 0:
            bx.set_ylabel("coaptation height h(x) (mm)")
        bx.legend(loc="lower center", fontsize=7.5, frameon=False)
        bx.grid(alpha=0.3)
    fig.suptitle(f"Coaptation region (gap ≤ {result.threshold_mm:g} mm to another leaflet) on "
                 f"the flat leaflets — regurgitant orifice "
                 f"{result.regurgitant_orifice_area_mm2:.2f} mm²"
                 f" ({'competent' if result.competent else 'incompetent'})", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150)
    plt.close(fig)
    log.info("wrote %s", path)
    return path


def plot_orifice_map(area_mm2: float, diagnostics: dict, path: str | Path) -> Path:
    """The orifice raster seen from the ventricle: footprints, open pixels, channels, dead ends."""
    plt = _pyplot()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    path = Path(path)
    cover = diagnostics["cover"]
    n = cover.shape[1]
    image = np.zeros((n, n), dtype=int)  # 0 outside the disk
    image[diagnostics["in_disk"]] = 1
    for i in range(len(cover)):
        image[cover[i] & diagnostics["in_disk"]] = 2 + i
    image[(cover.sum(axis=0) > 1) & diagnostics["in_disk"]] = 5
    image[diagnostics["open"]] = 6
    image[diagnostics["channel"]] = 7
    image[diagnostics["dead_end"]] = 8
    colours = ["white", "#eeeeee", "#d9a07b", "#c98b8b", "#b5a27a", "#8c7a6b", "red", "magenta",
               "#1f77b4"]
    lo = diagnostics["origin_mm"]
    hi = lo + n * diagnostics["pixel_mm"]
    fig, ax = plt.subplots(figsize=(8.2, 5.6), constrained_layout=True)
    ax.imshow(image, origin="lower", extent=(lo, hi, lo, hi), cmap=ListedColormap(colours),
              vmin=0, vmax=len(colours) - 1, interpolation="nearest")
    names = diagnostics["leaflet_names"]
    handles = [Patch(color=colours[2 + i], label=name.replace("_", "-"))
               for i, name in enumerate(names[:3])]
    handles += [Patch(color=colours[5], label="overlap, touching"),
                Patch(color=colours[1], label="gap < threshold (sealed)"),
                Patch(color="red", label="open"),
                Patch(color="magenta", label="leak channel (overlap, apart)"),
                Patch(color=colours[8], label="dead end (closed further down)")]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8,
              frameon=False)
    ax.set(xlabel="x (mm)", ylabel="y (mm)", aspect="equal",
           title=f"regurgitant orifice {area_mm2:.3f} mm² (pixel {diagnostics['pixel_mm']:g} mm)")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return path
