"""Figures: PyVista (off-screen) for 3-D views, matplotlib for flat outlines and curves.

Every function writes one PNG and returns its path.  They take plain arrays so
they work on results read back from disk as well as on live solutions.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

__all__ = [
    "LEAFLET_COLOURS",
    "GRAFT_COLOUR",
    "plot_flat_leaflet",
    "plot_valve_3d",
    "pyvista_surface",
]

log = logging.getLogger(__name__)

LEAFLET_COLOURS = {1: "#d9a07b", 2: "#c98b8b", 3: "#b5a27a"}
GRAFT_COLOUR = "#5b8fd9"


def _pyvista():
    os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
    import pyvista as pv

    pv.OFF_SCREEN = True
    return pv


def pyvista_surface(points: np.ndarray, cells: np.ndarray):
    """A :class:`pyvista.PolyData` triangle surface."""
    pv = _pyvista()
    faces = np.hstack([np.full((len(cells), 1), 3), cells]).astype(np.int64).ravel()
    return pv.PolyData(np.asarray(points, float), faces)


def plot_flat_leaflet(points: np.ndarray, triangles: np.ndarray, path: str | Path, *,
                      title: str = "", fibres: np.ndarray | None = None,
                      outline: np.ndarray | None = None) -> Path:
    """The flat leaflet triangulation (mm), optionally with fibre directions per cell."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.4), constrained_layout=True)
    ax.triplot(points[:, 0], points[:, 1], triangles, lw=0.4, color="0.35")
    if fibres is not None:
        c = points[triangles].mean(axis=1)
        step = max(1, len(c) // 400)
        ax.quiver(c[::step, 0], c[::step, 1], fibres[::step, 0], fibres[::step, 1],
                  color="tab:red", pivot="mid", scale=45, width=0.002, headwidth=0,
                  headlength=0, headaxislength=0, label="fibre direction")
        ax.legend(loc="lower right")
    if outline is not None:
        ax.plot(outline[:, 0], outline[:, 1], color="k", lw=1.2)
    ax.set_aspect("equal")
    ax.set_xlabel("x across the leaflet (mm)")
    ax.set_ylabel("height above the nadir (mm)")
    ax.set_title(title or f"flat leaflet: {len(points)} nodes, {len(triangles)} triangles")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return path


def plot_valve_3d(points: np.ndarray, cells: np.ndarray, cell_tags: np.ndarray,
                  path: str | Path, *, graft_tag: int | None = None, title: str = "",
                  view: str = "iso", scalars: np.ndarray | None = None,
                  scalar_name: str = "", clim: tuple[float, float] | None = None,
                  window: tuple[int, int] = (1000, 800)) -> Path:
    """Render the valve surface: leaflets coloured by tag (the graft in blue), or a field.

    ``view`` is ``"iso"``, ``"ventricular"`` (from below, looking up the axis)
    or ``"aortic"`` (from above).
    """
    pv = _pyvista()
    surf = pyvista_surface(points, cells)
    plotter = pv.Plotter(off_screen=True, window_size=list(window))
    plotter.set_background("white")
    if scalars is not None:
        surf.cell_data[scalar_name or "value"] = scalars
        plotter.add_mesh(surf, scalars=scalar_name or "value", cmap="viridis", clim=clim,
                         show_edges=True, edge_color="#555555", line_width=0.3,
                         scalar_bar_args={"title": scalar_name, "color": "black"})
    else:
        for tag in np.unique(cell_tags):
            part = surf.extract_cells(np.flatnonzero(cell_tags == tag))
            colour = GRAFT_COLOUR if tag == graft_tag else LEAFLET_COLOURS.get(int(tag), "tan")
            plotter.add_mesh(part, color=colour, show_edges=True, edge_color="#444444",
                             line_width=0.3, smooth_shading=False)
    radius = np.max(np.linalg.norm(points[:, :2], axis=1))
    circle = pv.Circle(radius=radius, resolution=180)
    circle.points[:, 2] = points[:, 2].min()
    plotter.add_mesh(circle.extract_feature_edges(), color="black", line_width=1.5)
    if view == "ventricular":
        plotter.view_vector((0, 0, -1), viewup=(0, 1, 0))
    elif view == "aortic":
        plotter.view_vector((0, 0, 1), viewup=(0, 1, 0))
    else:
        plotter.view_vector((1.0, -1.6, 1.1), viewup=(0, 0, 1))
    plotter.camera.zoom(1.15)
    if title:
        plotter.add_text(title, font_size=12, color="black")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(path))
    plotter.close()
    return path
