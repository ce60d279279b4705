"""The contact law's parameters as data (SPEC §5): the configuration's ``[contact]`` table.

A leaf module: :mod:`valve_dolfinx.config` takes the parameter set from here as one of a
case's sections, and :mod:`valve_dolfinx.contact` takes it to evaluate the law, so neither
imports the other for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from valve_dolfinx.exceptions import check_range
from valve_dolfinx.setting_fields import NOT_A_SETTING, check_setting, setting

__all__ = ["ContactParameters"]


@dataclass(frozen=True, slots=True)
class ContactParameters:
    """Parameters of the penalty contact (SPEC §5; :mod:`valve_dolfinx.contact.law`).

    ``stiffness``, ``cutoff``, ``thickness``, ``crossing_stiffness``, ``guard_distance`` and
    ``guard_stiffness`` are settings (the configuration's ``[contact]`` table).  The other
    fields are fixed numbers of the law (:data:`~valve_dolfinx.setting_fields.NOT_A_SETTING`):
    every case uses their defaults; the tests of the literal SPEC law set others.

    Attributes
    ----------
    stiffness
        Penalty stiffness ``k`` in mN/mm (SPEC: 10 N/m = 10 mN/mm).
    cutoff
        Distance ``h`` in mm beyond which a surface exerts no force (SPEC: 0.1 mm).
    thickness
        Contact thickness ``t_c`` (mm): the law acts on ``d = distance − t_c``,
        so two sheets rest about ``t_c`` apart (a plane, which stands for a
        mirror-image neighbour, at ``t_c/2``); the default 0.25 mm puts each leaflet's
        contact surface 0.125 mm off its mid-surface.  0 is the SPEC's zero-thickness
        law.  A positive value gives the membranes the volume real leaflets have: a
        third leaflet cannot slide into the (force-free) seam between two coapting ones
        at the valve centre without pushing them apart, which zero-thickness sheets do
        freely.
    crossing_stiffness
        Stiffness ``k_x`` (mN/mm) of a barrier against the *mid-surfaces*
        crossing (``d < -thickness``), added to the law: SPEC §5 asks for no
        interpenetration, but its penalty ``k`` = 10 mN/mm only answers a node
        pushed by its own pressure force.  A node pulled through a neighbour by
        membrane tension (the taut free edge of a stiff pericardial graft near
        a commissure: ~7 mN) would sink ~0.5 mm before ``k`` balanced it.  The
        barrier (:func:`~valve_dolfinx.contact.law.crossing_barrier`) leaves the SPEC
        law untouched wherever the mid-surfaces have not crossed -- every equilibrium
        of the normal valve -- and is C¹ (quadratic onset over ``crossing_width``).
        0 is the SPEC law alone.
    guard_distance
        Reach ``d̂`` (mm) of the barrier that keeps every surface from passing through
        another or itself (:mod:`valve_dolfinx.contact.guard`), between mid-surfaces.
        Shorter than ``thickness``, so that sheets at rest under the law are outside it.
    guard_stiffness
        ``κ`` (mN/mm³) of that barrier: a pair at distance ``d`` stores ``κ b(d)`` per unit
        area, ``b(d) = −(d − d̂)² ln(d/d̂)`` (mm²).  The default pushes back with about
        120 kPa (eleven times the diastolic pressure) at half the reach and grows without
        bound closer in.
    penetration_depth
        How far behind a triangle (mm) a node is still treated as penetrating
        it.  Nodes further behind are taken to belong to the other side of the
        (thin) sheet and are ignored.  Must exceed the largest penetration the
        solver can produce in one step.
    blend_distance
        ε (mm) of the smooth minimum over the triangles a node meets on one
        body: ``w ∝ exp(-(d - min d)/ε)``, so that a node in a crease does
        not jump between the two faces' normals (see
        ``SurfaceContact._blend_weights``).
    taper
        Fraction of the cut-off band ``[0, h)`` over whose outer part the
        exponential branch is faded smoothly to zero (a C¹ smoothstep on
        ``[(1 - taper)·h, h]``).  ``0`` is the literal SPEC law, whose force jumps
        from ``F·e^{-kh/F}`` to 0 at ``d = h``; with nodal pressure forces of a
        few mN that jump is several mN, and an implicit solver sees a
        discontinuous residual there: Newton fails repeatedly and the adaptive
        time step collapses.  0.5 leaves the law untouched for
        ``d ≤ h/2`` -- in particular ``f(0) = F`` and the slope ``-k`` at
        contact, which set the equilibrium -- and removes the jump.
    min_driving_force
        Floor on the driving force ``F`` in mN (the part of the node's pressure force
        pushing it into the surface), so that :math:`e^{-kd/F}` stays defined when no
        pressure acts; with the floor the law reduces to a pure penalty
        :math:`-k d` behind the surface and (numerically) zero in front of it.
    crossing_width
        Width (mm) of the crossing barrier's quadratic onset.
    """

    stiffness: float = setting(10.0, "mN/mm", "penalty stiffness k of the contact law")
    cutoff: float = setting(0.1, "mm", "distance h beyond which a surface exerts no force")
    thickness: float = setting(0.25, "mm", "contact thickness: sheets rest this far apart")
    crossing_stiffness: float = setting(1000.0, "mN/mm", "barrier against the mid-surfaces "
                                        "crossing (0: the SPEC law alone)")
    guard_distance: float = setting(0.1, "mm", "reach of the barrier that keeps every surface "
                                    "from passing through another or itself (shorter than "
                                    "thickness)")
    guard_stiffness: float = setting(1000.0, "mN/mm³", "stiffness κ of that barrier: energy "
                                     "κ·b(d) per unit area, b(d) = -(d - reach)² ln(d/reach)")
    penetration_depth: float = field(default=0.3, metadata=NOT_A_SETTING)
    blend_distance: float = field(default=0.05, metadata=NOT_A_SETTING)
    taper: float = field(default=0.5, metadata=NOT_A_SETTING)
    min_driving_force: float = field(default=1e-9, metadata=NOT_A_SETTING)
    crossing_width: float = field(default=0.02, metadata=NOT_A_SETTING)

    def __post_init__(self) -> None:
        check_setting(self, "crossing_stiffness", 0.0, 1e6, hint="0 is the SPEC law alone")
        check_setting(self, "guard_distance", 0.0, 1.0, low_open=True,
                      hint="the guard's reach should be shorter than the contact thickness")
        check_setting(self, "guard_stiffness", 0.0, 1e7, low_open=True)
        check_range("crossing_width", self.crossing_width, 0.0, 1.0, low_open=True, unit="mm")
        check_range("blend_distance", self.blend_distance, 0.0, 1.0, low_open=True, unit="mm")
        check_setting(self, "thickness", 0.0, 2.0)
        check_range("taper", self.taper, 0.0, 1.0,
                    hint="0 keeps the force jump at d = h, 1 fades it over the whole band")
        check_setting(self, "stiffness", 0.0, low_open=True)
        check_setting(self, "cutoff", 0.0, low_open=True)
        check_range("penetration_depth", self.penetration_depth, 0.0, low_open=True, unit="mm",
                    hint="it is the depth behind a triangle that still counts as penetration")
        check_range("min_driving_force", self.min_driving_force, 0.0, low_open=True, unit="mN",
                    hint="a tiny positive floor such as 1e-9 mN keeps exp(-k d / F) defined")

    @property
    def search_distance(self) -> float:
        """Padding (mm) of the bounding boxes: ``thickness + max(cutoff, penetration_depth)``."""
        return self.thickness + max(self.cutoff, self.penetration_depth)

    @property
    def reach(self) -> float:
        """Largest raw distance (mm) at which a surface pushes: ``thickness + cutoff``."""
        return self.thickness + self.cutoff
