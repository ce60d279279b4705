"""One patient's measured inputs (SPEC §9): typed, range-checked, read from and written to TOML.

A plan takes what the surgeon measures before cutting the graft:

* the loaded root diameter at the base, on echo or CT, and its uncertainty;
* the excised non-coronary leaflet's free-edge length and midline height, measured
  flat (optional: the SPEC §1 leaflet by default);
* optionally the diastolic pressure, the graft grid, the target coaptation height, the
  graft's fibre angle, the number of numerical paths each graft is solved along and a
  label printed on the template and the report;
* optionally comparison axes (``vary``, ``--vary KEY=V1,V2``): case settings that are not
  measured, such as the graft's flexural modulus, each value answered on its own, so
  that the plan shows whether the size depends on them;
* the numerics the plan's cases run with, when not the defaults: the mesh size and the
  wall-clock limit of each case.  ``patient.toml`` keeps them with the rest, so that
  ``valve-dolfinx plan DIR/patient.toml --out DIR`` runs the plan it records.

Every length carries its unit in its key (``root_diameter_mm``), in ``PATIENT.toml`` as
in :class:`PatientInput`; the same values come from ``valve-dolfinx plan`` flags
(:data:`FIELDS` names each key's flag).  Each value is checked against a clinical range
before anything is computed (docs/plan.md cites the sources): a value outside it is far
more likely a typing or unit error (cm for mm) than a patient.  Nothing here imports
DOLFINx.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from valve_dolfinx.exceptions import ConfigurationError, InputFileError, ParameterError, check_range
from valve_dolfinx.geometry.outline import LeafletShape
from valve_dolfinx.io import atomic_write
from valve_dolfinx.study.axes import axis_table, check_axis_values
from valve_dolfinx.study.grid import (
    ADAPTIVE,
    ADAPTIVE_BUDGET,
    DESIGNS,
    STUDY_HEIGHTS_PCT,
    STUDY_WIDTHS_PCT,
    TARGET_COAPTATION_MAX_MM,
    parse_percentages,
)
from valve_dolfinx.study.paths import study_paths

__all__ = [
    "DEFAULT_LEAFLET",
    "FIELDS",
    "MAX_COMPARISONS",
    "PATIENT_FILE",
    "PatientInput",
    "patient_from_mapping",
    "patient_toml",
    "read_patient",
    "write_patient",
]

#: the plan's copy of its inputs, written beside its outputs
PATIENT_FILE = "patient.toml"
#: the SPEC §1 leaflet: its free edge (π/3·20 mm) and midline height are the defaults
DEFAULT_LEAFLET = LeafletShape()


@dataclass(frozen=True)
class Field:
    """What a key of :class:`PatientInput` means, its flag and its clinical range."""

    flag: str
    unit: str
    meaning: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    why: str = ""


#: every input: its command-line flag, unit, meaning and clinical range (docs/plan.md)
FIELDS: dict[str, Field] = {
    "label": Field("--label", "", "printed on the graft template and the report (a plan "
                   "name; no identifying data is needed)"),
    "root_diameter_mm": Field(
        "--root-diameter", "mm", "loaded root diameter at the base (under the diastolic "
        "pressure), measured on echo or CT", 16.0, 35.0,
        why="adult aortic annuli are 23 ± 2 mm (women) and 26 ± 3 mm (men) on echo; "
        "check the unit (mm, not cm)"),
    "root_uncertainty_mm": Field(
        "--root-uncertainty", "mm", "± uncertainty of the root diameter measurement", 0.0,
        3.0, why="echo and CT measure the root to about ±1 mm; 0 takes the diameter as exact"),
    "leaflet_free_edge_mm": Field(
        "--leaflet-free-edge", "mm", "free-edge length of the excised non-coronary leaflet, "
        "measured flat", 15.0, 50.0,
        why="free edges are about twice the leaflet height (20-60 mm in adults); the "
        "SPEC §1 leaflet's is 20.94 mm"),
    "leaflet_height_mm": Field(
        "--leaflet-height", "mm", "midline height of the excised leaflet (nadir to free "
        "edge), measured flat", 10.0, 30.0,
        why="geometric cusp heights are 12-28 mm in adult tricuspid valves; the SPEC §1 "
        "leaflet's is 12.41 mm"),
    "pressure_mmhg": Field(
        "--pressure", "mmHg", "diastolic transvalvular pressure", 40.0, 120.0,
        why="diastolic aortic pressure is about 80 mmHg"),
    "graft_widths_pct": Field("--widths", "%", "graft width enlargements to study, per cent "
                              "of the measured free edge"),
    "graft_heights_pct": Field("--heights", "%", "graft height enlargements to study, per "
                               "cent of the measured height"),
    "target_coaptation_mm": Field(
        "--target-coaptation", "mm", "minimum coaptation height a graft must reach (unset: "
        "the normal valve's at the same root)", 0.0, TARGET_COAPTATION_MAX_MM, low_open=True,
        why="a normal valve coapts 3-4 mm at its centre"),
    "graft_fibre_angle_deg": Field(
        "--graft-fibre-angle", "deg", "fibre direction of the graft from its free edge",
        -90.0, 90.0, why="0 lays the fibres parallel to the free edge"),
    "paths": Field("--paths", "", "numerical paths every graft is solved along (the first N "
                   "of the study's; the recommendation takes the worst)"),
    "vary": Field("--vary", "", "comparison axes: case settings that are not measured, each "
                  "value answered on its own (docs/plan.md), e.g. vary = "
                  '{ "graft.bending_modulus_kpa" = [200.0, 2000.0] }'),
    "mesh_size_mm": Field(
        "--mesh-size", "mm", "target triangle edge length of every case (unset: the case "
        "default, 0.8 mm)", 0.05, 2.5,
        why="0.8 mm is the default, 1.6-2.5 mm a quick coarse plan"),
    "wall_time_limit_s": Field(
        "--wall-time-limit", "s", "wall-clock limit of each case (unset: the solver's)", 0.0,
        30 * 24 * 3600.0, low_open=True, why="the wall-clock limit of each case in seconds"),
    "design": Field("--full-grid", "", "'adaptive': cases chosen in rounds by the fitted "
                    "surface, within the budget; 'grid' (--full-grid): every graft of the grid "
                    "in every member (docs/plan.md)"),
    "budget": Field("--budget", "", "the most graft cases an adaptive plan solves per "
                    "comparison value"),
}
#: keys whose value is a length, pressure or angle
_NUMBERS = ("root_diameter_mm", "root_uncertainty_mm", "leaflet_free_edge_mm",
            "leaflet_height_mm", "pressure_mmhg", "target_coaptation_mm", "graft_fibre_angle_deg",
            "mesh_size_mm", "wall_time_limit_s")
#: numbers that may be unset (None: the default)
_OPTIONAL = ("target_coaptation_mm", "mesh_size_mm", "wall_time_limit_s")
_LEAFLET = ("leaflet_free_edge_mm", "leaflet_height_mm")
_LABEL_LENGTH = 60
#: the most comparison values (combinations of the ``vary`` axes) a plan answers: its one
#: page draws a sizing map for each, legible at print size up to three across
MAX_COMPARISONS = 3
#: case settings the plan sets from its own inputs, with the flags that set them: no
#: comparison axis may set them
_PLAN_KEYS = {
    "root.loaded_diameter_mm": "--root-diameter and --root-uncertainty (the diameters the "
                               "plan solves over are its uncertainty)",
    "loading.pressure_mmhg": "--pressure",
    "geometry.root_diameter_mm": "--leaflet-free-edge (the measured leaflet)",
    "geometry.gamma_deg": "--leaflet-free-edge and --leaflet-height (the measured leaflet)",
    "geometry.commissure_height_mm": "--leaflet-free-edge and --leaflet-height (the "
                                     "measured leaflet)",
    "graft.fibre_angle_deg": "--graft-fibre-angle",
    "geometry.mesh_size_mm": "--mesh-size",
}


@dataclass(frozen=True)
class PatientInput:
    """The measured inputs of one plan (mm, mmHg, degrees, per cent); see :data:`FIELDS`.

    ``root_diameter_mm`` has no default: it is the patient's measurement.  The leaflet
    defaults are the SPEC §1 leaflet's exact free edge and height, so a plan without a
    measured leaflet builds the default mesh.  Validated on construction
    (:class:`~valve_dolfinx.exceptions.ParameterError` naming the key and its flag).
    """

    root_diameter_mm: float
    root_uncertainty_mm: float = 1.0
    leaflet_free_edge_mm: float = DEFAULT_LEAFLET.free_edge_length
    leaflet_height_mm: float = DEFAULT_LEAFLET.height
    pressure_mmhg: float = 80.0
    graft_widths_pct: tuple[float, ...] = STUDY_WIDTHS_PCT
    graft_heights_pct: tuple[float, ...] = STUDY_HEIGHTS_PCT
    target_coaptation_mm: float | None = None
    graft_fibre_angle_deg: float = 0.0
    paths: int = 2
    vary: Mapping[str, tuple] = field(default_factory=dict)
    mesh_size_mm: float | None = None
    wall_time_limit_s: float | None = None
    label: str = "patient"
    design: str = ADAPTIVE
    budget: int = ADAPTIVE_BUDGET

    def __post_init__(self) -> None:
        set_ = object.__setattr__  # frozen: normalise in place once
        for key in _NUMBERS:
            value = getattr(self, key)
            if value is None and key in _OPTIONAL:
                continue
            set_(self, key, _checked_number(key, value))
        for key, what in (("graft_widths_pct", "width"), ("graft_heights_pct", "height")):
            set_(self, key, parse_percentages(_name(key), getattr(self, key), what))
        try:
            study_paths(self.paths)
        except ParameterError as err:
            raise ParameterError(f"{_name('paths')}: {err}") from None
        label = self.label
        if not isinstance(label, str) or not label.strip() or len(label) > _LABEL_LENGTH \
                or not label.isprintable():
            raise ParameterError(f"{_name('label')} = {label!r}: give a plan name of 1-"
                                 f"{_LABEL_LENGTH} printable characters on one line")
        set_(self, "label", label.strip())
        if self.design not in DESIGNS:
            raise ParameterError(f"{_name('design')} = {self.design!r}: give 'adaptive' (the "
                                 "default) or 'grid' (every graft of the grid)")
        budget = self.budget
        if isinstance(budget, bool) or not isinstance(budget, int) or budget < 1:
            raise ParameterError(f"{_name('budget')} = {budget!r}: give a whole number of "
                                 "graft cases >= 1")
        set_(self, "vary", _checked_vary(self.vary, self.case_settings()))

    # --- what the model takes ---------------------------------------------------------
    @property
    def native_shape(self) -> LeafletShape:
        """The native leaflets: the SPEC §1 outline scaled to the measured leaflet."""
        return LeafletShape.measured(self.leaflet_free_edge_mm, self.leaflet_height_mm)

    @property
    def wrap_diameter_mm(self) -> float:
        """Diameter the flat leaflets are wrapped onto: 3L/π."""
        return self.native_shape.root_diameter

    @property
    def root_diameters_mm(self) -> tuple[float, ...]:
        """The root diameters the plan covers: D − U, D, D + U (D alone if U = 0)."""
        d, u = self.root_diameter_mm, self.root_uncertainty_mm
        return (d,) if u == 0 else (d - u, d, d + u)

    def case_settings(self) -> dict:
        """Case settings in the ``CaseConfig.to_dict()`` layout: the measured leaflet, the
        pressure and the graft's fibres.  The root is prescribed at each of
        :attr:`root_diameters_mm` by the plan's study (``root.loaded_diameter_mm``)."""
        shape = self.native_shape
        return {"loading": {"pressure_mmhg": self.pressure_mmhg},
                "geometry": {"root_diameter_mm": shape.root_diameter,
                             "gamma_deg": shape.gamma_deg,
                             "commissure_height_mm": shape.commissure_height},
                "graft": {"fibre_angle_deg": self.graft_fibre_angle_deg}}

    def to_dict(self) -> dict:
        return asdict(self)


def _name(key: str) -> str:
    """``key (--flag)``: how a message names an input, for the file and the command line."""
    return f"{key} ({FIELDS[key].flag})"


def _checked_vary(vary: Any, base: Mapping) -> dict[str, tuple]:
    """The comparison axes ``{key: values}``, each value checked as a sweep's ``--vary``
    (:func:`~valve_dolfinx.study.axes.check_axis_values`), none a setting the plan sets
    from its inputs, at most :data:`MAX_COMPARISONS` combinations."""
    option = _name("vary")
    out = {}
    for key, values in axis_table(option, vary).items():
        if key in _PLAN_KEYS:
            raise ParameterError(f"{option} {key}: the plan sets it from {_PLAN_KEYS[key]}; "
                                 "give it there, or vary it with `valve-dolfinx sweep`")
        out[key] = check_axis_values(option, key, values, base)
    combinations = math.prod(len(v) for v in out.values())
    if combinations > MAX_COMPARISONS:
        given = " × ".join(str(len(v)) for v in out.values())
        raise ParameterError(f"{option}: {given} = {combinations} combinations of values; a "
                             f"plan answers at most {MAX_COMPARISONS} on its page: give fewer "
                             "values, or compare more with `valve-dolfinx sweep --vary`")
    return out


def _checked_number(key: str, value: Any) -> float:
    spec = FIELDS[key]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParameterError(f"{_name(key)} = {value!r} is not a number: give the value in "
                             f"{spec.unit} as a plain number (the unit is in the key's name)")
    return check_range(_name(key), value, spec.low, spec.high, low_open=spec.low_open,
                       unit=spec.unit, hint=spec.why)


# --- reading ----------------------------------------------------------------------------
def patient_from_mapping(data: Mapping[str, Any], source: str = "patient") -> PatientInput:
    """A validated :class:`PatientInput` from a mapping of :data:`FIELDS` keys.

    Raises
    ------
    ParameterError
        Naming ``source``: an unknown key (a key without its unit, ``root_diameter``, is
        told its unit-bearing name), a missing root diameter, one leaflet dimension
        without the other, a value of the wrong type or out of its clinical range.
    """
    known = {f.name for f in fields(PatientInput)}
    for key in data:
        if key not in known:
            hint = next((k for k in known if k.startswith(f"{key}_")), None)
            spell = (f"; lengths carry their unit in the key: {hint} ({FIELDS[hint].unit})"
                     if hint else f"; allowed keys are {', '.join(FIELDS)}")
            raise ParameterError(f"{source}: unknown key {key!r}{spell}")
    if "root_diameter_mm" not in data:
        raise ParameterError(f"{source}: root_diameter_mm is missing: give the loaded root "
                             "diameter at the base in mm, measured on echo or CT "
                             "(--root-diameter D on the command line)")
    given = [k for k in _LEAFLET if k in data]
    if len(given) == 1:
        missing = next(k for k in _LEAFLET if k not in given)
        raise ParameterError(f"{source}: {_name(given[0])} needs {_name(missing)} as well: "
                             "the excised leaflet is measured flat for both, or give neither "
                             "for the SPEC §1 leaflet")
    try:
        return PatientInput(**dict(data))
    except ParameterError as err:
        raise ParameterError(f"{source}: {err}") from None


def read_patient(path: str | Path, overrides: Mapping[str, Any] | None = None) -> PatientInput:
    """The patient file at ``path`` (TOML, keys of :data:`FIELDS`), with ``overrides``
    (e.g. the command line's flags) set over it."""
    path = Path(path)
    if path.is_dir():
        raise InputFileError(f"{path} is a folder, not a patient file: give the TOML file "
                             f"(a plan folder's is {path / PATIENT_FILE})")
    if not path.is_file():
        raise InputFileError(f"{path}: no such patient file; write one with the keys of "
                             "docs/plan.md (root_diameter_mm = 22.0, ...), or give the "
                             "values as flags (--root-diameter D ...)")
    try:  # utf-8-sig: a byte-order mark, as some editors write, is not part of the TOML
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigurationError(f"{path} is not valid TOML ({err})") from None
    data.update(overrides or {})
    return patient_from_mapping(data, source=str(path))


# --- writing ----------------------------------------------------------------------------
def patient_toml(patient: PatientInput) -> str:
    """``patient`` as TOML, every key with its unit and meaning; reading it back
    (:func:`read_patient`) gives ``patient`` exactly (floats are written in full)."""
    lines = ["# valve-dolfinx patient plan: the measured inputs, with units in the key names.",
             "# Run it with `valve-dolfinx plan FILE --out DIR`.", ""]
    for key, value in patient.to_dict().items():
        spec = FIELDS[key]
        comment = f"# {spec.unit}; {spec.meaning}" if spec.unit else f"# {spec.meaning}"
        if value is None or value == {}:
            lines.append(f"# {key} = (unset)  {comment}")
        else:
            lines.append(f"{key} = {_toml_value(value)}  {comment}")
    return "\n".join(lines) + "\n"


def _toml_value(value: Any) -> str:
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, Mapping):
        return "{ " + ", ".join(f"{json.dumps(k)} = {_toml_value(v)}"
                                for k, v in value.items()) + " }"
    if value is None:
        raise ParameterError("cannot write the value none to a patient file (TOML has no "
                             "null); give the setting's values explicitly")
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        raise ParameterError(f"cannot write {value!r} to a patient file")
    return repr(float(value))


def write_patient(path: str | Path, patient: PatientInput) -> Path:
    """Write ``patient`` to ``path`` as commented TOML, atomically."""
    text = patient_toml(patient)
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
