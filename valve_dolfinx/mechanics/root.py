"""The aortic root: a thin elastic tube distended by the diastolic pressure (SPEC §2).

Step 1 of the loading.  The flat leaflets are sized on the d = 20 mm cylinder;
the free edges add up to ``1 + free_edge_excess`` (15 %) times the
circumference of the *unpressurised* root, whose diameter is therefore
d₀ = d/1.15 = 17.39 mm.  At 80 mmHg the root radius R follows from the radial
balance of the transaortic pressure, the wall's hoop stress and the pull of the
leaflets attached to it, written as a one-degree-of-freedom energy balance:

    Π(R) = ½·E·t·2πR₀L·((R − R₀)/R₀)² + Π_leaf(R) − p·πL·(R² − R₀²),

    dΠ/dR = 0:  p·R = E·t·(R − R₀)/R₀ + Π_leaf'(R)/(2πL).

E and t are the wall's secant Young's modulus over 0-80 mmHg and its
thickness, L the height of the root segment carrying the leaflets (nadir to
commissure top).  The leaflets are unpressurised in this step (the valve is
open, the leaflets lie against the wall): Π_leaf(R) is their membrane energy
when wrapped on the cylinder of radius R, computed with the finite element
model; it is zero while R is below the wrap radius d/2 (the leaflets are then
circumferentially slack, and the tension-field relaxation gives them no
stiffness), and resists distension beyond it.  The root nodes (the leaflets'
attachment) are then held at radius R for step 2.

A measured (patient) loaded diameter can be prescribed instead
(``RootParameters.loaded_diameter``): the wall law is then not used, and the
leaflets' line load is still reported at that radius.

Default wall data
-----------------
Only the product E·t enters the balance.  It is taken from the in vivo
stiffness of the human ascending aorta, the thickness from MRI, and E = E·t/t:

* **Pressure-strain modulus** E_p = Δp/(ΔD/D) = 68.4 ± 30.5 kPa, measured from
  end-diastole to peak systole on multiphase CT in 45 men (the "young" group,
  42.6 ± 5.2 years; 162.0 ± 93.5 kPa in the group aged 69.0 ± 5.2 years):
  Martin C, Sun W, Primiano C, McKay R, Elefteriades J. Age-dependent ascending
  aorta mechanics assessed through multiphase CT. Ann Biomed Eng
  2013;41(12):2565-2574. doi:10.1007/s10439-013-0856-9.
* **Wall thickness** t = 1.5 mm: median MRI wall thickness of the ascending
  aorta in a general population (753 subjects aged 21-81 years), 1.46 mm in
  women (5th-95th percentile 1.15-1.88 mm) and 1.56 mm in men (1.22-1.99 mm):
  Mensel B, et al. MRI-based determination of reference values of thoracic
  aortic wall thickness in a general population. Eur Radiol
  2014;24(9):2038-2044. doi:10.1007/s00330-014-3188-8.

Conversion to the secant modulus of this tube.  The tube's law
p·R·R₀ = E·t·(R − R₀) is linear in the hoop strain, so its secant modulus over
0-80 mmHg is also its incremental one, and its pressure-strain modulus at the
diastolic pressure p is

    E_p = R·dp/dR = E·t/R₀ − p   ⇒   E·t = R₀·(E_p + p)
        = 8.696 mm × (68.4 + 10.67) kPa = 687.5 kPa·mm,
    E = 687.5 kPa·mm / 1.5 mm = 458 kPa.

E_p (equivalently the distensibility, ΔA/(A·Δp) ≈ 2/E_p = 2.9·10⁻² kPa⁻¹) is a
relative measure, independent of the vessel's size; transferring it from the
30 mm ascending aorta to the model's 20 mm root keeps E·t/R, the wall's
stiffness relative to its radius.  The real wall stiffens with pressure, so its
secant modulus from 0 mmHg is, if anything, lower than this diastolic-systolic
figure: the data err on the stiff side.

Result (default geometry, 80 mmHg): the free tube (no leaflets) would reach
20.10 mm; with the leaflets, stretched beyond the 20 mm wrap diameter and
pulling inwards with about 0.6 mN/mm, the root settles at 20.08-20.09 mm
(mesh sizes 0.6-1.2 mm).  The published method's own 15 % (d₀ = 17.39 mm loaded to
exactly 20 mm by a free tube) would need E·t = p·R·R₀/(R − R₀) = 711 kPa·mm,
within 4 % of the data above.  Across the young group's ±1 SD of E_p
(37.9-98.9 kPa) the loaded root spans about 21.45 mm (the leaflets then pull
15.7 mN/mm; the free tube would reach 22.29 mm) to 19.27 mm (leaflets slack),
which is why a measured diameter can be prescribed for a patient.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass

from scipy.optimize import brentq

from valve_dolfinx.exceptions import SolverError
from valve_dolfinx.setting_fields import check_setting, setting

__all__ = ["RootParameters", "RootState", "distend_root", "ASCENDING_AORTA_WALL_THICKNESS_MM"]

log = logging.getLogger(__name__)

#: Mensel et al. 2014 (module docstring): median MRI wall thickness of the ascending aorta,
#: between the women's 1.46 mm and the men's 1.56 mm
ASCENDING_AORTA_WALL_THICKNESS_MM = 1.5
#: range accepted for a prescribed loaded root diameter, mm
LOADED_DIAMETER_RANGE_MM = (10.0, 40.0)


@dataclass(frozen=True)
class RootParameters:
    """Aortic root wall: each setting's unit and meaning is on its field.

    ``free_edge_excess`` fixes the unpressurised root: d₀ = d/(1 + excess).  When
    ``loaded_diameter`` is set the wall law is not used.  Defaults and sources: module
    docstring.
    """

    free_edge_excess: float = setting(0.15, "", "free edges' length over the unpressurised "
                                      "root's circumference, minus 1")
    youngs_modulus: float = setting(458.0, "kPa", "secant Young's modulus of the root wall "
                                    "over 0-80 mmHg")
    wall_thickness: float = setting(ASCENDING_AORTA_WALL_THICKNESS_MM, "mm",
                                    "root wall thickness")
    loaded_diameter: float | None = setting(None, "mm", "prescribed root diameter at the "
                                            "loading pressure, a patient's measured root "
                                            "(unset: the wall law distends it)")

    def __post_init__(self) -> None:
        check_setting(self, "free_edge_excess", -0.2, 1.0, label="root.free_edge_excess")
        check_setting(self, "youngs_modulus", 1.0, 1e6, label="root.youngs_modulus_kpa",
                      hint="aortic wall moduli are 0.1-10 MPa (100-10000 kPa)")
        check_setting(self, "wall_thickness", 0.05, 10.0, label="root.wall_thickness_mm")
        if self.loaded_diameter is not None:
            check_setting(self, "loaded_diameter", *LOADED_DIAMETER_RANGE_MM,
                          label="root.loaded_diameter_mm", hint="the measured diameter of the "
                          "pressurised root base; None distends the root with the wall law")


@dataclass(frozen=True)
class RootState:
    """Result of the root step."""

    zero_pressure_diameter: float
    diameter: float
    hoop_strain: float
    leaflet_line_load: float  # mN/mm: inward pull of the leaflets per unit root height
    pressure: float
    prescribed: bool = False  # the diameter was RootParameters.loaded_diameter

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
    lie on the cylinder of radius R; ``None`` ignores the leaflets.  With
    ``params.loaded_diameter`` set, that diameter is returned and the leaflets'
    line load is evaluated there.
    """
    R0 = 0.5 * wrap_diameter / (1.0 + params.free_edge_excess)
    L = leaflet_height  # the root segment that carries the leaflets
    Et = params.youngs_modulus * params.wall_thickness
    h = 1e-4 * R0

    def leaflet_pull(R: float) -> float:  # Π_leaf'(R)/(2πL), mN/mm
        if leaflet_energy is None:
            return 0.0
        return (leaflet_energy(R + h) - leaflet_energy(R - h)) / (2 * h) / (2 * math.pi * L)

    def balance(R: float) -> float:
        return pressure * R - Et * (R - R0) / R0 - leaflet_pull(R)

    if params.loaded_diameter is not None:
        R = 0.5 * params.loaded_diameter
    elif pressure * R0 >= Et:
        raise SolverError(f"the root wall (E·t = {Et:g} kPa·mm) cannot hold {pressure:g} kPa: "
                          "increase root.youngs_modulus_kpa or root.wall_thickness_mm, or "
                          "prescribe root.loaded_diameter_mm")
    elif pressure == 0:
        R = R0
    else:
        # the leaflets can only pull inwards, so the free tube's radius bounds the solution
        R_free = R0 / (1.0 - pressure * R0 / Et)
        R = R_free if balance(R_free) >= 0.0 else brentq(balance, R0, R_free, xtol=1e-10)
    state = RootState(zero_pressure_diameter=2 * R0, diameter=2 * R, hoop_strain=R / R0 - 1,
                      leaflet_line_load=leaflet_pull(R), pressure=pressure,
                      prescribed=params.loaded_diameter is not None)
    log.info("root: d0 = %.3f mm -> d = %.3f mm%s at %.3f kPa (hoop strain %.3f, leaflet pull "
             "%.3g mN/mm)", state.zero_pressure_diameter, state.diameter,
             " (prescribed)" if state.prescribed else "", pressure, state.hoop_strain,
             state.leaflet_line_load)
    return state
