"""One colour scheme, the leaflet labels and the figure plumbing shared by every figure.

Colours are Okabe & Ito's palette (2008), distinguishable under the common
colour-vision deficiencies: the three native leaflets orange, sky blue and
bluish green, the graft always reddish purple, the regurgitant orifice
vermillion, the coaptation region grey, intersections yellow.  Sequential fields use viridis.

Figures are :class:`matplotlib.figure.Figure` objects drawn on their own Agg
canvas, never through :mod:`matplotlib.pyplot`: nothing here touches
matplotlib's backend or PyVista's global settings, so the package can be
imported in a Jupyter session or next to a GUI.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = [
    "OKABE_ITO",
    "LEAFLET_COLOURS",
    "GRAFT_COLOUR",
    "ORIFICE_COLOUR",
    "INTERSECTION_COLOUR",
    "COAPTATION_COLOUR",
    "SEQUENTIAL_CMAP",
    "LEAFLET_LABELS",
    "leaflet_colour",
    "leaflet_label",
    "key_numbers",
    "new_figure",
    "save_figure",
    "save_picture",
]

log = logging.getLogger(__name__)

#: Okabe & Ito (2008), "Color universal design"
OKABE_ITO = {"orange": "#E69F00", "sky_blue": "#56B4E9", "bluish_green": "#009E73",
             "yellow": "#F0E442", "blue": "#0072B2", "vermillion": "#D55E00",
             "reddish_purple": "#CC79A7", "black": "#000000"}
#: native leaflets by name (a mirror image of a leaflet takes the colour of its position)
LEAFLET_COLOURS = {"left_coronary": OKABE_ITO["orange"],
                   "right_coronary": OKABE_ITO["sky_blue"],
                   "non_coronary": OKABE_ITO["bluish_green"]}
GRAFT_COLOUR = OKABE_ITO["reddish_purple"]
ORIFICE_COLOUR = OKABE_ITO["vermillion"]
#: the marks where a leaflet passes through another or through itself
INTERSECTION_COLOUR = OKABE_ITO["yellow"]
COAPTATION_COLOUR = "#555555"
SEQUENTIAL_CMAP = "viridis"
LEAFLET_LABELS = {"left_coronary": "LC", "right_coronary": "RC", "non_coronary": "NC"}
_BY_POSITION = tuple(LEAFLET_COLOURS.values())
#: zlib level of the PNG files: the same pixels as the default level 6 in files a few per
#: cent larger, written in about half the time
PNG_COMPRESSION = 3


def leaflet_colour(patch, index: int | None = None) -> str:
    """The colour of a leaflet patch: the graft's, its own, or that of its position ``index``."""
    if patch.is_graft:
        return GRAFT_COLOUR
    if patch.name in LEAFLET_COLOURS:
        return LEAFLET_COLOURS[patch.name]
    return _BY_POSITION[(index if index is not None else patch.tag - 1) % len(_BY_POSITION)]


def leaflet_label(patch) -> str:
    """``LC``, ``RC``, ``NC``, ``graft``; mirror image ``k`` of a leaflet is ``LC mirror k``."""
    if patch.is_graft:
        return "graft"
    base, _, mirror = patch.name.partition("_mirror")
    label = LEAFLET_LABELS.get(base, base.replace("_", " "))
    return f"{label} mirror {mirror}" if mirror else label


def _get(result, key: str):
    value = result.get(key) if isinstance(result, Mapping) else getattr(result, key, None)
    return value


def _mm(value, unit: str = "mm", digits: int = 2) -> str:
    if value is None or isinstance(value, float) and not math.isfinite(value):
        return "–"
    return f"{value:.{digits}f} {unit}"


#: characters of the key numbers' line in a figure's title (:func:`key_numbers`)
KEY_NUMBERS_WIDTH = 100


def key_numbers(result) -> str:
    """``min coaptation 1.67 mm · central 2.17 mm · orifice 0.00 mm² · competent``.

    ``result`` is a case result (``result.json`` as a dict, or a ``CaseResult``): its
    verdict is :func:`~valve_dolfinx.result.competence_text`, the reason included; or a
    :class:`~valve_dolfinx.analysis.coaptation.CoaptationResult`, which knows only whether
    the valve is sealed.  A verdict that would make the line longer than
    :data:`KEY_NUMBERS_WIDTH` characters (where leaflets intersect) gets a line of its own.
    """
    from valve_dolfinx.result import competence_text

    low = _get(result, "min_coaptation_height_mm")
    if low is None:
        low = _get(result, "min_native_height_mm")
    central = _get(result, "central_coaptation_height_mm")
    if central is None:
        central = _get(result, "central_native_height_mm")
    orifice = _get(result, "regurgitant_orifice_area_mm2")
    if _get(result, "converged") is None:  # a coaptation analysis, not a case
        verdict = "sealed" if _get(result, "sealed") else "leaks"
    else:
        verdict = competence_text(result)
    numbers = (f"min coaptation {_mm(low)} · central {_mm(central)} · "
               f"orifice {_mm(orifice, 'mm²')}")
    together = f"{numbers} · {verdict}"
    return together if len(together) <= KEY_NUMBERS_WIDTH else f"{numbers}\n{verdict}"


def new_figure(width_in: float, height_in: float, **kwargs) -> Figure:
    """A figure on its own Agg canvas (constrained layout unless told otherwise)."""
    kwargs.setdefault("layout", "constrained")
    fig = Figure(figsize=(width_in, height_in), **kwargs)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Figure, path: str | Path | None, dpi: int = 150) -> Figure:
    """Write ``fig`` to ``path`` (PNG, the folder made if needed) if a path is given."""
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=dpi, pil_kwargs={"compress_level": PNG_COMPRESSION})
        log.debug("wrote %s", path)
    return fig


def save_picture(image, path: str | Path) -> Path:
    """Write a picture array ``(h, w, 3)`` to ``path`` (PNG, the folder made if needed)."""
    from PIL import Image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(path, format="PNG", compress_level=PNG_COMPRESSION)
    log.debug("wrote %s", path)
    return path

