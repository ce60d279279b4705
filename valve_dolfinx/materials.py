"""Planar Fung-type tissue law with a tension-field (wrinkling) relaxation (SPEC §3).

Strain energy per unit reference volume, in the material axes (1 = fibre)::

    W = c/2 · (exp(Q) − 1)
    Q = A1·E11² + A2·E22² + 2·A3·E11·E22 + A4·E12² + 2·A5·E11·E12 + 2·A6·E22·E12

``E`` is the in-plane Green–Lagrange strain tensor and ``E12`` its (tensor)
shear component.  The second Piola–Kirchhoff stress is ``S = ∂W/∂E`` taken
with respect to the symmetric tensor, so ``S12 = ½ ∂W/∂E12``.  Written as a
quadratic form, ``Q = vᵀ M v`` with ``v = (E11, E22, E12)`` and::

    M = [[A1, A3, A5],
         [A3, A2, A6],
         [A5, A6, A4]]

Units: c in kPa, A dimensionless, thickness in mm; membrane tension = thickness × stress
(kPa·mm = mN/mm).

Wrinkling
---------
A membrane cannot carry compression: it wrinkles.  :func:`relaxed_energy`
replaces the energy by that of the wrinkle-free "natural" state, judged in the
principal frame of the strain (n1, n2 with λ1 ≥ λ2), so every compressive
direction is freed, shear included -- not E11 and E22 clipped one by one:

* slack (λ1 ≤ 0): no tension at all, W = 0;
* wrinkled (λ1 > 0 and the stress along n2 would be compressive): the strain
  along n2 is replaced by the natural contraction λ2* that makes the n2 stress
  vanish.  With ``v1 = v(n1⊗n1)``, ``v2 = v(n2⊗n2)`` and ``a_ij = v_iᵀ M v_j``,
  ``n2·S·n2 ∝ λ1·a12 + λ2·a22``, so ``λ2* = −λ1·a12/a22`` and the wrinkled
  energy is ``c/2 (exp(λ1²·(a11 − a12²/a22)) − 1)``;
* taut (otherwise): the full energy.

The switch happens where ``n2·S·n2 = 0``, so the stress is continuous (the
energy is C¹) across taut/wrinkled/slack boundaries, which Newton's method
needs.  Wrinkles are taken along the principal strain direction (the
"mixed" criterion); for an anisotropic law the exact Pipkin relaxation would
also rotate the wrinkle direction until the stress is uniaxial, which would
need a local iteration at every quadrature point.  Without it, wrinkles
oblique to the fibres keep a small compressive principal stress (down to
−0.16 × the tension for the native leaflet, −0.02 for the pericardium); see
docs/model.md, which documents the treatment, its parameters and sources.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import ufl

from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.setting_fields import NOT_A_SETTING, check_setting, setting

__all__ = [
    "FungMaterial",
    "NATIVE_LEAFLET",
    "BOVINE_PERICARDIUM",
    "PRESETS",
    "preset",
    "fung_energy",
    "relaxed_energy",
    "pk2_stress_closed_form",
    "equibiaxial_response",
]

log = logging.getLogger(__name__)

#: Guard inside the square root of the principal-strain radius (strain units);
#: only enters the branch switches and the wrinkled energy, not a taut state.
_EIG_EPS = 1e-12
#: Principal-strain radius below which a strain counts as isotropic (never wrinkled).
_ISOTROPIC_R = 1e-9


@dataclass(frozen=True, slots=True)
class FungMaterial:
    """Fung-type planar tissue (SPEC §3): each setting's unit and meaning is on its field.

    ``name`` and ``reference``, the label and literature source of a preset, are not
    settings of a case configuration (:data:`~valve_dolfinx.setting_fields.NOT_A_SETTING`).
    """

    c: float = setting(unit="kPa", meaning="Fung stress scale")
    A1: float = setting(meaning="Fung coefficient of E11² (fibre)")
    A2: float = setting(meaning="Fung coefficient of E22² (cross-fibre)")
    A3: float = setting(meaning="Fung coefficient of 2·E11·E22")
    A4: float = setting(meaning="Fung coefficient of E12²")
    A5: float = setting(0.0, "", "Fung coefficient of 2·E11·E12")
    A6: float = setting(0.0, "", "Fung coefficient of 2·E22·E12")
    thickness: float = setting(0.5, "mm", "tissue thickness (tension = thickness × stress)")
    name: str = field(default="fung", metadata=NOT_A_SETTING)
    reference: str = field(default="", metadata=NOT_A_SETTING)

    def __post_init__(self) -> None:
        check_setting(self, "c", 0.0, 1e6, low_open=True, label=f"{self.name}.c")
        check_setting(self, "thickness", 0.0, 5.0, low_open=True, label=f"{self.name}.thickness",
                      hint="leaflets are about 0.5 mm thick")
        for k in ("A1", "A2", "A3", "A4", "A5", "A6"):
            check_setting(self, k, -1e4, 1e4, label=f"{self.name}.{k}")
        eig = np.linalg.eigvalsh(self.matrix)
        if eig.min() <= 0:
            raise ParameterError(
                f"{self.name}: the Fung matrix [[A1,A3,A5],[A3,A2,A6],[A5,A6,A4]] must be positive "
                f"definite for a stable tissue (smallest eigenvalue {eig.min():.3g})")

    @property
    def matrix(self) -> np.ndarray:
        """M with Q = vᵀ M v, v = (E11, E22, E12)."""
        return np.array([[self.A1, self.A3, self.A5],
                         [self.A3, self.A2, self.A6],
                         [self.A5, self.A6, self.A4]])

    @property
    def stiffness_scale(self) -> float:
        """Membrane stiffness scale (mN/mm): thickness × c × largest eigenvalue of M.

        The small-strain tangent modulus along the stiffest direction is about
        ``c·λmax(M)``; the BDF2 cross-check scales its numerical mass and
        damping to each tissue with it (SPEC §4: graft cases are stiff).
        """
        return self.thickness * self.c * float(np.linalg.eigvalsh(self.matrix).max())

    @staticmethod
    def isotropic(c: float, a: float, b: float = 0.0, thickness: float = 0.5,
                  name: str = "isotropic") -> FungMaterial:
        """Isotropic member of the family: Q = b·(tr E)² + a·tr(E²).

        In components A1 = A2 = a + b, A3 = b, A4 = 2a, A5 = A6 = 0
        (``tr(E²) = E11² + E22² + 2E12²``).
        """
        return FungMaterial(c, a + b, a + b, b, 2 * a, 0.0, 0.0, thickness, name,
                            "isotropic verification material")


#: Native human aortic valve leaflet, Billiar & Sacks (2000), J Biomech Eng 122:327.
NATIVE_LEAFLET = FungMaterial(
    c=9.7, A1=49.56, A2=5.29, A3=-3.12, A4=16.03, A5=-0.004, A6=-0.02, thickness=0.5,
    name="native_leaflet",
    reference="Billiar KL, Sacks MS (2000) J Biomech Eng 122:327-335; thickness 0.5 mm (SPEC §3)",
)

#: Glutaraldehyde-treated bovine pericardium, Sacks (1999) (SPEC §3 table).
BOVINE_PERICARDIUM = FungMaterial(
    c=3056.0, A1=25.46, A2=12.10, A3=5.07, A4=25.99, A5=0.0, A6=0.0, thickness=0.5,
    name="bovine_pericardium",
    reference="Sacks MS (1999) as tabulated in SPEC §3; thickness 0.5 mm, within the "
              "0.4-0.6 mm of commercial glutaraldehyde-treated bovine patches",
)

PRESETS = {m.name: m for m in (NATIVE_LEAFLET, BOVINE_PERICARDIUM)}


def preset(name: str) -> FungMaterial:
    """A named material preset (:data:`PRESETS`)."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ParameterError(f"unknown material {name!r}; presets are {sorted(PRESETS)}") from None


# --- UFL -------------------------------------------------------------------------
def _q_form(m: FungMaterial, e11, e22, e12):
    return (m.A1 * e11**2 + m.A2 * e22**2 + 2 * m.A3 * e11 * e22 + m.A4 * e12**2
            + 2 * m.A5 * e11 * e12 + 2 * m.A6 * e22 * e12)


def fung_energy(m: FungMaterial, E):
    """W(E) of a 2×2 UFL strain tensor given in the material axes (no relaxation)."""
    e12 = 0.5 * (E[0, 1] + E[1, 0])
    return 0.5 * m.c * (ufl.exp(_q_form(m, E[0, 0], E[1, 1], e12)) - 1.0)


def relaxed_energy(m: FungMaterial, E):
    """Tension-field relaxed W(E) (see the module docstring); E in the material axes."""
    e11, e22 = E[0, 0], E[1, 1]
    e12 = 0.5 * (E[0, 1] + E[1, 0])
    mean = 0.5 * (e11 + e22)
    radius = ufl.sqrt((0.5 * (e11 - e22)) ** 2 + e12**2 + _EIG_EPS**2)
    lam1, lam2 = mean + radius, mean - radius
    # spectral projector on n1: P1 = (E - λ2 I)/(λ1 - λ2); P2 = I - P1
    p11, p22, p12 = (e11 - lam2) / (2 * radius), (e22 - lam2) / (2 * radius), e12 / (2 * radius)
    v1 = (p11, p22, p12)
    v2 = (1.0 - p11, 1.0 - p22, -p12)
    M = m.matrix

    def a(u, w):
        return sum(float(M[i, j]) * u[i] * w[j] for i in range(3) for j in range(3)
                   if M[i, j] != 0.0)

    a11, a12, a22 = a(v1, v1), a(v1, v2), a(v2, v2)
    taut = fung_energy(m, E)
    wrinkled = 0.5 * m.c * (ufl.exp(lam1**2 * (a11 - a12**2 / a22)) - 1.0)
    # n2·S·n2 ∝ λ1·a12 + λ2·a22 < 0  → wrinkled.  A (nearly) isotropic strain has no
    # principal direction to wrinkle along (and the projector derivatives ~1/r blow up):
    # it is taut (λ1 > 0) or slack.
    is_wrinkled = ufl.And(ufl.lt(lam1 * a12 + lam2 * a22, 0.0), ufl.gt(radius, _ISOTROPIC_R))
    return ufl.conditional(ufl.le(lam1, 0.0), 0.0,
                           ufl.conditional(is_wrinkled, wrinkled, taut))


# --- closed forms (NumPy) for checks and curves ---------------------------------------
def pk2_stress_closed_form(m: FungMaterial, E11, E22, E12=0.0) -> np.ndarray:
    """(S11, S22, S12) = ∂W/∂E in the material axes, differentiated by hand (no relaxation).

    ``∂Q/∂E11 = 2(A1 E11 + A3 E22 + A5 E12)``, ``∂Q/∂E22 = 2(A2 E22 + A3 E11 + A6 E12)``,
    ``∂Q/∂E12 = 2(A4 E12 + A5 E11 + A6 E22)``; S12 is half the last (tensor shear).
    """
    E11, E22, E12 = (np.asarray(v, float) for v in (E11, E22, E12))
    Q = (m.A1 * E11**2 + m.A2 * E22**2 + 2 * m.A3 * E11 * E22 + m.A4 * E12**2
         + 2 * m.A5 * E11 * E12 + 2 * m.A6 * E22 * E12)
    g = m.c * np.exp(Q)  # c/2 · e^Q · 2
    return np.stack([g * (m.A1 * E11 + m.A3 * E22 + m.A5 * E12),
                     g * (m.A2 * E22 + m.A3 * E11 + m.A6 * E12),
                     0.5 * g * (m.A4 * E12 + m.A5 * E11 + m.A6 * E22)])


def equibiaxial_response(m: FungMaterial, max_stress: float = 60.0, n: int = 60,
                         measure: str = "first_pk") -> dict[str, np.ndarray]:
    """Strains of the equibiaxial test (E12 = 0, equal stresses along both axes).

    ``measure = "first_pk"`` equalises the Lagrangian (first Piola–Kirchhoff,
    nominal) stresses ``P_i = λ_i S_i`` with ``λ_i = √(1 + 2E_i)``, the
    quantity a biaxial rig controls; ``"second_pk"`` equalises ``S_i``.  Each
    stress level is solved for (E11, E22) by Newton's method started from the
    previous level (the response is monotone).
    """
    from scipy.optimize import fsolve

    levels = np.linspace(0.0, max_stress, n + 1)
    out = np.zeros((len(levels), 2))
    guess = np.array([1e-6, 1e-6])
    for i, t in enumerate(levels[1:], start=1):
        def residual(e, t=t):
            s = pk2_stress_closed_form(m, e[0], e[1])[:2]
            if measure == "first_pk":
                s = s * np.sqrt(1.0 + 2.0 * e)
            return s - t

        sol, _, _, msg = fsolve(residual, guess, full_output=True, xtol=1e-13)
        if np.max(np.abs(residual(sol))) > 1e-9 * max(t, 1.0):
            raise RuntimeError(f"equibiaxial solve failed at {t:g} kPa: {msg}")
        out[i] = guess = sol
    stretch = np.sqrt(1.0 + 2.0 * out)
    return {"stress": levels, "E11": out[:, 0], "E22": out[:, 1],
            "stretch11": stretch[:, 0], "stretch22": stretch[:, 1]}
