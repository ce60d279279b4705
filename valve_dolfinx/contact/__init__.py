"""Leaflet contact (SPEC §5): force law, broad phase and node-to-surface penalty model."""

from __future__ import annotations

from valve_dolfinx.contact.broadphase import (
    CellGrid,
    CellIndex,
    candidate_pairs,
    padded_bounds,
)
from valve_dolfinx.contact.geometry import (
    barycentric_gradients,
    closest_point_on_triangles,
    plane_projection,
    triangle_normals,
)
from valve_dolfinx.contact.law import (
    DRIVING_FORCE_MODES,
    ContactParameters,
    contact_force,
    driving_force,
)
from valve_dolfinx.contact.model import (
    ContactResult,
    PlaneContact,
    SurfaceContact,
    triangle_halo,
    vertex_adjacency,
)

__all__ = [
    "DRIVING_FORCE_MODES",
    "ContactParameters",
    "ContactResult",
    "PlaneContact",
    "SurfaceContact",
    "CellGrid",
    "barycentric_gradients",
    "CellIndex",
    "candidate_pairs",
    "closest_point_on_triangles",
    "contact_force",
    "driving_force",
    "padded_bounds",
    "plane_projection",
    "triangle_halo",
    "triangle_normals",
    "vertex_adjacency",
]
