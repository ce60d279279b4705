"""3-D views of the valve with PyVista, rendered off screen.

Views (``view``): ``"iso"`` (oblique, from the aortic side), ``"side"`` (lower,
nearer the side: the open valve's shape), ``"aortic"``
(along the axis from the aorta, what the surgeon sees) and ``"ventricular"``
(along the axis from the ventricle: a mirror image of the aortic view).  The
camera uses a parallel projection, so the scale bar (5 mm) holds everywhere in
the picture.  Each leaflet is drawn in its colour and labelled (LC, RC, NC,
graft); the regurgitant orifice, when given and not empty, is drawn in front of
the leaflets in the axial views; where an edge of the loaded surface passes through one
of its triangles (:mod:`valve_dolfinx.analysis.intersection`), a yellow ball.

The figure functions return the rendered picture as an ``(h, w, 3)`` array
(show it with ``PIL.Image.fromarray`` or ``matplotlib``'s ``imshow``) and write
it to ``path`` if one is given; :func:`valve_plotter` returns the plotter
itself, to render or explore interactively.  A :class:`ViewRenderer` passed as
``views`` draws several figures in one off-screen window, which saves each
figure the creation of a window and an OpenGL context.  PyVista's global
settings are never changed: every plotter is created with ``off_screen`` set
explicitly.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from valve_dolfinx.plotting.orifice import orifice_outline, orifice_rectangles
from valve_dolfinx.plotting.style import (
    INTERSECTION_COLOUR,
    ORIFICE_COLOUR,
    SEQUENTIAL_CMAP,
    leaflet_colour,
    leaflet_label,
    save_picture,
)

__all__ = ["VIEWS", "SCALE_BAR_MM", "GAP_RANGE_MM", "pyvista_surface", "node_gap",
           "orifice_surface", "valve_plotter", "render", "ViewRenderer", "plot_valve_3d",
           "plot_gap_3d"]

log = logging.getLogger(__name__)

#: view name -> (vector from the focal point to the camera, view-up)
VIEWS = {"iso": ((0.8, -1.3, 2.4), (0.0, 0.0, 1.0)),
         "side": ((1.0, -1.6, 1.1), (0.0, 0.0, 1.0)),
         "aortic": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
         "ventricular": ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0))}
VIEW_TITLES = {"iso": "oblique view from the aortic side", "side": "oblique view from the side",
               "aortic": "seen from the aorta",
               "ventricular": "seen from the ventricle"}
SCALE_BAR_MM = 5.0
#: radius of the ball that marks an intersecting edge–triangle pair (mm): larger than the
#: contact gap, so that it shows on both sides of the leaflets it pierces
INTERSECTION_MARK_MM = 0.3
#: colour range of the gap view (mm): gaps wider than this are drawn in the top colour
GAP_RANGE_MM = (0.0, 3.0)


def _pv():
    import pyvista
    from vtkmodules.vtkCommonCore import vtkLogger

    # VTK logs to stderr past `logging`, in colour: its warnings (such as the missing X
    # display of an off-screen render, which needs none) only with debug logging (-v)
    debug = logging.getLogger("valve_dolfinx").isEnabledFor(logging.DEBUG)
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_WARNING if debug
                                 else vtkLogger.VERBOSITY_ERROR)
    return pyvista


def pyvista_surface(points: np.ndarray, cells: np.ndarray):
    """A :class:`pyvista.PolyData` triangle surface."""
    faces = np.hstack([np.full((len(cells), 1), 3), cells]).astype(np.int64).ravel()
    return _pv().PolyData(np.asarray(points, float), faces)


def node_gap(valve, coaptation) -> np.ndarray:
    """Per valve node, the loaded distance (mm) to the nearest other leaflet (NaN if none)."""
    gap = np.full(len(valve.points), np.nan)
    for patch in valve.leaflets:
        lc = coaptation.leaflets.get(patch.name)
        if lc is not None:
            gap[patch.nodes] = np.fmin(gap[patch.nodes], lc.node_gap_mm)
    return gap


def orifice_surface(diagnostics: dict, z: float):
    """The orifice's pixel runs as quads in the plane ``z`` (its area is the orifice's)."""
    rects = orifice_rectangles(diagnostics)
    if len(rects) == 0:
        return None
    points = np.concatenate([rects.reshape(-1, 2), np.full((4 * len(rects), 1), z)], axis=1)
    faces = np.hstack([np.full((len(rects), 1), 4),
                       np.arange(4 * len(rects)).reshape(-1, 4)]).astype(np.int64).ravel()
    return _pv().PolyData(points, faces)


def _screen_axes(view: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Direction of projection, screen right and screen up of a view."""
    vector, up = (np.asarray(v, float) for v in VIEWS[view])
    d = -vector / np.linalg.norm(vector)
    right = np.cross(d, up)
    right /= np.linalg.norm(right)
    return d, right, np.cross(right, d)


def _add_scale_bar(plotter, points: np.ndarray, view: str, length: float) -> None:
    d, right, up = _screen_axes(view)
    s, t, w = points @ right, points @ up, points @ d
    span = max(s.max() - s.min(), t.max() - t.min())
    start = s.min() * right + (t.min() - 0.07 * span) * up + w.mean() * d
    end = start + length * right
    pv = _pv()
    plotter.add_mesh(pv.Line(start, end), color="black", line_width=6)
    tick = 0.02 * span * up
    for p in (start, end):
        plotter.add_mesh(pv.Line(p - tick, p + tick), color="black", line_width=3)
    plotter.add_point_labels([start - 0.06 * span * up], [f"{length:g} mm"],
                             font_size=22, text_color="black", shape=None,
                             show_points=False, always_visible=True)


def _add_labels(plotter, positions: np.ndarray, valve, view: str) -> None:
    """Each leaflet's label on its belly in the axial views, a legend in the oblique one."""
    entries = [(leaflet_label(p), leaflet_colour(p, i)) for i, p in enumerate(valve.leaflets)]
    if view not in ("aortic", "ventricular"):
        plotter.add_legend([list(e) for e in entries], bcolor="white", border=True,
                           face="rectangle", size=(0.14, 0.05 * len(entries) + 0.02),
                           loc="lower right")
        return
    for patch, (label, colour) in zip(valve.leaflets, entries, strict=True):
        x = positions[patch.nodes]
        anchor = x.mean(axis=0)  # in front of the leaflets, over the belly's middle
        anchor[2] = x[:, 2].max() + 1.0 if view == "aortic" else x[:, 2].min() - 1.0
        plotter.add_point_labels([anchor], [label], font_size=26, bold=True,
                                 text_color="black", shape_color=colour, shape_opacity=0.85,
                                 margin=5, show_points=False, always_visible=True)


def _add_intersections(plotter, points: np.ndarray) -> None:
    """A ball at each point where an edge passes through a triangle, and what they are."""
    pv = _pv()
    balls = pv.PolyData(points).glyph(geom=pv.Sphere(radius=INTERSECTION_MARK_MM),
                                      orient=False, scale=False)
    plotter.add_mesh(balls, color=INTERSECTION_COLOUR, ambient=0.4)
    n = len(points)
    plotter.add_text(f"yellow: {n} intersecting edge–triangle pair{'s' if n > 1 else ''}",
                     position="lower_left", font_size=10, color="black")


def _place_camera(plotter, view: str, zoom: float) -> None:
    vector, up = VIEWS[view]
    plotter.enable_parallel_projection()
    plotter.view_vector(vector, viewup=up)
    plotter.reset_camera()
    plotter.camera.zoom(zoom)


def valve_plotter(positions: np.ndarray, valve, *, view: str = "iso", title: str = "",
                  scalars: np.ndarray | None = None, scalar_title: str = "",
                  clim: tuple[float, float] | None = None, contour: float | None = None,
                  orifice: dict | None = None, intersections: np.ndarray | None = None,
                  labels: bool = True, scale_bar: bool = True,
                  scalar_bar: bool = True,
                  window: tuple[int, int] = (1000, 850), off_screen: bool = True,
                  plotter=None, zoom: float = 1.25):
    """A plotter holding the valve in one view (see the module docstring).

    ``scalars`` (one value per node) colour the surface instead of the leaflet
    colours, with a colour bar titled ``scalar_title`` (unless ``scalar_bar``
    is false) and, if ``contour`` is given, a black line where the field
    equals it.  ``orifice`` is the orifice
    raster's diagnostics; ``intersections`` ``(K, 3)`` the points where an edge passes
    through a triangle, each marked with a ball.  Pass ``plotter`` to draw into a subplot
    of an existing one.
    """
    if view not in VIEWS:
        raise ValueError(f"view = {view!r}; use one of {', '.join(VIEWS)}")
    pv = _pv()
    positions = np.asarray(positions, float)
    if plotter is None:
        plotter = pv.Plotter(off_screen=off_screen, window_size=list(window))
    plotter.set_background("white")
    surf = pyvista_surface(positions, valve.cells)
    edges = {"show_edges": True, "edge_color": "#4d4d4d", "line_width": 0.3, "ambient": 0.25,
             "diffuse": 0.8}
    if scalars is not None:
        surf.point_data["field"] = np.asarray(scalars, float)
        plotter.add_mesh(surf, scalars="field", cmap=SEQUENTIAL_CMAP, clim=clim,
                         nan_color="#bbbbbb", show_scalar_bar=False, **edges)
        if scalar_bar:
            plotter.add_scalar_bar(title=scalar_title, color="black", n_labels=7, fmt="%.1f",
                                   title_font_size=20, label_font_size=18, vertical=False,
                                   position_x=0.45, position_y=0.03, height=0.09, width=0.5)
        if contour is not None:
            lines = surf.contour([contour], scalars="field")
            if lines.n_points:
                plotter.add_mesh(lines, color="black", line_width=3)
    else:
        for i, patch in enumerate(valve.leaflets):
            part = surf.extract_cells(np.flatnonzero(valve.cell_tags == patch.tag))
            plotter.add_mesh(part, color=leaflet_colour(patch, i), **edges)
    z = positions[:, 2]
    radius = float(np.max(np.linalg.norm(positions[valve.attachment_nodes(), :2], axis=1)))
    ring = pv.Circle(radius=radius, resolution=180)
    ring.points[:, 2] = z.min()
    plotter.add_mesh(ring.extract_feature_edges(), color="#555555", line_width=1.5)
    if orifice is not None and view in ("aortic", "ventricular"):
        quads = orifice_surface(orifice, z.max() + 0.5 if view == "aortic" else z.min() - 0.5)
        if quads is not None:
            plotter.add_mesh(quads, color=ORIFICE_COLOUR, opacity=0.9, lighting=False)
            for line in orifice_outline(orifice):
                xyz = np.column_stack([line, np.full(len(line), quads.points[0, 2])])
                plotter.add_mesh(pv.lines_from_points(xyz), color="black", line_width=2)
            plotter.add_text(f"vermillion: regurgitant orifice {quads.area:.2f} mm² "
                             "(projected along the axis)", position="lower_right",
                             font_size=10, color="black")
    if intersections is not None and len(intersections):
        _add_intersections(plotter, np.asarray(intersections, float))
    if labels and scalars is None:
        _add_labels(plotter, positions, valve, view)
    if scale_bar:
        _add_scale_bar(plotter, np.concatenate([positions, ring.points]), view, SCALE_BAR_MM)
    if title:
        plotter.add_text(title, position="upper_left", font_size=13, color="black")
    _place_camera(plotter, view, zoom)
    return plotter


def render(plotter, path: str | Path | None = None) -> np.ndarray:
    """The plotter's picture ``(h, w, 3)``, written to ``path`` if given; closes the plotter."""
    image = plotter.screenshot(None, return_img=True)
    plotter.close()
    return _written(image, path)


def _written(image: np.ndarray, path: str | Path | None) -> np.ndarray:
    if path is not None:
        save_picture(image, path)
    return image


class ViewRenderer:
    """One off-screen window that renders picture after picture.

    Each :meth:`picture` empties the scene (its lights stay), lets ``draw`` fill
    it without rendering after every addition, and renders once.  Use it as a
    context manager, or call :meth:`close`.
    """

    def __init__(self) -> None:
        self._plotter = None

    def picture(self, window: tuple[int, int], draw: Callable) -> np.ndarray:
        """The picture ``(h, w, 3)`` of the scene ``draw(plotter)`` makes in a ``window``."""
        if self._plotter is None:
            self._plotter = _pv().Plotter(off_screen=True, window_size=list(window))
        plotter = self._plotter
        plotter.suppress_rendering = True
        try:
            plotter.renderer.clear_actors()
            plotter.remove_legend()
            plotter.scalar_bars.clear()
            plotter.window_size = list(window)
            draw(plotter)
        finally:
            plotter.suppress_rendering = False
        plotter.render()
        return plotter.screenshot(None, return_img=True)

    def close(self) -> None:
        if self._plotter is not None:
            self._plotter.close()
            self._plotter = None

    def __enter__(self) -> ViewRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@contextlib.contextmanager
def _window(views: ViewRenderer | None) -> Iterator[ViewRenderer]:
    """``views``, or a window of the figure's own if ``views`` is None."""
    if views is not None:
        yield views
        return
    with ViewRenderer() as own:
        yield own


def plot_valve_3d(positions: np.ndarray, valve, path: str | Path | None = None, *,
                  view: str = "iso", title: str = "", orifice: dict | None = None,
                  intersections: np.ndarray | None = None,
                  window: tuple[int, int] = (1000, 850),
                  views: ViewRenderer | None = None) -> np.ndarray:
    """The valve in one view, leaflets coloured and labelled, with a scale bar.

    ``positions`` are the node positions to draw (``valve.points`` for the
    valve as built); ``orifice`` (the orifice raster's diagnostics) draws the
    regurgitant orifice in the axial views; ``intersections`` ``(K, 3)`` marks where an
    edge of the surface passes through one of its triangles; ``views`` renders it in a
    shared window.  Returns the picture; writes it to ``path`` if given.
    """
    def draw(plotter) -> None:
        valve_plotter(positions, valve, view=view, title=title, orifice=orifice,
                      intersections=intersections, plotter=plotter)

    with _window(views) as shared:
        return _written(shared.picture(window, draw), path)


def plot_gap_3d(positions: np.ndarray, valve, coaptation, path: str | Path | None = None, *,
                title: str = "", window: tuple[int, int] = (1800, 850),
                views: ViewRenderer | None = None) -> np.ndarray:
    """The loaded valve coloured by the gap to the nearest other leaflet (mm), two views.

    Left: oblique from the aortic side; right: from the aorta, each in half of
    ``window``.  A black line marks the coaptation threshold.  ``views`` renders
    it in a shared window.  Returns the picture; writes it to ``path`` if given.
    """
    gap = node_gap(valve, coaptation)
    bar = "gap to the nearest other leaflet (mm)"

    def half(view: str, heading: str, scalar_bar: bool) -> Callable:
        def draw(plotter) -> None:
            valve_plotter(positions, valve, view=view, scalars=gap, scalar_title=bar,
                          clim=GAP_RANGE_MM, contour=coaptation.threshold_mm,
                          plotter=plotter, scalar_bar=scalar_bar, title=heading)
        return draw

    left = (title + "\n" if title else "") + VIEW_TITLES["iso"]
    right = (VIEW_TITLES["aortic"] + f"; black line: gap = {coaptation.threshold_mm:g} mm "
             "(coaptation threshold)")
    size = (window[0] // 2, window[1])
    with _window(views) as shared:
        image = np.hstack([shared.picture(size, half("iso", left, False)),
                           shared.picture(size, half("aortic", right, True))])
    return _written(image, path)
