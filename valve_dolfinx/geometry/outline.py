"""The flat, stress-free outline of an aortic leaflet (SPEC §1).

In coordinates normalised by the root base diameter ``d`` the leaflet is
bounded by

* the lower attachment edge ``y(x) = sin²(x) / tan(γ)``, ``x ∈ [-π/6, π/6]``
  measured from the leaflet midline, ``y`` the height above the nadir;
* two straight commissure segments of height ``h_c`` (5 mm) rising from the
  ends of the lower edge;
* the straight free edge joining the commissure tops, of length ``π/3``
  (so three free edges make up the circumference ``π d``).

Physical coordinates are millimetres: ``x_mm = d·x``, ``y_mm = d·y``.  A graft
is the same outline scaled by ``1 + W`` across (x) and ``1 + H`` in height (y).

A measured leaflet (SPEC §9: the excised leaflet's free edge ``L`` and midline height
``H``, measured flat) is the default outline scaled by ``L/L₀`` across and ``H/H₀`` in
height (:meth:`LeafletShape.measured`), written with the outline's own parameters:
``d = d₀·L/L₀`` (the wrap diameter 3L/π), ``tan γ = tan γ₀·(L/L₀)/(H/H₀)`` and
``h_c = h_c₀·H/H₀``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.integrate import cumulative_simpson

from valve_dolfinx.exceptions import ParameterError, check_range

__all__ = ["LeafletShape", "GraftSize", "flat_area_ratio", "MAX_GRAFT_PCT", "GRAFT_TOO_SMALL",
           "GRAFT_TOO_LARGE"]

#: Largest graft enlargement accepted (per cent).  Pericardial patches in the
#: study go to 27 % (width) and 40 % (height); doubling the leaflet is already
#: far outside surgical practice, larger values are treated as typing errors.
MAX_GRAFT_PCT = 100.0
#: Why a graft enlargement below 0 or above :data:`MAX_GRAFT_PCT` is rejected.
GRAFT_TOO_SMALL = ("a graft smaller than the native leaflet cannot be sewn onto its annulus; "
                   "give a non-negative enlargement in per cent, e.g. 21")
GRAFT_TOO_LARGE = (f"more than {MAX_GRAFT_PCT:g} % (doubling the native leaflet) is far outside "
                   "surgical practice and taken for a typing error; the study's grafts go to "
                   "27 % wider and 40 % higher")


def flat_area_ratio(width_pct: float, height_pct: float) -> float:
    """Flat graft area over the native leaflet's, (1 + W)(1 + H)."""
    return (1 + width_pct / 100) * (1 + height_pct / 100)


class GraftSize(NamedTuple):
    """A graft's enlargement over the native leaflet, per cent of its width and height."""

    width_pct: float
    height_pct: float

    @property
    def label(self) -> str:
        """``W14/H13``, as every table and figure names a graft."""
        return f"W{self.width_pct:g}/H{self.height_pct:g}"

    @property
    def stem(self) -> str:
        """``W14_H13``: the graft's part of a file name."""
        return f"W{self.width_pct:g}_H{self.height_pct:g}"

    @property
    def area_ratio(self) -> float:
        """Flat area over the native leaflet's, (1 + W)(1 + H)."""
        return flat_area_ratio(self.width_pct, self.height_pct)

    @classmethod
    def parse(cls, text: str, option: str = "--template") -> GraftSize:
        """``"14/13"`` or ``"W14/H13"`` (per cent), range-checked."""
        match = re.fullmatch(r"\s*W?\s*([-+0-9.eE]+)\s*[/_,]\s*H?\s*([-+0-9.eE]+)\s*", text)
        try:
            size = cls(float(match.group(1)), float(match.group(2)))
        except (AttributeError, ValueError):
            raise ParameterError(f"{option} {text!r}: give the graft as W/H in per cent of "
                                 "the measured leaflet, e.g. 14/13") from None
        for value in size:
            if not 0.0 <= value <= MAX_GRAFT_PCT:
                reason = GRAFT_TOO_SMALL if value < 0 else GRAFT_TOO_LARGE
                raise ParameterError(f"{option} {text!r}: {value:g} is outside the allowed "
                                     f"range [0, {MAX_GRAFT_PCT:g}] %: {reason}")
        return size


@dataclass(frozen=True, slots=True)
class LeafletShape:
    """Flat leaflet outline; all lengths in mm.

    Parameters
    ----------
    root_diameter
        Diameter ``d`` of the cylinder the flat leaflets are wrapped onto (mm).
    gamma_deg
        Angle γ of the lower attachment edge ``y = sin²x / tan γ`` (degrees).
    commissure_height
        Height of the straight commissural attachment segments (mm).
    width_pct, height_pct
        Graft enlargement W and H in per cent (0 for a native leaflet).
    """

    root_diameter: float = 20.0
    gamma_deg: float = 34.0
    commissure_height: float = 5.0
    width_pct: float = 0.0
    height_pct: float = 0.0

    def __post_init__(self) -> None:
        check_range("root_diameter", self.root_diameter, 5.0, 50.0, unit="mm",
                    hint="adult aortic roots are 18-30 mm across")
        check_range("gamma_deg", self.gamma_deg, 5.0, 85.0, unit="deg")
        check_range("commissure_height", self.commissure_height, 0.0, 20.0, low_open=True,
                    unit="mm")
        for name in ("width_pct", "height_pct"):
            check_range(f"graft_{name}", getattr(self, name), 0.0, MAX_GRAFT_PCT, unit="%",
                        low_hint=GRAFT_TOO_SMALL, high_hint=GRAFT_TOO_LARGE)

    # --- scales ------------------------------------------------------------
    @property
    def sx(self) -> float:
        """Width scale factor 1 + W."""
        return 1.0 + self.width_pct / 100.0

    @property
    def sy(self) -> float:
        """Height scale factor 1 + H."""
        return 1.0 + self.height_pct / 100.0

    def native(self) -> LeafletShape:
        """The same outline without graft enlargement."""
        return LeafletShape(self.root_diameter, self.gamma_deg, self.commissure_height)

    @classmethod
    def measured(cls, free_edge_mm: float, height_mm: float) -> LeafletShape:
        """The SPEC §1 outline scaled to a leaflet measured flat (free edge and midline height).

        The default outline scaled by ``kx = L/L₀`` across and ``ky = H/H₀`` in height:
        ``d = d₀·kx`` (so the wrap diameter is 3L/π and three free edges make up the
        circumference), ``tan γ = tan γ₀·kx/ky`` (the lower edge's rise ``d/(4 tan γ)``
        scales by ``ky``) and ``h_c = h_c₀·ky``.  The default leaflet's own ``L₀`` and
        ``H₀`` (:attr:`free_edge_length`, :attr:`height`) give the default outline's
        parameters exactly, and so the default mesh; a uniformly scaled leaflet
        (``kx = ky``) keeps γ exactly.
        """
        default = cls()
        kx = free_edge_mm / default.free_edge_length
        ky = height_mm / default.height
        gamma = default.gamma_deg
        if kx != ky:
            gamma = math.degrees(math.atan(math.tan(math.radians(gamma)) * kx / ky))
        return cls(default.root_diameter * kx, gamma, default.commissure_height * ky)

    # --- dimensions (mm) ---------------------------------------------------
    @property
    def half_width(self) -> float:
        """Half the free-edge length: (π/6)·d·(1+W)."""
        return math.pi / 6.0 * self.root_diameter * self.sx

    @property
    def free_edge_length(self) -> float:
        """Length of the straight free edge: (π/3)·d·(1+W) (20.94 mm by default)."""
        return 2.0 * self.half_width

    @property
    def commissure_bottom(self) -> float:
        """Height of the commissure's lower end above the nadir (7.41 mm by default)."""
        return self.sy * self.root_diameter * math.sin(math.pi / 6) ** 2 / math.tan(
            math.radians(self.gamma_deg))

    @property
    def height(self) -> float:
        """Midline height = height of the free edge above the nadir (12.41 mm by default)."""
        return self.commissure_bottom + self.sy * self.commissure_height

    # --- the lower attachment edge -----------------------------------------
    def lower_edge(self, x: np.ndarray | float) -> np.ndarray:
        """Height of the lower attachment edge at flat abscissa ``x`` (mm)."""
        d = self.root_diameter
        t = np.asarray(x, dtype=float) / (d * self.sx)
        return self.sy * d * np.sin(t) ** 2 / math.tan(math.radians(self.gamma_deg))

    def lower_edge_slope(self, x: np.ndarray | float) -> np.ndarray:
        """dy/dx of the lower attachment edge."""
        d = self.root_diameter
        t = np.asarray(x, dtype=float) / (d * self.sx)
        return (self.sy / self.sx) * np.sin(2 * t) / math.tan(math.radians(self.gamma_deg))

    def lower_edge_arclength(self, n: int = 4001) -> tuple[np.ndarray, np.ndarray]:
        """Cumulative arc length of the lower edge from its left end, on ``n`` abscissae.

        Simpson's rule on a dense grid: relative error ~1e-13 at the default ``n``.
        """
        x = np.linspace(-self.half_width, self.half_width, n)
        ds = np.sqrt(1.0 + self.lower_edge_slope(x) ** 2)
        s = cumulative_simpson(ds, x=x, initial=0.0)
        return x, s

    def fibre_direction(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Unit circumferential collagen direction of a native leaflet at flat points.

        The leaflet is foliated by the curves ``y_t(x) = (1-t)·y_free + t·y_lower(x)``,
        ``t ∈ [0, 1]``: ``t = 0`` is the straight free edge, ``t = 1`` the lower
        attachment edge.  Each curve runs from commissure to commissure and sags
        towards the belly, like the circumferential collagen bundles described by
        Sacks & Yoganathan (2007): parallel to the free edge near the free edge,
        arcing down towards the commissures and the attachment edge lower down.
        The fibre direction is the tangent ``(1, t·y_lower'(x))`` of the curve
        through the point.
        """
        x = np.clip(np.asarray(x, float), -self.half_width, self.half_width)
        y = np.asarray(y, float)
        low = self.lower_edge(x)
        t = np.clip((self.height - y) / np.maximum(self.height - low, 1e-12), 0.0, 1.0)
        v = np.stack([np.ones_like(x), t * self.lower_edge_slope(x)], axis=-1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    def check_mesh_size(self, mesh_size: float) -> float:
        """Validate a target edge length against the outline (at least 2 edges per commissure)."""
        limit = 0.5 * self.native().commissure_height
        return check_range("mesh_size", mesh_size, 0.05, limit, unit="mm",
                           hint=f"it must resolve the {self.native().commissure_height:g} mm "
                           "commissure with at least two edges; 0.3-1.0 mm is typical")
