"""The graft template's A4 page: the graft at true size, to print and cut from (SPEC §9).

The page shows the graft to cut (:class:`~valve_dolfinx.geometry.template.GraftTemplate`):

* the cut line, the margin outside the suture line and the free edge drawn distinctly,
  the suture line (the attachment edge itself), the midline, the fibre direction (the
  graft's fibre angle from its free edge);
* the free-edge length and the height in mm, the plan's label, and a 50 mm
  calibration bar with the instruction to measure it after printing.

The page is described once, in millimetres with y upwards
(:class:`~valve_dolfinx.plotting.page.Drawing`), and written twice
(:mod:`valve_dolfinx.plotting.page`): as SVG in millimetre units (``width="210mm"``, a
viewBox in mm) and as PDF through matplotlib, on an A4 figure whose single axes maps one
data unit onto one millimetre of paper.  Printed at 100 % either measures what it says.
:mod:`valve_dolfinx.plan.template` writes the files.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np

from valve_dolfinx.geometry.template import GraftTemplate
from valve_dolfinx.plotting.page import A4_MM, Drawing
from valve_dolfinx.plotting.style import OKABE_ITO

__all__ = ["CALIBRATION_MM", "CUT_WIDTH_MM", "FREE_EDGE_WIDTH_MM", "template_drawing"]

#: length of the calibration bar (mm)
CALIBRATION_MM = 50.0
#: line widths (mm): the cut line and the free edge, which are measured on the print
CUT_WIDTH_MM = 0.25
FREE_EDGE_WIDTH_MM = 0.5
_FREE_EDGE_COLOUR = OKABE_ITO["blue"]
_FIBRE_COLOUR = OKABE_ITO["bluish_green"]
_MARGIN_FILL = "#d0d0d0"
_GRAFT_FILL = "#f7e6ef"
_GUIDE = "#404040"


def _arrow_head(tip: np.ndarray, direction: np.ndarray, length: float = 1.6,
                width: float = 1.0) -> np.ndarray:
    d = direction / np.linalg.norm(direction)
    n = np.array([-d[1], d[0]])
    base = tip - length * d
    return np.array([tip, base + 0.5 * width * n, base - 0.5 * width * n])


def _double_arrow(page: Drawing, start, end, colour: str, width_mm: float = 0.2) -> None:
    start, end = np.asarray(start, float), np.asarray(end, float)
    page.line([start, end], stroke=colour, width_mm=width_mm)
    for tip, back in ((end, start), (start, end)):
        page.line(_arrow_head(tip, tip - back), stroke=None, fill=colour, closed=True)


def _fibres(page: Drawing, template: GraftTemplate, origin: np.ndarray) -> None:
    """Three parallel double arrows at the fibre angle, side by side across the fibres, in
    the graft's left half (the right half is left to the height's dimension); short enough
    to stay inside the graft at any angle."""
    s = template.shape
    angle = math.radians(template.fibre_angle_deg)
    along = np.array([math.cos(angle), math.sin(angle)])
    across = np.array([-along[1], along[0]])
    half = min(0.3 * s.half_width, 0.2 * s.height)
    centre = origin + [-0.35 * s.half_width, 0.55 * s.height]
    for k in (-1, 0, 1):
        mid = centre + k * 0.22 * min(s.height, s.half_width) * across
        _double_arrow(page, mid - half * along, mid + half * along, _FIBRE_COLOUR, 0.25)


def _legend(page: Drawing, x: float, y: float, template: GraftTemplate) -> float:
    """The key to the lines, from ``y`` downwards; returns the y below it."""
    m = template.margin_mm
    rows = [
        (dict(stroke="#000000", width_mm=CUT_WIDTH_MM), "cut line"),
        (dict(stroke=_FREE_EDGE_COLOUR, width_mm=FREE_EDGE_WIDTH_MM),
         "free edge: cut on it, no margin"),
        (dict(stroke=_GUIDE, width_mm=0.2, dash_mm=(1.2, 0.8)),
         "suture line: the graft's attachment edge (lower edge and commissures)"),
        (dict(stroke=None, fill=_MARGIN_FILL, closed=True),
         f"suturing margin, {m:g} mm, outside the suture line"),
        (dict(stroke=_FIBRE_COLOUR, width_mm=0.25),
         f"fibre direction, {template.fibre_angle_deg:g}° from the free edge"
         + (" (parallel to it)" if template.fibre_angle_deg == 0 else "")),
        (dict(stroke=_GUIDE, width_mm=0.2, dash_mm=(3.0, 0.8, 0.5, 0.8)),
         "midline: the height is measured along it"),
    ]
    for style, words in rows:
        if style.get("fill"):
            page.line([[x, y - 1.2], [x + 10, y - 1.2], [x + 10, y + 1.2], [x, y + 1.2]],
                      **style)
        else:
            page.line([[x, y], [x + 10, y]], **style)
        page.text(x + 14, y - 1.1, words, size_pt=9)
        y -= 6.5
    return y


#: what to do with the print, in order
_STEPS = (
    "Print at 100 % ('actual size', not 'fit to page') and measure the 50 mm bar.",
    "Cut the template out along the solid line; the blue free edge has no margin.",
    "Lay it on the pericardium with the green arrows along the chosen fibre direction, "
    "trace it and cut the graft along the traced line.",
    "Sew along the suture line: the dashed line, the margin's width inside the cut edge.",
)


def _calibration_bar(page: Drawing, x0: float, y0: float) -> None:
    """A filled bar of :data:`CALIBRATION_MM` with white ticks every 10 mm."""
    page.line([[x0, y0], [x0 + CALIBRATION_MM, y0], [x0 + CALIBRATION_MM, y0 + 3.0],
               [x0, y0 + 3.0]], stroke=None, fill="#000000", closed=True,
              name="calibration-bar")
    for k in range(1, int(CALIBRATION_MM // 10)):
        page.line([[x0 + 10 * k, y0 + 0.8], [x0 + 10 * k, y0 + 2.2]], stroke="#ffffff",
                  width_mm=0.3)
    page.text(x0 + CALIBRATION_MM + 3, y0 + 0.6, f"{CALIBRATION_MM:g} mm", size_pt=10,
              bold=True)
    page.text(x0, y0 - 5.0, f"Check after printing: this bar must measure {CALIBRATION_MM:g} "
              "mm. If it does not,", size_pt=9)
    page.text(x0, y0 - 9.0, "print again at 100 % before cutting.", size_pt=9)
    page.regions["calibration"] = (x0, y0, x0 + CALIBRATION_MM, y0 + 3.0)


def _graft(page: Drawing, template: GraftTemplate, origin: np.ndarray) -> None:
    """The graft, its margin, the guide lines and its two dimensions."""
    s, m = template.shape, template.margin_mm
    a, top = s.half_width, s.height
    page.line(origin + template.cut_line(), stroke=None, fill=_MARGIN_FILL, closed=True)
    page.line(origin + template.outline(), stroke=None, fill=_GRAFT_FILL, closed=True)
    page.line(origin + template.attachment(), stroke=_GUIDE, width_mm=0.2, dash_mm=(1.2, 0.8),
              name="suture-line")
    page.line(origin + np.array([[0.0, 0.0], [0.0, top]]), stroke=_GUIDE, width_mm=0.2,
              dash_mm=(3.0, 0.8, 0.5, 0.8), name="midline")
    _fibres(page, template, origin)
    page.line(origin + template.cut_line(), stroke="#000000", width_mm=CUT_WIDTH_MM,
              closed=True, name="cut-line")
    page.line(origin + np.array([[-a, top], [a, top]]), stroke=_FREE_EDGE_COLOUR,
              width_mm=FREE_EDGE_WIDTH_MM, name="free-edge")
    # the free edge's length above it; the height along the midline, labelled outside
    dim_y = origin[1] + top + 8.0
    for x in (-a, a):
        page.line([[origin[0] + x, origin[1] + top + 2.0], [origin[0] + x, dim_y + 1.5]],
                  stroke=_GUIDE, width_mm=0.15)
    _double_arrow(page, [origin[0] - a, dim_y], [origin[0] + a, dim_y], _GUIDE)
    page.text(origin[0], dim_y + 2.0, f"free edge {s.free_edge_length:.1f} mm", size_pt=10,
              anchor="middle", bold=True, colour=_FREE_EDGE_COLOUR)
    _double_arrow(page, origin, origin + [0.0, top], _GUIDE, 0.15)
    label_x = origin[0] + a + m + 5.0
    page.text(label_x, origin[1] + 0.5 * top - 1.2, f"height {top:.1f} mm", size_pt=10,
              bold=True)
    page.text(label_x, origin[1] + 0.5 * top - 5.0, "along the midline", size_pt=8)
    cut = (origin[0] - a - m, origin[1] - m, origin[0] + a + m, origin[1] + top)
    page.regions["cut"] = cut
    page.regions["thumbnail"] = (min(cut[0] - 6.0, origin[0] - 24.0), cut[1] - 4.0,
                                 label_x + 36.0, dim_y + 7.0)


def template_drawing(template: GraftTemplate, patient_line: str = "") -> Drawing:
    """The A4 page of ``template`` (see the module docstring); ``patient_line`` says which
    measured leaflet the percentages refer to."""
    from valve_dolfinx._version import __version__

    width, _ = A4_MM
    s, m = template.shape, template.margin_mm
    page = Drawing()
    left = 20.0
    page.text(left, 280, f"Graft template: {template.label}", size_pt=15, bold=True)
    page.text(left, 273, f"Pericardial graft {template.graft.label}: "
              f"+{template.graft.width_pct:g} % width, +{template.graft.height_pct:g} % "
              "height of the measured leaflet", size_pt=10)
    if patient_line:
        page.text(left, 267.5, patient_line, size_pt=9)
    page.text(left, 261, "True size when printed at 100 %: measure the 50 mm bar before "
              "cutting.", size_pt=10, bold=True)

    origin = np.array([0.5 * width, 238.0 - s.height])
    page.graft_origin = (float(origin[0]), float(origin[1]))
    _graft(page, template, origin)
    y = page.regions["cut"][1] - 14.0
    page.text(left, y, f"Cut piece {template.cut_width_mm:.1f} mm wide and "
              f"{template.cut_height_mm:.1f} mm high: the graft ({s.free_edge_length:.1f} × "
              f"{s.height:.1f} mm) and its {m:g} mm suturing margin.", size_pt=9)
    _calibration_bar(page, left, y - 14.0)
    y = _legend(page, left, y - 34.0, template)
    page.text(left, y - 4.0, "How to use it", size_pt=11, bold=True)
    y -= 11.0
    for number, step in enumerate(_STEPS, start=1):
        for k, line in enumerate(textwrap.wrap(step, 84)):
            page.text(left + (0 if k == 0 else 5.0), y, f"{number}. {line}" if k == 0
                      else line, size_pt=9)
            y -= 5.5
    page.text(left, 15, f"valve_dolfinx {__version__} · plan {template.label} · template "
              f"{template.graft.label} · a model's prediction; the surgeon decides.",
              size_pt=7, colour=_GUIDE)
    return page
