"""Running one patient's plan: check, study, template, report (SPEC §9).

:func:`run_plan` does, in order:

1. validates everything the plan will run (the patient, the study grid, every case
   setting) before any computation;
2. checks in closed form whether the native leaflets can span the measured root at all
   (:mod:`valve_dolfinx.plan.reach`); if not, that is the answer and nothing is computed;
3. runs the plan's study, :func:`run_plan_study` -- the one function that decides which
   cases are solved and turns their results into a :class:`PlanRecommendation`;
4. draws the template of the recommended (or closest) graft and of any graft asked for;
5. writes ``plan.md``, ``plan.pdf`` and ``summary.json``.

Layout of a plan folder ``DIR``::

    DIR/patient.toml                 the inputs as they ran (reloadable)
    DIR/plan.md, DIR/plan.pdf        the one-page report
    DIR/summary.json                 the answer, the reach check, the templates' dimensions
    DIR/template_W<w>_H<h>.svg/.pdf  the graft at true size (and .png, the report's thumbnail)
    DIR/study/                       the study folder (a sweep's layout: cases/, results.csv...)

Every step but the study is cheap; the study resumes like a sweep, so a rerun with the
same inputs recomputes nothing and rewrites the plan's files.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from valve_dolfinx._compat import MPI
from valve_dolfinx.config import config_from_dict, set_dotted
from valve_dolfinx.exceptions import OutputConflictError, ParameterError
from valve_dolfinx.io import check_output_folder, write_json
from valve_dolfinx.plan.patient import PATIENT_FILE, PatientInput, read_patient, write_patient
from valve_dolfinx.plan.reach import FreeEdgeReach, free_edge_reach
from valve_dolfinx.plan.recommendation import GraftSize, PlanRecommendation
from valve_dolfinx.plan.report import PlanFigures, RunInfo, write_plan_report
from valve_dolfinx.plan.template import GraftTemplate, TemplateFiles, write_template
from valve_dolfinx.study.grid import StudySettings

__all__ = ["LIMITATIONS", "STUDY_DIR", "PlanOutcome", "PlanStudy", "plan_study_settings",
           "run_plan", "run_plan_study"]

log = logging.getLogger(__name__)

#: the plan's study folder inside the plan folder
STUDY_DIR = "study"
SUMMARY_FILE = "summary.json"
#: what the answer does not cover, printed on the report
LIMITATIONS = (
    "An idealised valve: a cylindrical root prescribed at the measured diameter, the three "
    "leaflets scaled from the one measured leaflet, published tissue laws for the leaflets "
    "and the glutaraldehyde-fixed pericardium, one static closure under diastolic pressure "
    "(no flow, no opening, no remodelling or ageing of the graft); coaptation heights are "
    "resolved to about 0.3 mm at the default mesh.")
#: the numerical path every case of today's study takes (the case default)
_PATH = "conformal placement"


@dataclass
class PlanStudy:
    """What the plan's study hands back (on rank 0; the other ranks get None)."""

    recommendation: PlanRecommendation
    figures: PlanFigures
    run: RunInfo
    folder: Path


@dataclass
class PlanOutcome:
    """What :func:`run_plan` did (its files and answer on rank 0)."""

    out: Path
    recommendation: PlanRecommendation
    reach: FreeEdgeReach
    templates: list[TemplateFiles] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    elapsed_s: float = 0.0


def plan_study_settings(patient: PatientInput, mesh_size_mm: float | None = None,
                        wall_time_limit_s: float | None = None) -> StudySettings:
    """The study settings of a plan, every case setting validated (no DOLFINx imported).

    Raises
    ------
    ParameterError
        A mesh size the measured leaflet cannot take (its commissures must carry two
        edges), a grid value or a setting out of range -- before any computation.
    """
    settings = StudySettings(widths_pct=patient.graft_widths_pct,
                             heights_pct=patient.graft_heights_pct,
                             mesh_size_mm=mesh_size_mm, wall_time_limit_s=wall_time_limit_s,
                             target_coaptation_mm=patient.target_coaptation_mm,
                             panel_cases=(), case=patient.case_settings())
    data = patient.case_settings()
    if mesh_size_mm is not None:
        set_dotted(data, "geometry.mesh_size", mesh_size_mm)
    config_from_dict(data, source="the plan's case settings")
    return settings


# --- the plan's study: the one part that the robust-sizing machinery replaces -------------
def run_plan_study(patient: PatientInput, settings: StudySettings, out: Path,
                   comm: MPI.Comm, *, case_function: Callable | None = None,
                   progress: Callable[[dict], None] | None = None) -> PlanStudy | None:
    """Solve the plan's cases into ``out`` and turn them into the plan's answer.

    This is the single place where the plan decides what to compute and how a
    recommendation follows from it; everything around it (the reach check, the
    templates, the report) only reads the :class:`PlanStudy` it returns.

    Today it runs one member: the study of :func:`valve_dolfinx.study.runner.run_study`
    (the normal valve and every graft of the grid) at the measured root diameter, along
    the cases' default numerical path, and recommends with
    :func:`valve_dolfinx.study.recommend.recommend` (the target: the normal valve's
    minimum coaptation height, or the patient's).  The uncertainty members -- the root
    diameters D − U, D, D + U and more than one path, with the recommendation taken on
    each graft's worst member -- come with the robust-sizing study (``--uncertain``,
    ``--paths``); the body of this function is where they go.

    Parameters
    ----------
    patient
        The measured inputs.
    settings
        The study settings of :func:`plan_study_settings` (grid, mesh, case settings).
    out
        The study folder (created; resumable like a sweep's).
    comm
        The ranks that share the study (collective).
    case_function, progress
        Passed to ``run_study`` (a stand-in case function in tests; the progress bar).

    Returns
    -------
    PlanStudy or None
        The answer, the pictures and what was run on rank 0; None on the other ranks.
    """
    from valve_dolfinx.study.runner import run_study

    outcome = run_study(settings, out, comm, case_function=case_function, progress=progress)
    if comm.rank != 0:
        return None
    report = outcome.report
    member = f"root {patient.root_diameter_mm:.1f} mm, {_PATH}"
    recommendation = _from_study(report.recommendation, report.rows, member)
    shown = recommendation.template_graft
    case = out / "cases" / (shown.stem if shown is not None else "normal")
    figures = PlanFigures(sizing_map=_existing(out / "sizing_map.png"),
                          closed_aortic=_existing(case / "closed_valve_aortic.png"),
                          closed_ventricular=_existing(case / "closed_valve_ventricular.png"),
                          closed_member=f"root {patient.root_diameter_mm:.1f} mm")
    rows = report.rows
    first = rows[0] if rows else {}
    run = RunInfo(versions=first.get("versions") or {},
                  mesh_size_mm=first.get("mesh_size_mm", settings.mesh_size_mm),
                  cases=len(rows), converged=sum(bool(r.get("converged")) for r in rows),
                  wall_time_s=sum(float(r.get("wall_time_s") or 0.0) for r in rows))
    return PlanStudy(recommendation, figures, run, out)


def _existing(path: Path) -> Path | None:
    return path if path.is_file() else None


def _from_study(rec, rows: list[dict], member: str) -> PlanRecommendation:
    """The plan's answer from a one-member study's :class:`~valve_dolfinx.study.recommend.
    Recommendation` (its cases named ``W<w>/H<h>``)."""
    sizes = {}
    for row in rows:
        if row.get("graft_width_pct") is not None:
            size = GraftSize(float(row["graft_width_pct"]), float(row["graft_height_pct"]))
            sizes[size.label] = size
    source = ("the normal valve's at the same root" if rec.target_source.startswith(
        "the normal valve") else rec.target_source)
    common = dict(target_mm=rec.target_mm, target_source=source, members=(member,))
    if rec.recommended is not None:
        return PlanRecommendation(graft=sizes[rec.recommended],
                                  margin_mm=rec.recommended_height_mm - rec.target_mm,
                                  limiting_member=member, **common)
    if rec.best is not None:
        return PlanRecommendation(closest=sizes[rec.best], shortfall_mm=rec.shortfall_mm,
                                  **common)
    return PlanRecommendation(**common)


# --- the plan ----------------------------------------------------------------------------
def _check_folder(out: Path, patient: PatientInput, force: bool) -> None:
    """Refuse a folder that cannot hold the plan (``check_output_folder``), or that holds
    another patient's plan (unless ``force``)."""
    check_output_folder(out)
    saved = out / PATIENT_FILE
    if force or not saved.is_file():
        return
    try:
        same = read_patient(saved) == patient
    except (ParameterError, OSError):
        same = False
    if not same:
        raise OutputConflictError(f"--out {out} holds the plan of other inputs ({saved} "
                                  "differs); give another folder, or --force to replace it")


def run_plan(patient: PatientInput, out: str | Path, comm: MPI.Comm | None = None, *,
             mesh_size_mm: float | None = None, wall_time_limit_s: float | None = None,
             templates: Sequence[GraftSize] = (), force: bool = False,
             case_function: Callable | None = None,
             progress: Callable[[dict], None] | None = None) -> PlanOutcome:
    """Plan one patient's repair into the folder ``out`` (see the module docstring).

    Parameters
    ----------
    patient
        The measured inputs.
    out
        The plan folder (created).
    comm
        The ranks that share the study (default ``COMM_WORLD``).
    mesh_size_mm, wall_time_limit_s
        The cases' mesh and wall-clock limit (default: the case defaults).
    templates
        Grafts to draw besides the recommended (or closest) one.
    force
        Replace the plan of other inputs in ``out``.
    case_function, progress
        Passed to the study (:func:`run_plan_study`).

    Raises
    ------
    ParameterError, OutputConflictError, OutputNotFolderError, OutputNotWritableError
        Before any computation: a setting out of range, an unusable ``out``.
    """
    comm = MPI.COMM_WORLD if comm is None else comm
    out = Path(out)
    t0 = time.perf_counter()
    settings = plan_study_settings(patient, mesh_size_mm, wall_time_limit_s)
    error = None
    if comm.rank == 0:
        try:
            _check_folder(out, patient, force)
            write_patient(out / PATIENT_FILE, patient)
        except (OutputConflictError, OSError) as err:
            error = err
    error = comm.bcast(error, root=0)
    if error is not None:
        raise error
    reach = free_edge_reach(patient.leaflet_free_edge_mm, patient.root_diameter_mm,
                            patient.pressure_mmhg)
    study = None
    if reach.can_seal:
        study = run_plan_study(patient, settings, out / STUDY_DIR, comm,
                               case_function=case_function, progress=progress)
    elif comm.rank == 0:
        log.warning("%s", reach.sentence())
    outcome = None
    if comm.rank == 0:
        outcome = _write_plan(out, patient, reach, study, templates)
        outcome.elapsed_s = time.perf_counter() - t0
    outcome = comm.bcast(outcome, root=0)
    return outcome


def _write_plan(out: Path, patient: PatientInput, reach: FreeEdgeReach,
                study: PlanStudy | None, extra: Sequence[GraftSize]) -> PlanOutcome:
    """Templates, plan.md, plan.pdf and summary.json (rank 0)."""
    if study is None:
        recommendation = PlanRecommendation(cannot_seal=reach.sentence())
        figures, run = PlanFigures(), RunInfo()
    else:
        recommendation, figures, run = study.recommendation, study.figures, study.run
    grafts = [g for g in (recommendation.template_graft, *extra) if g is not None]
    line = (f"Measured leaflet: free edge {patient.leaflet_free_edge_mm:.1f} mm, height "
            f"{patient.leaflet_height_mm:.1f} mm; root {patient.root_diameter_mm:.1f} ± "
            f"{patient.root_uncertainty_mm:.1f} mm")
    drawn = [write_template(GraftTemplate(patient.native_shape, g, patient.graft_fibre_angle_deg,
                                          label=patient.label), out, line)
             for g in dict.fromkeys(grafts)]
    if drawn and recommendation.template_graft is not None:
        figures = replace(figures, template=drawn[0].png)
    md, pdf = write_plan_report(out, patient, recommendation, figures, run, LIMITATIONS, reach)
    summary = write_json(out / SUMMARY_FILE, {
        "patient": patient.to_dict(), "recommendation": recommendation.to_dict(),
        "reach": reach.to_dict(), "templates": [t.to_dict() for t in drawn],
        "run": run.to_dict(), "study": STUDY_DIR if study is not None else None})
    files = [md, pdf, summary, *(p for t in drawn for p in (t.svg, t.pdf, t.png))]
    log.debug("plan %s: %s", patient.label, recommendation.headline())
    return PlanOutcome(out, recommendation, reach, drawn, files)
