"""Nothing wrong is recorded as a result: interrupts and errors inside the solvers' callbacks.

SIGINT and SIGTERM, sent as real signals at several points of a run (the root step, a
pseudo-time step, the analysis, the output) and of a sweep, end the command with
status 130 or 143 and one line, write no ``result.json`` and commit no study case; the
rerun computes the result of an uninterrupted run.  An exception raised inside a PETSc
callback (a test double of a hook that raises at its k-th call) is an error naming it,
never ``converged: false``.  The runs close the normal valve on a 2 mm mesh for 20
pseudo-time steps (``converged: false`` by the step limit, exit status 3), which is enough
to reach every stage in a few seconds.
"""

from __future__ import annotations

import json
import logging
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from valve_dolfinx.exceptions import ExitCode, Interrupted, SolverError

ROOT = Path(__file__).resolve().parents[1]
#: a short run: 20 pseudo-time steps of the normal valve on a 2 mm mesh, without figures
#: (drawing them is most of its time) but where the signal interrupts their drawing
RUN = ["run", "--mesh-size", "2.0", "--set", "solver.pseudo_transient.max_steps=20",
       "--no-figures"]
#: fields of result.json that differ between two computations of the same case
VOLATILE = ("wall_time_s",)


def _cli(*args: str, timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "valve_dolfinx.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def _interrupt(args: list[str], trigger: str, sig: int, timeout: float = 180
               ) -> tuple[int, str]:
    """Start ``valve-dolfinx -v ARGS``, send ``sig`` once a line of its log matches
    ``trigger``, and return its exit status and log."""
    proc = subprocess.Popen([sys.executable, "-m", "valve_dolfinx.cli", "-v", *args],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    lines = []
    for line in proc.stderr:
        lines.append(line)
        if re.search(trigger, line):
            proc.send_signal(sig)
            break
    rest = proc.communicate(timeout=timeout)[1]
    assert re.search(trigger, "".join(lines)), "".join(lines)[-3000:]
    return proc.returncode, "".join(lines) + rest


def _stable(folder: Path) -> dict:
    """result.json without its timings (the intersection check times itself too)."""
    data = json.loads((folder / "result.json").read_text())
    stable = {k: v for k, v in data.items() if k not in VOLATILE}
    stable["intersections"] = {k: v for k, v in stable.get("intersections", {}).items()
                               if k != "check_time_s"}
    return stable


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory) -> Path:
    """The short run, uninterrupted."""
    out = tmp_path_factory.mktemp("reference") / "case"
    proc = _cli(*RUN, "--out", str(out))
    assert proc.returncode == ExitCode.NOT_CONVERGED, proc.stderr[-3000:]
    return out


# --- the guard and the deferred signals, in this process ----------------------------------
def test_guard_raises_what_a_callback_raised(caplog):
    """The first exception of any kind is kept; the solver's own stop is a failed solve
    (nothing raised), an interrupt is raised as itself, anything else as a SolverError with
    the exception's type, message, the callback and where the solve was."""
    from valve_dolfinx.solvers.callbacks import CallbackGuard

    class Stop(RuntimeError):
        pass

    def residual(k):
        raise ZeroDivisionError(f"stand-in bug at call {k}")

    guard = CallbackGuard(stops=(Stop,))
    wrapped = guard.wrap(residual)
    for k in (1, 2):  # PETSc stops at the first; a second one would not replace it
        with pytest.raises(ZeroDivisionError):
            wrapped(k)
    with pytest.raises(SolverError) as err:
        guard.reraise("at step 7")
    assert str(err.value) == ("ZeroDivisionError in the solver's callback residual at step 7: "
                              "stand-in bug at call 1")
    assert isinstance(err.value.__cause__, ZeroDivisionError)
    guard.reraise("at step 8")  # forgotten once raised
    with pytest.raises(Stop):
        guard.wrap(_raising(Stop("dt below dt_min")))()
    guard.reraise("at step 9")  # a failed solve: the solver reports it
    interrupt = Interrupted(signal.SIGTERM)
    with pytest.raises(Interrupted):
        guard.wrap(_raising(interrupt))()
    with pytest.raises(Interrupted) as raised:
        guard.reraise("at step 10")
    assert raised.value is interrupt and raised.value.signum == signal.SIGTERM


def _raising(err: BaseException):
    def callback():
        raise err

    return callback


def test_a_signal_in_a_solve_waits_for_the_next_callback():
    """Inside the guard a real SIGINT only notes itself: the code running goes on, the next
    guarded callback raises it (and the guard keeps it); without a callback, leaving the
    guard raises it."""
    from valve_dolfinx.solvers.callbacks import CallbackGuard

    calls = []
    guard = CallbackGuard()
    callback = guard.wrap(lambda: calls.append("ran"))
    handler = signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt), guard:
        os.kill(os.getpid(), signal.SIGINT)
        calls.append("after the signal")  # not interrupted: PETSc's C code would go on
        callback()
    assert calls == ["after the signal"]
    assert isinstance(guard.caught, KeyboardInterrupt)
    with pytest.raises(KeyboardInterrupt), guard:
        os.kill(os.getpid(), signal.SIGINT)
        calls.append("the solve ends")
    assert calls[-1] == "the solve ends"
    assert signal.getsignal(signal.SIGINT) is handler  # restored


# --- an error inside a PETSc callback -----------------------------------------------------
@pytest.mark.parametrize("solver", ["ptc", "bdf2"])
def test_error_in_a_callback_is_an_error_not_an_unconverged_case(tmp_path, caplog,
                                                                 monkeypatch, solver):
    """The contact hook made to raise at its 5th residual evaluation (inside TS.solve): the
    run ends with status 5 and one line naming the exception, its message, the callback and
    the step; no result.json, so nothing reads as ``converged: false``."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.solvers.contact_hook import ContactHook

    calls = []
    real = ContactHook.add_residual

    def add_residual(self, state, b):
        calls.append(1)
        if len(calls) == 5:
            raise ZeroDivisionError("stand-in bug in the contact force")
        return real(self, state, b)

    monkeypatch.setattr(ContactHook, "add_residual", add_residual)
    out = tmp_path / "case"
    code = main(["run", "--mesh-size", "2.0", "--solver", solver, "--out", str(out)])
    assert code == ExitCode.SOLVER
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1, errors
    assert re.search(r"ZeroDivisionError in the solver's callback ifunction at .*step \d+.*: "
                     r"stand-in bug in the contact force", errors[0]), errors[0]
    assert len(calls) == 5 and not (out / "result.json").exists()


def test_error_in_a_callback_fails_the_study_case(tmp_path, monkeypatch, quiet_cli):
    """In a sweep the case is recorded as failed with the exception as its reason (not as a
    finished, unconverged case), and the sweep ends with status 9."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.solvers.contact_hook import ContactHook

    def add_residual(self, state, b):
        raise ZeroDivisionError("stand-in bug in the contact force")

    monkeypatch.setattr(ContactHook, "add_residual", add_residual)
    out = tmp_path / "study"
    code = main(["sweep", "--widths", "0", "--heights", "0", "--mesh-size", "2.0",
                 "--case-index", "0", "--out", str(out)])
    assert code == ExitCode.STUDY_INCOMPLETE
    record = json.loads((out / "cases" / "normal" / "case.json").read_text())
    assert record["status"] == "failed"
    assert "ZeroDivisionError" in record["reason"] and "stand-in bug" in record["reason"]
    result = json.loads((out / "cases" / "normal" / "result.json").read_text())
    assert result["min_coaptation_height_mm"] is None and result["error"] == record["reason"]


# --- real signals to a run --------------------------------------------------------------------
@pytest.mark.parametrize("stage,trigger,sig", [
    ("root step", r"INFO +distributed valve:", signal.SIGTERM),
    ("early step", r"closing: step 2,", signal.SIGINT),
    ("analysis", r"pseudo-transient continuation: NOT converged", signal.SIGINT),
    pytest.param("output", r"wrote .*closed_valve\.png", signal.SIGTERM,
                 marks=pytest.mark.slow),  # the figures drawn twice: over 30 s
])
def test_interrupted_run_records_nothing_and_resumes(tmp_path, reference_run, stage, trigger,
                                                     sig):
    """The signal ends the run with 128 + its number and one line; no result.json (an
    interrupted rerun of a finished case, with --force, removes the old one first); the
    rerun gives the uninterrupted run's result."""
    out = tmp_path / "case"
    force = []
    if stage == "early step":
        shutil.copytree(reference_run, out)
        force = ["--force"]
    run = [arg for arg in RUN if arg != "--no-figures"] if stage == "output" else RUN
    code, log = _interrupt([*run, "--out", str(out), *force], trigger, sig)
    assert code == 128 + sig, log[-3000:]
    errors = [line for line in log.splitlines() if "error:" in line]
    assert len(errors) == 1 and f"interrupted ({signal.Signals(sig).name})" in errors[0], log
    assert not (out / "result.json").exists()
    proc = _cli(*run, "--out", str(out))
    assert proc.returncode == ExitCode.NOT_CONVERGED, proc.stderr[-3000:]
    assert "already holds this case" not in proc.stdout
    assert (out / "closed_valve.png").is_file() == (run is not RUN)
    assert _stable(out) == _stable(reference_run)
    assert (out / "history.csv").read_text() == (reference_run / "history.csv").read_text()


# --- real signals to a sweep ------------------------------------------------------------------
@pytest.mark.slow
def test_interrupted_sweep_records_nothing_and_resumes(tmp_path):
    """SIGINT to a real sweep once its first case is logged, while the second is computed:
    status 130; the second case is neither finished nor claimed; the rerun computes only it
    (``--no-figures``: no case draws its figures, the report has no panels)."""
    out = tmp_path / "study"
    sweep = ["sweep", "--widths", "0", "--heights", "0", "--mesh-size", "2.0", "--set",
             "solver.pseudo_transient.max_steps=20", "--no-progress", "--no-figures",
             "--out", str(out)]
    code, log = _interrupt(sweep, r"\[1/2\] normal:", signal.SIGINT)
    assert code == ExitCode.INTERRUPTED, log[-3000:]
    assert sorted(p.name for p in (out / "cases").iterdir()) == [".claims", ".staging",
                                                                   "normal"]
    assert not any((out / "cases" / ".claims").iterdir())
    assert not any((out / "cases" / ".staging").iterdir())
    listing = _cli(*sweep, "--list").stdout
    assert re.search(r"normal .* finished", listing) and re.search(r"W0_H0 .* pending", listing)
    proc = _cli(*sweep)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "1 case(s) computed" in proc.stdout
    assert "1 of 2 cases already finished" in proc.stderr
    assert not list((out / "cases").rglob("*.png"))  # --no-figures: not even the panels
