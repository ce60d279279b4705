"""Nothing false from `report`, from a second process or from a rerun.

Every reader of a study's cases -- `sweep`, `plan`, `nomogram`, `report` -- counts a case
only when it is the case the study's layout expects (settings hash and start), finished,
and intact by the SHA-256 of each file recorded at commit; a study with any other case
writes no answer and ends with status 9 naming it.  Each test reproduces a way an answer
went wrong before (an interrupted rerun with another setting, a damaged or missing case, a
case another process holds, an interrupted --force, the documented plan rerun, inputs that
failed late), on the stand-in case functions of ``test_study`` and ``test_plan``, with real
processes and signals where the way needs them, so that it takes seconds.
"""

from __future__ import annotations

import json
import logging
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from test_plan import _patient, no_case
from test_plan import stand_in_case as plan_case
from test_study import ROOT, _runs, _settings, _sweep_cmd, cli_with
from test_study import stand_in_case as study_case

from valve_dolfinx._compat import MPI
from valve_dolfinx.exceptions import ExitCode, Interrupted, StudyIncompleteError

#: the files that state a plan's answer, and those of its study
PLAN_ANSWER = ("plan.md", "plan.pdf", "summary.json", "template_W14_H13.svg",
               "template_W14_H13.pdf", "template_W14_H13.png")
STUDY_ANSWER = ("sizing_map.png", "coaptation_vs_width.png")


def _interrupted_after(n: int, case_function):
    """``case_function`` that is interrupted (as by Ctrl-C) when its ``n + 1``-th case starts."""
    calls: list[str] = []

    def case(config, out_dir, comm, *, start=None):
        if len(calls) == n:
            raise Interrupted(signal.SIGINT)
        calls.append(out_dir.name)
        return case_function(config, out_dir, comm, start=start)

    return case


def _counting(case_function, ran: list[str]):
    def case(config, out_dir, comm, *, start=None):
        ran.append(Path(out_dir).name.split("@")[0])
        return case_function(config, out_dir, comm, start=start)

    return case


def _rows(study: Path) -> dict[str, dict]:
    return {r["case"]: r for r in json.loads((study / "results.json").read_text())}


# --- 1. cases of other settings --------------------------------------------------------------
def test_report_over_an_interrupted_rerun_with_other_settings_is_no_answer(tmp_path, caplog,
                                                                           quiet_cli):
    """A sweep rerun with another bending modulus, interrupted after its first case: study.json
    holds the new settings, the other case folders the old ones.  `report` names them stale,
    writes no recommendation or map over them and ends with status 9; the sweep computes
    exactly them and the report is then whole."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.study.runner import run_study

    out = tmp_path / "study"
    run_study(_settings(), out, MPI.COMM_SELF, case_function=study_case)
    assert all((out / name).is_file() for name in STUDY_ANSWER)
    stiff = _settings(case={"native": {"bending_modulus_kpa": 100.0}})
    with pytest.raises(Interrupted):
        run_study(stiff, out, MPI.COMM_SELF, case_function=_interrupted_after(1, study_case))
    assert main(["report", str(out)]) == ExitCode.STUDY_INCOMPLETE
    rows = _rows(out)
    stale = sorted(name for name, row in rows.items() if row["status"] == "stale")
    assert stale == ["W0_H0", "W7_H0"]  # the normal valve was recomputed before the interrupt
    assert rows["W7_H0"]["min_coaptation_height_mm"] is None
    assert "computed with other settings" in rows["W7_H0"]["reason"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] is False and summary["recommendations"] == []
    assert summary["unfinished"] == {"stale": ["W0_H0", "W7_H0"]}
    assert not any((out / name).exists() for name in STUDY_ANSWER)
    report = (out / "report.md").read_text()
    assert "## No answer: the study is incomplete" in report and "## Recommendation" not in report
    assert "stale: W0_H0, W7_H0" in caplog.text

    ran: list[str] = []
    run_study(stiff, out, MPI.COMM_SELF, case_function=_counting(study_case, ran))
    assert sorted(ran) == ["W0_H0", "W7_H0"]
    assert main(["report", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["complete"] is True


def test_a_folder_without_study_json_is_read_without_an_expected_identity(tmp_path, quiet_cli):
    """Without study.json there are no settings to expect: every whole case counts (the grid
    is guessed from the folders), as before; a damaged one still does not."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.study.runner import run_study

    out = tmp_path / "study"
    run_study(_settings(mesh_size_mm=1.9), out, MPI.COMM_SELF, case_function=study_case)
    (out / "study.json").unlink()
    assert main(["report", str(out)]) == 0
    assert {row["status"] for row in _rows(out).values()} == {"finished"}
    _edit_same_size(out / "cases" / "W0_H0" / "result.json")
    assert main(["report", str(out)]) == ExitCode.STUDY_INCOMPLETE
    assert _rows(out)["W0_H0"]["status"] == "damaged"


# --- 1, 5. damaged and missing cases ---------------------------------------------------------
def _edit_same_size(path: Path) -> None:
    """Change one digit of result.json's minimum coaptation height, keeping the file's size."""
    text = path.read_text()
    key = '"min_coaptation_height_mm": '
    at = text.index(key) + len(key)
    digit = next(i for i in range(at, len(text)) if text[i].isdigit())
    edited = text[:digit] + ("1" if text[digit] != "1" else "2") + text[digit + 1:]
    assert len(edited) == len(text) and edited != text
    path.write_text(edited)


def test_a_same_size_edit_is_found_and_recomputed(tmp_path, caplog):
    """An edited number in result.json (the file's size unchanged) makes the case damaged:
    the report leaves it out and a rerun computes it again, naming the file."""
    from valve_dolfinx.study.runner import run_study

    out, ran = tmp_path / "study", []
    run_study(_settings(), out, MPI.COMM_SELF, case_function=study_case)
    whole = _rows(out)["W7_H0"]["min_coaptation_height_mm"]
    _edit_same_size(out / "cases" / "W7_H0" / "result.json")
    caplog.set_level(logging.WARNING)
    outcome = run_study(_settings(), out, MPI.COMM_SELF,
                        case_function=_counting(study_case, ran))
    assert ran == ["W7_H0"]
    assert "W7_H0: result.json has changed since it was written" in caplog.text
    assert outcome.report.complete
    assert _rows(out)["W7_H0"]["min_coaptation_height_mm"] == whole


@pytest.mark.parametrize("damage", ["deleted normal valve", "truncated result", "same-size edit"])
def test_report_on_a_plan_with_a_missing_or_damaged_case_writes_no_plan(tmp_path, capsys,
                                                                       caplog, quiet_cli,
                                                                       damage):
    """`report DIR` on a plan whose study lacks a case, or holds a damaged one, ends with
    status 9 naming it and leaves no plan behind; `plan` then computes that case alone."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.plan.runner import run_plan

    out, patient = tmp_path / "plan", _patient()
    run_plan(patient, out, MPI.COMM_SELF, mesh_size_mm=2.0, case_function=plan_case)
    summary = json.loads((out / "summary.json").read_text())
    cases = out / "study" / "cases"
    name = "normal__root.loaded_diameter_mm=22"
    if damage == "deleted normal valve":
        for path in sorted((cases / name).iterdir()):
            path.unlink()
        (cases / name).rmdir()
        why = f"not run yet: {name}"
    elif damage == "truncated result":
        text = (cases / name / "result.json").read_text()
        (cases / name / "result.json").write_text(text[: len(text) // 2])
        why = f"damaged: {name}"
    else:
        _edit_same_size(cases / name / "result.json")
        why = f"damaged: {name}"
    assert main(["report", str(out)]) == ExitCode.STUDY_INCOMPLETE
    assert why in caplog.text and "No plan is written" in caplog.text
    assert "No graft" not in capsys.readouterr().out
    for answer in ("plan.md", "plan.pdf", "summary.json"):
        assert not (out / answer).exists(), answer
    ran: list[str] = []
    run_plan(patient, out, MPI.COMM_SELF, mesh_size_mm=2.0,
             case_function=_counting(plan_case, ran))
    assert ran == [name]
    assert json.loads((out / "summary.json").read_text()) == summary


# --- 2. a case another live process holds ----------------------------------------------------
@pytest.fixture
def holder():
    """A live process of another run, to hold claims: ``holder(out, name)`` writes its claim."""
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])

    def hold(out: Path, name: str) -> Path:
        from valve_dolfinx.study.store import CaseClaim, _process_start

        path = CaseClaim.for_case(out, name).path
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"host": socket.gethostname(), "pid": proc.pid,
                                    "start": _process_start(proc.pid), "token": "other",
                                    "run": "another run"}))
        return path

    hold.proc = proc
    yield hold
    proc.kill()
    proc.wait()


def test_no_wait_names_the_case_another_process_computes(tmp_path, caplog, quiet_cli, holder):
    """W7_H0 claimed by a live process: `sweep --no-wait` computes the others, ends with status
    9 naming W7_H0 as in progress with its pid, and writes no answer; `report` says the
    same; the claim is left alone."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.study.store import prepare_output

    out = prepare_output(tmp_path / "study")
    claim = holder(out, "W7_H0")
    grid = ["--widths", "0", "7", "--heights", "0", "--mesh-size", "2", "--no-progress"]
    assert cli_with(study_case, ["sweep", *grid, "--out", str(out), "--no-wait"]) == \
        ExitCode.STUDY_INCOMPLETE
    (error,) = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert f"in progress in another process: W7_H0 (pid {holder.proc.pid} on" in error
    assert claim.is_file() and not (out / "cases" / "W7_H0").exists()
    assert not any((out / name).exists() for name in STUDY_ANSWER)
    caplog.clear()
    assert main(["report", str(out)]) == ExitCode.STUDY_INCOMPLETE
    assert f"in progress: W7_H0 (pid {holder.proc.pid} on" in caplog.text
    assert json.loads((out / "summary.json").read_text())["complete"] is False


def test_a_second_sweep_waits_for_the_case_the_first_computes(tmp_path):
    """Two real sweeps on one folder, the second started while the first computes the last
    case (held at a gate until the second says it waits): the second waits for it, and both
    end with the whole answer, each case computed once."""
    out, run_log, gate = tmp_path / "study", tmp_path / "runs.log", tmp_path / "gate"
    env = {**os.environ, "STUDY_RUN_LOG": str(run_log), "STUDY_STAND_IN_GATE": str(gate)}
    sweep = _sweep_cmd("--widths", "7", "--heights", "0", "--mesh-size", "2", "--out",
                       str(out), "--no-progress")
    first = subprocess.Popen(sweep, env=env, cwd=ROOT, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while len(_runs(run_log)) < 2 and time.time() < deadline:  # W7_H0 is at the gate
        time.sleep(0.02)
    second = subprocess.Popen(sweep, env=env, cwd=ROOT, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    waited = ""
    for line in second.stderr:
        if "waiting for" in line:
            waited = line
            break
    gate.touch()
    out_second, _ = second.communicate(timeout=60)
    first.communicate(timeout=60)
    assert first.returncode == second.returncode == 0
    assert re.search(rf"waiting for W7_H0: pid {first.pid} on \S+ computes it", waited), waited
    assert _runs(run_log) == ["normal", "W7_H0"]  # each computed once, by the first
    assert "0 case(s) computed" in out_second
    assert "the study is incomplete" not in out_second
    # the whole answer of one graft: the solved cell as it is, too few cells for a surface
    assert "No answer: a response surface needs at least 6 solved cells" in out_second
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] is True and len(summary["recommendations"]) == 1


def test_a_sweep_waits_for_a_case_another_process_holds(tmp_path, caplog, quiet_cli, holder):
    """Without --no-wait the sweep logs that it waits for W7_H0, and when the process holding
    it ends without finishing it, takes the case over and computes it: the answer is whole."""
    from valve_dolfinx.study.runner import run_study
    from valve_dolfinx.study.store import prepare_output

    out = prepare_output(tmp_path / "study")
    holder(out, "W7_H0")
    caplog.set_level(logging.INFO)
    timer = threading.Timer(1.5, lambda: (holder.proc.kill(), holder.proc.wait()))
    timer.start()
    ran: list[str] = []
    try:
        outcome = run_study(_settings(), out, MPI.COMM_SELF, poll_s=0.2,
                            case_function=_counting(study_case, ran))
    finally:
        timer.cancel()
    assert f"waiting for W7_H0: pid {holder.proc.pid} on" in caplog.text
    assert sorted(ran) == ["W0_H0", "W7_H0", "normal"] and ran[-1] == "W7_H0"
    assert outcome.report.complete and not outcome.in_progress
    assert (out / "sizing_map.png").is_file()


def test_plan_no_wait_writes_no_plan_over_a_case_in_progress(tmp_path, holder):
    from valve_dolfinx.plan.runner import run_plan

    out, patient = tmp_path / "plan", _patient(root_uncertainty_mm=0.0, paths=1)
    holder(out / "study", "W14_H13__root.loaded_diameter_mm=22")
    with pytest.raises(StudyIncompleteError, match="in progress: W14_H13"):
        run_plan(patient, out, MPI.COMM_SELF, mesh_size_mm=2.0, case_function=plan_case,
                 wait=False)
    assert not (out / "plan.md").exists() and not (out / "summary.json").exists()


# --- 4. --force and the documented rerun -----------------------------------------------------
def test_an_interrupted_force_rerun_leaves_no_old_answer(tmp_path, caplog, quiet_cli):
    """`plan --force` with another fibre angle, interrupted after its first case: the old plan,
    its templates and its study's report are gone before anything is computed; `report DIR`
    then ends with status 9 (the old cases are stale) and writes no plan."""
    from valve_dolfinx.cli import main
    from valve_dolfinx.plan.runner import run_plan

    out = tmp_path / "plan"
    run_plan(_patient(), out, MPI.COMM_SELF, mesh_size_mm=2.0, case_function=plan_case)
    assert all((out / name).is_file() for name in PLAN_ANSWER)
    turned = _patient(graft_fibre_angle_deg=30.0)
    with pytest.raises(Interrupted):
        run_plan(turned, out, MPI.COMM_SELF, mesh_size_mm=2.0, force=True,
                 case_function=_interrupted_after(0, plan_case))
    for name in (*PLAN_ANSWER, "study/summary.json", "study/report.md", "study/sizing_map.png"):
        assert not (out / name).exists(), name
    assert "graft_fibre_angle_deg = 30.0" in (out / "patient.toml").read_text()
    assert main(["report", str(out)]) == ExitCode.STUDY_INCOMPLETE
    assert "stale: W7_H13__root.loaded_diameter_mm=21" in caplog.text
    assert not (out / "plan.md").exists() and not (out / "summary.json").exists()


def test_the_documented_rerun_recomputes_nothing(tmp_path, capsys, caplog, quiet_cli):
    """`plan DIR/patient.toml --out DIR` after a plan on a 2 mm mesh runs that plan again
    (patient.toml records the mesh): nothing is computed, the same answer is written.  The
    same file with another mesh would replace finished cases: refused without --force."""
    out = tmp_path / "plan"
    assert cli_with(plan_case, ["plan", "--root-diameter", "22", "--leaflet-free-edge", "22",
                                "--leaflet-height", "13", "--widths", "7", "14", "--heights",
                                "13", "--mesh-size", "2", "--full-grid", "--out", str(out),
                                "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert "mesh_size_mm = 2.0" in (out / "patient.toml").read_text()
    patient = str(out / "patient.toml")
    assert cli_with(no_case, ["plan", patient, "--out", str(out), "--no-progress"]) == 0
    assert json.loads((out / "summary.json").read_text()) == summary
    assert cli_with(no_case, ["plan", patient, "--out", str(out), "--mesh-size", "1.9",
                              "--no-progress"]) == ExitCode.OUTPUT_CONFLICT
    assert "--force" in caplog.text


def test_a_plan_whose_study_ran_with_other_settings_needs_force(tmp_path):
    """A patient.toml without the numerics (as written before they were recorded) over a
    study on a 2 mm mesh: rerunning it at the default mesh is refused, nothing computed."""
    from valve_dolfinx.exceptions import OutputConflictError
    from valve_dolfinx.plan.patient import write_patient
    from valve_dolfinx.plan.runner import run_plan

    out = tmp_path / "plan"
    run_plan(_patient(), out, MPI.COMM_SELF, mesh_size_mm=2.0, case_function=plan_case)
    write_patient(out / "patient.toml", _patient())
    with pytest.raises(OutputConflictError, match="computed with other settings"):
        run_plan(_patient(), out, MPI.COMM_SELF, case_function=no_case)


# --- 5, 6. inputs checked before computing, in words that name the problem -------------------
@pytest.mark.parametrize("label", ["fee $5 or $6", "plan $\\frac$ 7"])
def test_a_label_with_dollars_is_plain_text_everywhere(tmp_path, label):
    """A plan label with paired `$` is drawn as written on the template and the report: not
    typeset as math (the dollars gone), nor, when it is no valid math, a crash after the
    study."""
    from test_plan import _pdf_text

    from valve_dolfinx.plan.runner import run_plan

    out = tmp_path / "plan"
    run_plan(_patient(label=label), out, MPI.COMM_SELF, mesh_size_mm=2.0,
             case_function=plan_case)
    assert f"Repair plan: {label}" in _pdf_text(out / "plan.pdf")
    assert f"Graft template: {label}" in _pdf_text(out / "template_W14_H13.pdf")


def test_patient_and_configuration_files_are_read_with_a_byte_order_mark(tmp_path):
    from valve_dolfinx.config import load_config
    from valve_dolfinx.plan.patient import read_patient

    patient = tmp_path / "PATIENT.toml"
    patient.write_bytes(b"\xef\xbb\xbfroot_diameter_mm = 22.0\n")
    assert read_patient(patient).root_diameter_mm == 22.0
    config = tmp_path / "case.toml"
    config.write_bytes(b"\xef\xbb\xbf[loading]\npressure_mmhg = 90.0\n")
    assert load_config(config).pressure_mmhg == 90.0


@pytest.mark.parametrize("command,expect", [
    (["plan", "{dir}", "--out", "{out}"], "{dir} is a folder, not a patient file"),
    (["sweep", "--config", "{dir}", "--out", "{out}"], "{dir} is a folder, not a configuration"),
    (["run", "--config", "{dir}", "--out", "{out}"], "{dir} is a folder, not a configuration"),
])
def test_a_folder_given_as_a_file_is_named_as_a_folder(tmp_path, caplog, quiet_cli, command,
                                                       expect):
    from valve_dolfinx.cli import main

    where = {"dir": str(tmp_path), "out": str(tmp_path / "out")}
    assert main([part.format(**where) for part in command]) == ExitCode.INPUT
    assert expect.format(**where) in caplog.text
    assert not (tmp_path / "out").exists()


def test_report_names_a_plan_folder_without_its_patient_file(tmp_path, caplog, quiet_cli):
    from valve_dolfinx.cli import main
    from valve_dolfinx.plan.runner import run_plan

    out = tmp_path / "plan"
    run_plan(_patient(), out, MPI.COMM_SELF, mesh_size_mm=2.0, case_function=plan_case)
    (out / "patient.toml").unlink()
    assert main(["report", str(out)]) == ExitCode.INPUT
    assert f"{out} holds a plan's study/ but no patient.toml" in caplog.text


def test_report_into_a_folder_it_cannot_write_names_the_folder(tmp_path, caplog, quiet_cli,
                                                               monkeypatch):
    """A folder that refuses new files (a read-only one: mkstemp's PermissionError, raised
    here since the tests may run as root) is named, not the hidden temporary file."""
    import tempfile

    from valve_dolfinx.cli import main
    from valve_dolfinx.study.runner import run_study

    out = tmp_path / "study"
    run_study(_settings(), out, MPI.COMM_SELF, case_function=study_case, report=False)

    def refuse(prefix="", suffix="", dir=None):
        raise PermissionError(13, "Permission denied", f"{dir}/{prefix}x1y2{suffix}")

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    assert main(["report", str(out)]) == ExitCode.OUTPUT_NOT_WRITABLE
    (error,) = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert f"{out} cannot be written (Permission denied)" in error and "x1y2" not in error


@pytest.mark.parametrize("command", [["sweep", "--widths", "7", "--heights", "0"],
                                     ["plan", "--root-diameter", "22"]])
def test_one_target_range_everywhere(tmp_path, caplog, quiet_cli, command):
    from valve_dolfinx.cli import main

    out = tmp_path / "out"
    assert main([*command, "--target-coaptation", "12", "--out", str(out)]) == ExitCode.USAGE
    assert "(0, 10] mm" in caplog.text and not out.exists()


def test_a_target_from_a_normal_valve_that_leaks_is_said_so(tmp_path):
    """The normal valve at 23 mm leaks: the plan's answer and the study's recommendation say
    that the target there comes from a valve that is not competent."""
    from test_plan import _words

    from valve_dolfinx.plan.runner import run_plan

    def leaking_at_23(config, out_dir, comm, *, start=None):
        result = plan_case(config, out_dir, comm, start=start)
        if not config.geometry.has_graft and config.root.loaded_diameter == 23.0:
            result.update(competent=False, regurgitant_orifice_area_mm2=0.4,
                          competence_reason="leaks 0.40 mm²")
        return result

    out = tmp_path / "plan"
    outcome = run_plan(_patient(), out, MPI.COMM_SELF, mesh_size_mm=2.0,
                       case_function=leaking_at_23)
    warning = f"the normal valve is not competent (leaks 0.40 mm²) at {_words(23.0, 1)}"
    assert warning in outcome.answers.headline()
    assert warning in json.loads((out / "summary.json").read_text())["answers"]["values"][0][
        "headline"]
    (study,) = json.loads((out / "study" / "summary.json").read_text())["recommendations"]
    assert "Caution: the target is the height of a normal valve that is not competent" in (
        study["text"])
    assert list(study["incompetent_targets"]) == [
        "root.loaded_diameter_mm=23, path 1 (from the closed valve)",
        "root.loaded_diameter_mm=23, path 2 (from the open valve)"]
