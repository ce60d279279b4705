"""Analysis of the loaded valve: coaptation region, heights, area, intersections and
competence (SPEC §6)."""

from __future__ import annotations

from valve_dolfinx.analysis.coaptation import (
    DEFAULT_PIXEL_MM,
    DEFAULT_THRESHOLD_MM,
    CoaptationResult,
    LeafletCoaptation,
    analyse_coaptation,
    coaptation_height_profile,
    distance_to_surface,
    fraction_below,
    leaflet_pair_gaps,
    profile_break_points,
    region_area,
    regurgitant_orifice_area,
)
from valve_dolfinx.analysis.intersection import (
    Intersections,
    find_intersections,
    valve_intersections,
)
from valve_dolfinx.analysis.orifice import orifice_leak_map, rasterise_footprint
from valve_dolfinx.analysis.sealing import through_flow

__all__ = [
    "DEFAULT_PIXEL_MM",
    "DEFAULT_THRESHOLD_MM",
    "CoaptationResult",
    "Intersections",
    "LeafletCoaptation",
    "analyse_coaptation",
    "coaptation_height_profile",
    "distance_to_surface",
    "find_intersections",
    "fraction_below",
    "leaflet_pair_gaps",
    "orifice_leak_map",
    "profile_break_points",
    "rasterise_footprint",
    "through_flow",
    "region_area",
    "regurgitant_orifice_area",
    "valve_intersections",
]
