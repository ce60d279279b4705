"""The plan's one page (A4) as a matplotlib figure, from its words and pictures.

:func:`draw_plan_page` lays out a :class:`PlanPage`, top to bottom: the title, the
answer framed in the colour of its kind, the measured inputs beside the graft template's
thumbnail, the sizing map and the closed valve from the aorta and from the ventricle (with
several comparison values, their sizing maps side by side instead), what was run, the
limitations.  A picture that was not made is a grey box that says so.
The figure is exactly A4 on its own canvas (:func:`valve_dolfinx.plotting.style.
new_figure`), its parts placed in millimetres; every text is at least 7 pt at print
size, and the inputs are wrapped, never cut.  What the page says is computed by
:mod:`valve_dolfinx.plan.report`.
"""

from __future__ import annotations

import textwrap
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from valve_dolfinx.plotting.page import A4_MM, PT_MM
from valve_dolfinx.plotting.style import OKABE_ITO, new_figure

__all__ = ["PlanPage", "MapDrawer", "draw_plan_page", "SIZING_MAP_MM", "sizing_map_mm"]

_BOX = {"graft": "#e3f1ea", "closest": "#fbefd9", "cannot_seal": "#f8dfd6"}
_EDGE = {"graft": OKABE_ITO["bluish_green"], "closest": OKABE_ITO["orange"],
         "cannot_seal": OKABE_ITO["vermillion"]}
#: the largest box of the sizing map on the page (width, height in mm); the page draws the
#: map at the size of the box it has (its height may be less), so that it prints at 100 %
SIZING_MAP_MM = (116.0, 100.0)
#: ``draw(k, width_mm, height_mm)``: draws comparison value ``k``'s sizing map at that size
#: and returns its PNG (None: not made)
MapDrawer = Callable[[int, float, float], "Path | None"]
#: the inputs' values column: where it starts (mm) and its width (characters at 8 pt)
_VALUES_X_MM, _VALUES_CHARS = 64.0, 58
#: the page's printed area across (mm from the left edge) and the gap between pictures
_LEFT_MM, _RIGHT_MM, _GAP_MM = 12.0, 198.0, 4.0
#: where the two closed views stand beside the sizing map, side by side (x, width in mm)
_VIEWS_X_MM, _VIEWS_MM = 134.0, 64.0


def sizing_map_mm(n: int) -> tuple[float, float]:
    """The largest box of each of ``n`` sizing maps on the page (width, height in mm): one
    beside the closed valve (:data:`SIZING_MAP_MM`), several side by side across the
    page."""
    if n <= 1:
        return SIZING_MAP_MM
    return ((_RIGHT_MM - _LEFT_MM - _GAP_MM * (n - 1)) / n, SIZING_MAP_MM[1])


@dataclass(frozen=True)
class PlanPage:
    """What the plan's page shows (pictures: PNG files, None: not made).

    ``kind`` is ``"graft"``, ``"closest"`` or ``"cannot_seal"`` (the answer box's colour);
    ``details`` the lines under the headline; ``inputs`` (what, value) rows; ``reach``
    what the native free edges can span (may be ""); ``nothing_computed`` the paragraph
    that replaces the pictures when no study ran ("" otherwise); ``sizing_captions`` the
    caption of each comparison value's sizing map (one without comparison axes: the
    closed-valve pictures are then beside it), which :func:`draw_plan_page` has drawn at
    the size it prints them; ``sizing_key`` what the maps' lines and marks mean, printed
    below them; ``shown`` the graft and member the closed-valve pictures show.
    """

    title: str
    subtitle: str
    kind: str
    headline: str
    details: list[str] = field(default_factory=list)
    inputs: list[tuple[str, str]] = field(default_factory=list)
    reach: str = ""
    nothing_computed: str = ""
    template: Path | None = None
    template_caption: str = "Graft template"
    template_missing: str = "not made"
    sizing_captions: list[str] = field(default_factory=list)
    sizing_key: str = ""
    closed_aortic: Path | None = None
    closed_ventricular: Path | None = None
    shown: str = ""
    run: list[str] = field(default_factory=list)
    limitations: str = ""
    footer: str = ""


def _axes_mm(fig, x: float, y: float, w: float, h: float):
    """Axes at (x, y) of width w and height h, in millimetres from the lower left corner."""
    return fig.add_axes((x / A4_MM[0], y / A4_MM[1], w / A4_MM[0], h / A4_MM[1]))


def _rounded(x, y, w, h, face, edge, transform):
    from matplotlib.patches import FancyBboxPatch

    return FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0,rounding_size=0.02",
                          facecolor=face, edgecolor=edge, linewidth=1.0, transform=transform)


def _text(fig, x: float, y: float, text: str, size: float = 9.0, spacing: float = 1.3,
          **kw) -> float:
    """Text whose first line's top is at ``y`` (mm), as written (a ``$`` is a dollar sign, not
    math); returns the y below its last line."""
    fig.text(x / A4_MM[0], y / A4_MM[1], text, fontsize=size, va="top", linespacing=spacing,
             parse_math=False, **kw)
    return y - (text.count("\n") + 1) * size * spacing * PT_MM


def _height(text: str, size: float, spacing: float = 1.3) -> float:
    """The height (mm) of ``text`` as :func:`_text` writes it."""
    return (text.count("\n") + 1) * size * spacing * PT_MM


def _picture(fig, box: tuple[float, float, float, float], path: Path | None, caption: str,
             missing: str) -> None:
    """A PNG fitted into ``box`` (mm) with its caption above, or a grey box saying why not."""
    import matplotlib.image

    x, y, w, h = box
    fig.text(x / A4_MM[0], (y + h + 1.0) / A4_MM[1], caption, fontsize=8,
             fontweight="bold", parse_math=False, va="bottom", linespacing=1.3)
    ax = _axes_mm(fig, x, y, w, h)
    ax.set_axis_off()
    if path is not None and Path(path).is_file():
        ax.imshow(matplotlib.image.imread(path), interpolation="antialiased")
        ax.set_anchor("N")
        return
    ax.add_patch(_rounded(0.0, 0.0, 1.0, 1.0, "#eeeeee", "#bbbbbb", ax.transAxes))
    ax.text(0.5, 0.5, textwrap.fill(missing, 38), ha="center", va="center", fontsize=8,
            color="#555555", transform=ax.transAxes, parse_math=False)


def _answer_box(fig, page: PlanPage, top: float) -> float:
    """The answer, framed in the colour of its kind; returns the y below the box."""
    y = _text(fig, 16, top - 4.0, textwrap.fill(page.headline, 80), size=10.5,
              spacing=1.35, fontweight="bold")
    if page.details:
        y = _text(fig, 16, y - 2.0, "\n".join(textwrap.fill(d, 116) for d in page.details),
                  size=8)
    bottom = y - 3.0
    fig.patches.append(_rounded(12 / A4_MM[0], bottom / A4_MM[1], 186 / A4_MM[0],
                                (top - bottom) / A4_MM[1], _BOX[page.kind], _EDGE[page.kind],
                                fig.transFigure))
    return bottom


def _inputs(fig, rows: list[tuple[str, str]], top: float) -> float:
    """The (what, value) rows, each value wrapped in its column; returns the y below."""
    y = top
    for what, value in rows:
        _text(fig, 12, y, what, size=8, spacing=1.3, color="#333333")
        y = _text(fig, _VALUES_X_MM, y, textwrap.fill(value, _VALUES_CHARS), size=8,
                  spacing=1.3) - 1.0
    return y


def _captions(page: PlanPage) -> list[str]:
    """The maps' captions wrapped to their width."""
    captions = page.sizing_captions or ["Sizing map"]
    width = sizing_map_mm(len(captions))[0]
    return [textwrap.fill(c, int(width / 1.9)) for c in captions]


def _pictures(fig, page: PlanPage, top: float, height: float,
              draw_map: MapDrawer | None) -> None:
    """In a row ``height`` mm high below ``top``: the sizing map on the left, the closed
    valve from the aorta and from the ventricle side by side on the right; or, with several
    comparison values, their sizing maps side by side.  ``draw_map`` draws each map at
    the size of its box."""
    captions = _captions(page)
    width = sizing_map_mm(len(captions))[0]
    for k, caption in enumerate(captions):
        path = draw_map(k, width, height) if draw_map is not None else None
        _picture(fig, (_LEFT_MM + k * (width + _GAP_MM), top - height, width, height), path,
                 caption, "not made")
    if len(captions) > 1:
        return
    half = 0.5 * (_VIEWS_MM - _GAP_MM)
    _picture(fig, (_VIEWS_X_MM, top - height, half, height), page.closed_aortic,
             _views_caption(page), "not made")
    _picture(fig, (_VIEWS_X_MM + half + _GAP_MM, top - height, half, height),
             page.closed_ventricular, "", "not made")


def _views_caption(page: PlanPage) -> str:
    """The caption of the two closed views, side by side."""
    return "Closed valve (aorta | ventricle)" + (f"\n{page.shown}" if page.shown else "")


def draw_plan_page(page: PlanPage, draw_map: MapDrawer | None = None):
    """The page as a matplotlib figure of exactly A4 (see the module docstring).

    ``draw_map`` draws each sizing map at the size of the box the page gives it, once the
    page's text has been laid out (None: grey boxes)."""
    fig = new_figure(A4_MM[0] / 25.4, A4_MM[1] / 25.4, layout=None)
    y = _text(fig, 12, 288, page.title, size=16, fontweight="bold")
    y = _text(fig, 12, y - 1.0, page.subtitle, size=8, color="#333333")
    y = _answer_box(fig, page, y - 3.0)

    top = y - 6.0
    _text(fig, 12, top, "Measured inputs", size=10, fontweight="bold")
    y = _inputs(fig, page.inputs, top - 6.0)
    if page.reach:
        y = _text(fig, 12, y - 1.0, textwrap.fill(page.reach, 76), size=7.5, color="#333333")
    run = "\n".join(textwrap.fill(line, 118) for line in page.run)
    limitations = textwrap.fill(page.limitations, 118)
    if page.nothing_computed:
        y = _text(fig, 12, y - 8.0, textwrap.fill(page.nothing_computed, 100), size=9)
    else:
        thumb = 44.0
        _picture(fig, (136, top - 4.0 - thumb, 62, thumb), page.template,
                 page.template_caption, page.template_missing)
        captions = _captions(page)
        heads = [*captions, *([_views_caption(page)] if len(captions) == 1 else [])]
        above = max(_height(c, 8) for c in heads) + 1.0
        row = min(y, top - 4.0 - thumb) - 4.0 - above
        key = textwrap.fill(page.sizing_key, 140)
        below = _height(key, 7.5) + 1.5 if page.sizing_key else 0.0
        # from the footer up: the limitations, what was run, the gap below the pictures
        bottom = (14.0 + 7.0 + _height(limitations, 8) + 1.5 + _height("L", 10) + 4.0
                  + _height(run, 8) + 1.5 + _height("W", 10) + 6.0)
        height = min(SIZING_MAP_MM[1], row - below - bottom)
        _pictures(fig, page, row, height, draw_map)
        y = row - height
        if page.sizing_key:
            y = _text(fig, _LEFT_MM, y - 1.5, key, size=7.5, color="#333333")
    y = _text(fig, 12, y - 6.0, "What was run", size=10, fontweight="bold")
    y = _text(fig, 12, y - 1.5, run, size=8)
    y = _text(fig, 12, y - 4.0, "Limitations", size=10, fontweight="bold")
    _text(fig, 12, y - 1.5, limitations, size=8, style="italic")
    _text(fig, 12, 14, page.footer, size=7, color="#555555")
    return fig
