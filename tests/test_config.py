"""Configuration files, the public API and the run folder's guard.

One real closure runs here: the normal valve's symmetric reference on a 1.6 mm mesh
(about 20 s), from a TOML file through ``valve-dolfinx run --config``.  Everything
else reads or writes configurations, or stops before computing.
"""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from valve_dolfinx.config import (
    TABLES,
    CaseConfig,
    config_toml,
    load_config,
    setting_keys,
    settings_hash,
)
from valve_dolfinx.exceptions import ExitCode, ParameterError
from valve_dolfinx.geometry.valve import ValveParameters
from valve_dolfinx.mechanics.root import RootParameters
from valve_dolfinx.solvers.parameters import PseudoTransientParameters

#: the case the real run computes: cheap, and every file of a case is written
CASE_TOML = "[geometry]\nsymmetric_reference = true\nmesh_size_mm = 1.6\n"


def _errors(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]


def _must_not_run(monkeypatch) -> None:
    import valve_dolfinx.case as case

    def fail(*args, **kwargs):
        raise AssertionError("a case was computed")

    monkeypatch.setattr(case, "run_case", fail)


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


# --- writing and reading ----------------------------------------------------------------------
def test_printed_defaults_load_as_the_defaults(tmp_path, capsys):
    from valve_dolfinx.cli import main

    assert main(["config"]) == 0
    text = capsys.readouterr().out
    (tmp_path / "case.toml").write_text(text)
    assert load_config(tmp_path / "case.toml") == CaseConfig()
    settings = [line for line in text.splitlines() if line and not line.startswith(("#", "["))]
    unset = [line for line in text.splitlines() if line.startswith("# ") and " = (unset)" in line]
    # every setting written once (the unset ones as comments), with its unit and meaning
    assert len(settings) + len(unset) == len(setting_keys(CaseConfig().to_dict()))
    assert all("  # " in line for line in settings + unset)
    assert "pressure_mmhg = 80.0  # mmHg; " in text and "mesh_size_mm = 0.8  # mm; " in text


def test_a_changed_configuration_round_trips(tmp_path):
    """Every kind of value (unset, a graft, a PETSc option table, an integer for a real
    number) comes back equal through the written TOML."""
    config = CaseConfig(geometry=ValveParameters(mesh_size=1.6, graft_width_pct=21,
                                                 graft_height_pct=27.0),
                        root=RootParameters(loaded_diameter=21.5), pressure_mmhg=95.0,
                        pseudo_transient=PseudoTransientParameters(
                            petsc_options={"ksp_type": "preonly", "snes_max_it": 7}),
                        solver="bdf2")
    (tmp_path / "c.toml").write_text(config_toml(config))
    again = load_config(tmp_path / "c.toml")
    assert again == config and again.settings_hash() == config.settings_hash()
    assert isinstance(again.geometry.graft_width_pct, float)


def test_overrides_and_flags_apply_in_order(tmp_path):
    (tmp_path / "c.toml").write_text("[loading]\npressure_mmhg = 90\n[geometry]\n"
                                     "mesh_size_mm = 1.2\n")
    config = load_config(tmp_path / "c.toml", ["loading.pressure_mmhg=100", "solver.method=bdf2",
                                               "root.loaded_diameter_mm=none"],
                         {"geometry.mesh_size_mm": 1.6})
    assert config.pressure_mmhg == 100.0 and config.solver == "bdf2"
    assert config.geometry.mesh_size == 1.6 and config.root.loaded_diameter is None
    assert config.native_material == CaseConfig().native_material  # the rest: defaults


@pytest.mark.parametrize("text,named", [
    ("pressure = 80\n", "unknown key 'pressure'"),
    ("[geometry]\nmesh_sise = 1.0\n", "unknown key 'geometry.mesh_sise'"),
    ("[study]\n[contact]\nstifness = 3\n", "unknown key 'contact.stifness'"),
    ("[loading]\npressure_mmhg = 900\n", "loading.pressure_mmhg = 900"),
    ("[geometry]\nmesh_size_mm = 40\n", "geometry.mesh_size_mm = 40"),
    ("[graft.material]\nc_kpa = -1\n", "graft.material.c_kpa = -1"),
    ("[graft]\nbending_modulus_kpa = -1\n", "graft.bending_modulus_kpa = -1"),
    ("[root]\nloaded_diameter_mm = 5\n", "root.loaded_diameter_mm = 5"),
    ("[solver.pseudo_transient]\nresidual_tolerance_mn = 0\n",
     "solver.pseudo_transient.residual_tolerance_mn = 0"),
    ("[solver.pseudo_transient]\nmax_steps = \"many\"\n",
     "solver.pseudo_transient.max_steps = 'many' must be a int"),
    ("[solver]\nmethod = \"newton\"\n", "solver.method = 'newton' is not one of"),
    ("[solver]\nwall_time_limit_s = 0\n", "solver.wall_time_limit_s = 0"),
    ("geometry = 3\n", "geometry must be a table"),
    ("[loading]\npressure_mmhg = \n", "is not valid TOML"),
])
def test_bad_file_names_the_key(tmp_path, text, named):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ParameterError) as err:
        load_config(path)
    assert named in str(err.value) and str(path) in str(err.value)


@pytest.mark.parametrize("text,named", [
    ("[contact]\ntaper = 0.5\n", "unknown key 'contact.taper' (every case takes 0.5)"),
    ("[native.material]\nname = \"native_leaflet\"\n", "unknown key 'native.material.name'"),
    ("[solver.pseudo_transient]\ndt_initial = 0.05\n",
     "unknown key 'solver.pseudo_transient.dt_initial'"),
    ("quadrature_degree = 1\n", "unknown key 'quadrature_degree'"),
])
def test_a_key_an_earlier_version_wrote_is_refused_with_the_fix(tmp_path, text, named):
    """A config.toml of an earlier version holds settings since fixed or removed: the error
    names the key, the number every case takes where it is fixed, and says to delete the
    line."""
    path = tmp_path / "old.toml"
    path.write_text(text)
    with pytest.raises(ParameterError) as err:
        load_config(path)
    assert named in str(err.value)
    assert "not a setting of this version" in str(err.value)
    assert "delete the line" in str(err.value)


def test_every_key_an_earlier_version_wrote_is_named_at_once(tmp_path):
    """The whole configuration an earlier version wrote: one error names every key that is
    not a setting now, so that one edit fixes the file."""
    text = config_toml().replace("\nstiffness_mn_per_mm",
                                 "\ntaper = 0.5\npairing = \"two_pass\"\nstiffness_mn_per_mm")
    path = tmp_path / "old.toml"
    path.write_text("quadrature_degree = 1\n" + text)
    with pytest.raises(ParameterError) as err:
        load_config(path)
    assert ("unknown keys 'quadrature_degree', 'contact.taper' (every case takes 0.5), "
            "'contact.pairing'; they are not settings") in str(err.value)
    assert "delete those lines" in str(err.value)


def test_cli_bad_configuration_stops_before_computing(tmp_path, caplog, monkeypatch):
    from valve_dolfinx.cli import main

    _must_not_run(monkeypatch)
    path = tmp_path / "bad.toml"
    path.write_text("[graft]\nwidth_pct = 500\nheight_pct = 0\n")
    assert main(["run", "--config", str(path), "--out", str(tmp_path / "out")]) == 2
    (err,) = _errors(caplog)
    assert "graft.width_pct = 500" in err and "\n" not in err
    assert main(["run", "--set", "nosuch.key=1", "--out", str(tmp_path / "out")]) == 2
    assert "unknown key 'nosuch'" in _errors(caplog)[-1]
    assert main(["run", "--set", "loading.pressure_mmhg", "--out", str(tmp_path / "out")]) == 2
    assert "table.key=value" in _errors(caplog)[-1]
    assert not (tmp_path / "out").exists()


def test_settings_hash_is_the_physics_and_numerics():
    base = CaseConfig()
    timed = replace(base, wall_time_limit_s=5.0)
    assert timed.settings_hash() == base.settings_hash()  # a wall-clock limit is not physics
    assert replace(base, pressure_mmhg=81.0).settings_hash() != base.settings_hash()
    mesh = replace(base, geometry=replace(base.geometry, mesh_size=1.6))
    assert mesh.settings_hash() != base.settings_hash()
    # result.json's parameters (the configuration plus the root state) hash the same
    assert settings_hash({**base.to_dict(), "root_state": {"diameter": 20.1}}) == \
        base.settings_hash()


def test_a_case_analysed_under_an_earlier_rule_is_another_identity(monkeypatch):
    """A result judged by an earlier analysis (e.g. before the intersection check decided
    competence) must not be resumed or reported as today's: the analysis version is part
    of the settings hash."""
    import valve_dolfinx.config as config_module

    today = CaseConfig().settings_hash()
    monkeypatch.setattr(config_module, "ANALYSIS_VERSION", config_module.ANALYSIS_VERSION - 1)
    assert CaseConfig().settings_hash() != today


# --- the package -------------------------------------------------------------------------------
def _python(code: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter from the repository root; it must succeed."""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=Path(__file__).resolve().parents[1])
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


def test_import_is_light_and_the_api_is_complete():
    code = ("import sys, valve_dolfinx as vd\n"
            "heavy = [m for m in ('dolfinx', 'petsc4py', 'matplotlib', 'pyvista', 'gmsh') "
            "if m in sys.modules]\n"
            "assert not heavy, heavy\n"
            "vd.CaseConfig(); vd.load_config; vd.load_case; vd.build_valve\n"
            "heavy = [m for m in ('dolfinx', 'petsc4py', 'matplotlib', 'pyvista') "
            "if m in sys.modules]\n"
            "assert not heavy, heavy\n"
            "assert all(callable(getattr(vd, n)) for n in vd.__all__ if n != '__version__')\n"
            "print(vd.__version__)\n")
    proc = _python(code)
    import valve_dolfinx

    assert proc.stdout.strip() == valve_dolfinx.__version__
    assert {"build_valve", "CaseConfig", "load_config", "run_case", "run_sweep",
            "load_case", "PatientInput", "read_patient", "run_plan"} <= set(valve_dolfinx.__all__)


def test_cli_version(capsys):
    import valve_dolfinx
    from valve_dolfinx.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"valve-dolfinx {valve_dolfinx.__version__}"


def test_config_needs_no_dolfinx():
    code = ("import sys\n"
            "from valve_dolfinx.config import load_config, config_toml\n"
            "config_toml(load_config(overrides=['loading.pressure_mmhg=90']))\n"
            "assert not {'dolfinx', 'petsc4py', 'gmsh'} & set(sys.modules)\n")
    _python(code)


# --- a run from a configuration file -----------------------------------------------------------
@pytest.fixture(scope="module")
def case_run(tmp_path_factory):
    """``valve-dolfinx run --config case.toml`` of the 1.6 mm symmetric reference (no
    figures: no test here looks at them)."""
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.cli import main

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial fixture")
    folder = tmp_path_factory.mktemp("config_run")
    (folder / "case.toml").write_text(CASE_TOML)
    out = folder / "case"
    code = main(["run", "--config", str(folder / "case.toml"), "--out", str(out),
                 "--no-figures"])
    return code, folder, out


def test_run_writes_the_resolved_configuration(case_run):
    code, folder, out = case_run
    assert code == 0
    data = json.loads((out / "result.json").read_text())
    written = load_config(out / "config.toml")
    assert written == load_config(folder / "case.toml")
    assert written.settings_hash() == data["settings_hash"]
    assert written.geometry.mesh_size == data["mesh_size_mm"] == 1.6
    import valve_dolfinx

    assert data["version"] == valve_dolfinx.__version__
    assert data["git_commit"] is None or len(data["git_commit"]) == 40
    # every setting is written, not only those the file gave
    assert "[solver.dynamics]" in (out / "config.toml").read_text()
    assert set(TABLES) - {"native.material", "graft.material", "solver.pseudo_transient",
                          "solver.dynamics"} <= set(data["parameters"])
    assert setting_keys(CaseConfig().to_dict()) == [
        k for k in setting_keys(data["parameters"]) if k.split(".")[0] in TABLES]


def test_the_written_configuration_is_this_case(case_run, capsys):
    """Run again from the written config.toml into the same folder: the same settings, so
    the stored result is this case's (not recomputed)."""
    from valve_dolfinx.cli import main

    _, _, out = case_run
    before = _tree(out)
    assert main(["run", "--config", str(out / "config.toml"), "--out", str(out)]) == 0
    assert "already holds this case" in capsys.readouterr().out
    assert _tree(out) == before


def test_another_case_never_overwrites_a_result(case_run, caplog, monkeypatch):
    from valve_dolfinx.cli import main

    _must_not_run(monkeypatch)
    _, _, out = case_run
    before = _tree(out)
    for argv in (["--set", "loading.pressure_mmhg=100"], ["--config", str(out / "config.toml"),
                                                  "--mesh-size", "2.0"]):
        caplog.clear()
        assert main(["run", *argv, "--out", str(out)]) == ExitCode.OUTPUT_CONFLICT
        (err,) = _errors(caplog)
        assert f"--out {out}" in err and "--force" in err and "\n" not in err
    assert _tree(out) == before


def test_out_that_is_a_file_stops_at_once(tmp_path, caplog, monkeypatch):
    from valve_dolfinx.cli import main

    _must_not_run(monkeypatch)
    target = tmp_path / "result.txt"
    target.write_text("keep me")
    assert main(["run", "--out", str(target)]) == ExitCode.OUTPUT_NOT_FOLDER
    (err,) = _errors(caplog)
    assert f"--out {target} is a file" in err and "\n" not in err
    assert target.read_text() == "keep me"


def test_changed_pressure_in_the_file_changes_the_result(case_run, tmp_path):
    """100 instead of 80 mmHg in the file: the root (step 1, solved before the closure)
    distends further.  One pseudo-time step of the closure is enough to see it."""
    from valve_dolfinx.cli import main

    _, folder, out = case_run
    text = (out / "config.toml").read_text()
    assert "pressure_mmhg = 80.0" in text
    path = tmp_path / "higher.toml"
    path.write_text(text.replace("pressure_mmhg = 80.0", "pressure_mmhg = 100.0")
                    .replace("max_steps = 4000", "max_steps = 1"))
    assert main(["run", "--config", str(path), "--out", str(tmp_path / "higher"),
                 "--no-figures"]) == 3
    low = json.loads((out / "result.json").read_text())
    high = json.loads((tmp_path / "higher" / "result.json").read_text())
    assert high["parameters"]["loading"]["pressure_mmhg"] == 100.0
    assert high["root_diameter_mm"] > low["root_diameter_mm"] + 0.01
    assert high["settings_hash"] != low["settings_hash"]


def test_load_case_gives_the_surface_to_draw(case_run):
    import numpy as np

    from valve_dolfinx import load_case

    _, _, out = case_run
    case = load_case(out)
    data = json.loads((out / "result.json").read_text())
    assert case.result.central_coaptation_height_mm == data["central_coaptation_height_mm"]
    assert case.config == load_config(out / "config.toml")
    # the symmetric reference is drawn as the solved leaflet and its two mirror images
    assert len(case.valve.leaflets) == 3 and case.positions.shape == (case.valve.num_nodes, 3)
    with np.load(out / "loaded_state.npz") as written:
        n = len(written["positions"])
        assert np.array_equal(case.positions[:n], written["positions"])
    with pytest.raises(FileNotFoundError, match="not a finished case folder"):
        load_case(out.parent)


# --- the defaults the command line states ------------------------------------------------------
def _option_help(command: str, option: str) -> str:
    """The help text of ``option`` of ``valve-dolfinx command`` (as written, unwrapped)."""
    import argparse

    from valve_dolfinx.cli import _parser

    sub = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))
    return next(a.help for a in sub.choices[command]._actions if option in a.option_strings)


def test_the_help_states_the_code_defaults():
    """The parser imports nothing heavy (``--help`` and a bad flag answer at once), so the
    defaults its help states are spelt out there: each is the one the code uses."""
    from valve_dolfinx.plan.patient import DEFAULT_LEAFLET, PatientInput
    from valve_dolfinx.solvers.parameters import PseudoTransientParameters
    from valve_dolfinx.study.grid import (
        ADAPTIVE_BUDGET,
        STUDY_HEIGHTS_PCT,
        STUDY_WIDTHS_PCT,
        StudySettings,
    )

    def spelt(values) -> str:
        return " ".join(f"{v:g}" for v in values)

    patient = PatientInput(root_diameter_mm=21.0)
    expected = {
        ("sweep", "--widths"): f"(default {spelt(STUDY_WIDTHS_PCT)})",
        ("sweep", "--heights"): f"(default {spelt(STUDY_HEIGHTS_PCT)})",
        ("sweep", "--budget"): f"(default {ADAPTIVE_BUDGET})",
        ("sweep", "--ranks-per-case"): f"(default {StudySettings().ranks_per_case})",
        ("plan", "--budget"): f"(default {patient.budget})",
        ("plan", "--root-uncertainty"): f"(default {patient.root_uncertainty_mm:g})",
        ("plan", "--leaflet-free-edge"): f"{DEFAULT_LEAFLET.free_edge_length:.2f} mm)",
        ("plan", "--leaflet-height"): f"(default {DEFAULT_LEAFLET.height:.2f})",
        ("plan", "--pressure"): f"(default {patient.pressure_mmhg:g})",
        ("plan", "--graft-fibre-angle"): f"(default {patient.graft_fibre_angle_deg:g}:",
        ("plan", "--paths"): f"(default {patient.paths})",
        ("run", "--wall-time-limit"): f"{PseudoTransientParameters().wall_time_limit_s:g} s)",
    }
    for (command, option), text in expected.items():
        assert text in _option_help(command, option), (command, option, text)
    assert patient.graft_widths_pct == STUDY_WIDTHS_PCT
