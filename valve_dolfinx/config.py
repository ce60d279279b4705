"""The configuration of one closure case: typed, validated, without DOLFINx.

:class:`CaseConfig` holds everything that defines a case: the valve geometry,
the pressure, the tissues, the root, the contact law, the solver path and its
numerical settings, and the analysis settings.  Each nested parameter set
validates its own ranges; :class:`CaseConfig` checks how they combine.  Nothing
here imports DOLFINx or PETSc, so a configuration is loaded and checked in a
fraction of a second, before any mesh is built.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace

from valve_dolfinx.contact.law import ContactParameters
from valve_dolfinx.exceptions import ParameterError, check_range
from valve_dolfinx.geometry.valve import ValveParameters
from valve_dolfinx.materials import BOVINE_PERICARDIUM, NATIVE_LEAFLET, FungMaterial
from valve_dolfinx.root import RootParameters
from valve_dolfinx.solvers.parameters import DynamicsParameters, PseudoTransientParameters

__all__ = [
    "MMHG_TO_KPA",
    "VALVE_CONTACT",
    "SOLVERS",
    "CaseConfig",
    "case_name",
]

#: 1 mmHg in kPa (80 mmHg = 10.666 kPa)
MMHG_TO_KPA = 0.133322
#: Contact of the closing valve (SPEC §5 law, k = 10 mN/mm, h = 0.1 mm) with the numerical
#: choices of docs/contact.md: the leaflets' contact surfaces are offset 0.125 mm (half of
#: ``thickness``) from their mid-surfaces, so the three leaflets cannot wedge into each
#: other's seams at the valve centre; the blending width smooths nodes in mesh-scale creases.
#: The side of every node-triangle pair, between leaflets as within one, is the side the node
#: approaches from (recorded at the last accepted state), whichever face of the triangle that is.
VALVE_CONTACT = ContactParameters(thickness=0.25, penetration_depth=0.3, blend_distance=0.05)
#: leaflets never contact each other within this distance (mm) of where they are sewn
#: together, measured on the unloaded valve (see SurfaceContact: attached_reference)
COMMISSURE_EXCLUSION_MM = 2.5
#: face contacts with a neighbour leaflet fade out over this many triangle heights beyond
#: its free edge (see SurfaceContact: boundary_band): coapting free edges lie level
FREE_EDGE_BAND = 1.0
#: effective flexural modulus of the leaflets (kPa): D = E_b·t³/12 (docs/closure.md)
BENDING_MODULUS_KPA = 200.0
#: paths to the loaded equilibrium (CaseConfig.solver): pseudo-transient continuation (the
#: default) and damped BDF2 dynamics (SPEC §4, the cross-check)
SOLVERS = ("ptc", "bdf2")

#: the nested parameter sets of a CaseConfig, by field name
_SECTIONS = {"geometry": ValveParameters, "native_material": FungMaterial,
             "graft_material": FungMaterial, "root": RootParameters,
             "contact": ContactParameters, "pseudo_transient": PseudoTransientParameters,
             "dynamics": DynamicsParameters}


@dataclass
class CaseConfig:
    """Everything that defines one closure case (written beside every result).

    ``symmetric_reference=True`` runs the cheap reference of SPEC §4 instead of
    the valve: the left-coronary leaflet alone, closing against the two planes
    through the valve axis at ±60° that its neighbours mirror it across (the
    contact law sees the distance to the mirror image, as between leaflets).

    ``bending_modulus_kpa`` gives the leaflets their flexural rigidity
    ``D = E_b·t³/12`` (:mod:`valve_dolfinx.bending`; 0 = pure membrane): it
    regularises the slack free-edge tip at the triple point, without which the
    three-leaflet valve does not converge (docs/closure.md).
    ``solver`` picks the path to the equilibrium: ``"ptc"`` (the default:
    pseudo-transient continuation with PETSc TS and SNES, contact and bending
    in the Newton system from the first step,
    :mod:`~valve_dolfinx.solvers.pseudo_transient`) or ``"bdf2"`` (SPEC §4: damped
    BDF2 dynamics with PETSc TS, :mod:`~valve_dolfinx.solvers.dynamics`, the
    cross-check).  Both stop at a static equilibrium.
    ``nodulus_length_mm`` (0 mm) is the free-edge length at the triple point
    treated as the nodulus of Arantius by the coaptation heights
    (:mod:`valve_dolfinx.analysis.coaptation`); 0 leaves nothing out.
    """

    geometry: ValveParameters = field(default_factory=ValveParameters)
    pressure_mmhg: float = 80.0
    native_material: FungMaterial = NATIVE_LEAFLET
    graft_material: FungMaterial = BOVINE_PERICARDIUM
    root: RootParameters = field(default_factory=RootParameters)
    contact: ContactParameters = field(default_factory=lambda: VALVE_CONTACT)
    solver: str = "ptc"
    pseudo_transient: PseudoTransientParameters = field(
        default_factory=PseudoTransientParameters)
    dynamics: DynamicsParameters = field(default_factory=DynamicsParameters)
    coaptation_threshold_mm: float = 0.5
    orifice_pixel_mm: float = 0.05
    nodulus_length_mm: float = 0.0
    commissure_exclusion_mm: float = COMMISSURE_EXCLUSION_MM
    free_edge_band: float = FREE_EDGE_BAND
    quadrature_degree: int = 1
    symmetric_reference: bool = False
    bending_modulus_kpa: float = BENDING_MODULUS_KPA

    def __post_init__(self) -> None:
        check_range("pressure_mmhg", self.pressure_mmhg, 0.0, 300.0, low_open=True,
                    unit="mmHg", hint="diastolic aortic pressure is about 80 mmHg")
        check_range("coaptation_threshold_mm", self.coaptation_threshold_mm, 0.0, 5.0,
                    low_open=True, unit="mm")
        check_range("bending_modulus_kpa", self.bending_modulus_kpa, 0.0, 1e5, unit="kPa",
                    hint="0 switches bending off; leaflets are of order 100 kPa in flexure")
        if self.solver not in SOLVERS:
            raise ParameterError(f"solver = {self.solver!r} is not one of {SOLVERS}: "
                                 "'ptc' (pseudo-transient continuation, the default) or "
                                 "'bdf2' (damped BDF2 dynamics, the cross-check)")
        if self.symmetric_reference and self.geometry.has_graft:
            raise ParameterError("symmetric_reference needs the normal valve (no graft)")

    @property
    def pressure_kpa(self) -> float:
        return self.pressure_mmhg * MMHG_TO_KPA

    def to_dict(self) -> dict:
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            out[f.name] = asdict(value) if hasattr(value, "__dataclass_fields__") else value
        return out

    @classmethod
    def from_dict(cls, data: dict) -> CaseConfig:
        unknown = set(data) - {f.name for f in fields(cls)}
        if unknown:
            raise ParameterError(f"unknown configuration keys {sorted(unknown)}")
        kw = {k: (_SECTIONS[k](**v) if k in _SECTIONS and isinstance(v, dict) else v)
              for k, v in data.items()}
        return cls(**kw)

    def with_graft(self, width_pct: float | None, height_pct: float | None) -> CaseConfig:
        geometry = replace(self.geometry, graft_width_pct=width_pct, graft_height_pct=height_pct)
        return replace(self, geometry=geometry)


def case_name(geometry: ValveParameters) -> str:
    """``normal`` or ``W<width>_H<height>``: the case's folder name in a study."""
    if not geometry.has_graft:
        return "normal"
    return f"W{geometry.graft_width_pct:g}_H{geometry.graft_height_pct:g}"
