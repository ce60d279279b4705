"""A page described in millimetres, written as SVG and drawn by matplotlib at true size.

:class:`Drawing` holds polylines, polygons and lines of text on an A4 page (mm, y up
from the lower left corner), in drawing order.  :func:`drawing_svg` writes it as SVG in
millimetre units (``width="210mm"``, a viewBox in mm); :func:`page_figure` draws it on a
matplotlib figure of exactly A4 whose single axes maps one data unit onto one millimetre
of paper; :func:`region_inches` is one of its named rectangles, to save that part alone.
Printed at 100 % either measures what it says (the graft templates of
:mod:`valve_dolfinx.plotting.template` are such pages).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from xml.sax.saxutils import escape

import numpy as np

__all__ = ["A4_MM", "PT_MM", "Drawing", "PathItem", "TextItem", "drawing_svg", "page_figure",
           "region_inches"]

#: A4 portrait (mm)
A4_MM = (210.0, 297.0)
#: one typographic point (mm)
PT_MM = 25.4 / 72.0


@dataclass(frozen=True)
class PathItem:
    """A polyline or polygon on the page (mm, y up)."""

    points: np.ndarray
    stroke: str | None = "#000000"
    width_mm: float = 0.2
    dash_mm: tuple[float, ...] = ()
    fill: str | None = None
    closed: bool = False
    name: str = ""


@dataclass(frozen=True)
class TextItem:
    """One line of text: ``(x, y)`` is the baseline's start, middle or end (mm, y up)."""

    x: float
    y: float
    text: str
    size_pt: float = 9.0
    anchor: str = "start"
    bold: bool = False
    colour: str = "#000000"


@dataclass
class Drawing:
    """Everything on one A4 page, in drawing order (mm, y up from the lower left corner).

    ``graft_origin`` is where the graft's nadir sits on the page; ``regions`` name the
    page rectangles ``(x0, y0, x1, y1)`` of the parts a reader may want (the cut piece,
    the calibration bar, the thumbnail).
    """

    paths: list[PathItem] = field(default_factory=list)
    texts: list[TextItem] = field(default_factory=list)
    graft_origin: tuple[float, float] = (0.0, 0.0)
    regions: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)

    def line(self, points, **style) -> None:
        self.paths.append(PathItem(np.asarray(points, dtype=float), **style))

    def text(self, x: float, y: float, text: str, **style) -> None:
        self.texts.append(TextItem(x, y, text, **style))


def _svg_path(item: PathItem, height: float) -> str:
    pts = " L ".join(f"{x:.4f} {height - y:.4f}" for x, y in item.points)
    attrs = [f'd="M {pts}{" Z" if item.closed else ""}"',
             f'fill="{item.fill or "none"}"', f'stroke="{item.stroke or "none"}"']
    if item.name:
        attrs.insert(0, f'id="{item.name}"')
    if item.stroke:
        attrs.append(f'stroke-width="{item.width_mm:g}" stroke-linejoin="round"')
    if item.dash_mm:
        attrs.append(f'stroke-dasharray="{" ".join(f"{d:g}" for d in item.dash_mm)}"')
    return f"  <path {' '.join(attrs)}/>"


def _svg_text(item: TextItem, height: float) -> str:
    weight = ' font-weight="bold"' if item.bold else ""
    return (f'  <text x="{item.x:.3f}" y="{height - item.y:.3f}" font-size="'
            f'{item.size_pt * PT_MM:.3f}" text-anchor="{item.anchor}" fill="{item.colour}"'
            f"{weight}>{escape(item.text)}</text>")


def drawing_svg(page: Drawing, title: str = "") -> str:
    """The page as SVG text: millimetre units, the viewBox in mm (y down, as SVG has it)."""
    width, height = A4_MM
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:g}mm" '
             f'height="{height:g}mm" viewBox="0 0 {width:g} {height:g}">',
             f"  <title>{escape(title)}</title>",
             '  <g font-family="DejaVu Sans, Arial, Helvetica, sans-serif">']
    lines += [_svg_path(p, height) for p in page.paths]
    lines += [_svg_text(t, height) for t in page.texts]
    lines += ["  </g>", "</svg>"]
    return "\n".join(lines) + "\n"


def page_figure(page: Drawing):
    """The page as a matplotlib figure of exactly A4, one data unit = one millimetre."""
    from matplotlib.patches import Polygon

    from valve_dolfinx.plotting.style import new_figure

    width, height = A4_MM
    fig = new_figure(width / 25.4, height / 25.4, layout=None)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, width)
    ax.set_ylim(0.0, height)
    ax.set_axis_off()
    for item in page.paths:
        lw = item.width_mm / PT_MM if item.stroke else 0.0
        style = (0, [d / PT_MM / lw for d in item.dash_mm]) if item.dash_mm else "solid"
        if item.fill or item.closed:
            ax.add_patch(Polygon(item.points, closed=item.closed, facecolor=item.fill or "none",
                                 edgecolor=item.stroke or "none", linewidth=lw,
                                 linestyle=style, joinstyle="round"))
        else:
            ax.plot(item.points[:, 0], item.points[:, 1], color=item.stroke, linewidth=lw,
                    linestyle=style, solid_joinstyle="round", solid_capstyle="butt",
                    dash_capstyle="butt")
    for t in page.texts:
        ax.text(t.x, t.y, t.text, fontsize=t.size_pt, ha={"start": "left", "middle": "center",
                                                          "end": "right"}[t.anchor],
                va="baseline", color=t.colour, fontweight="bold" if t.bold else "normal",
                parse_math=False)  # a label is plain text: a $ is a dollar sign
    return fig


def region_inches(page: Drawing, name: str):
    """The page's rectangle ``name`` (:attr:`Drawing.regions`) as a matplotlib box in
    inches, for ``savefig(bbox_inches=...)`` of :func:`page_figure`'s figure."""
    from matplotlib.transforms import Bbox

    return Bbox.from_extents(*(v / 25.4 for v in page.regions[name]))
