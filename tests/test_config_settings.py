"""Each setting is defined once, on its dataclass field, with its unit and meaning: what
`valve-dolfinx config`, the range checks, the graft-only settings and docs/outputs.md's
settings table read from it.  Nothing here computes a case."""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import pytest

from valve_dolfinx.config import (
    GRAFT_ONLY_SETTINGS,
    SETTINGS_TABLE_MARKERS,
    CaseConfig,
    config_toml,
    describe,
    get_dotted,
    load_config,
    setting_keys,
    settings_table_markdown,
    write_settings_table,
)
from valve_dolfinx.exceptions import ConfigurationError, ParameterError
from valve_dolfinx.setting_fields import setting, setting_field

DOCS = Path(__file__).resolve().parents[1] / "docs" / "outputs.md"

#: ``settings_hash`` of two configurations, computed before the settings carried their unit
#: and meaning on their fields: the identities of stored results must not move.  (Raising
#: ``ANALYSIS_VERSION`` changes every identity on purpose: then update these.)
PINNED_HASHES = {
    "default": "599763696d770096765342f84d3bc54209509c653c5525dbaff746bfe58e40f6",
    "W21_H27": "1d44d6a37a65ab4af29328ec91c1c53e04b0bcb9b42d46e9a4c04585975d3ff2",
}


def _every_setting() -> list[tuple[str, str]]:
    """``(section, key)`` of every setting of the default configuration ("" = top level)."""
    return [tuple(k.split(".")) if "." in k else ("", k)
            for k in setting_keys(CaseConfig().to_dict())]


def _table_rows(text: str) -> dict[str, list[str]]:
    """The rows of a settings table by key (backticks and brackets stripped)."""
    rows = {}
    for line in text.splitlines()[2:]:
        cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
        rows[cells[0].strip("`[]")] = cells
    return rows


# --- the case identity -------------------------------------------------------------------------
def test_settings_hash_of_existing_cases_is_unchanged():
    assert CaseConfig().settings_hash() == PINNED_HASHES["default"]
    assert CaseConfig().with_graft(21.0, 27.0).settings_hash() == PINNED_HASHES["W21_H27"]


@pytest.mark.parametrize("argv", [
    [],
    ["--set", "geometry.graft_width_pct=21", "--set", "geometry.graft_height_pct=27",
     "--set", "graft_tension_field=false", "--set", "root.loaded_diameter=21.5",
     "--set", "pseudo_transient.petsc_options={ ksp_type = \"preonly\", snes_max_it = 7 }",
     "--set", "native_material.A5=0", "--set", "solver=bdf2"],
])
def test_cli_config_round_trips(tmp_path, capsys, argv):
    """`valve-dolfinx config` written to a file and read back: the same settings, the same
    case identity, and writing it again gives the same text."""
    from valve_dolfinx.cli import main

    assert main(["config", *argv]) == 0
    text = capsys.readouterr().out
    (tmp_path / "case.toml").write_text(text)
    again = load_config(tmp_path / "case.toml")
    overrides = [argv[i + 1] for i in range(0, len(argv), 2)]
    wanted = load_config(overrides=overrides)
    assert again.to_dict() == wanted.to_dict()
    assert again.settings_hash() == wanted.settings_hash()
    assert config_toml(again) == text
    if argv:
        assert again.geometry.graft_width_pct == 21.0 and again.graft_tension_field is False
        assert again.pseudo_transient.petsc_options == {"ksp_type": "preonly", "snes_max_it": 7}
        assert again.settings_hash() != CaseConfig().settings_hash()


# --- unit and meaning on the field -------------------------------------------------------------
def test_every_setting_field_carries_its_unit_and_meaning():
    settings = _every_setting()
    assert len(settings) == 52  # 8 top-level, 9 geometry, 2 x 8 material, 4 root, 6 contact,
    #                             6 pseudo-transient, 3 dynamics
    for section, key in settings:
        unit, meaning = describe(section, key)
        assert isinstance(unit, str) and len(meaning) > 10, (section, key)
    # the tables themselves are fields of CaseConfig with a meaning
    for f in fields(CaseConfig):
        assert describe("", f.name)[1]


def test_a_setting_without_its_meaning_is_refused():
    with pytest.raises(TypeError, match="meaning"):
        setting(1.0, "mm")

    @dataclass
    class Section:
        declared: float = setting(1.0, "mm", "a length")
        bare: float = 2.0

    assert setting_field(Section, "declared").metadata["unit"] == "mm"
    with pytest.raises(KeyError, match="Section.bare is a setting without its unit"):
        setting_field(Section, "bare")


def test_fixed_numbers_have_no_description():
    """A field that is not a setting (the contact law's taper, a material's name) is
    described nowhere: describe refuses it like an unknown key."""
    for section, key in [("contact", "taper"), ("native_material", "name"), ("", "nosuch"),
                         ("nosuch", "c")]:
        with pytest.raises(KeyError):
            describe(section, key)


@pytest.mark.parametrize("key,value", [
    ("pressure_mmhg", 900.0),
    ("geometry.billow_mm", 50.0),
    ("graft_material.thickness", 9.0),
    ("root.youngs_modulus", 0.5),
    ("contact.guard_stiffness", -1.0),
    ("pseudo_transient.residual_tolerance", 0.0),
    ("dynamics.stop_increment_mm", 2.0),
])
def test_a_range_message_gives_the_unit_of_the_field(key, value):
    section, _, name = key.rpartition(".")
    unit = describe(section, name)[0]
    with pytest.raises(ParameterError) as err:
        load_config(values={key: value})
    assert f"{key} = {value!r}" in str(err.value)
    assert f"] {unit}" in str(err.value)


# --- graft-only settings -----------------------------------------------------------------------
def test_graft_only_settings_follow_from_the_fields():
    assert set(GRAFT_ONLY_SETTINGS) == {
        "graft_material", "graft_bending_modulus_kpa", "graft_tension_field",
        "geometry.graft_fibre_angle_deg", "geometry.graft_placement", "geometry.billow_mm"}
    changed = load_config(overrides=[
        "geometry.graft_width_pct=14", "geometry.graft_height_pct=13",
        "graft_material.c=100", "graft_bending_modulus_kpa=50", "graft_tension_field=false",
        "geometry.graft_fibre_angle_deg=30", "geometry.graft_placement=billowed",
        "geometry.billow_mm=-1", "bending_modulus_kpa=300", "native_material.thickness=0.4"])
    normal = changed.normal_valve()
    defaults = CaseConfig().to_dict()
    for key in GRAFT_ONLY_SETTINGS:  # back at the default: the normal valve does not use it
        assert get_dotted(normal.to_dict(), key) == get_dotted(defaults, key), key
    assert not normal.geometry.has_graft
    # settings the native leaflets use are the configuration's own
    assert normal.bending_modulus_kpa == 300.0 and normal.native_material.thickness == 0.4


# --- the settings table of docs/outputs.md -----------------------------------------------------
def test_the_table_lists_every_setting_with_its_field_description():
    rows = _table_rows(settings_table_markdown())
    for section, key in _every_setting():
        name = f"{section}.{key}" if section else key
        unit, meaning = describe(section, key)
        _, default, unit_cell, meaning_cell = rows.pop(name)
        assert unit_cell == unit and meaning_cell.startswith(meaning)
        assert meaning_cell.endswith("*graft only*") == (name in GRAFT_ONLY_SETTINGS)
    # what is left: one row per table, with the table's meaning
    tables = {k for k, v in CaseConfig().to_dict().items() if isinstance(v, dict)}
    assert set(rows) == tables
    assert all(rows[t][3].startswith(describe("", t)[1]) for t in tables)
    table = _table_rows(settings_table_markdown())
    assert table["geometry.mesh_size"][1:3] == ["`0.8`", "mm"]
    assert table["graft_material.c"][1:3] == ["`3056.0`", "kPa"]
    assert table["root.loaded_diameter"][1] == "unset"
    assert table["graft_material"][3].endswith("*graft only*")


def test_the_documented_settings_table_is_the_code_s():
    begin, end = SETTINGS_TABLE_MARKERS
    text = DOCS.read_text(encoding="utf-8")
    assert text.count(begin) == 1 and text.count(end) == 1
    documented = text.split(begin + "\n")[1].split(end)[0]
    assert documented == settings_table_markdown(), (
        "docs/outputs.md's settings table differs from the settings' fields: run "
        ".venv/bin/python -c \"from valve_dolfinx.config import write_settings_table; "
        "write_settings_table('docs/outputs.md')\"")


def test_write_settings_table_replaces_a_stale_table(tmp_path):
    begin, end = SETTINGS_TABLE_MARKERS
    path = tmp_path / "doc.md"
    stale = f"# Doc\n\nbefore\n\n{begin}\n| key | old |\n{end}\n\nafter\n"
    path.write_text(stale)
    assert write_settings_table(path) is True
    text = path.read_text()
    assert text == f"# Doc\n\nbefore\n\n{begin}\n{settings_table_markdown()}{end}\n\nafter\n"
    assert write_settings_table(path) is False and path.read_text() == text
    path.write_text("# Doc without markers\n")
    with pytest.raises(ConfigurationError, match="markers"):
        write_settings_table(path)
