"""Leaflet contact (SPEC §5): force law, broad phase, node-to-surface and node-to-plane
penalty models."""

from __future__ import annotations

from valve_dolfinx.contact.broadphase import (
    CellGrid,
    CellIndex,
    candidate_pairs,
    padded_bounds,
)
from valve_dolfinx.contact.exclusions import triangle_halo, vertex_adjacency
from valve_dolfinx.contact.geometry import (
    barycentric_gradients,
    closest_point_on_triangles,
    plane_projection,
    triangle_normals,
)
from valve_dolfinx.contact.law import (
    ContactParameters,
    contact_force,
    driving_force,
)
from valve_dolfinx.contact.planes import PlaneContact
from valve_dolfinx.contact.results import ContactResult
from valve_dolfinx.contact.surface import SurfaceContact

__all__ = [
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
