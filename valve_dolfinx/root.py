"""The aortic root: a thin elastic tube distended by the diastolic pressure (SPEC §2).

Step 1 of the loading.  The flat leaflets are sized on the d = 20 mm cylinder;
the free edges add up to ``1 + free_edge_excess`` (15 %) times the
circumference of the *unpressurised* root, whose diameter is therefore
d₀ = d/1.15 = 17.39 mm.  At 80 mmHg the root radius R follows from the radial
balance of the transaortic pressure, the wall's hoop stress and the pull of the
leaflets attached to it, written as a one-degree-of-freedom energy balance:

    Π(R) = ½·E·t·2πR₀L·((R − R₀)/R₀)² + Π_leaf(R) − p·πL·(R² − R₀²),

    dΠ/dR = 0:  p·R = E·t·(R − R₀)/R₀ + Π_leaf'(R)/(2πL).

E and t are the wall's Young's modulus and thickness, L the height of the
root segment carrying the leaflets (nadir to commissure top).  The leaflets are
unpressurised in this step (the valve is open, the leaflets lie against the
wall): Π_leaf(R) is their membrane energy when wrapped on the cylinder of
radius R, computed with the finite element model; it is zero while R is below
the wrap radius d/2 (the leaflets are then circumferentially slack, and the
tension-field relaxation gives them no stiffness), and resists distension
beyond it.  The root nodes (the leaflets' attachment) are then held at radius
R for step 2.

Default wall data (see docs/closure.md):
* Young's modulus 2.0 MPa: the isotropic aortic-wall modulus that best matched
  measured root wall displacements in "Large-displacement 3D structural
  analysis of an aortic valve model with nonlinear material properties",
  J Med Eng Technol (doi:10.1080/0309190042000193847);
* wall thickness 1.6 mm: sinus of Valsalva, PLoS ONE 6(8):e23106 (2011),
  Table 1 (doi:10.1371/journal.pone.0023106).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass

from scipy.optimize import brentq

from valve_dolfinx.exceptions import SolverError, check_range

__all__ = ["RootParameters", "RootState", "distend_root"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RootParameters:
    """Aortic root wall (mm, kPa).

    ``free_edge_excess`` fixes the unpressurised root: d₀ = d/(1 + excess).
    ``height`` is the root segment carrying the leaflets; ``None`` = the leaflet
    height (nadir to commissure top).
    """

    free_edge_excess: float = 0.15
    youngs_modulus: float = 2000.0
    wall_thickness: float = 1.6
    height: float | None = None

    def __post_init__(self) -> None:
        check_range("root.free_edge_excess", self.free_edge_excess, -0.2, 1.0)
        check_range("root.youngs_modulus", self.youngs_modulus, 1.0, 1e6, unit="kPa",
                    hint="aortic wall moduli are 0.1-10 MPa (100-10000 kPa)")
        check_range("root.wall_thickness", self.wall_thickness, 0.05, 10.0, unit="mm")
        if self.height is not None:
            check_range("root.height", self.height, 0.5, 100.0, unit="mm")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class RootState:
    """Result of the root step."""

    zero_pressure_diameter: float
    diameter: float
    hoop_strain: float
    leaflet_line_load: float  # mN/mm: inward pull of the leaflets per unit root height
    pressure: float

    @property
    def radius(self) -> float:
        return 0.5 * self.diameter

    def to_dict(self) -> dict:
        return asdict(self)


def distend_root(params: RootParameters, wrap_diameter: float, leaflet_height: float,
                 pressure: float, leaflet_energy: Callable[[float], float] | None = None,
                 ) -> RootState:
    """Solve the root balance for the radius at ``pressure`` (kPa).

    ``leaflet_energy(R)`` returns the leaflets' membrane energy (mN·mm) when they
    lie on the cylinder of radius R; ``None`` ignores the leaflets.
    """
    R0 = 0.5 * wrap_diameter / (1.0 + params.free_edge_excess)
    L = params.height or leaflet_height
    Et = params.youngs_modulus * params.wall_thickness
    h = 1e-4 * R0

    def leaflet_pull(R: float) -> float:  # Π_leaf'(R)/(2πL), mN/mm
        if leaflet_energy is None:
            return 0.0
        return (leaflet_energy(R + h) - leaflet_energy(R - h)) / (2 * h) / (2 * math.pi * L)

    def balance(R: float) -> float:
        return pressure * R - Et * (R - R0) / R0 - leaflet_pull(R)

    if pressure * R0 >= Et:
        raise SolverError(f"the root wall (E·t = {Et:g} kPa·mm) cannot hold {pressure:g} kPa: "
                          "increase root.youngs_modulus or root.wall_thickness")
    # the leaflets can only pull inwards, so the free tube's radius bounds the solution
    R_free = R0 / (1.0 - pressure * R0 / Et)
    if pressure == 0:
        R = R0
    elif balance(R_free) >= 0.0:
        R = R_free
    else:
        R = brentq(balance, R0, R_free, xtol=1e-10)
    state = RootState(zero_pressure_diameter=2 * R0, diameter=2 * R, hoop_strain=R / R0 - 1,
                      leaflet_line_load=leaflet_pull(R), pressure=pressure)
    log.info("root: d0 = %.3f mm -> d = %.3f mm at %.3f kPa (hoop strain %.3f, leaflet pull "
             "%.3g mN/mm)", state.zero_pressure_diameter, state.diameter, pressure,
             state.hoop_strain, state.leaflet_line_load)
    return state
