"""Every figure of one closed valve, written into its case folder.

:data:`CASE_FIGURES` names the files and says what each shows; the titles
carry the case's key numbers (minimum and central coaptation height,
regurgitant orifice area, competence).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.plotting.flat import plot_coaptation_map
from valve_dolfinx.plotting.orifice import plot_orifice_map
from valve_dolfinx.plotting.scene import ViewRenderer, plot_gap_3d, plot_valve_3d
from valve_dolfinx.plotting.sections import plot_cross_sections, plot_cut_planes
from valve_dolfinx.plotting.style import key_numbers

__all__ = ["CASE_FIGURES", "case_label", "draw_closed_views", "write_case_figures"]

log = logging.getLogger(__name__)

#: file name -> what it shows
CASE_FIGURES = {
    "closed_valve.png": "the closed valve, oblique view from the aortic side",
    "closed_valve_aortic.png": "the closed valve seen from the aorta (the surgeon's view)",
    "closed_valve_ventricular.png": "the closed valve seen from the ventricle, with the "
                                    "regurgitant orifice when there is one",
    "coaptation_gap.png": "the closed valve coloured by the gap to the nearest other leaflet",
    "cut_planes.png": "axial cuts through the graft's (NC's) midline and through its commissure",
    "cross_sections.png": "horizontal sections, with the regurgitant orifice when there is one",
    "coaptation_map.png": "the coaptation region on the flat leaflets and the height profiles",
    "orifice_map.png": "the orifice raster seen along the axis: footprints, orifice, pockets",
}


def _get(result, key: str):
    return result.get(key) if isinstance(result, Mapping) else getattr(result, key, None)


def _closed(result) -> str:
    """``closed under 80 mmHg`` (the pressure of the case's parameters)."""
    pressure = ((_get(result, "parameters") or {}).get("loading") or {}).get("pressure_mmhg")
    return "closed" + (f" under {pressure:g} mmHg" if isinstance(pressure, int | float)
                       and math.isfinite(pressure) else "")


def case_label(result) -> str:
    """``normal valve`` or ``graft W21/H27``."""
    width = _get(result, "graft_width_pct")
    if width is None:
        return "normal valve"
    return f"graft {GraftSize(width, _get(result, 'graft_height_pct')).label}"


def write_case_figures(out: str | Path, positions: np.ndarray, valve, coaptation, result, *,
                       intersections: np.ndarray | None = None,
                       mirrored: bool = False) -> list[Path]:
    """Draw the figures of :data:`CASE_FIGURES` of a closed valve into ``out``.

    ``positions`` are the loaded node positions of ``valve``, ``coaptation``
    its :class:`~valve_dolfinx.analysis.coaptation.CoaptationResult` (the
    orifice raster in ``coaptation.orifice``), ``result`` the case result
    (``CaseResult`` or its dict) whose key numbers go into the titles;
    ``intersections`` ``(K, 3)`` the points where an edge passes through a triangle
    (:attr:`~valve_dolfinx.analysis.intersection.Intersections.points`), marked in the
    3-D views; ``mirrored`` says the valve is one solved leaflet and its mirror images.
    The coaptation figures need at least two leaflets.  Returns the files
    written.
    """
    out = Path(out)
    name = case_label(result) + (" (one leaflet and its mirror images)" if mirrored else "")
    orifice = getattr(coaptation, "orifice", None) if coaptation is not None else None
    coapted = coaptation is not None and len(valve.leaflets) > 1
    written = _write_views(out, positions, valve, coaptation if coapted else None, result,
                           name, orifice, intersections)
    plot_cut_planes(positions, valve, out / "cut_planes.png", title=name, result=result)
    plot_cross_sections(positions, valve, out / "cross_sections.png", title=name,
                        result=result, orifice=orifice)
    written += [out / "cut_planes.png", out / "cross_sections.png"]
    if coapted:
        plot_coaptation_map(coaptation, valve, out / "coaptation_map.png", title=name,
                            result=result)
        written.append(out / "coaptation_map.png")
        if orifice is not None:
            plot_orifice_map(orifice, valve, out / "orifice_map.png",
                             title=f"{name}: regurgitant orifice, seen along the axis "
                                   "from the aorta", result=result)
            written.append(out / "orifice_map.png")
    for path in written:
        log.debug("wrote %s", path)
    return written


def _write_views(out: Path, positions: np.ndarray, valve, coaptation, result, name: str,
                 orifice: dict | None, intersections: np.ndarray | None) -> list[Path]:
    """The 3-D figures of a case, in one off-screen window closed before the 2-D ones are
    drawn; the gap view only if ``coaptation`` is given."""
    numbers = key_numbers(result)
    closed = _closed(result)
    written = []
    with ViewRenderer() as views:
        for file, view, what in (("closed_valve.png", "iso", "oblique from the aorta"),
                                 ("closed_valve_aortic.png", "aortic", "from the aorta"),
                                 ("closed_valve_ventricular.png", "ventricular",
                                  "from the ventricle")):
            plot_valve_3d(positions, valve, out / file, view=view,
                          title=f"{name}: {closed}, {what}\n{numbers}", orifice=orifice,
                          intersections=intersections, views=views)
            written.append(out / file)
        if coaptation is not None:
            plot_gap_3d(positions, valve, coaptation, out / "coaptation_gap.png",
                        title=f"{name}: gap to the nearest other leaflet\n{numbers}",
                        views=views)
            written.append(out / "coaptation_gap.png")
    return written


def draw_closed_views(case_folder: str | Path, out: str | Path) -> tuple[Path, Path]:
    """The closed valve of a finished case folder seen from the aorta and from the
    ventricle (with its regurgitant orifice and its intersections), drawn from its loaded
    state into ``out`` as ``<case>_aortic.png`` and ``<case>_ventricular.png``: for a case
    that drew no figures of its own (a study draws only its panel cases')."""
    from valve_dolfinx.analysis import analyse_coaptation
    from valve_dolfinx.analysis.intersection import valve_intersections
    from valve_dolfinx.result import load_case

    case = load_case(case_folder)
    coaptation = analyse_coaptation(case.positions, case.valve,
                                    threshold_mm=case.config.coaptation_threshold_mm)
    intersections = valve_intersections(case.positions, case.valve).points
    name = case_label(case.result)
    numbers = key_numbers(case.result)
    written = []
    with ViewRenderer() as views:
        for view, what in (("aortic", "from the aorta"), ("ventricular", "from the ventricle")):
            path = Path(out) / f"{Path(case_folder).name}_{view}.png"
            plot_valve_3d(case.positions, case.valve, path, view=view,
                          title=f"{name}: {_closed(case.result)}, {what}\n{numbers}",
                          orifice=coaptation.orifice, intersections=intersections,
                          views=views)
            written.append(path)
    return written[0], written[1]
