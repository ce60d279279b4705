"""Every figure of the package: 3-D views, sections, flat maps, the orifice, the sizing study,
the plan's page and templates.

* :mod:`~valve_dolfinx.plotting.style`: the colour scheme (Okabe-Ito), leaflet
  labels, the key numbers of a case, figure creation and saving.
* :mod:`~valve_dolfinx.plotting.scene`: PyVista 3-D views (from the aorta,
  from the ventricle, oblique; coloured by the gap to the nearest leaflet).
* :mod:`~valve_dolfinx.plotting.sections`: axial cuts and horizontal sections.
* :mod:`~valve_dolfinx.plotting.flat`: the flat leaflet mesh, the coaptation map.
* :mod:`~valve_dolfinx.plotting.orifice`: the regurgitant orifice.
* :mod:`~valve_dolfinx.plotting.case`: every figure of a case folder.
* :mod:`~valve_dolfinx.plotting.study`: the sizing study's figures.
* :mod:`~valve_dolfinx.plotting.page`: a page described in millimetres, as SVG and as an A4
  figure at true size.
* :mod:`~valve_dolfinx.plotting.template`: the graft template's page, at true size.
* :mod:`~valve_dolfinx.plotting.plan`: the plan's one-page report.

Matplotlib figures are returned as :class:`matplotlib.figure.Figure` objects,
3-D views as picture arrays; each function writes a PNG when given a path.
Importing or using this package changes neither matplotlib's backend nor
PyVista's global settings.
"""

from __future__ import annotations

from valve_dolfinx.plotting.case import (
    CASE_FIGURES,
    case_label,
    draw_closed_views,
    write_case_figures,
)
from valve_dolfinx.plotting.flat import leaflet_outline, plot_coaptation_map, plot_flat_leaflet
from valve_dolfinx.plotting.orifice import (
    draw_orifice,
    orifice_mask,
    orifice_rectangles,
    plot_orifice_map,
)
from valve_dolfinx.plotting.scene import (
    node_gap,
    plot_gap_3d,
    plot_valve_3d,
    pyvista_surface,
    render,
    valve_plotter,
)
from valve_dolfinx.plotting.sections import (
    axial_cuts,
    plot_cross_sections,
    plot_cut_planes,
    slice_triangles,
)
from valve_dolfinx.plotting.study import (
    PANEL_IMAGES,
    plot_case_panel,
    plot_coaptation_vs_width,
    plot_nomogram,
    plot_sizing_map,
)
from valve_dolfinx.plotting.style import (
    GRAFT_COLOUR,
    INTERSECTION_COLOUR,
    LEAFLET_COLOURS,
    ORIFICE_COLOUR,
    key_numbers,
    leaflet_colour,
    leaflet_label,
)

__all__ = [
    "CASE_FIGURES",
    "GRAFT_COLOUR",
    "INTERSECTION_COLOUR",
    "LEAFLET_COLOURS",
    "ORIFICE_COLOUR",
    "PANEL_IMAGES",
    "axial_cuts",
    "case_label",
    "draw_closed_views",
    "draw_orifice",
    "key_numbers",
    "leaflet_colour",
    "leaflet_label",
    "leaflet_outline",
    "node_gap",
    "orifice_mask",
    "orifice_rectangles",
    "plot_case_panel",
    "plot_coaptation_map",
    "plot_coaptation_vs_width",
    "plot_cross_sections",
    "plot_cut_planes",
    "plot_flat_leaflet",
    "plot_gap_3d",
    "plot_nomogram",
    "plot_orifice_map",
    "plot_sizing_map",
    "plot_valve_3d",
    "pyvista_surface",
    "render",
    "slice_triangles",
    "valve_plotter",
    "write_case_figures",
]
