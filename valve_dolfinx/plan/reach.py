"""Can the native leaflets close this root at all?  A closed-form bound on the free edges' reach.

To close the valve each free edge has to run from its two commissures, on the root
wall, to the centre of the orifice: its loaded length must be at least the root's
diameter D (twice the radius).  The native free edge of flat length L is stretched
along its fibres, which run parallel to it (SPEC §1), so it reaches ``L·λ`` with
``λ`` its fibre stretch.  The leaflets cannot seal the root, whatever the graft
(the graft replaces only the third leaflet), if even the largest stretch the
pressure can give the free edge leaves ``L·λ_max < D``.

The free edge's state.  The free edge is an edge of the membrane with no load on it
in its plane (the pressure and the neighbours' contact act normal to the leaflet), so
the tension across it vanishes there: the edge is in uniaxial tension T along itself,
along the fibres.  With the cross-fibre stress zero and ``E12 = 0`` the Fung law of SPEC
§3 gives, in closed form,

    E22 = −(A3/A2)·E11,   Q = a·E11²,   S11 = c·a·E11·exp(a·E11²),   a = A1 − A3²/A2,

and the tension per current length ``T = t·λ1·S11/λ2`` (``λi = √(1 + 2·Eii)``) is one
increasing function of ``E11``, inverted by bracketing.  (A cross-fibre tension inside
the leaflet does not bound the edge: measured on this law at these tensions, a small one
raises the fibre strain by about 1 % (the stretch by 0.2 %), an equal one lowers it by a
quarter, because it stiffens the fibres through ``exp(Q)``.)

The largest tension.  A membrane that carries a pressure ``p`` over a curvature of
radius ``r`` has tension ``T = p·r`` along that curvature (Laplace; a second,
positive principal curvature only lowers it).  A closed leaflet's fibres span the
commissural chord (√3·D/2) as an arc of about the root's radius; a free edge just
long enough to reach the centre (``L·λ = D``) spanning that chord as a circular arc
has a radius of 0.55·D.  The bound takes ``r = D``, twice the root's radius:
``T_max = p·D``.

For the native leaflet at 80 mmHg and D = 20 mm (T = 213 mN/mm) ``λ_max = 1.167``; the
free edges of the closed default valve are stretched 1.027 on average (2 mm mesh).  The
largest root the leaflets can span, ``D_max = L·λ_max(p·D_max)``, is 24.6 mm for the
SPEC §1 leaflet under 80 mmHg.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from scipy.optimize import brentq

from valve_dolfinx.config import MMHG_TO_KPA
from valve_dolfinx.exceptions import check_range
from valve_dolfinx.materials import NATIVE_LEAFLET, FungMaterial

__all__ = ["FreeEdgeReach", "free_edge_reach", "free_edge_strains", "largest_root_mm",
           "max_fibre_stretch"]


def _edge_tension(m: FungMaterial, e11: float) -> float:
    """Tension along a free edge (mN/mm) whose fibre strain is ``e11`` (module docstring)."""
    a = m.A1 - m.A3**2 / m.A2
    e22 = -m.A3 / m.A2 * e11
    s11 = m.c * a * e11 * math.exp(a * e11**2)
    return m.thickness * s11 * math.sqrt((1.0 + 2.0 * e11) / (1.0 + 2.0 * e22))


def free_edge_strains(m: FungMaterial, tension: float) -> tuple[float, float]:
    """Green-Lagrange strains (E11, E22) of a free edge in tension ``tension`` (mN/mm)
    along its fibres and none across them."""
    check_range("tension", tension, 0.0, 1e6, unit="mN/mm")
    high = 0.05
    while _edge_tension(m, high) < tension:  # the tension grows exponentially with E11
        high *= 2.0
    e11 = brentq(lambda e: _edge_tension(m, e) - tension, 0.0, high, xtol=1e-14, rtol=1e-14)
    return e11, -m.A3 / m.A2 * e11


def max_fibre_stretch(pressure_kpa: float, root_diameter_mm: float,
                      material: FungMaterial = NATIVE_LEAFLET) -> float:
    """Upper bound on the stretch of a free edge spanning a root of this diameter: its
    stretch at the tension ``p·D`` (module docstring)."""
    e11, _ = free_edge_strains(material, pressure_kpa * root_diameter_mm)
    return math.sqrt(1.0 + 2.0 * e11)


def largest_root_mm(free_edge_mm: float, pressure_kpa: float,
                    material: FungMaterial = NATIVE_LEAFLET) -> float:
    """The largest root diameter D a free edge of flat length L can span:
    ``D = L·λ_max(p·D)`` (the reach grows more slowly than D, so there is one root)."""
    def excess(d: float) -> float:
        return free_edge_mm * max_fibre_stretch(pressure_kpa, d, material) - d

    high = 2.0 * free_edge_mm
    while excess(high) > 0.0:
        high *= 2.0
    return brentq(excess, free_edge_mm, high, xtol=1e-12, rtol=1e-14)


@dataclass(frozen=True)
class FreeEdgeReach:
    """The closed-form check of one root diameter (mm, mmHg).

    ``reach_mm`` is the most the free edge can span stretched to ``stretch``, the bound on
    its fibre stretch; ``largest_root_mm`` is the largest root it spans under this pressure.
    """

    free_edge_mm: float
    root_diameter_mm: float
    pressure_mmhg: float
    stretch: float
    reach_mm: float
    largest_root_mm: float

    @property
    def can_seal(self) -> bool:
        return self.reach_mm >= self.root_diameter_mm

    def sentence(self) -> str:
        """The verdict in one line, with the numbers behind it."""
        pull = (f"pulled as far as {self.pressure_mmhg:g} mmHg can pull {{it}} "
                f"(×{self.stretch:.3f}), {{what}} {self.reach_mm:.1f} mm")
        if self.can_seal:
            return (f"The native free edges ({self.free_edge_mm:.1f} mm) can span this "
                    f"{self.root_diameter_mm:.1f} mm root: "
                    + pull.format(it="them", what="they reach")
                    + f"; they span roots up to {self.largest_root_mm:.1f} mm.")
        return (f"The native leaflets cannot seal this {self.root_diameter_mm:.1f} mm root "
                f"whatever the graft: each free edge ({self.free_edge_mm:.1f} mm) must reach "
                f"from its commissures to the centre, {self.root_diameter_mm:.1f} mm, and "
                + pull.format(it="it", what="it reaches only")
                + f"; these leaflets span roots up to {self.largest_root_mm:.1f} mm.")

    def to_dict(self) -> dict:
        return {**asdict(self), "can_seal": self.can_seal}


def free_edge_reach(free_edge_mm: float, root_diameter_mm: float, pressure_mmhg: float,
                    material: FungMaterial = NATIVE_LEAFLET) -> FreeEdgeReach:
    """Whether free edges of flat length L can span a root of diameter D under the pressure."""
    pressure_kpa = pressure_mmhg * MMHG_TO_KPA
    stretch = max_fibre_stretch(pressure_kpa, root_diameter_mm, material)
    return FreeEdgeReach(free_edge_mm, root_diameter_mm, pressure_mmhg, stretch,
                         free_edge_mm * stretch,
                         largest_root_mm(free_edge_mm, pressure_kpa, material))
