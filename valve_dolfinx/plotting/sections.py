"""Plane sections of the loaded valve: axial cuts (planes through the axis) and horizontal ones.

The valve axis is z (the nadirs at z ≈ 0, the aorta above).  An axial cut at
azimuth φ is the plane holding the axis and ``(cos φ, sin φ, 0)``; it is drawn
in its own plane, the abscissa being the signed distance from the axis along
that direction.  :func:`axial_cuts` chooses the two cuts that show a graft
best: through the graft's midline (and so through the commissure opposite it),
and through one of the graft's commissures (and so through the midline of the
leaflet opposite that commissure).  On a valve without a graft the
non-coronary leaflet takes the graft's place.
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch

from valve_dolfinx.plotting.orifice import draw_orifice, orifice_mask
from valve_dolfinx.plotting.style import (
    ORIFICE_COLOUR,
    key_numbers,
    leaflet_colour,
    leaflet_label,
    new_figure,
    save_figure,
)

__all__ = ["AxialCut", "axial_cuts", "leaflet_azimuths", "slice_triangles", "plot_cut_planes",
           "plot_cross_sections"]


def slice_triangles(x: np.ndarray, cells: np.ndarray, normal: np.ndarray,
                    offset: float = 0.0) -> np.ndarray:
    """Segments ``(k, 2, 3)`` where the plane ``normal·x = offset`` cuts the triangles."""
    p = x[cells]
    d = p @ normal - offset
    pos = d > 0
    cut = pos.any(axis=1) & ~pos.all(axis=1)
    p, d, pos = p[cut], d[cut], pos[cut]
    ends = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        crosses = pos[:, i] != pos[:, j]
        t = np.where(crosses, d[:, i] / np.where(crosses, d[:, i] - d[:, j], 1.0), np.nan)
        ends.append(p[:, i] + t[:, None] * (p[:, j] - p[:, i]))
    ends = np.stack(ends, axis=1)  # (k, 3 edges, 3): exactly two edges are cut
    keep = ~np.isnan(ends[..., 0])
    return ends[keep].reshape(-1, 2, 3)


def leaflet_azimuths(valve) -> np.ndarray:
    """Azimuth (degrees) of each leaflet's midline, from its free-edge midpoint as built."""
    angles = []
    for patch in valve.leaflets:
        x, y = valve.points[patch.nodes[patch.midline_free_edge_node], :2]
        angles.append(math.degrees(math.atan2(y, x)))
    return np.array(angles)


def _angle_gap(a: float, b: np.ndarray) -> np.ndarray:
    return np.abs((np.asarray(b) - a + 180.0) % 360.0 - 180.0)


class AxialCut:
    """An axial cut: its azimuth and what it passes through on either side of the axis."""

    def __init__(self, phi_deg: float, positive: str, negative: str) -> None:
        self.phi_deg, self.positive, self.negative = float(phi_deg), positive, negative

    def __repr__(self) -> str:
        return f"AxialCut({self.phi_deg:g}°: {self.negative} | {self.positive})"


def axial_cuts(valve) -> list[AxialCut]:
    """The cut through the graft's (else NC's) midline, and the one through its commissure."""
    patches = list(valve.leaflets)
    phi = leaflet_azimuths(valve)
    labels = [leaflet_label(p) for p in patches]
    main = next((i for i, p in enumerate(patches) if p.is_graft),
                next((i for i, p in enumerate(patches) if p.name == "non_coronary"), 0))

    def midline(angle: float) -> str:
        return f"{labels[int(np.argmin(_angle_gap(angle, phi)))]} midline"

    def commissure(angle: float) -> str:
        near = np.argsort(_angle_gap(angle, phi))[:2]
        return "–".join(labels[k] for k in sorted(near)) + " commissure"

    if len(patches) < 2:
        return [AxialCut(phi[main], midline(phi[main]), "opposite side")]
    first = phi[main]
    second = first + 60.0
    return [AxialCut(first, midline(first), commissure(first + 180.0)),
            AxialCut(second, commissure(second), midline(second + 180.0))]


def _leaflet_handles(valve) -> list[Line2D]:
    return [Line2D([], [], color=leaflet_colour(p, i), lw=2.5, label=leaflet_label(p))
            for i, p in enumerate(valve.leaflets)]


def _radius(positions: np.ndarray, valve) -> float:
    return float(np.max(np.linalg.norm(positions[valve.attachment_nodes(), :2], axis=1)))


def plot_cut_planes(positions: np.ndarray, valve, path=None, *, title: str = "",
                    result=None, cuts: list[AxialCut] | None = None):
    """The loaded leaflets in the axial cuts of :func:`axial_cuts` (or ``cuts``).

    ``result`` (a case or coaptation result), if given, puts its key numbers
    in the title.  Returns the figure; writes it to ``path`` if given.
    """
    cuts = axial_cuts(valve) if cuts is None else cuts
    fig = new_figure(6.2 * len(cuts), 5.4)
    axes = fig.subplots(1, len(cuts), squeeze=False)[0]
    radius = _radius(positions, valve)
    z = positions[:, 2]
    for ax, cut in zip(axes, cuts, strict=True):
        # a hair off the cut's azimuth: a commissure made by mirroring lies exactly in the
        # plane, where no triangle crosses it
        phi = math.radians(cut.phi_deg + 0.01)
        e = np.array([math.cos(phi), math.sin(phi), 0.0])
        n = np.array([-math.sin(phi), math.cos(phi), 0.0])
        for i, patch in enumerate(valve.leaflets):
            segments = slice_triangles(positions, valve.cells[valve.cell_tags == patch.tag], n)
            if len(segments) == 0:
                continue
            lines = np.stack([segments @ e, segments[..., 2]], axis=-1)
            ax.add_collection(LineCollection(lines, colors=leaflet_colour(patch, i),
                                             linewidths=2.2))
        for side in (-radius, radius):
            ax.axvline(side, color="0.55", lw=1.0)
        ax.axvline(0.0, color="0.75", lw=0.8, ls=":")
        ax.set(aspect="equal", xlim=(-1.2 * radius, 1.2 * radius),
               ylim=(z.min() - 1.0, z.max() + 2.5),
               xlabel=f"distance from the axis along φ = {cut.phi_deg % 360:.0f}° (mm)",
               ylabel="height above the nadirs (mm)")
        top = z.max() + 1.6
        ax.text(-radius, top, f"← {cut.negative}", ha="left", va="center", fontsize=9)
        ax.text(radius, top, f"{cut.positive} →", ha="right", va="center", fontsize=9)
        ax.set_title(f"axial cut through the {cut.positive} and the {cut.negative}",
                     fontsize=10)
        ax.grid(alpha=0.25)
    axes[0].legend(handles=_leaflet_handles(valve), loc="lower left", fontsize=8)
    heading = (title + ": " if title else "") + "axial cuts (grey: root wall)"
    fig.suptitle(heading + (f"\n{key_numbers(result)}" if result is not None else ""),
                 fontsize=11)
    return save_figure(fig, path, dpi=140)


def plot_cross_sections(positions: np.ndarray, valve, path=None, *, title: str = "",
                        heights: tuple[float, ...] | None = None, result=None,
                        orifice: dict | None = None):
    """Horizontal cuts (z = const) of the loaded valve, seen from the aorta.

    ``orifice`` (the orifice raster's diagnostics), if its area is not 0, is
    drawn in each section, projected along the axis.  Returns the figure;
    writes it to ``path`` if given.
    """
    z = positions[:, 2]
    if heights is None:
        heights = tuple(np.round(np.linspace(z.min(), z.max(), 6)[1:-1], 1))
    radius = _radius(positions, valve)
    fig = new_figure(3.9 * len(heights), 5.2)
    axes = fig.subplots(1, len(heights), squeeze=False, sharey=True)[0]
    leaks = orifice is not None and orifice_mask(orifice).any()
    for k, (ax, z0) in enumerate(zip(axes, heights, strict=True)):
        if leaks:
            draw_orifice(ax, orifice, zorder=1)
        for i, patch in enumerate(valve.leaflets):
            cells = valve.cells[valve.cell_tags == patch.tag]
            segments = slice_triangles(positions, cells, np.array([0.0, 0.0, 1.0]), z0)
            ax.add_collection(LineCollection(segments[..., :2], colors=leaflet_colour(patch, i),
                                             linewidths=2.0, zorder=3))
        ax.add_patch(Circle((0.0, 0.0), radius, fill=False, color="0.55", zorder=2))
        lim = 1.1 * radius
        ax.set(xlim=(-lim, lim), ylim=(-lim, lim), aspect="equal", xlabel="x (mm)",
               title=f"z = {z0:g} mm")
        if k == 0:
            ax.set_ylabel("y (mm)")
        ax.grid(alpha=0.25)
    handles = _leaflet_handles(valve)
    if leaks:
        handles.append(Patch(color=ORIFICE_COLOUR, label="regurgitant orifice (projected)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=9,
               frameon=False)
    heading = (title + ": " if title else "") + "horizontal sections, seen from the aorta"
    fig.suptitle(heading + (f"\n{key_numbers(result)}" if result is not None else ""),
                 fontsize=11)
    return save_figure(fig, path, dpi=120)
