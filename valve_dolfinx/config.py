"""The configuration of one closure case: typed, validated, without DOLFINx.

:class:`CaseConfig` holds everything that defines a case: the valve geometry,
the pressure, the tissues, the root, the contact law, the solver path and its
numerical settings, and the analysis settings.  Numbers that every case takes alike are
not settings: they are constants of the module that uses them (each solver path's step
control, the contact's taper at the commissures, ...) or fields of a parameter set marked
:data:`NOT_A_SETTING`.  Every setting is a dataclass field declared with
:func:`~valve_dolfinx.setting_fields.setting`, which carries its unit and meaning: the
comments of :func:`config_toml`, :func:`describe` and the settings table of docs/outputs.md
(:func:`settings_table_markdown`) read them there.  :data:`LAYOUT` places each setting once,
in a table by concept (``[graft]``, ``[solver.dynamics]``, ...) under its field's name with
the suffix of its unit (:data:`UNIT_SUFFIXES`); a key of the earlier layout is refused with
its new name (:data:`RENAMED`).  The parameter sets keep the names the physics code reads
(``config.geometry.mesh_size``); the file, ``--set`` and the study axes spell the layout's
keys (``geometry.mesh_size_mm``).  Each nested parameter set
validates its own ranges; :class:`CaseConfig` checks how they combine.  Nothing
here imports DOLFINx or PETSc, so a configuration is loaded and checked in a
fraction of a second, before any mesh is built.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from valve_dolfinx.contact_parameters import ContactParameters
from valve_dolfinx.exceptions import ConfigurationError, InputFileError, ParameterError
from valve_dolfinx.geometry.valve import ValveParameters
from valve_dolfinx.io import atomic_write
from valve_dolfinx.materials import BOVINE_PERICARDIUM, NATIVE_LEAFLET, FungMaterial
from valve_dolfinx.mechanics.root import RootParameters
from valve_dolfinx.setting_fields import (
    NOT_A_SETTING,
    check_setting,
    is_setting,
    setting,
    setting_field,
)
from valve_dolfinx.solvers.parameters import DynamicsParameters, PseudoTransientParameters

__all__ = [
    "MMHG_TO_KPA",
    "NODULUS_LENGTH_MM",
    "SOLVERS",
    "CONFIG_FILE",
    "NOT_A_SETTING",
    "ContactParameters",
    "CaseConfig",
    "case_name",
    "describe",
    "settings_table_markdown",
    "write_settings_table",
    "load_config",
    "read_config_file",
    "apply_overrides",
    "parse_value",
    "set_dotted",
    "get_dotted",
    "setting_keys",
    "GRAFT_ONLY_SETTINGS",
    "GRAFT_TABLE",
    "LAYOUT",
    "TABLES",
    "RENAMED",
    "UNIT_SUFFIXES",
    "WALL_CLOCK_KEY",
    "key_with_unit",
    "check_key",
    "check_keys",
    "config_from_dict",
    "config_toml",
    "write_config",
    "settings_hash",
    "ANALYSIS_VERSION",
    "wall_clock_limits",
    "canonical_hash",
]

#: 1 mmHg in kPa (80 mmHg = 10.666 kPa)
MMHG_TO_KPA = 0.133322
#: Length (mm, flat, centred on the midline) of the free-edge tip treated as the nodulus
#: of Arantius: one leaflet thickness (0.5 mm, SPEC §3) either side of the triple point,
#: where three 0.5 mm thick free edges meet and a zero-thickness membrane has no
#: meaningful coaptation height (docs/coaptation.md §2).
NODULUS_LENGTH_MM = 1.0
#: effective flexural modulus of the native leaflets (kPa): D = E_b·t³/12 (docs/model.md §3)
BENDING_MODULUS_KPA = 200.0
#: effective flexural modulus of the graft (kPa): the native leaflets' value, for want of a
#: measurement on glutaraldehyde-fixed pericardium to cite (docs/model.md §3)
GRAFT_BENDING_MODULUS_KPA = BENDING_MODULUS_KPA
#: paths to the loaded equilibrium (CaseConfig.solver): pseudo-transient continuation (the
#: default) and damped BDF2 dynamics (SPEC §4, the cross-check)
SOLVERS = ("ptc", "bdf2")

#: the resolved configuration written beside every result
CONFIG_FILE = "config.toml"
#: top-level table of a sizing study's configuration file (read by valve_dolfinx.study.grid)
STUDY_TABLE = "study"
#: the one setting that bounds the run's wall-clock time, not its result (left out of
#: settings_hash)
WALL_CLOCK_KEY = "solver.wall_time_limit_s"

#: version of what a case's result holds and how it is judged (its analysis, competence
#: included); part of every settings hash, so that a case analysed under an earlier rule is
#: another identity: a rerun recomputes it and a report counts it as stale.  Raise it when
#: the analysis of a loaded state changes what a result says.
ANALYSIS_VERSION = 2

#: the nested parameter sets of a CaseConfig, by field name
_SECTIONS = {"geometry": ValveParameters, "native_material": FungMaterial,
             "graft_material": FungMaterial, "root": RootParameters,
             "contact": ContactParameters, "pseudo_transient": PseudoTransientParameters,
             "dynamics": DynamicsParameters}


@dataclass
class CaseConfig:
    """Everything that defines one closure case (written beside every result); each
    setting's unit and meaning is on its field, and :data:`LAYOUT` says under which key of
    which table the configuration file shows it.

    ``symmetric_reference=True`` runs the cheap reference of SPEC §4 instead of
    the valve: the left-coronary leaflet alone, closing against the two planes
    through the valve axis at ±60° that its neighbours mirror it across (the
    contact law sees the distance to the mirror image, as between leaflets).

    ``bending_modulus_kpa`` gives the native leaflets their flexural rigidity
    (:mod:`valve_dolfinx.mechanics.bending`): it gives the slack free-edge tip at the
    triple point a length scale instead of a fold at the scale of the mesh (docs/model.md
    §3, with its effect on the figure of merit); fixed pericardium carries compression by
    bending, hence the graft's own.  ``graft_tension_field`` false resists compression
    in-plane (SPEC §3; the native leaflets always wrinkle).  ``solver`` ``"ptc"``
    (:mod:`~valve_dolfinx.solvers.pseudo_transient`) puts contact and bending in the Newton
    system from the first step; ``"bdf2"`` is :mod:`~valve_dolfinx.solvers.dynamics`
    (SPEC §4); both stop at a static equilibrium.  ``nodulus_length_mm`` (1 mm: one leaflet
    thickness either side of the triple point) is left out of the coaptation heights
    (:mod:`valve_dolfinx.analysis.coaptation`); the raw minimum with the tip is always
    reported.
    """

    # the parameter sets: LAYOUT shows their settings and gives each table its meaning
    geometry: ValveParameters = field(default_factory=ValveParameters)
    pressure_mmhg: float = setting(80.0, "mmHg", "transvalvular diastolic pressure on the "
                                   "aortic side")
    native_material: FungMaterial = NATIVE_LEAFLET
    graft_material: FungMaterial = BOVINE_PERICARDIUM
    root: RootParameters = field(default_factory=RootParameters)
    contact: ContactParameters = field(default_factory=ContactParameters)
    solver: str = setting("ptc", "", "path to the loaded equilibrium: 'ptc' (pseudo-transient "
                          "continuation, the default) or 'bdf2' (damped BDF2 dynamics, the "
                          "cross-check)")
    wall_time_limit_s: float | None = setting(None, "s", "wall-clock limit of the solve "
                                              "(unset: the method's own, 900 s for 'ptc', "
                                              "3600 s for 'bdf2')")
    pseudo_transient: PseudoTransientParameters = field(
        default_factory=PseudoTransientParameters)
    dynamics: DynamicsParameters = field(default_factory=DynamicsParameters)
    coaptation_threshold_mm: float = setting(0.5, "mm", "leaflets closer than this to a "
                                             "neighbour coapt")
    nodulus_length_mm: float = setting(NODULUS_LENGTH_MM, "mm", "free-edge length at the "
                                       "triple point treated as the nodulus of Arantius by "
                                       "the coaptation heights (0: none)")
    symmetric_reference: bool = setting(False, "", "true: one leaflet against the two ±60° "
                                        "symmetry planes (the normal valve's cheap reference)")
    bending_modulus_kpa: float = setting(BENDING_MODULUS_KPA, "kPa", "flexural modulus E_b of "
                                         "the native leaflets, D = E_b·t³/12 with their "
                                         "thickness (0: pure membrane)")
    graft_bending_modulus_kpa: float = setting(GRAFT_BENDING_MODULUS_KPA, "kPa", "flexural "
                                               "modulus E_b of the graft (fixed pericardium), "
                                               "D = E_b·t³/12 with the graft's thickness (0: "
                                               "pure membrane)")
    graft_tension_field: bool = setting(True, "", "how the graft carries compression: true, "
                                        "the tension-field relaxed energy (it wrinkles); "
                                        "false, the plain Fung law (it resists compression "
                                        "in-plane)")

    def __post_init__(self) -> None:  # messages name each setting by its key (LAYOUT)
        check_setting(self, "pressure_mmhg", 0.0, 300.0, low_open=True,
                      label="loading.pressure_mmhg",
                      hint="diastolic aortic pressure is about 80 mmHg")
        check_setting(self, "coaptation_threshold_mm", 0.0, 5.0, low_open=True,
                      label="analysis.coaptation_threshold_mm")
        check_setting(self, "bending_modulus_kpa", 0.0, 1e5, label="native.bending_modulus_kpa",
                      hint="0 switches the native leaflets' bending off; they are of order "
                      "100-1000 kPa in flexure")
        check_setting(self, "graft_bending_modulus_kpa", 0.0, 1e5,
                      label="graft.bending_modulus_kpa",
                      low_hint="0 switches the graft's bending off",
                      high_hint="that is beyond even the in-plane tensile modulus of fixed "
                      "pericardium (tens of MPa)")
        if self.wall_time_limit_s is not None:
            check_setting(self, "wall_time_limit_s", 0.0, 1e7, low_open=True,
                          label=WALL_CLOCK_KEY)
        if self.solver not in SOLVERS:
            raise ParameterError(f"solver.method = {self.solver!r} is not one of {SOLVERS}: "
                                 "'ptc' (pseudo-transient continuation, the default) or "
                                 "'bdf2' (damped BDF2 dynamics, the cross-check)")
        if self.symmetric_reference and self.geometry.has_graft:
            raise ParameterError("geometry.symmetric_reference needs the normal valve (no "
                                 "graft: leave graft.width_pct and graft.height_pct unset)")

    @property
    def pressure_kpa(self) -> float:
        return self.pressure_mmhg * MMHG_TO_KPA

    def solver_parameters(self) -> PseudoTransientParameters | DynamicsParameters:
        """The settings of the solver path ``solver``, with the configuration's wall-clock
        limit (``solver.wall_time_limit_s``) if it sets one."""
        params = self.pseudo_transient if self.solver == "ptc" else self.dynamics
        if self.wall_time_limit_s is None:
            return params
        return replace(params, wall_time_limit_s=self.wall_time_limit_s)

    def to_dict(self) -> dict:
        """The settings in the layout of the configuration file (:data:`LAYOUT`): tables by
        concept, each key with its unit suffix."""
        out: dict = {}
        for key, (name, attr) in _KEYS.items():
            value = getattr(self, name)
            set_dotted(out, key, value if attr is None else getattr(value, attr))
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> CaseConfig:
        """A configuration from (part of) the :meth:`to_dict` layout (:func:`config_from_dict`)."""
        return config_from_dict(data)

    def settings_hash(self) -> str:
        """SHA-256 of the settings that determine the result (see :func:`settings_hash`)."""
        return settings_hash(self.to_dict())

    def with_graft(self, width_pct: float | None, height_pct: float | None) -> CaseConfig:
        geometry = replace(self.geometry, graft_width_pct=width_pct, graft_height_pct=height_pct)
        return replace(self, geometry=geometry)

    def normal_valve(self) -> CaseConfig:
        """This configuration's normal valve: no graft, and the ``[graft]`` table, whose
        settings only a graft uses (:data:`GRAFT_ONLY_SETTINGS`), at its defaults, which the
        normal valve's result does not depend on."""
        data = self.to_dict()
        del data[GRAFT_TABLE]
        return config_from_dict(data, source="normal valve")


# --- the layout of the configuration file ----------------------------------------------------
#: unit of a setting → the suffix that ends its key: the one unit-suffix rule of the
#: configuration (docs/outputs.md).  A dimensionless setting or a switch has no suffix.
UNIT_SUFFIXES = {"mm": "_mm", "deg": "_deg", "%": "_pct", "kPa": "_kpa", "mmHg": "_mmhg",
                 "s": "_s", "mN": "_mn", "mN/mm": "_mn_per_mm", "mN/mm³": "_mn_per_mm3"}

#: the table whose settings only a graft uses
GRAFT_TABLE = "graft"

#: The configuration file's tables, by concept, in the order they are written: each table's
#: meaning and what it shows, as ``(key, CaseConfig field, its attribute)`` rows or as a
#: parameter set that the table shows whole (``(None, field, None)``: each setting under the
#: name of its attribute with the suffix of its unit).  The units and meanings are the
#: fields' own (:func:`~valve_dolfinx.setting_fields.setting`); this table only places them.
LAYOUT: dict[str, tuple[str, tuple[tuple[str | None, str, str | None], ...]]] = {
    "loading": ("the load: the diastolic pressure that closes the valve", (
        ("pressure_mmhg", "pressure_mmhg", None),)),
    "geometry": ("the valve's geometry and mesh (SPEC §1), and the modelled domain", (
        ("root_diameter_mm", "geometry", "root_diameter"),
        ("gamma_deg", "geometry", "gamma_deg"),
        ("commissure_height_mm", "geometry", "commissure_height"),
        ("mesh_size_mm", "geometry", "mesh_size"),
        ("symmetric_reference", "symmetric_reference", None))),
    "native": ("the native leaflets: their bending; their tissue in [native.material]", (
        ("bending_modulus_kpa", "bending_modulus_kpa", None),)),
    "native.material": ("the native leaflets' tissue (Fung law, SPEC §3)", (
        (None, "native_material", None),)),
    GRAFT_TABLE: ("the graft: its size, fibres, placement, bending and compressive "
                  "response; its tissue in [graft.material] (every setting here and there "
                  "only a graft uses)", (
        ("width_pct", "geometry", "graft_width_pct"),
        ("height_pct", "geometry", "graft_height_pct"),
        ("fibre_angle_deg", "geometry", "graft_fibre_angle_deg"),
        ("placement", "geometry", "graft_placement"),
        ("billow_mm", "geometry", "billow_mm"),
        ("bending_modulus_kpa", "graft_bending_modulus_kpa", None),
        ("tension_field", "graft_tension_field", None))),
    f"{GRAFT_TABLE}.material": ("the graft's tissue (Fung law, SPEC §3)", (
        (None, "graft_material", None),)),
    "root": ("the aortic root's wall (SPEC §2)", ((None, "root", None),)),
    "contact": ("the contact law (SPEC §5)", ((None, "contact", None),)),
    "analysis": ("how a loaded valve's coaptation is measured", (
        ("coaptation_threshold_mm", "coaptation_threshold_mm", None),
        ("nodulus_length_mm", "nodulus_length_mm", None))),
    "solver": ("the path to the loaded equilibrium and its wall-clock limit; each path's "
               "numerics in its subtable", (
        ("method", "solver", None),
        ("wall_time_limit_s", "wall_time_limit_s", None))),
    "solver.pseudo_transient": ("numerics of the pseudo-transient continuation "
                                "(method = 'ptc')", ((None, "pseudo_transient", None),)),
    "solver.dynamics": ("numerics of the damped BDF2 dynamics (method = 'bdf2')", (
        (None, "dynamics", None),)),
}


def key_with_unit(name: str, unit: str) -> str:
    """``name`` ending in the suffix of ``unit`` (:data:`UNIT_SUFFIXES`), unless it does."""
    suffix = UNIT_SUFFIXES[unit] if unit else ""
    return name if name.endswith(suffix) else name + suffix


def _field_of(name: str, attr: str | None) -> Any:
    """The field of CaseConfig ``name`` or of its parameter set's ``attr``."""
    return setting_field(_SECTIONS[name], attr) if attr else setting_field(CaseConfig, name)


def _layout_keys() -> dict[str, tuple[str, str | None]]:
    """Every setting's dotted key → ``(CaseConfig field, attribute or None)``, in the order
    of :data:`LAYOUT`; TypeError if a key breaks the unit-suffix rule."""
    keys: dict[str, tuple[str, str | None]] = {}
    for table, (_, rows) in LAYOUT.items():
        for key, name, attr in rows:
            if key is not None:
                keys[f"{table}.{key}"] = (name, attr)
                continue
            for f in fields(_SECTIONS[name]):
                if is_setting(f):
                    keys[f"{table}.{key_with_unit(f.name, f.metadata['unit'])}"] = (name, f.name)
    suffixes = tuple(UNIT_SUFFIXES.values())
    for key, (name, attr) in keys.items():
        unit = _field_of(name, attr).metadata["unit"]
        leaf = key.rpartition(".")[2]
        if (leaf != key_with_unit(leaf, unit)) if unit else leaf.endswith(suffixes):
            raise TypeError(f"{key}: a key ends in the suffix of its unit ({unit!r}) and a "
                            "dimensionless key in none (UNIT_SUFFIXES)")
    return keys


_KEYS = _layout_keys()

#: every table of the configuration file (a dotted name for a subtable)
TABLES = tuple(LAYOUT)

#: settings that only a graft uses: those of the ``[graft]`` table and its subtable.  The
#: normal valve of a study takes them at their defaults (:meth:`CaseConfig.normal_valve`), so
#: normal valves that differ in graft settings alone are one case
GRAFT_ONLY_SETTINGS = tuple(k for k in _KEYS if k.split(".")[0] == GRAFT_TABLE)

#: the configuration's keys before its tables were arranged by concept → each one's key now.
#: A file, an override or a study axis that uses one gets an error naming the new key.
RENAMED = {
    "pressure_mmhg": "loading.pressure_mmhg",
    "solver": "solver.method",
    "coaptation_threshold_mm": "analysis.coaptation_threshold_mm",
    "nodulus_length_mm": "analysis.nodulus_length_mm",
    "symmetric_reference": "geometry.symmetric_reference",
    "bending_modulus_kpa": "native.bending_modulus_kpa",
    "graft_bending_modulus_kpa": "graft.bending_modulus_kpa",
    "graft_tension_field": "graft.tension_field",
    "geometry.root_diameter": "geometry.root_diameter_mm",
    "geometry.commissure_height": "geometry.commissure_height_mm",
    "geometry.mesh_size": "geometry.mesh_size_mm",
    "geometry.graft_width_pct": "graft.width_pct",
    "geometry.graft_height_pct": "graft.height_pct",
    "geometry.graft_fibre_angle_deg": "graft.fibre_angle_deg",
    "geometry.graft_placement": "graft.placement",
    "geometry.billow_mm": "graft.billow_mm",
    **{f"{old}.{name}": f"{new}.material.{key_with_unit(name, 'kPa' if name == 'c' else '')}"
       for old, new in (("native_material", "native"), ("graft_material", GRAFT_TABLE))
       for name in ("c", "A1", "A2", "A3", "A4", "A5", "A6")},
    "native_material.thickness": "native.material.thickness_mm",
    "graft_material.thickness": "graft.material.thickness_mm",
    "root.youngs_modulus": "root.youngs_modulus_kpa",
    "root.wall_thickness": "root.wall_thickness_mm",
    "root.loaded_diameter": "root.loaded_diameter_mm",
    "contact.stiffness": "contact.stiffness_mn_per_mm",
    "contact.cutoff": "contact.cutoff_mm",
    "contact.thickness": "contact.thickness_mm",
    "contact.crossing_stiffness": "contact.crossing_stiffness_mn_per_mm",
    "contact.guard_distance": "contact.guard_distance_mm",
    "contact.guard_stiffness": "contact.guard_stiffness_mn_per_mm3",
    "pseudo_transient.residual_tolerance": "solver.pseudo_transient.residual_tolerance_mn",
    **{f"pseudo_transient.{name}": f"solver.pseudo_transient.{name}"
       for name in ("mass_length_mm", "coarse_mesh_mm", "max_steps", "petsc_options")},
    "pseudo_transient.wall_time_limit_s": WALL_CLOCK_KEY,
    "dynamics.relaxation_time": "solver.dynamics.relaxation_time_s",
    "dynamics.stop_increment_mm": "solver.dynamics.stop_increment_mm",
    "dynamics.wall_time_limit_s": WALL_CLOCK_KEY,
}
#: the tables of the old keys (a file's ``[native_material]``, ...)
_RENAMED_TABLES = {k.split(".")[0] for k in RENAMED if "." in k} - set(TABLES)


def case_name(geometry: ValveParameters) -> str:
    """``normal`` or ``W<width>_H<height>``: a case's name in a study before its axis values."""
    if not geometry.has_graft:
        return "normal"
    from valve_dolfinx.geometry.outline import GraftSize

    return GraftSize(geometry.graft_width_pct, geometry.graft_height_pct).stem


# --- meaning and unit of every setting ------------------------------------------------------
def describe(key: str) -> tuple[str, str]:
    """``(unit, meaning)`` of the setting ``key`` (dotted, ``geometry.mesh_size_mm``) from its
    field's metadata, or ``("", meaning)`` of a table (``graft.material``); KeyError for a
    key that is neither."""
    if key in LAYOUT:
        return "", LAYOUT[key][0]
    if key not in _KEYS:
        raise KeyError(f"{key!r} is not a setting of the configuration")
    metadata = _field_of(*_KEYS[key]).metadata
    return metadata["unit"], metadata["meaning"]


#: the comments that enclose the generated settings table in docs/outputs.md
SETTINGS_TABLE_MARKERS = ("<!-- settings table: generated by "
                          "valve_dolfinx.config.write_settings_table -->",
                          "<!-- end of the settings table -->")


def settings_table_markdown() -> str:
    """Every setting, its default, unit and meaning as a Markdown table (the one in
    docs/outputs.md): each table's row, then its keys as ``table.key``; a setting only a
    graft uses (:data:`GRAFT_ONLY_SETTINGS`) says so."""
    data = CaseConfig().to_dict()

    def row(name: str, default: str) -> str:
        unit, meaning = describe(name)
        if name in GRAFT_ONLY_SETTINGS:
            meaning += "; *graft only*"
        shown = f"`[{name}]`" if name in LAYOUT else f"`{name}`"
        cells = (cell.replace("|", "\\|") for cell in (shown, default, unit, meaning))
        return "| " + " | ".join(cells) + " |"

    def default(value: Any) -> str:
        return "unset" if value is None else f"`{_toml_value(value)}`"

    rows = ["| key | default | unit | meaning |", "|---|---|---|---|"]
    for table in LAYOUT:
        rows.append(row(table, ""))
        rows += [row(key, default(get_dotted(data, key))) for key in _KEYS
                 if key.rpartition(".")[0] == table]
    return "\n".join(rows) + "\n"


def write_settings_table(path: str | Path) -> bool:
    """Write :func:`settings_table_markdown` between :data:`SETTINGS_TABLE_MARKERS` in the
    Markdown file at ``path``; True if the file changed."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    begin, end = SETTINGS_TABLE_MARKERS
    head, sep, rest = text.partition(begin + "\n")
    _, sep2, tail = rest.partition(end)
    if not sep or not sep2:
        raise ConfigurationError(f"{path}: the settings table's markers {begin!r} and "
                                 f"{end!r} are missing; put them where the table belongs")
    new = head + begin + "\n" + settings_table_markdown() + end + tail
    if new == text:
        return False
    atomic_write(path, lambda tmp: tmp.write_text(new, encoding="utf-8"))
    return True


# --- loading --------------------------------------------------------------------------------
def load_config(path: str | Path | None = None, overrides: Iterable[str] = (),
                values: Mapping[str, Any] | None = None) -> CaseConfig:
    """The case configuration: defaults < the file at ``path`` < ``overrides`` < ``values``.

    Parameters
    ----------
    path
        A TOML file in the :meth:`CaseConfig.to_dict` layout (any subset of the keys);
        a ``[study]`` table, a sizing study's grid, is skipped.  ``None``: the defaults.
    overrides
        ``"table.key=value"`` strings (``--set``); the value is read as a TOML value,
        or taken as a string if it is not one (``solver.method=bdf2``).
    values
        ``{"table.key": value}`` set last (the command line's named flags).

    Raises
    ------
    ParameterError
        On an unknown key, a value of the wrong type or out of its range (the message
        names the key, ``table.key``), or a file that is not TOML.
    InputFileError
        If ``path`` does not exist (an ``OSError``).
    """
    data: dict = {}
    source = "configuration"
    if path is not None:
        data = read_config_file(path)
        data.pop(STUDY_TABLE, None)
        source = str(path)
    apply_overrides(data, overrides)
    for key, value in (values or {}).items():
        set_dotted(data, key, value)
    return config_from_dict(data, source)


def read_config_file(path: str | Path) -> dict:
    """The TOML file at ``path`` as a dict (errors name the file)."""
    path = Path(path)
    if path.is_dir():
        raise InputFileError(f"{path} is a folder, not a configuration file (--config): give "
                             "the TOML file; `valve-dolfinx config > case.toml` writes one")
    if not path.is_file():
        raise InputFileError(f"{path}: no such configuration file (--config); "
                             "`valve-dolfinx config > case.toml` writes one to start from")
    try:  # utf-8-sig: a byte-order mark, as some editors write, is not part of the TOML
        return tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigurationError(f"{path} is not valid TOML ({err})") from None


def apply_overrides(data: dict, overrides: Iterable[str]) -> dict:
    """Set each ``"table.key=value"`` of ``overrides`` in the nested ``data`` (in place)."""
    for text in overrides:
        key, sep, raw = text.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ParameterError(f"--set {text!r}: give table.key=value, e.g. --set "
                                 "loading.pressure_mmhg=100 or --set geometry.mesh_size_mm=1.6")
        if key in RENAMED:
            check_key(key, source="--set")
        set_dotted(data, key, parse_value(raw))
    return data


def parse_value(text: str) -> Any:
    """A setting's value as typed on the command line: a TOML value (``21``, ``true``,
    ``"a b"``), or the text itself if it is not one (a bare word such as ``bdf2``)."""
    text = text.strip()
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def set_dotted(data: dict, key: str, value: Any) -> None:
    """Set ``data[a][b] = value`` for ``key = "a.b"`` (tables created as needed)."""
    *tables, name = key.split(".")
    target = data
    for table in tables:
        target = target.setdefault(table, {})
        if not isinstance(target, dict):
            raise ParameterError(f"{key}: {table!r} is a value, not a table")
    target[name] = value


def get_dotted(data: Mapping[str, Any], key: str) -> Any:
    """``data[a][b]`` for ``key = "a.b"``; KeyError if a table or the key is missing."""
    value: Any = data
    for name in key.split("."):
        if not isinstance(value, Mapping) or name not in value:
            raise KeyError(key)
        value = value[name]
    return value


def setting_keys(data: Mapping[str, Any]) -> list[str]:
    """The dotted keys of the settings (and of any other leaf) in ``data`` (the
    :meth:`CaseConfig.to_dict` layout, any subset): ``loading.pressure_mmhg``,
    ``root.loaded_diameter_mm``, ...  A table descended into is one of :data:`TABLES`, or of
    the old layout (:data:`RENAMED`), so that a dict-valued setting stays one key."""
    def walk(table: Mapping[str, Any], prefix: str) -> list[str]:
        keys = []
        for name, value in table.items():
            key = f"{prefix}{name}"
            if isinstance(value, Mapping) and (key in TABLES or key in _RENAMED_TABLES):
                keys += walk(value, key + ".")
            else:
                keys.append(key)
        return keys

    return walk(data, "")


def check_key(key: str, source: str = "configuration") -> None:
    """Raise ParameterError if the dotted ``key`` is not a setting: naming the new key of a
    key of the old layout (:data:`RENAMED`), or the settings of its table."""
    check_keys([key], source)


def check_keys(keys: Iterable[str], source: str = "configuration") -> None:
    """:func:`check_key` of every key, all the renamed ones named in one message."""
    keys = list(keys)
    renamed = [k for k in keys if k in RENAMED]
    if renamed:
        named = "; ".join(f"{k} was renamed {RENAMED[k]}" for k in renamed)
        raise ParameterError(f"{source}: {named} (the settings are arranged in tables by "
                             "concept, every dimensional key ending in its unit; "
                             "`valve-dolfinx config` prints them all)")
    unknown = [k for k in keys if k not in _KEYS]
    if unknown:
        raise ParameterError(f"{source}: {_unknown_message(unknown)}")


def config_from_dict(data: Mapping[str, Any], source: str = "configuration") -> CaseConfig:
    """A validated :class:`CaseConfig` from (part of) the :meth:`CaseConfig.to_dict` layout.

    Keys left out keep their defaults (a table given in part keeps the rest of its
    defaults).  Integers are accepted for real-valued settings.

    Raises
    ------
    ParameterError
        Naming ``source`` and the dotted key: a key of the old layout (with its new name),
        an unknown key, a value of the wrong type, or a value outside its range.
    """
    for name, value in data.items():
        if name in TABLES and not isinstance(value, Mapping) and name not in RENAMED:
            raise ParameterError(f"{source}: {name} must be a table of settings "
                                 f"([{name}] in a TOML file), got {value!r}")
    keys = setting_keys(data)
    check_keys(keys, source)
    defaults = CaseConfig()
    top: dict[str, Any] = {}
    changes: dict[str, dict[str, Any]] = {}
    for key in keys:
        name, attr = _KEYS[key]
        value = _checked_value(key, get_dotted(data, key), _field_of(name, attr).type, source)
        if attr is None:
            top[name] = value
        else:
            changes.setdefault(name, {})[attr] = value
    for name, kw in changes.items():
        try:
            top[name] = replace(getattr(defaults, name), **kw)
        except ParameterError as err:
            raise ParameterError(f"{source}: {_dotted_message(name, str(err))}") from None
    try:
        return replace(defaults, **top)
    except ParameterError as err:
        raise ParameterError(f"{source}: {err}") from None


def _unknown_message(unknown: list[str]) -> str:
    """What the keys that are not settings are, and the fix: a file of an earlier version
    can hold many (all are named at once)."""
    defaults = CaseConfig()

    def fixed(key: str) -> str:  # a parameter set's fixed number: what every case takes
        table, _, name = key.rpartition(".")
        section = next((n for _, n, a in LAYOUT.get(table, ("", ()))[1] if _ is None), None)
        value = getattr(getattr(defaults, section), name, None) if section else None
        return (f" (every case takes {value!r})" if isinstance(value, int | float)
                and not isinstance(value, bool) else "")

    named = ", ".join(f"{key!r}{fixed(key)}" for key in unknown)
    earlier = ("(a file written by an earlier version may hold keys that are now fixed "
               "numbers of the model or were removed)")
    if len(unknown) > 1:
        return (f"unknown keys {named}; they are not settings of this version {earlier}: "
                "delete those lines (`valve-dolfinx config` prints every setting)")
    table = unknown[0].rpartition(".")[0]
    if table in LAYOUT:
        allowed = [k.rpartition(".")[2] for k in _KEYS if k.rpartition(".")[0] == table]
        where = f"allowed keys of [{table}] are {', '.join(allowed)}"
    else:
        where = f"the tables are {', '.join(TABLES)}"
    return (f"unknown key {named}; it is not a setting of this version {earlier}: delete the "
            f"line; {where}")


def _dotted_message(name: str, message: str) -> str:
    """A range message of the parameter set ``name`` with the settings spelled by their keys
    (``geometry.mesh_size_mm``): the one it starts with, and any other it names by an
    identifier with an underscore.  (CaseConfig's own messages name the keys.)"""
    keys = {attr: key for key, (field_name, attr) in _KEYS.items() if field_name == name}
    match = re.match(r"(?:[\w.]+\.)?(\w+)( = .*|\b.*)", message, re.DOTALL)
    if match and match.group(1) in keys:
        message = f"{keys[match.group(1)]}{match.group(2)}"
    return re.sub(r"(?<![\w.])(\w+_\w+)(?![\w.])",
                  lambda m: keys.get(m.group(1), m.group(1)), message)


def _checked_value(key: str, value: Any, annotation: Any, source: str) -> Any:
    """``value`` checked against the field's annotation (a string: postponed annotations)."""
    kinds = str(annotation).replace(" ", "").split("|")
    if value is None or (isinstance(value, str) and value.lower() == "none" and "None" in kinds):
        if "None" in kinds:
            return None
        raise ParameterError(f"{source}: {key} needs a value ({kinds[0]})")
    if isinstance(value, bool):
        ok = "bool" in kinds
    elif isinstance(value, int):
        ok = "int" in kinds or "float" in kinds
        if ok and "int" not in kinds:
            value = float(value)
    elif isinstance(value, float):
        ok = "float" in kinds
    elif isinstance(value, str):
        ok = "str" in kinds
    elif isinstance(value, Mapping):
        ok = "dict" in kinds
        value = dict(value)
    else:
        ok = False
    if not ok:
        wanted = " or ".join(k for k in kinds if k != "None")
        raise ParameterError(f"{source}: {key} = {value!r} must be a {wanted}")
    return value


# --- writing --------------------------------------------------------------------------------
def config_toml(config: CaseConfig | None = None) -> str:
    """``config`` (default: the defaults) as TOML, every key with its unit and meaning.

    Settings without a value (``None``: "unset") are written as comments, so that
    reading the text back (:func:`load_config`) gives ``config`` again.
    """
    config = CaseConfig() if config is None else config
    data = config.to_dict()
    lines = [
        "# valve-dolfinx case configuration: every setting with its unit and meaning.",
        "# Run it with `valve-dolfinx run --config FILE`; keys left out keep their defaults;",
        "# `--set table.key=value` overrides one key.  A dimensional key ends in its unit.",
    ]
    for table, (meaning, _) in LAYOUT.items():
        lines += ["", f"[{table}]  # {meaning}"]
        lines += [_toml_line(key, get_dotted(data, key)) for key in _KEYS
                  if key.rpartition(".")[0] == table]
    return "\n".join(lines) + "\n"


def _toml_line(key: str, value: Any) -> str:
    unit, meaning = describe(key)
    comment = f"# {unit}; {meaning}" if unit else f"# {meaning}"
    name = key.rpartition(".")[2]
    if value is None:
        return f"# {name} = (unset)  {comment}"
    return f"{name} = {_toml_value(value)}  {comment}"


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)  # inf, -inf and nan are TOML too
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, Mapping):
        items = ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items())
        return "{ " + items + " }" if items else "{}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise ParameterError(f"cannot write {value!r} ({type(value).__name__}) to TOML")


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def write_config(path: str | Path, config: CaseConfig) -> Path:
    """Write ``config`` as commented TOML to ``path``, atomically (reloadable with --config)."""
    text = config_toml(config)
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


# --- identity of the settings ---------------------------------------------------------------
def canonical_hash(data: Any) -> str:
    """SHA-256 of ``data`` as canonical JSON (sorted keys, NaN/infinity as null)."""
    text = json.dumps(_canonical(data), sort_keys=True, separators=(",", ":"),
                      allow_nan=False, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _canonical(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_canonical(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if hasattr(value, "item") and callable(value.item):  # NumPy scalars
        return _canonical(value.item())
    return value


def settings_hash(config: Mapping[str, Any]) -> str:
    """SHA-256 of the settings that determine a result, from the :meth:`CaseConfig.to_dict`
    layout (keys that are not settings, such as ``result.json``'s ``root_state``, are
    ignored).

    Every physical and numerical setting enters it, and :data:`ANALYSIS_VERSION`; the
    wall-clock limit (:data:`WALL_CLOCK_KEY`) does not (it decides whether a run finishes,
    not where it lands).  Integers count as the equal real numbers.  Output paths, figures
    and logging are not part of a :class:`CaseConfig`.
    """
    data: dict = {}
    for key in setting_keys(config):
        if key in _KEYS and key != WALL_CLOCK_KEY:
            set_dotted(data, key, _as_float(get_dotted(config, key)))
    data["analysis_version"] = ANALYSIS_VERSION
    return canonical_hash(data)


def wall_clock_limits(config: Mapping[str, Any]) -> dict[str, float | None]:
    """The wall-clock limit (s) of a :meth:`CaseConfig.to_dict` layout, by key: the setting
    :func:`settings_hash` leaves out."""
    try:
        return {WALL_CLOCK_KEY: get_dotted(config, WALL_CLOCK_KEY)}
    except KeyError:
        return {WALL_CLOCK_KEY: None}


def _as_float(value: Any) -> Any:
    """Numbers as floats (21 and 21.0 are the same setting; a file may write either)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value
