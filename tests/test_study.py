"""The graft sizing study (SPEC §7): grid validation, resumable sweeps, MPI, job arrays, report.

Most tests run a fast stand-in for the case function (:func:`stand_in_case`, a
deterministic function of the graft size that sleeps a little and writes
stand-in pictures), so that killing, resuming and spreading a sweep over ranks
take seconds; ``test_real_case_through_the_sweep`` runs ``run_case`` itself
on one coarse case.  Run as a script, this file is the ``valve-dolfinx`` CLI
with the stand-in case function (the subprocess tests use it that way).
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
THIS = Path(__file__).resolve()
BIN = Path(sys.executable).parent
#: fields that may differ between two computations of the same case
VOLATILE = ("wall_time_s", "n_ranks", "started_at", "finished_at", "elapsed_s", "pid", "host")
SMALL_GRID = ["--widths", "0", "7", "--heights", "0"]


# --- the stand-in case function --------------------------------------------------------------
def _picture(path: Path, seed: float) -> None:
    import matplotlib.image
    import numpy as np

    y, x = np.mgrid[0:60, 0:90] / 60.0
    matplotlib.image.imsave(path, np.sin(6 * x + seed) * np.cos(4 * y), cmap="viridis")


def _loaded_state(path: Path, nodes: int) -> None:
    """A loaded_state.npz of ``nodes`` nodes (the arrays run_case writes, stand-in values)."""
    import numpy as np

    points = np.arange(3.0 * nodes).reshape(nodes, 3)
    np.savez_compressed(path, positions=points + 1.0, reference=points,
                        cells=np.array([[0, 1, 2]]), cell_tags=np.array([1]),
                        contact_forces=np.zeros((nodes, 3)))


def stand_in_case(config, out_dir: Path, comm, *, start: Path | None = None) -> dict:
    """A case result that depends on the graft size only, written like ``run_case`` writes."""
    g = config.geometry
    w, h = g.graft_width_pct, g.graft_height_pct
    assert comm.allreduce(1) == comm.size  # the case's own communicator works
    log = os.environ.get("STUDY_RUN_LOG")
    if log and comm.rank == 0:  # a case that starts
        with open(log, "a") as fh:
            fh.write(f"{'normal' if w is None else f'W{w:g}_H{h:g}'} {os.getpid()}\n")
    time.sleep(float(os.environ.get("STUDY_STAND_IN_SLEEP", "0.05")))
    gate = os.environ.get("STUDY_STAND_IN_GATE")
    while gate and w is not None and not Path(gate).exists():  # a graft waits for the gate
        time.sleep(0.02)
    if comm.rank == 0:
        for name in ("closed_valve_ventricular.png", "cut_planes.png", "coaptation_map.png"):
            _picture(Path(out_dir) / name, 0.0 if w is None else w + h)
        _loaded_state(Path(out_dir) / "loaded_state.npz", 100)
    if w is not None and w >= 90:
        raise RuntimeError("stand-in failure for huge grafts")
    area = 1.0 if w is None else (1 + w / 100) * (1 + h / 100)
    return {"graft_width_pct": w, "graft_height_pct": h, "converged": w != 14.0,
            "min_coaptation_height_mm": 3.0 if w is None else 2.6 + 0.04 * w + 0.01 * h,
            "central_coaptation_height_mm": 4.0 * area, "coaptation_area_mm2": 330.0 * area,
            "regurgitant_orifice_area_mm2": 0.0 if w is None or w > 0 else 0.25,
            "competent": w is None or w > 0, "root_diameter_mm": 20.0,
            "max_penetration_mm": 0.01, "n_dofs": 300, "n_ranks": comm.size,
            "wall_time_s": 0.05, "future_field_mm": 1.5, "leaflets": {"a": {"h": 1.0}},
            "parameters": config.to_dict(), "versions": {"stand_in": "1"}}


def cli_with(case_function, argv: list[str]) -> int:
    """``valve-dolfinx argv`` computing every case with ``case_function``."""
    from valve_dolfinx import cli
    from valve_dolfinx.study import runner

    real = runner.run_closure_case
    runner.run_closure_case = lambda config, out, comm, start=None, **_: case_function(
        config, out, comm, start=start)
    try:
        return cli.main(argv)
    finally:  # in-process callers (tests) get the real case function back
        runner.run_closure_case = real


def _main_with_stand_in(argv: list[str]) -> int:
    return cli_with(stand_in_case, argv)


# --- helpers ----------------------------------------------------------------------------------
def _sweep_cmd(*args: str, mpi: int = 0) -> list[str]:
    """A stand-in sweep in a subprocess, without figures: the tests that run one compare
    tables and logs (a report's panels are drawn by the in-process sweeps)."""
    cmd = [sys.executable, str(THIS), "sweep", "--no-figures", *args]
    return [str(BIN / "mpirun"), "-n", str(mpi), *cmd] if mpi else cmd


def _run(cmd: list[str], run_log: Path, sleep: float = 0.05, timeout: float = 240):
    env = {**os.environ, "STUDY_RUN_LOG": str(run_log), "STUDY_STAND_IN_SLEEP": str(sleep)}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    return proc


def _runs(run_log: Path) -> list[str]:
    return [line.split()[0] for line in run_log.read_text().splitlines()] if run_log.exists() \
        else []


def stable_csv(path: Path) -> list[dict]:
    """``results.csv`` without the fields that differ between two runs of the same cases."""
    from valve_dolfinx.study.table import read_csv_rows

    return [{k: v for k, v in row.items() if k not in VOLATILE} for row in read_csv_rows(path)]


def _stable_json(value):
    if isinstance(value, dict):
        return {k: _stable_json(v) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [_stable_json(v) for v in value]
    return value


@pytest.fixture(scope="module")
def reference_sweep(tmp_path_factory) -> Path:
    """The small grid swept serially, in this process (what the subprocess sweeps must give)."""
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.study.runner import run_study

    out = tmp_path_factory.mktemp("reference") / "study"
    run_study(_settings(mesh_size_mm=None), out, MPI.COMM_SELF, case_function=stand_in_case)
    return out


def test_a_signal_while_a_case_is_claimed_leaves_no_claim(tmp_path, monkeypatch):
    """SIGINT arriving just after a case is claimed (before the case runs) ends the sweep
    with ``Interrupted`` and leaves no claim behind, so nothing looks held by a process
    that is gone."""
    import os
    import signal

    from valve_dolfinx._compat import MPI
    from valve_dolfinx.exceptions import Interrupted
    from valve_dolfinx.interrupts import interrupt_on_signals
    from valve_dolfinx.study import store
    from valve_dolfinx.study.runner import run_study

    acquire = store.CaseClaim.acquire
    ran = []

    def acquire_then_signal(claim):
        held = acquire(claim)
        os.kill(os.getpid(), signal.SIGINT)
        return held

    def case(*args, **kwargs):
        ran.append(args[1])
        return stand_in_case(*args, **kwargs)

    monkeypatch.setattr(store.CaseClaim, "acquire", acquire_then_signal)
    out = tmp_path / "study"
    with interrupt_on_signals(), pytest.raises(Interrupted):
        run_study(_settings(), out, MPI.COMM_SELF, case_function=case)
    assert ran == []
    assert not any((out / "cases" / ".claims").iterdir())
    assert not any((out / "cases" / ".staging").iterdir())


def _settings(**kw):
    from valve_dolfinx.study.grid import StudySettings

    kw.setdefault("widths_pct", (0, 7))
    kw.setdefault("heights_pct", (0,))
    kw.setdefault("mesh_size_mm", 2.0)
    return StudySettings(**kw)


# --- grid and settings ------------------------------------------------------------------------
@pytest.mark.parametrize("option,values,expect", [
    ("--widths", ["-5"], ["'-5'", "[0, 100] %"]),
    ("--widths", ["0", "7", "7.0"], ["'7.0'", "twice", "[0, 100] %"]),
    ("--heights", ["13", "abc"], ["'abc'", "not a number", "[0, 100] %"]),
    ("--heights", ["1e6"], ["'1e6'", "[0, 100] %"]),
    ("--widths", ["nan"], ["'nan'", "[0, 100] %", "give a finite number"]),
    ("--widths", [], ["--widths is empty", "[0, 100] %"]),
    ("--mesh-size", ["40"], ["mesh_size = 40.0", "[0.05, 2.5] mm"]),
    ("--ranks-per-case", ["0"], ["ranks_per_case = 0", ">= 1"]),
])
def test_invalid_grid_stops_before_computing(tmp_path, caplog, quiet_cli, monkeypatch, option,
                                             values, expect):
    """A bad value stops the sweep at once with one line naming it and its range; nothing is
    computed and the output folder is not even created."""
    from valve_dolfinx import cli
    from valve_dolfinx.study import runner

    def must_not_run(*args, **kw):
        raise AssertionError("a case ran")

    monkeypatch.setattr(runner, "run_closure_case", must_not_run)
    out = tmp_path / "study"
    argv = ["sweep", "--widths", "0", "7", "--heights", "0", "--out", str(out), option, *values]
    assert cli.main(argv) == 2
    err = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(err) == 1 and err[0].startswith("error: ") and "\n" not in err[0], err
    for text in expect:
        assert text in err[0]
    assert not out.exists()


def test_settings_from_toml(tmp_path):
    from valve_dolfinx.exceptions import ParameterError
    from valve_dolfinx.study.grid import load_study_toml

    path = tmp_path / "study.toml"
    path.write_text('[loading]\npressure_mmhg = 90\n[study]\nwidths = [14, 0]\nheights = "0, 27"\n'
                    'mesh_size = 1.5\npanel_cases = ["W14_H27"]\n'
                    '[solver.pseudo_transient]\nmax_steps = 77\n')
    settings = load_study_toml(path)
    assert settings.widths_pct == (0.0, 14.0) and settings.heights_pct == (0.0, 27.0)
    assert [c.name for c in settings.cases()] == ["normal", "W0_H0", "W0_H27", "W14_H0",
                                                  "W14_H27"]
    configs = settings.layout().configs
    assert configs["W14_H27"].geometry.graft_height_pct == 27.0
    assert configs["normal"].geometry.mesh_size == 1.5
    assert configs["normal"].pseudo_transient.max_steps == 77
    assert configs["W14_H27"].pressure_mmhg == 90.0
    assert load_study_toml(path, ["solver.pseudo_transient.max_steps=78"]).case[
        "solver"]["pseudo_transient"]["max_steps"] == 78
    path.write_text("[study]\nwidth = [0]\n")
    with pytest.raises(ParameterError, match="unknown key 'width'"):
        load_study_toml(path)
    path.write_text("[study]\n[solver.dynamics]\nno_such_setting = 1\n")
    with pytest.raises(ParameterError, match="unknown key 'solver.dynamics.no_such_setting'"):
        load_study_toml(path)
    path.write_text("[study.case.solver.pseudo_transient]\nmax_steps = 77\n")
    with pytest.raises(ParameterError, match=r"\[study.case\] is not read"):
        load_study_toml(path)


def test_unwritable_output_fails_before_computing(tmp_path):
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.exceptions import OutputNotFolderError, OutputNotWritableError
    from valve_dolfinx.study.runner import run_study

    calls = []
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    targets = [(blocker / "study", OutputNotFolderError, "is below the file"),
               (blocker, OutputNotFolderError, "is a file")]
    if os.geteuid() != 0:  # root writes through permissions
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        targets.append((locked / "study", OutputNotWritableError, "cannot be created"))
    for out, error, text in targets:
        with pytest.raises(error, match=text):
            run_study(_settings(), out, MPI.COMM_SELF,
                      case_function=lambda *a, **kw: calls.append(a) or {})
    assert calls == []


# --- the sweep path ---------------------------------------------------------------------------
def test_small_grid_writes_every_file(tmp_path, caplog):
    """2 × 1 grafts + normal: case folders, tables (SPEC §7 schema, agreeing with the case
    folders), both plots, the panels and report.md; one log line per finished case."""
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.study.runner import run_study
    from valve_dolfinx.study.table import SPEC_COLUMNS, flatten, read_csv_rows

    out = tmp_path / "study"
    settings = _settings(panel_cases=("W0_H0", "W7_H0", "W21_H27"))
    with caplog.at_level(logging.INFO, logger="valve_dolfinx.study"):
        outcome = run_study(settings, out, MPI.COMM_SELF, case_function=stand_in_case,
                            poll_s=0.05)
    assert outcome.computed == ["W0_H0", "W7_H0", "normal"]
    lines = [r.getMessage() for r in caplog.records if r.name == "valve_dolfinx.study.runner"]
    assert sum("min coaptation" in line for line in lines) == 3
    for name in ("normal", "W0_H0", "W7_H0"):
        for f in ("result.json", "case.json", "closed_valve_ventricular.png"):
            assert (out / "cases" / name / f).is_file(), (name, f)
    for f in ("results.csv", "results.json", "coaptation_vs_width.png", "sizing_map.png",
              "report.md", "summary.json", "panels/normal.png", "panels/W0_H0.png",
              "panels/W7_H0.png"):
        assert (out / f).stat().st_size > 100, f
    assert not (out / "panels" / "W21_H27.png").exists()  # not on this grid

    csv_rows = read_csv_rows(out / "results.csv")
    header = list(csv_rows[0])
    assert header[:len(SPEC_COLUMNS)] == list(SPEC_COLUMNS)
    assert {"case", "status", "reason", "config_hash", "future_field_mm",
            "leaflets.a.h", "parameters.geometry.mesh_size_mm", "versions.stand_in"} <= set(header)
    json_rows = json.loads((out / "results.json").read_text())
    assert [r["case"] for r in json_rows] == [r["case"] for r in csv_rows] == [
        "normal", "W0_H0", "W7_H0"]
    for row_csv, row_json in zip(csv_rows, json_rows, strict=True):
        case = json.loads((out / "cases" / row_json["case"] / "result.json").read_text())
        assert set(SPEC_COLUMNS) <= set(row_json)
        for key, value in flatten(case).items():  # every field of the case, unchanged
            assert flatten(row_json)[key] == value, key
            text = row_csv[key]
            if isinstance(value, bool):
                assert text == str(value).lower()
            elif isinstance(value, float):
                assert float(text) == value
            elif value is None:
                assert text == ""
    normal, w0, w7 = json_rows
    assert normal["graft_width_pct"] is None and w0["graft_width_pct"] == 0.0
    assert w0["competent"] is False and w0["regurgitant_orifice_area_mm2"] == 0.25
    report = (out / "report.md").read_text()
    for text in ("## Recommendation", "W7/H0", "coaptation_vs_width.png", "sizing_map.png",
                 "panels/W0_H0.png", "| W0_H0 |"):
        assert text in report


def test_failed_and_unconverged_cases_are_recorded(tmp_path):
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.study.runner import run_study

    out = tmp_path / "study"
    outcome = run_study(_settings(widths_pct=(14, 95)), out, MPI.COMM_SELF,
                        case_function=stand_in_case)
    rows = {r["case"]: r for r in outcome.report.rows}
    assert rows["W95_H0"]["status"] == "failed" and rows["W95_H0"]["converged"] is False
    assert "stand-in failure" in rows["W95_H0"]["reason"]
    assert rows["W14_H0"]["status"] == "finished" and rows["W14_H0"]["converged"] is False
    assert rows["normal"]["converged"] is True and rows["normal"]["reason"] == ""


def test_changed_configuration_is_recomputed(tmp_path):
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.study.runner import run_study

    out, ran = tmp_path / "study", []

    def counting(config, folder, comm, *, start):
        ran.append(config.geometry.mesh_size)
        return stand_in_case(config, folder, comm, start=start)

    run_study(_settings(), out, MPI.COMM_SELF, case_function=counting, report=False)
    run_study(_settings(), out, MPI.COMM_SELF, case_function=counting, report=False)
    assert ran == [2.0] * 3  # second sweep: nothing to do
    run_study(_settings(mesh_size_mm=1.9), out, MPI.COMM_SELF, case_function=counting)
    assert ran == [2.0] * 3 + [1.9] * 3
    assert not any((out / "cases" / ".staging").iterdir())


def _case_of(config) -> str:
    from valve_dolfinx.config import case_name

    return case_name(config.geometry)


def test_damaged_cases_are_reported_and_recomputed(tmp_path, caplog, capsys, quiet_cli):
    """A truncated result.json, a truncated case.json and a deleted loaded_state.npz in a
    finished study: `report` lists each case with what is wrong and exits with status 9; a
    sweep recomputes exactly those cases, warning with the file, and the tables are again
    those of the whole study."""
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.cli import main
    from valve_dolfinx.exceptions import ExitCode
    from valve_dolfinx.study.runner import run_study

    out, ran = tmp_path / "study", []

    def counting(config, folder, comm, *, start):
        ran.append(_case_of(config))
        return stand_in_case(config, folder, comm, start=start)

    settings = _settings(widths_pct=(0, 7, 14))
    run_study(settings, out, MPI.COMM_SELF, case_function=counting)
    whole = stable_csv(out / "results.csv")
    cases = out / "cases"
    for name, file in (("W0_H0", "result.json"), ("W7_H0", "case.json")):
        text = (cases / name / file).read_text()
        (cases / name / file).write_text(text[:len(text) // 2])
    (cases / "normal" / "loaded_state.npz").unlink()
    damaged = {"W0_H0": "result.json is not valid JSON", "W7_H0": "case.json is not valid JSON",
               "normal": "loaded_state.npz is missing"}

    assert main(["report", str(out)]) == ExitCode.STUDY_INCOMPLETE
    assert "incomplete (3 case(s) without a result" in caplog.text
    rows = {r["case"]: r for r in json.loads((out / "results.json").read_text())}
    assert set(rows) == {"normal", "W0_H0", "W7_H0", "W14_H0"}
    for name, reason in damaged.items():
        assert rows[name]["status"] == "damaged" and reason in rows[name]["reason"], name
        assert rows[name]["min_coaptation_height_mm"] is None
    assert rows["W14_H0"]["status"] == "finished"
    assert "damaged: normal, W0_H0, W7_H0" in (out / "report.md").read_text()
    assert "| W0_H0 |" in (out / "report.md").read_text()

    caplog.clear()
    ran.clear()
    run_study(settings, out, MPI.COMM_SELF, case_function=counting)
    assert sorted(ran) == sorted(damaged)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING
                and "recomputing" in r.getMessage()]
    for name, reason in damaged.items():
        assert any(f"cases/{name}: {reason}" in w for w in warnings), (name, warnings)
    assert main(["report", str(out)]) == 0
    assert stable_csv(out / "results.csv") == whole


def test_a_study_without_its_cases_is_incomplete(tmp_path, caplog, quiet_cli):
    """`report` on a study with no finished case, or with cases not run yet, writes what it
    has and exits with status 9; a sweep whose case failed does too, naming it."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.exceptions import ExitCode
    from valve_dolfinx.study.store import prepare_output

    empty = prepare_output(tmp_path / "empty")
    assert main(["report", str(empty)]) == ExitCode.STUDY_INCOMPLETE
    assert "no case has finished yet" in caplog.text
    assert (empty / "report.md").is_file()
    array = tmp_path / "array"
    assert _main_with_stand_in(["sweep", *SMALL_GRID, "--out", str(array),
                                "--case-index", "1"]) == 0
    caplog.clear()
    assert main(["report", str(array)]) == ExitCode.STUDY_INCOMPLETE
    # case 1 (W0_H0) starts from the closed normal valve (path 1), which it computes first
    assert "not run yet: W7_H0" in (array / "report.md").read_text()
    caplog.clear()
    assert _main_with_stand_in(["sweep", "--widths", "7", "95", "--heights", "0", "--out",
                                str(tmp_path / "failing"), "--no-progress"]) == \
        ExitCode.STUDY_INCOMPLETE
    (error,) = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert "1 case(s) failed: W95_H0" in error


def test_claims_are_exclusive_and_stale_ones_are_taken_over(tmp_path):
    from valve_dolfinx.study.store import CaseClaim, prepare_output

    prepare_output(tmp_path)
    first, second = CaseClaim.for_case(tmp_path, "W7_H0"), CaseClaim.for_case(tmp_path, "W7_H0")
    assert first.acquire() and not second.acquire()
    first.release()
    assert second.acquire()
    second.release()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    first.path.write_text(json.dumps({"host": os.uname().nodename, "pid": dead.pid,
                                      "start": None}))
    assert second.acquire()  # the process that held it is gone
    second.release()


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_sweep_resumes_without_recomputing(tmp_path, reference_sweep, sig):
    """A real signal to a sweep after its first case: SIGTERM ends it with status 143,
    SIGKILL kills it; the rerun finishes the others without recomputing the first and gives
    the same tables as an uninterrupted sweep.  (SIGINT to a sweep of real closures:
    ``tests/test_interrupts.py``.)"""
    out, run_log = tmp_path / "study", tmp_path / "runs.log"
    env = {**os.environ, "STUDY_RUN_LOG": str(run_log), "STUDY_STAND_IN_SLEEP": "1.0"}
    proc = subprocess.Popen(_sweep_cmd(*SMALL_GRID, "--out", str(out), "--no-progress"),
                            env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = out / "cases" / "normal" / "case.json"
    deadline = time.time() + 120
    while len(_runs(run_log)) < 2 and time.time() < deadline and proc.poll() is None:
        time.sleep(0.02)  # until the first case is done and the second one in flight
    assert first.exists(), proc.communicate()[1][-2000:]
    proc.send_signal(sig)
    proc.communicate(timeout=60)
    assert proc.returncode == (-sig if sig == signal.SIGKILL else 128 + sig)
    assert not (out / "cases" / "W0_H0").exists() and not (out / "cases" / "W7_H0").exists()
    # the second case was in flight: the larger graft first
    assert _runs(run_log) == ["normal", "W7_H0"]
    claims = list((out / "cases" / ".claims").iterdir())
    # SIGTERM releases the claim on the way out; SIGKILL leaves it, stale, to the rerun
    assert [c.name for c in claims] == (["W7_H0.claim"] if sig == signal.SIGKILL else [])
    record = first.read_text()

    _run(_sweep_cmd(*SMALL_GRID, "--out", str(out), "--no-progress"), run_log)
    assert _runs(run_log) == ["normal", "W7_H0", "W7_H0", "W0_H0"]
    assert first.read_text() == record  # untouched
    assert not list((out / "cases" / ".claims").iterdir())
    assert not list((out / "cases" / ".staging").iterdir())
    assert stable_csv(out / "results.csv") == stable_csv(reference_sweep / "results.csv")
    assert (_stable_json(json.loads((out / "results.json").read_text()))
            == _stable_json(json.loads((reference_sweep / "results.json").read_text())))


@pytest.mark.slow
def test_serial_and_mpi_sweeps_agree(tmp_path, reference_sweep):
    """`mpirun -n 2` spreads the cases over two groups, runs each exactly once and gives the
    serial sweep's tables; --ranks-per-case 2 runs every case on both ranks."""
    for k in (1, 2):
        out, log = tmp_path / f"mpi{k}", tmp_path / f"mpi{k}.log"
        # the grafts start from the normal valve (path 1): the other group waits for it, so
        # a case lasts longer than the scheduler's 1 s poll
        proc = _run(_sweep_cmd(*SMALL_GRID, "--out", str(out), "--ranks-per-case", str(k),
                               mpi=2), log, sleep=1.5)
        runs = [line.split() for line in log.read_text().splitlines()]
        assert sorted(r[0] for r in runs) == ["W0_H0", "W7_H0", "normal"]
        assert len({r[1] for r in runs}) == (2 if k == 1 else 1)  # both groups took cases
        assert proc.stdout.count("case(s) computed") == 1  # rank 0 alone prints
        assert stable_csv(out / "results.csv") == stable_csv(reference_sweep / "results.csv")
        rows = json.loads((out / "results.json").read_text())
        assert {r["n_ranks"] for r in rows} == {k}


@pytest.mark.slow
def test_two_sweeps_on_one_folder_share_the_cases(tmp_path):
    """Two sweeps started together on one folder: every case computed once, by one of them."""
    out, run_log = tmp_path / "study", tmp_path / "runs.log"
    env = {**os.environ, "STUDY_RUN_LOG": str(run_log), "STUDY_STAND_IN_SLEEP": "0.5"}
    grid = ["--widths", "0", "7", "14", "--heights", "0", "13", "--no-progress"]
    procs = [subprocess.Popen(_sweep_cmd(*grid, "--out", str(out)), env=env, cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)
             for _ in range(2)]
    for proc in procs:
        _, err = proc.communicate(timeout=180)
        assert proc.returncode == 0, err[-2000:]
    runs = [line.split() for line in run_log.read_text().splitlines()]
    assert sorted(r[0] for r in runs) == sorted(
        ["normal"] + [f"W{w}_H{h}" for w in (0, 7, 14) for h in (0, 13)])
    assert len({r[1] for r in runs}) == 2  # both took cases
    assert len(json.loads((out / "results.json").read_text())) == 7


def test_case_index_runs_and_report_equal_one_sweep(tmp_path, capsys, caplog, quiet_cli):
    whole, array = tmp_path / "whole", tmp_path / "array"
    assert _main_with_stand_in(["sweep", *SMALL_GRID, "--out", str(whole), "--no-progress"]) == 0
    assert _main_with_stand_in(["sweep", *SMALL_GRID, "--out", str(array), "--list"]) == 0
    listing = capsys.readouterr().out
    assert "0  normal" in listing and "2  W7_H0" in listing and "pending" in listing
    for i in (2, 0, 1):
        assert _main_with_stand_in(["sweep", *SMALL_GRID, "--out", str(array),
                                    "--case-index", str(i)]) == 0
    assert not (array / "results.csv").exists()  # the array's tasks leave the report
    assert _main_with_stand_in(["report", str(array)]) == 0
    assert stable_csv(array / "results.csv") == stable_csv(whole / "results.csv")
    assert (array / "sizing_map.png").is_file() and (array / "report.md").is_file()
    _main_with_stand_in(["sweep", *SMALL_GRID, "--out", str(array), "--list"])
    assert capsys.readouterr().out.count("finished") == 3
    assert _main_with_stand_in(["sweep", *SMALL_GRID, "--out", str(array),
                                "--case-index", "3"]) == 2
    assert "case index 3 is outside the allowed range [0, 2]" in caplog.text


@pytest.mark.parametrize("terminal,option,bar", [(True, [], True),
                                                  (True, ["--no-progress"], False),
                                                  (False, [], False)])
def test_progress_bar_and_plain_lines(tmp_path, capsys, caplog, quiet_cli, monkeypatch,
                                      terminal, option, bar):
    """One bar of cases done/total on a terminal; --no-progress, or a stderr that is no
    terminal (a log file, a batch job): the per-case log lines without a bar."""
    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal)
    with caplog.at_level(logging.INFO, logger="valve_dolfinx.study"):
        assert _main_with_stand_in(["sweep", *SMALL_GRID, "--out", str(tmp_path), *option]) == 0
    err = capsys.readouterr().err
    drawn = "sweep:" in err and "3/3" in err and ("case/s" in err or "s/case" in err)
    assert drawn == bar and ("\r" in err) == bar
    assert sum("min coaptation" in r.getMessage() for r in caplog.records) == 3


@pytest.mark.mpi
def test_every_case_once_over_the_ranks(tmp_path_factory):
    """In process, on COMM_WORLD (1 or 2 ranks): each case exactly once, the same table on
    every rank count."""
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.study.runner import run_study

    comm = MPI.COMM_WORLD
    out = Path(comm.bcast(str(tmp_path_factory.mktemp("study")) if comm.rank == 0 else None))
    ran = []

    def counting(config, folder, group, *, start):
        ran.append(config.geometry.graft_width_pct)
        return stand_in_case(config, folder, group, start=start)

    outcome = run_study(_settings(widths_pct=(0, 7, 14)), out, comm, case_function=counting)
    everything = sum(comm.allgather(ran), [])
    assert sorted(everything, key=lambda w: -1 if w is None else w) == [None, 0.0, 7.0, 14.0]
    assert outcome.computed == ["W0_H0", "W14_H0", "W7_H0", "normal"]
    if comm.rank == 0:
        rows = outcome.report.rows
        assert [r["case"] for r in rows] == ["normal", "W0_H0", "W7_H0", "W14_H0"]


def test_graft_sweep_demo(tmp_path, quiet_cli, monkeypatch, capsys):
    """demos/graft_sweep.py runs the study through run_study (stand-in cases) and reports."""
    import importlib.util

    from valve_dolfinx.study import runner

    monkeypatch.setattr(runner, "run_closure_case",
                        lambda config, out, comm, start=None, **_: stand_in_case(config, out,
                                                                                  comm))
    spec = importlib.util.spec_from_file_location("demo_graft_sweep",
                                                  ROOT / "demos" / "graft_sweep.py")
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    outcome = demo.main(["--out", str(tmp_path), "--widths", "7", "14", "--heights", "0",
                         "13", "--no-progress"])
    assert len(outcome.computed) == 5
    text = capsys.readouterr().out
    # W14 does not converge: two solved cells are too few for a surface
    assert "5 cases:" in text and "No answer: a response surface needs at least 6" in text
    assert (tmp_path / "report.md").is_file() and (tmp_path / "sizing_map.png").is_file()


# --- the recommendation -----------------------------------------------------------------------
def _row(w, h, height, converged=True, competent=True):
    return {"graft_width_pct": w, "graft_height_pct": h, "converged": converged,
            "competent": competent, "min_coaptation_height_mm": height}


def _plane(target, base, per_w, per_h, sizes=(0, 7, 14)):
    """A one-member study on a 3 × 3 grid whose heights are the plane
    ``base + per_w·W + per_h·H`` (mm), every graft sealed; the normal valve at ``target``."""
    return [_row(None, None, target), *(_row(w, h, base + per_w * w + per_h * h)
                                        for w in sizes for h in (0, 13, 27))]


def test_recommendation_reads_the_answer_beside_the_solved_cells():
    """Heights on the plane 2 + 0.08 W + 0.03 H against a target of 3 mm: on that plane the
    flat area (1 + W)(1 + H) along the target's line H = (1 - 0.08 W)/0.03 falls as W grows,
    so the smallest adequate size is where the line meets H = 0: W = 12.5 %, read on the
    1 % lattice as W13/H0 (3.04 mm; W12/H0 is 0.04 mm short, more than the noise of an
    exact plane).  No grid cell qualifies below W14/H0."""
    from valve_dolfinx.sizing import recommend

    rows = _plane(3.0, 2.0, 0.08, 0.03)
    rec = recommend(rows, ladder=None)
    assert rec.target_mm == 3.0 and "normal valve" in rec.target_source
    assert rec.answer.size == (13.0, 0.0) and rec.answer.size.label == "W13/H0"
    assert rec.answer.margin_mm == pytest.approx(0.04, abs=0.01)
    assert rec.answer.tolerance_mm < 0.01 and rec.answer.resolution.path_scatter_mm is None
    # every case sealed: every cell's share of sealed cases is 1, and so is the interpolation
    assert rec.answer.seal_probability == 1.0
    assert rec.answer.highest == (14.0, 27.0)
    # the solved cells beside it, as solved: W7/H0 is 2.56 mm, 0.44 mm short
    cell = rec.cell("W7/H0")
    assert cell.worst_height_mm == pytest.approx(2.56) and cell.margin_mm == pytest.approx(-0.44)
    assert not cell.qualifies and rec.cell("W14/H0").qualifies
    assert "**W13/H0**" in rec.text and "one numerical path" in rec.text
    assert rec.confirm == [""]  # W13/H0 is off the grid: solve it in the one member
    # a given target moves the answer up the plane: 0.08 W + 0.03 H >= 1.3 needs H > 0 at
    # W <= 14 (W14 gives 0.08·14 + 0.03 H >= 1.3 for H >= 6)
    higher = recommend(rows, target_mm=3.3, ladder=None)
    assert higher.answer.size.width_pct == 14.0 and 5.0 <= higher.answer.size.height_pct <= 7.0


def test_recommendation_when_none_qualifies():
    """The plane 1 + 0.05 W + 0.02 H reaches 2.24 mm at W14/H27 against a target of 3.5 mm:
    no graft, the closest W14/H27, 1.26 mm short; without a converged normal valve there is
    no target."""
    from valve_dolfinx.sizing import recommend

    rows = _plane(3.5, 1.0, 0.05, 0.02)
    rec = recommend(rows, ladder=None)
    assert rec.answer.size is None and rec.answer.why == "short"
    assert rec.answer.closest.label == "W14/H27"
    assert rec.answer.shortfall_mm == pytest.approx(1.26, abs=0.01)
    assert rec.text.startswith("No graft:") and "1.26 mm short" in rec.text
    no_normal = recommend(rows[1:], ladder=None)
    assert no_normal.target_mm is None and "give --target-coaptation" in no_normal.text
    assert no_normal.answer.size is None and no_normal.answer.why == "no target"
    unconverged = recommend([_row(None, None, 3.5, converged=False), *rows[1:]], ladder=None)
    assert unconverged.answer.why == "no target" and "did not converge" in unconverged.text


def test_a_thin_margin_is_shown_with_its_significant_digits_in_the_report(tmp_path):
    """The stand-in W7/H0 reaches 2.88 mm; against a target of 2.8777 mm its margin of
    0.0023 mm reads +0.0023 in the worst-case table of report.md (not 0.00), and a margin
    of 0.12 mm keeps two decimals."""
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.study.report import build_report
    from valve_dolfinx.study.runner import run_study

    out = tmp_path / "study"
    run_study(_settings(target_coaptation_mm=2.8777), out, MPI.COMM_SELF,
              case_function=stand_in_case)
    report = (out / "report.md").read_text()
    # two grafts are too few for a surface: no answer, the solved cells as they are
    assert "No answer: a response surface needs at least 6 solved cells" in report
    assert "| W7/H0 | 2.88 | 0.00 | +0.0023 |" in report
    wider = build_report(out, _settings(target_coaptation_mm=2.76))
    assert wider.recommendations[0].cell("W7/H0").margin_mm == pytest.approx(0.12, abs=1e-9)
    assert "| W7/H0 | 2.88 | 0.00 | +0.12 |" in (out / "report.md").read_text()


@pytest.mark.parametrize(("margin", "plain", "signed"), [
    (0.12, "0.12", "+0.12"), (0.0023, "0.0023", "+0.0023"), (-0.0023, "-0.0023", "-0.0023"),
    (0.0001, "0.00010", "+0.00010"), (-0.0, "0.00", "+0.00"),
    (2.0 - 2.0000000000000004, "0.00", "+0.00")])  # round-off of a tie: no 13 decimals
def test_margin_text_shows_a_thin_margin_and_hides_round_off(margin, plain, signed):
    from valve_dolfinx.result import margin_text

    assert margin_text(margin) == plain and margin_text(margin, signed=True) == signed


# --- run_case itself --------------------------------------------------------------------------
#: the intersection given to the real case (standing in for W21/H27's 30 pairs, 0.17–0.28 mm
#: from a post, at the default mesh): three pairs at three of its nodes, this far from a post
INTERSECTION_POST_MM = (0.5, 1.0, 2.0)
INTERSECTION_REASON = ("leaflets intersect: 3 edge–triangle pairs, 0.50–2.00 mm from a post "
                       "(left-coronary/right-coronary 3)")


def _intersecting(state):
    """Edge–triangle pairs made up on the real loaded valve (see INTERSECTION_POST_MM)."""
    from valve_dolfinx.analysis.intersection import IntersectingPair, Intersections

    _, positions = state.shown()
    pairs = tuple(IntersectingPair((0, 1), 0, ("left-coronary", "right-coronary"),
                                   tuple(positions[50 * (k + 1)]), d)
                  for k, d in enumerate(INTERSECTION_POST_MM))
    return Intersections(pairs, candidates=1000, time_s=0.0)


def test_only_the_cases_the_panels_show_draw_their_figures(monkeypatch):
    """Of a study over two roots and two paths, the closure draws the figures of the first
    normal valve and of the first case of each panel graft (the report's panels), of no
    other case, and of none with ``figures=False``."""
    from valve_dolfinx.study import runner

    drawn = {}

    def closure(config, folder, comm, *, start=None, figures=True, fields_output=True):
        drawn[folder.name] = figures
        return {}

    monkeypatch.setattr(runner, "run_closure_case", closure)
    settings = _settings(widths_pct=(0, 7, 14), heights_pct=(0, 27), paths=2,
                         uncertain={"root.loaded_diameter_mm": [20, 21]},
                         panel_cases=("W7_H0", "W14_H27"))
    layout = settings.layout(())
    for figures in (True, False):
        drawn.clear()
        case_function = runner._closure_cases(settings, layout, figures, False)
        for case in layout.cases:
            case_function(layout.configs[case.name], Path(case.name), None, start=None)
        assert len(drawn) == len(layout.cases) == 2 + 2 * 2 * 6
        expected = {"normal__root.loaded_diameter_mm=20", "W7_H0__root.loaded_diameter_mm=20",
                    "W14_H27__root.loaded_diameter_mm=20"} if figures else set()
        assert {name for name, draws in drawn.items() if draws} == expected


@pytest.fixture(scope="module")
def real_sweep(tmp_path_factory):
    """One real closure through the sweep path: the normal valve on a 2 mm mesh (a minute or
    less), its leaflets made to intersect (:func:`_intersecting`), so that it is not
    competent; the
    outcome, the study folder and the log records of the case and of the sweep."""
    import valve_dolfinx.case as case
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.study.runner import run_study

    out = tmp_path_factory.mktemp("real") / "study"
    records = []
    handler = logging.Handler(logging.INFO)
    handler.emit = records.append
    library = logging.getLogger("valve_dolfinx")
    level = library.level
    library.addHandler(handler)
    library.setLevel(logging.INFO)
    try:
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(case, "check_intersections", _intersecting)
            outcome = run_study(_settings(widths_pct=(0,), wall_time_limit_s=90.0), out,
                                MPI.COMM_SELF, case_indices=[0], poll_s=0.05)
    finally:
        library.removeHandler(handler)
        library.setLevel(level)
    return outcome, out, records


@pytest.mark.timeout(300)
def test_real_case_through_the_sweep(real_sweep):
    """The real case is recorded whether it converged or not, with every file, and fields.vtu
    that meshio and PyVista read.  (A study of the cheap symmetric reference cannot be set
    up: its grafts are not valves of one leaflet.)"""
    from valve_dolfinx.exceptions import ParameterError
    from valve_dolfinx.study.table import SPEC_COLUMNS

    outcome, out, _ = real_sweep
    with pytest.raises(ParameterError, match="geometry.symmetric_reference needs the normal valve"):
        _settings(widths_pct=(0,), case={"geometry": {"symmetric_reference": True}}).cases()
    assert outcome.computed == ["normal"]
    folder = out / "cases" / "normal"
    record = json.loads((folder / "case.json").read_text())
    row = outcome.report.rows[0]
    assert record["status"] == "finished", record["reason"]
    for name in ("result.json", "config.toml", "fields.vtu", "closed_valve_ventricular.png",
                 "cut_planes.png"):  # the normal valve draws its figures for the panels
        assert (folder / name).is_file(), name
    assert set(SPEC_COLUMNS) <= set(row) and isinstance(row["converged"], bool)
    assert row["parameters"]["geometry"]["mesh_size_mm"] == 2.0 and row["n_dofs"] > 0
    assert (out / "panels" / "normal.png").is_file()
    if row["converged"]:
        assert 2.0 < row["min_coaptation_height_mm"] < 6.0
    _assert_fields_readable(folder)


@pytest.mark.timeout(300)
def test_competence_agrees_everywhere_when_leaflets_intersect(real_sweep):
    """A case whose leaflets intersect is not competent, with the same reason in the case's and
    the sweep's log lines, result.json, results.csv, report.md and the figure titles."""
    from valve_dolfinx.plotting import key_numbers
    from valve_dolfinx.result import competence_text
    from valve_dolfinx.study.table import read_csv_rows

    _, out, records = real_sweep
    result = json.loads((out / "cases" / "normal" / "result.json").read_text())
    assert result["competent"] is False
    assert result["competence_reason"].endswith(INTERSECTION_REASON)
    assert result["intersecting_pairs"] == 3
    verdict = competence_text(result)
    assert verdict == f"not competent ({result['competence_reason']})"
    lines = [r.getMessage() for r in records if r.name in ("valve_dolfinx.case",
                                                           "valve_dolfinx.study.runner")]
    assert len(lines) == 2 and all(verdict in line for line in lines), lines
    (row,) = read_csv_rows(out / "results.csv")
    assert row["competent"] == "false" and row["competence_reason"] == result["competence_reason"]
    assert f"| no ({result['competence_reason']}) |" in (out / "report.md").read_text()
    assert key_numbers(result).endswith(verdict)


def _assert_fields_readable(folder: Path) -> None:
    """fields.vtu reads with meshio and with PyVista, and holds the solved state: reference
    points + displacement = the loaded positions of loaded_state.npz, the same contact forces
    and leaflet tags, 2×2 stress and strain per cell."""
    import meshio
    import numpy as np
    import pyvista

    with np.load(folder / "loaded_state.npz") as state:
        written = {k: state[k] for k in state.files}
    n, m = len(written["positions"]), len(written["cells"])
    mesh = meshio.read(folder / "fields.vtu")
    assert np.array_equal(mesh.cells_dict["triangle"], written["cells"])
    assert np.allclose(mesh.points + mesh.point_data["displacement"], written["positions"],
                       atol=1e-12)
    assert np.array_equal(mesh.point_data["contact_force"], written["contact_forces"])
    assert np.array_equal(mesh.cell_data["leaflet"][0], written["cell_tags"])
    grid = pyvista.read(folder / "fields.vtu")
    assert (grid.n_points, grid.n_cells) == (n, m)
    for name, shape in (("stress", (m, 4)), ("strain", (m, 4)), ("area_stretch", (m,))):
        assert grid.cell_data[name].shape == shape and np.all(np.isfinite(grid.cell_data[name]))
    assert np.all(grid.cell_data["area_stretch"] > 0.5)
    assert set(grid.point_data) >= {"displacement", "contact_force", "coaptation_gap"}



if __name__ == "__main__":  # the CLI with the stand-in case function (subprocess tests)
    sys.exit(_main_with_stand_in(sys.argv[1:]))
