"""The graft to cut: the flat graft of a measured leaflet and its suturing margin (SPEC §9).

The flat graft is the package's own outline (:class:`~valve_dolfinx.geometry.outline.
LeafletShape` of the measured leaflet with the graft's enlargement), with a suturing margin
(1 mm) outside the attachment edge -- the lower edge and the two commissures -- and none
along the free edge: the cut line is the attachment edge offset outwards by the margin
(rounded at the commissures' lower corners, as a uniform margin is) and closed by the free
edge.  :mod:`valve_dolfinx.plotting.template` draws it at true size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from valve_dolfinx.geometry.outline import GraftSize, LeafletShape

__all__ = ["SUTURE_MARGIN_MM", "GraftTemplate"]

#: suturing margin outside the attachment edge (mm)
SUTURE_MARGIN_MM = 1.0
#: points on the lower edge of the outline, and on each rounded corner of the cut line
_EDGE_POINTS = 241
_CORNER_POINTS = 25


@dataclass(frozen=True)
class GraftTemplate:
    """The flat graft of a measured leaflet (mm; the nadir at the origin, y up).

    ``native`` is the measured leaflet's outline, ``graft`` the enlargement,
    ``fibre_angle_deg`` the graft's fibre direction from its free edge.
    """

    native: LeafletShape
    graft: GraftSize
    fibre_angle_deg: float = 0.0
    margin_mm: float = SUTURE_MARGIN_MM
    label: str = ""

    @property
    def shape(self) -> LeafletShape:
        n = self.native
        return LeafletShape(n.root_diameter, n.gamma_deg, n.commissure_height,
                            self.graft.width_pct, self.graft.height_pct)

    @property
    def cut_width_mm(self) -> float:
        """Width of the piece to cut: the free edge plus the margin at both commissures."""
        return self.shape.free_edge_length + 2.0 * self.margin_mm

    @property
    def cut_height_mm(self) -> float:
        """Height of the piece to cut: the graft's height plus the margin below the nadir
        (the lower edge is flat there, so its offset's lowest point is the margin below)."""
        return self.shape.height + self.margin_mm

    def attachment(self) -> np.ndarray:
        """The suture line ``(n, 2)``: left commissure top, down, along the lower edge, up
        to the right commissure top."""
        s = self.shape
        a, top = s.half_width, s.height
        x = np.linspace(-a, a, _EDGE_POINTS)
        lower = np.stack([x, s.lower_edge(x)], axis=1)
        return np.vstack([[-a, top], lower, [a, top]])

    def outline(self) -> np.ndarray:
        """The graft's closed outline ``(n, 2)``: the attachment and the free edge back."""
        line = self.attachment()
        return np.vstack([line, line[:1]])

    def cut_line(self) -> np.ndarray:
        """The closed cut line ``(n, 2)``: the attachment offset outwards by the margin
        (lower edge along its normal, commissures sideways, rounded corners between),
        joined to the free edge's ends along the free edge's level."""
        s, m = self.shape, self.margin_mm
        a, top, low = s.half_width, s.height, s.commissure_bottom
        x = np.linspace(-a, a, _EDGE_POINTS)
        slope = s.lower_edge_slope(x)
        normal = np.stack([slope, -np.ones_like(x)], axis=1) / np.hypot(slope, 1.0)[:, None]
        lower = np.stack([x, s.lower_edge(x)], axis=1) + m * normal
        # corners: arcs about the commissures' lower ends, from the commissure's normal
        # (sideways) to the lower edge's normal at its end
        tilt = math.atan2(-1.0, float(slope[-1]))  # angle of the right end's normal
        right = np.linspace(tilt, 0.0, _CORNER_POINTS)
        left = np.linspace(math.pi, math.pi - tilt, _CORNER_POINTS)
        arc_left = np.stack([-a + m * np.cos(left), low + m * np.sin(left)], axis=1)
        arc_right = np.stack([a + m * np.cos(right), low + m * np.sin(right)], axis=1)
        return np.vstack([[-a, top], [-a - m, top], arc_left, lower[1:-1], arc_right,
                          [a + m, top], [a, top], [-a, top]])
