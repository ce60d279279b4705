"""The configuration of one closure case: typed, validated, without DOLFINx.

:class:`CaseConfig` holds everything that defines a case: the valve geometry,
the pressure, the tissues, the root, the contact law, the solver path and its
numerical settings, and the analysis settings.  Numbers that every case takes alike are
not settings: they are constants of the module that uses them (each solver path's step
control, the contact's taper at the commissures, ...) or fields of a parameter set marked
:data:`NOT_A_SETTING`.  Every setting is a dataclass field declared with
:func:`~valve_dolfinx.setting_fields.setting`, which carries its unit and meaning: the
comments of :func:`config_toml`, :func:`describe` and the settings table of docs/outputs.md
(:func:`settings_table_markdown`) read them there.  Each nested parameter set
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
from dataclasses import asdict, dataclass, fields, replace
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
    is_graft_only,
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
#: settings that bound the run's wall-clock time, not its result (left out of settings_hash)
_WALL_CLOCK_KEYS = ("wall_time_limit_s",)

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
    setting's unit and meaning is on its field.

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

    geometry: ValveParameters = setting(default_factory=ValveParameters,
                                        meaning="the valve's geometry and mesh (SPEC §1)")
    pressure_mmhg: float = setting(80.0, "mmHg", "transvalvular diastolic pressure on the "
                                   "aortic side")
    native_material: FungMaterial = setting(NATIVE_LEAFLET, "", "the native leaflets' tissue "
                                            "(Fung law, SPEC §3)")
    graft_material: FungMaterial = setting(BOVINE_PERICARDIUM, "", "the graft's tissue (Fung "
                                           "law, SPEC §3)", graft_only=True)
    root: RootParameters = setting(default_factory=RootParameters,
                                   meaning="the aortic root's wall (SPEC §2)")
    contact: ContactParameters = setting(default_factory=ContactParameters,
                                         meaning="the contact law (SPEC §5)")
    solver: str = setting("ptc", "", "path to the loaded equilibrium: 'ptc' (pseudo-transient "
                          "continuation, the default) or 'bdf2' (damped BDF2 dynamics, the "
                          "cross-check)")
    pseudo_transient: PseudoTransientParameters = setting(
        default_factory=PseudoTransientParameters,
        meaning="numerics of the pseudo-transient continuation (solver = 'ptc')")
    dynamics: DynamicsParameters = setting(
        default_factory=DynamicsParameters,
        meaning="numerics of the damped BDF2 dynamics (solver = 'bdf2')")
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
                                               "pure membrane)", graft_only=True)
    graft_tension_field: bool = setting(True, "", "how the graft carries compression: true, "
                                        "the tension-field relaxed energy (it wrinkles); "
                                        "false, the plain Fung law (it resists compression "
                                        "in-plane)", graft_only=True)

    def __post_init__(self) -> None:
        check_setting(self, "pressure_mmhg", 0.0, 300.0, low_open=True,
                      hint="diastolic aortic pressure is about 80 mmHg")
        check_setting(self, "coaptation_threshold_mm", 0.0, 5.0, low_open=True)
        check_setting(self, "bending_modulus_kpa", 0.0, 1e5,
                      hint="0 switches the native leaflets' bending off; they are of order "
                      "100-1000 kPa in flexure")
        check_setting(self, "graft_bending_modulus_kpa", 0.0, 1e5,
                      low_hint="0 switches the graft's bending off",
                      high_hint="that is beyond even the in-plane tensile modulus of fixed "
                      "pericardium (tens of MPa)")
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
        """The settings, nested by section (a parameter set's fields that are not settings,
        :data:`NOT_A_SETTING`, are left out)."""
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            out[f.name] = _settings_of(value) if f.name in _SECTIONS else value
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
        """This configuration's normal valve: no graft, and every setting only a graft uses
        (:data:`GRAFT_ONLY_SETTINGS`) at its default, which the normal valve's result does
        not depend on."""
        defaults = CaseConfig().to_dict()
        data = self.with_graft(None, None).to_dict()
        for key in GRAFT_ONLY_SETTINGS:
            set_dotted(data, key, get_dotted(defaults, key))
        return config_from_dict(data, source="normal valve")


def _setting_names(section: Any) -> list[str]:
    """The settings of a parameter set (class or instance): its fields but those marked
    :data:`NOT_A_SETTING`."""
    return [f.name for f in fields(section) if is_setting(f)]


def _graft_only_settings() -> tuple[str, ...]:
    """The dotted keys of the settings declared ``graft_only`` (a top-level field that is a
    table covers all of it)."""
    keys = []
    for f in fields(CaseConfig):
        if is_graft_only(f):
            keys.append(f.name)
        elif f.name in _SECTIONS:
            keys += [f"{f.name}.{g.name}" for g in fields(_SECTIONS[f.name])
                     if is_setting(g) and is_graft_only(g)]
    return tuple(keys)


#: settings that only a graft uses, from their fields' ``graft_only`` flag (dotted keys; a
#: key that names a table covers all of it): the normal valve of a study takes them at their
#: defaults (:meth:`CaseConfig.normal_valve`), so normal valves that differ in graft settings
#: alone are one case
GRAFT_ONLY_SETTINGS = _graft_only_settings()


def _settings_of(section: Any) -> dict:
    values = asdict(section)
    return {name: values[name] for name in _setting_names(section)}


def case_name(geometry: ValveParameters) -> str:
    """``normal`` or ``W<width>_H<height>``: a case's name in a study before its axis values."""
    if not geometry.has_graft:
        return "normal"
    from valve_dolfinx.geometry.outline import GraftSize

    return GraftSize(geometry.graft_width_pct, geometry.graft_height_pct).stem


# --- meaning and unit of every setting ------------------------------------------------------
def describe(section: str, key: str) -> tuple[str, str]:
    """``(unit, meaning)`` of ``section.key`` (``section`` "" for a top-level key), from the
    field's metadata; KeyError for a key that is not a setting."""
    if section and section not in _SECTIONS:
        raise KeyError(f"{section!r} is not a table of the configuration")
    metadata = setting_field(_SECTIONS[section] if section else CaseConfig, key).metadata
    return metadata["unit"], metadata["meaning"]


#: the comments that enclose the generated settings table in docs/outputs.md
SETTINGS_TABLE_MARKERS = ("<!-- settings table: generated by "
                          "valve_dolfinx.config.write_settings_table -->",
                          "<!-- end of the settings table -->")


def settings_table_markdown() -> str:
    """Every setting, its default, unit and meaning as a Markdown table (the one in
    docs/outputs.md): the top-level keys, then each table's row and its keys as
    ``table.key``; a setting only a graft uses (:data:`GRAFT_ONLY_SETTINGS`) says so."""
    data = CaseConfig().to_dict()

    def row(section: str, key: str, default: str) -> str:
        unit, meaning = describe(section, key)
        name = f"{section}.{key}" if section else key
        if name in GRAFT_ONLY_SETTINGS:
            meaning += "; *graft only*"
        shown = f"`[{name}]`" if name in _SECTIONS else f"`{name}`"
        cells = (cell.replace("|", "\\|") for cell in (shown, default, unit, meaning))
        return "| " + " | ".join(cells) + " |"

    def default(value: Any) -> str:
        return "unset" if value is None else f"`{_toml_value(value)}`"

    rows = ["| key | default | unit | meaning |", "|---|---|---|---|"]
    rows += [row("", k, default(v)) for k, v in data.items() if k not in _SECTIONS]
    for name in _SECTIONS:
        rows.append(row("", name, ""))
        rows += [row(name, k, default(v)) for k, v in data[name].items()]
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
        ``"section.key=value"`` strings (``--set``); the value is read as a TOML value,
        or taken as a string if it is not one (``solver=bdf2``).
    values
        ``{"section.key": value}`` set last (the command line's named flags).

    Raises
    ------
    ParameterError
        On an unknown key, a value of the wrong type or out of its range (the message
        names the key, ``section.key``), or a file that is not TOML.
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
    """Set each ``"section.key=value"`` of ``overrides`` in the nested ``data`` (in place)."""
    for text in overrides:
        key, sep, raw = text.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ParameterError(f"--set {text!r}: give section.key=value, e.g. "
                                 "--set pressure_mmhg=100 or --set geometry.mesh_size=1.6")
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
    """The dotted keys of the settings in ``data`` (the :meth:`CaseConfig.to_dict` layout,
    any subset): ``pressure_mmhg``, ``root.loaded_diameter``, ..."""
    keys = []
    for key, value in data.items():
        if key in _SECTIONS and isinstance(value, Mapping):
            keys += [f"{key}.{name}" for name in value]
        else:
            keys.append(key)
    return keys


def config_from_dict(data: Mapping[str, Any], source: str = "configuration") -> CaseConfig:
    """A validated :class:`CaseConfig` from (part of) the :meth:`CaseConfig.to_dict` layout.

    Keys left out keep their defaults (a table given in part keeps the rest of its
    defaults).  Integers are accepted for real-valued settings.

    Raises
    ------
    ParameterError
        Naming ``source`` and the dotted key: an unknown key, a value of the wrong
        type, or a value outside its range.
    """
    defaults = CaseConfig()
    known = {f.name: f for f in fields(CaseConfig)}
    unknown = _unknown_keys(data, defaults)
    if unknown:
        raise ParameterError(f"{source}: {_unknown_message(unknown)}")
    kw: dict[str, Any] = {}
    for key, value in data.items():
        if key in _SECTIONS:
            kw[key] = _section(key, value, getattr(defaults, key), source)
        else:
            kw[key] = _checked_value(key, value, known[key].type, source)
    try:
        return replace(defaults, **kw)
    except ParameterError as err:
        raise ParameterError(f"{source}: {err}") from None


def _section(name: str, value: Any, default: Any, source: str) -> Any:
    """The parameter set ``name`` with the keys of ``value`` changed from ``default``."""
    if isinstance(value, type(default)):
        return value
    if not isinstance(value, Mapping):
        raise ParameterError(f"{source}: {name} must be a table of settings "
                             f"([{name}] in a TOML file), got {value!r}")
    known = {f.name: f for f in fields(default) if f.name in _setting_names(default)}
    changes = {}
    for key, item in value.items():
        changes[key] = _checked_value(f"{name}.{key}", item, known[key].type, source)
    try:
        return replace(default, **changes)
    except ParameterError as err:
        raise ParameterError(f"{source}: {_dotted_message(name, known, str(err))}") from None


def _unknown_keys(data: Mapping[str, Any], defaults: CaseConfig
                  ) -> list[tuple[str, str, list[str]]]:
    """Every key of ``data`` that is not a setting: ``(dotted key, the number every case takes
    if it is a fixed number of its parameter set (else ""), the settings of its table)``."""
    top = [f.name for f in fields(CaseConfig)]
    unknown = [(key, "", sorted(top)) for key in data if key not in top]
    for name in _SECTIONS:
        value, default = data.get(name), getattr(defaults, name)
        if not isinstance(value, Mapping):
            continue
        settings = _setting_names(default)
        for key in value:
            if key not in settings:
                fixed = getattr(default, key, None)
                fixed = (f" (every case takes {fixed!r})" if isinstance(fixed, int | float)
                         and not isinstance(fixed, bool) else "")
                unknown.append((f"{name}.{key}", fixed, settings))
    return unknown


def _unknown_message(unknown: list[tuple[str, str, list[str]]]) -> str:
    """What the keys that are not settings are, and the fix: a file of an earlier version
    can hold many (all are named at once)."""
    named = ", ".join(f"{key!r}{fixed}" for key, fixed, _ in unknown)
    earlier = ("(a file written by an earlier version may hold keys that are now fixed "
               "numbers of the model or were removed)")
    if len(unknown) > 1:
        return (f"unknown keys {named}; they are not settings of this version {earlier}: "
                "delete those lines (`valve-dolfinx config` prints every setting)")
    key, _, settings = unknown[0]
    table = f" of [{key.split('.')[0]}]" if "." in key else ""
    return (f"unknown key {named}; it is not a setting of this version {earlier}: delete the "
            f"line; allowed keys{table} are {', '.join(settings)}")


def _dotted_message(section: str, keys: Iterable[str], message: str) -> str:
    """A parameter set's range message with the key spelled ``section.key``."""
    match = re.match(r"(?:\w+\.)?(\w+)( = .*)", message, re.DOTALL)
    if match and match.group(1) in keys:
        return f"{section}.{match.group(1)}{match.group(2)}"
    return f"[{section}] {message}"


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
        "# `--set section.key=value` overrides one key.",
        "",
    ]
    lines += [_toml_line("", k, v) for k, v in data.items() if k not in _SECTIONS]
    for name in _SECTIONS:
        lines += ["", f"[{name}]"]
        lines += [_toml_line(name, k, v) for k, v in data[name].items()]
    return "\n".join(lines) + "\n"


def _toml_line(section: str, key: str, value: Any) -> str:
    unit, meaning = describe(section, key)
    comment = f"# {unit}; {meaning}" if unit else f"# {meaning}"
    if value is None:
        return f"# {key} = (unset)  {comment}"
    return f"{key} = {_toml_value(value)}  {comment}"


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
    layout (other keys, such as ``result.json``'s ``root_state``, are ignored).

    Every physical and numerical setting enters it, and :data:`ANALYSIS_VERSION`; the
    wall-clock limits do not (they decide whether a run finishes, not where it lands).
    Integers count as the equal real numbers.  Output paths, figures and logging are not
    part of a :class:`CaseConfig`.
    """
    names = {f.name for f in fields(CaseConfig)}
    data = {}
    for key, value in config.items():
        if key not in names:
            continue
        if isinstance(value, Mapping):
            value = {k: _as_float(v) for k, v in value.items() if k not in _WALL_CLOCK_KEYS}
        data[key] = _as_float(value)
    data["analysis_version"] = ANALYSIS_VERSION
    return canonical_hash(data)


def wall_clock_limits(config: Mapping[str, Any]) -> dict[str, float]:
    """The wall-clock limits (s) of a :meth:`CaseConfig.to_dict` layout, by section: the
    settings :func:`settings_hash` leaves out."""
    return {f"{section}.{key}": float(values[key])
            for section, values in config.items() if isinstance(values, Mapping)
            for key in _WALL_CLOCK_KEYS if key in values}


def _as_float(value: Any) -> Any:
    """Numbers as floats (21 and 21.0 are the same setting; a file may write either)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value
