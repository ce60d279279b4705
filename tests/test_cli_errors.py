"""What the command line does when something goes wrong: one line, a documented exit status.

Every error that reaches ``valve-dolfinx`` is logged as one line (``error: ...``, with time
and level) and ends the command with the status of :class:`ExitCode` (listed in
``valve-dolfinx --help``); the traceback only with ``-v``.  Under ``mpirun`` a failure on
one rank ends every rank.  Files come out with the mode the user's umask gives.
"""

from __future__ import annotations

import logging
import os
import re
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from valve_dolfinx.exceptions import (
    DegenerateGeometryError,
    ExitCode,
    MeshError,
    OutputConflictError,
    ParameterError,
    SolverError,
    exit_code,
)

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
#: a log line of an error: date, time, level, then the message
ERROR_LINE = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d ERROR +(\[rank \d+/\d+\] )?error: ")


def _cli(*args: str, umask: int | None = None, timeout: float = 300):
    preexec = None if umask is None else (lambda: os.umask(umask))
    return subprocess.run([sys.executable, "-m", "valve_dolfinx.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, preexec_fn=preexec)


def _error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if "error:" in line]


def _assert_one_error_line(stderr: str, *expected: str) -> str:
    """Exactly one error line, holding every ``expected`` text, and no traceback."""
    assert "Traceback" not in stderr, stderr
    lines = _error_lines(stderr)
    assert len(lines) == 1, stderr
    assert ERROR_LINE.match(lines[0]), lines[0]
    for text in expected:
        assert text in lines[0], lines[0]
    return lines[0]


# --- exit statuses -------------------------------------------------------------------------
def test_exit_codes_are_distinct_and_listed_in_the_help():
    codes = [int(c) for c in ExitCode]
    assert len(set(codes)) == len(codes)
    proc = _cli("--help", timeout=60)
    assert proc.returncode == 0
    for code in ExitCode:
        assert re.search(rf"^  {int(code)} +\S", proc.stdout, re.MULTILINE), code


@pytest.mark.parametrize("err,code", [
    (ParameterError("x"), ExitCode.USAGE),
    (ValueError("x"), ExitCode.USAGE),
    (FileNotFoundError(2, "No such file or directory", "a.npz"), ExitCode.INPUT),
    (MeshError("x"), ExitCode.INPUT),
    (SolverError("x"), ExitCode.SOLVER),
    (DegenerateGeometryError("x"), ExitCode.SOLVER),
    (OutputConflictError("x"), ExitCode.OUTPUT_CONFLICT),
    (KeyboardInterrupt(), ExitCode.INTERRUPTED),
    (ZeroDivisionError("x"), ExitCode.INTERNAL),
])
def test_each_error_has_its_exit_code(err, code):
    assert exit_code(err) == code


def test_missing_study_folder_is_an_input_error(tmp_path):
    proc = _cli("report", str(tmp_path / "no_such_study"), timeout=120)
    assert proc.returncode == ExitCode.INPUT
    _assert_one_error_line(proc.stderr, "no_such_study", "valve-dolfinx sweep")


def test_missing_configuration_file_is_an_input_error(tmp_path):
    proc = _cli("sweep", "--config", str(tmp_path / "study.toml"), "--out",
                str(tmp_path / "study"), timeout=120)
    assert proc.returncode == ExitCode.INPUT
    _assert_one_error_line(proc.stderr, "study.toml", "no such configuration file")
    assert not (tmp_path / "study").exists()


def test_broken_toml_is_a_configuration_error(tmp_path):
    bad = tmp_path / "study.toml"
    bad.write_text("[study]\nwidths = [0, 7\nheights = [0]\n")
    proc = _cli("sweep", "--config", str(bad), "--out", str(tmp_path / "study"), timeout=120)
    assert proc.returncode == ExitCode.USAGE
    _assert_one_error_line(proc.stderr, str(bad), "not valid TOML")
    assert not (tmp_path / "study").exists()


def test_missing_or_broken_mesh_file_is_an_input_error(tmp_path):
    """``run --mesh``: a missing file and a file that is not a valve mesh each stop the run
    before any computation, with status 4 and one line naming the file."""
    missing = tmp_path / "valve.npz"
    proc = _cli("run", "--mesh", str(missing), "--out", str(tmp_path / "a"), timeout=120)
    assert proc.returncode == ExitCode.INPUT, proc.stderr[-2000:]
    _assert_one_error_line(proc.stderr, str(missing), "valve-dolfinx mesh")
    for broken, content in (("broken.npz", b"not a mesh"), ("empty.npz", b"")):
        broken = tmp_path / broken
        broken.write_bytes(content)
        proc = _cli("run", "--mesh", str(broken), "--out", str(tmp_path / "b"), timeout=120)
        assert proc.returncode == ExitCode.INPUT, proc.stderr[-2000:]
        _assert_one_error_line(proc.stderr, str(broken), "valve-dolfinx mesh")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_run_closes_a_mesh_file_with_its_geometry(tmp_path):
    """``run --mesh`` takes the geometry (here a 1.6 mm W21/H27 graft valve) from the file:
    the result records it, whatever the configuration's geometry says; ``--no-figures``
    writes the fields but no PNG."""
    import json

    from valve_dolfinx.geometry.valve import ValveParameters, build_valve, save_valve_mesh

    mesh = save_valve_mesh(build_valve(ValveParameters(
        mesh_size=1.6, graft_width_pct=21, graft_height_pct=27)), tmp_path / "graft.npz")
    out = tmp_path / "case"
    proc = _cli("run", "--mesh", str(mesh), "--set", "solver.pseudo_transient.max_steps=1",
                "--no-figures", "--out", str(out))
    assert proc.returncode == ExitCode.NOT_CONVERGED, proc.stderr[-2000:]
    assert (out / "fields.vtu").is_file() and not list(out.glob("*.png"))  # --no-figures
    parameters = json.loads((out / "result.json").read_text())["parameters"]
    assert (parameters["geometry"]["mesh_size_mm"], parameters["graft"]["width_pct"],
            parameters["graft"]["height_pct"]) == (1.6, 21, 27)
    proc = _cli("run", "--mesh", str(mesh), "--mesh-size", "1.2", "--out", str(out))
    assert proc.returncode == ExitCode.USAGE and "--mesh" in proc.stderr


@pytest.mark.parametrize("width,reason", [("500", "typing error"),
                                          ("-5", "cannot be sewn onto its annulus")])
def test_range_error_gives_the_reason_of_the_crossed_bound(tmp_path, caplog, width, reason):
    from valve_dolfinx.cli import main

    code = main(["run", "--out", str(tmp_path / "case"), "--graft-width", width,
                 "--graft-height", "0"])
    assert code == ExitCode.USAGE
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and "graft.width_pct" in errors[0] and reason in errors[0]
    other = "cannot be sewn" if reason == "typing error" else "typing error"
    assert other not in errors[0]
    assert not (tmp_path / "case").exists()


# --- errors raised inside a command --------------------------------------------------------
def _report_raising(monkeypatch, err: BaseException) -> None:
    from valve_dolfinx.study import report

    def build_report(*args, **kwargs):
        raise err

    monkeypatch.setattr(report, "build_report", build_report)


@pytest.mark.parametrize("err,code,expected", [
    (SolverError("the root wall cannot hold 10.7 kPa: increase root.youngs_modulus_kpa"),
     ExitCode.SOLVER, "increase root.youngs_modulus_kpa"),
    (ZeroDivisionError("float division by zero"), ExitCode.INTERNAL,
     "rerun with -v for the traceback"),
    (KeyboardInterrupt(), ExitCode.INTERRUPTED, "interrupted"),
    (PermissionError(13, "Permission denied", "/results/report.md"), ExitCode.INPUT,
     "/results/report.md: Permission denied"),
])
def test_error_in_a_command_is_one_line_without_traceback(tmp_path, capsys, monkeypatch, err,
                                                          code, expected):
    from valve_dolfinx.cli import main

    _report_raising(monkeypatch, err)
    assert main(["report", str(tmp_path)]) == code
    _assert_one_error_line(capsys.readouterr().err, expected)


def test_verbose_shows_the_traceback_and_log_file_keeps_the_line(tmp_path, capsys, monkeypatch):
    from valve_dolfinx.cli import main

    _report_raising(monkeypatch, ZeroDivisionError("float division by zero"))
    log_file = tmp_path / "logs" / "run.log"
    assert main(["report", str(tmp_path), "-v", "--log-file", str(log_file)]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "ZeroDivisionError" in err
    logged = log_file.read_text()
    assert ERROR_LINE.match(logged) and "float division by zero" in logged
    assert main(["-q", "report", str(tmp_path), "--log-file", str(log_file)]) == 1
    assert len(_error_lines(log_file.read_text())) == 2  # appended


def test_unwritable_log_file_is_a_usage_error(tmp_path, capsys):
    from valve_dolfinx.cli import main

    (tmp_path / "a_file").write_text("")
    with pytest.raises(SystemExit) as exit_:
        main(["report", str(tmp_path), "--log-file", str(tmp_path / "a_file" / "run.log")])
    assert exit_.value.code == ExitCode.USAGE
    err = capsys.readouterr().err
    assert "Traceback" not in err and "--log-file" in err and "writable" in err


def test_solver_failure_in_a_run_is_one_line(tmp_path, capsys, monkeypatch):
    """A solver that breaks down mid-run (stand-in for PETSc failing): status 5, one line."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.solvers.pseudo_transient import PseudoTransientSolver

    def broken_solve(self, progress=None):
        raise SolverError("SNES diverged at step 1 (DIVERGED_LINE_SEARCH): residual 30.3 mN")

    monkeypatch.setattr(PseudoTransientSolver, "solve", broken_solve)
    code = main(["run", "--mesh-size", "1.6", "--out", str(tmp_path / "case")])
    assert code == ExitCode.SOLVER
    _assert_one_error_line(capsys.readouterr().err, "SNES diverged", "DIVERGED_LINE_SEARCH")


def test_unconverged_run_exits_3_with_files_readable_under_umask_022(tmp_path):
    """A wall-time limit that cannot be met: status 3, the reason on stderr, no traceback;
    every file written is 0644 under umask 022 (not the temporary files' 0600)."""
    out = tmp_path / "case"
    proc = _cli("run", "--mesh-size", "1.6", "--wall-time-limit", "0.01", "--out", str(out),
                umask=0o022)
    assert proc.returncode == ExitCode.NOT_CONVERGED, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    assert "wall-clock limit" in proc.stderr and "NOT converged" in proc.stdout
    # stderr is no terminal: no progress bar; VTK's warnings (no X display) only under -v
    assert "\r" not in proc.stderr and "\x1b[" not in proc.stderr
    assert "X server" not in proc.stderr and (out / "closed_valve.png").is_file()
    files = [p for p in out.rglob("*") if p.is_file()]
    assert {"result.json", "config.toml", "history.csv"} <= {p.name for p in files}
    modes = {p.name: oct(stat.S_IMODE(p.stat().st_mode)) for p in files}
    assert set(modes.values()) == {"0o644"}, modes


# --- the output folder, before any computation ------------------------------------------
def _must_not_build(monkeypatch) -> None:
    from valve_dolfinx.geometry import valve

    def build_valve(*args, **kwargs):
        raise AssertionError("a mesh was built")

    monkeypatch.setattr(valve, "build_valve", build_valve)


@pytest.mark.parametrize("command", [["run", "--mesh-size", "2.0"], ["mesh"],
                                     ["sweep", "--widths", "0", "--heights", "0"]])
def test_out_below_a_file_is_the_same_error_in_every_command(tmp_path, caplog, monkeypatch,
                                                             quiet_cli, command):
    """--out below a file: status 7 and one line naming the file, before any mesh is built,
    in run, mesh and sweep alike; --out that is a file: the same status."""
    from valve_dolfinx.cli import main

    _must_not_build(monkeypatch)
    blocker = tmp_path / "results"
    blocker.write_text("keep me")
    for out, text in ((blocker / "case", f"is below the file {blocker}"),
                      (blocker, "is a file")):
        caplog.clear()
        assert main([*command, "--out", str(out)]) == ExitCode.OUTPUT_NOT_FOLDER
        errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
        assert len(errors) == 1 and f"--out {out} {text}" in errors[0], errors
    assert blocker.read_text() == "keep me"


#: prctl(2) operation, and the capabilities that let root write through permissions
PR_CAPBSET_DROP, CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH = 24, 1, 2


def _respect_permissions() -> None:
    """In a child of root: drop the capabilities to override file permissions (from its
    bounding set, so that they do not come back at exec)."""
    if os.geteuid() == 0:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        for cap in (CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH):
            if libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0) != 0:
                raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def test_run_into_a_read_only_folder_stops_before_the_mesh(tmp_path):
    """--out inside a folder that may not be written: status 8 and one line, before the mesh
    is built (the run logs nothing else)."""
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    out = locked / "case"
    proc = subprocess.run([sys.executable, "-m", "valve_dolfinx.cli", "run", "--mesh-size",
                           "2.0", "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                          timeout=120, preexec_fn=_respect_permissions)
    assert proc.returncode == ExitCode.OUTPUT_NOT_WRITABLE, proc.stderr[-2000:]
    line = _assert_one_error_line(proc.stderr, f"--out {out} cannot be created",
                                  "Permission denied")
    assert proc.stderr.strip() == line and not out.exists()


def test_load_case_names_the_damaged_file(tmp_path):
    from valve_dolfinx import load_case
    from valve_dolfinx.exceptions import InputFileError

    (tmp_path / "result.json").write_text('{"converged": tr')
    with pytest.raises(InputFileError, match=rf"{tmp_path}: result.json is not valid JSON"):
        load_case(tmp_path)
    assert exit_code(InputFileError("x")) == ExitCode.INPUT


@pytest.mark.parametrize("umask,mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_atomic_write_honours_the_umask(tmp_path, umask, mode):
    from valve_dolfinx.io import read_json, write_json

    old = os.umask(umask)
    try:
        path = write_json(tmp_path / "out" / "result.json", {"converged": True})
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == mode
    assert read_json(path) == {"converged": True}
    assert [p.name for p in path.parent.iterdir()] == ["result.json"]  # no temporary left


# --- under MPI -----------------------------------------------------------------------------
ONE_RANK_FAILS = """
import sys
from valve_dolfinx import cli
from valve_dolfinx._compat import MPI
from valve_dolfinx.exceptions import SolverError
from valve_dolfinx.study import report

def build_report(*args, **kwargs):
    if MPI.COMM_WORLD.rank == 1:
        raise SolverError("stand-in failure on rank 1 only")
    MPI.COMM_WORLD.barrier()  # rank 0 waits for a rank that will never come

report.build_report = build_report
sys.exit(cli.main(["report", sys.argv[1]]))
"""


def test_failure_on_one_rank_ends_every_rank(tmp_path):
    script = tmp_path / "one_rank_fails.py"
    script.write_text(ONE_RANK_FAILS)
    start = time.perf_counter()
    proc = subprocess.run([str(BIN / "mpirun"), "-n", "2", sys.executable, str(script),
                           str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    elapsed = time.perf_counter() - start
    assert proc.returncode != 0
    line = _assert_one_error_line(proc.stderr, "stand-in failure on rank 1 only")
    assert "[rank 1/2]" in line
    assert elapsed < 60  # MPI start-up and imports; without the abort rank 0 never returns
