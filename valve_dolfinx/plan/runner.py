"""Running one patient's plan: check, study, template, report (SPEC §9).

:func:`run_plan` does, in order:

1. validates everything the plan will run (the patient, the study grid, every case
   setting) before any computation;
2. checks in closed form whether the native leaflets can span the measured root at all
   (:mod:`valve_dolfinx.plan.reach`); if not, that is the answer and nothing is computed;
3. runs the plan's study, :func:`run_plan_study` -- the one function that decides which
   cases are solved -- over the members (the root diameters D − U, D, D + U within the
   leaflets' reach, the numerical paths) and the patient's comparison values (``vary``),
   and turns each value's worst-case recommendation into a :class:`PlanRecommendation`
   (:func:`plan_study_answer`; all of them: :class:`PlanAnswers`);
4. draws the template of the recommended (or closest) graft of each value, of the size
   that qualifies at every value, and of any graft asked for;
5. writes ``plan.md``, ``plan.pdf`` and ``summary.json``.

:func:`rebuild_plan` (``valve-dolfinx report DIR``) does 4 and 5 again from the case
folders and ``patient.toml``, computing nothing.

Layout of a plan folder ``DIR``::

    DIR/patient.toml                 the inputs as they ran (reloadable)
    DIR/plan.md, DIR/plan.pdf        the one-page report
    DIR/summary.json                 the answer, the reach check, the templates' dimensions
    DIR/sizing_map.png               the study's sizing map at the size the page prints it
                                     (with --vary: sizing_map__KEY=VALUE.png per value)
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
from typing import TYPE_CHECKING

from valve_dolfinx._compat import MPI
from valve_dolfinx.exceptions import (
    InputFileError,
    OutputConflictError,
    ParameterError,
    StudyIncompleteError,
)
from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.geometry.template import GraftTemplate
from valve_dolfinx.io import check_output_folder, write_json
from valve_dolfinx.plan.patient import PATIENT_FILE, PatientInput, read_patient, write_patient
from valve_dolfinx.plan.reach import FreeEdgeReach, free_edge_reach
from valve_dolfinx.plan.recommendation import PlanAnswers, PlanRecommendation
from valve_dolfinx.plan.report import PlanFigures, RunInfo, write_plan_report
from valve_dolfinx.plan.template import TemplateFiles, write_template
from valve_dolfinx.sizing.cells import NORMAL_TARGET
from valve_dolfinx.study.axes import axis_label
from valve_dolfinx.study.grid import StudySettings
from valve_dolfinx.study.store import CASES_DIR, RESULT_FILE, SETTINGS_FILE

if TYPE_CHECKING:
    from valve_dolfinx.sizing.recommendation import Recommendation
    from valve_dolfinx.study.layout import Member
    from valve_dolfinx.study.report import StudyReport

__all__ = ["LIMITATIONS", "ROOT_KEY", "STUDY_DIR", "PlanOutcome", "PlanStudy", "member_words",
           "plan_study_answer", "plan_study_settings", "reachable_roots", "rebuild_plan",
           "run_plan", "run_plan_study"]

log = logging.getLogger(__name__)

#: the plan's study folder inside the plan folder
STUDY_DIR = "study"
SUMMARY_FILE = "summary.json"
#: what the answer does not cover, printed on the report
LIMITATIONS = (
    "An idealised valve: a cylindrical root prescribed at the measured diameter (± its "
    "uncertainty), the three leaflets scaled from the one measured leaflet, published tissue "
    "laws for the leaflets and the glutaraldehyde-fixed pericardium, one static closure "
    "under diastolic pressure (no flow, no opening, no remodelling or ageing of the graft); "
    "coaptation heights are resolved to about 0.3 mm at the default mesh.")
#: the case setting the plan's uncertainty axis sets: the loaded root diameter (mm)
ROOT_KEY = "root.loaded_diameter_mm"


@dataclass
class PlanStudy:
    """What the plan's study hands back (on rank 0; the other ranks get None): the answer
    and the pictures of each comparison value (one without ``vary``), what was run."""

    answers: PlanAnswers
    figures: list[PlanFigures]
    run: RunInfo
    folder: Path


@dataclass
class PlanOutcome:
    """What :func:`run_plan` did (its files and answers on rank 0)."""

    out: Path
    answers: PlanAnswers
    reach: FreeEdgeReach
    templates: list[TemplateFiles] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    elapsed_s: float = 0.0


def reachable_roots(patient: PatientInput) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The root diameters of the plan (D − U, D, D + U) the native free edges can span,
    and those they cannot (:func:`~valve_dolfinx.plan.reach.free_edge_reach`)."""
    within, beyond = [], []
    for diameter in patient.root_diameters_mm:
        reach = free_edge_reach(patient.leaflet_free_edge_mm, diameter, patient.pressure_mmhg)
        (within if reach.can_seal else beyond).append(diameter)
    return tuple(within), tuple(beyond)


def plan_study_settings(patient: PatientInput, mesh_size_mm: float | None = None,
                        wall_time_limit_s: float | None = None) -> StudySettings:
    """The study settings of a plan, every case setting validated (no DOLFINx imported).

    The mesh size and wall-clock limit are the patient's (``mesh_size_mm``,
    ``wall_time_limit_s``) unless given here.  The case settings are the patient's valve
    (:meth:`PatientInput.case_settings`); the
    loaded root diameter is an uncertainty axis over the plan's diameters that the native
    leaflets can span (:func:`reachable_roots`), every graft is solved along the
    patient's number of numerical paths, and the patient's ``vary`` axes are the study's
    comparison axes.  (A plan whose measured root they cannot span
    runs no study; its settings then only check the inputs.)

    Raises
    ------
    ParameterError
        A mesh size the measured leaflet cannot take (its commissures must carry two
        edges), a grid value or a setting out of range -- before any computation.
    """
    mesh_size_mm = patient.mesh_size_mm if mesh_size_mm is None else mesh_size_mm
    if wall_time_limit_s is None:
        wall_time_limit_s = patient.wall_time_limit_s
    diameters = reachable_roots(patient)[0] or (patient.root_diameter_mm,)
    return StudySettings(widths_pct=patient.graft_widths_pct,
                         heights_pct=patient.graft_heights_pct,
                         mesh_size_mm=mesh_size_mm, wall_time_limit_s=wall_time_limit_s,
                         target_coaptation_mm=patient.target_coaptation_mm,
                         panel_cases=(), case=patient.case_settings(),
                         uncertain={ROOT_KEY: list(diameters)}, paths=patient.paths,
                         vary={k: list(v) for k, v in patient.vary.items()},
                         design=patient.design, budget=patient.budget,
                         case_source="the plan's case settings")


# --- the plan's study ----------------------------------------------------------------------
def run_plan_study(patient: PatientInput, settings: StudySettings, out: Path,
                   comm: MPI.Comm, *, case_function: Callable | None = None,
                   progress: Callable[[dict], None] | None = None,
                   wait: bool = True) -> PlanStudy | None:
    """Solve the plan's cases into ``out`` and turn them into the plan's answer.

    This is the single place where the plan decides what to compute; everything around
    it (the reach check, the templates, the report) only reads the :class:`PlanStudy`
    it returns.  The study (:func:`valve_dolfinx.study.runner.run_study` with
    :func:`plan_study_settings`) solves the normal valve and every graft of the grid in
    every *member*: each root diameter D − U, D, D + U that the native leaflets can span,
    along each of the patient's numerical paths (the normal valve once per diameter), at
    each of the patient's comparison values (``vary``).  A
    diameter beyond their reach is not computed: no graft seals it
    (:mod:`valve_dolfinx.plan.reach`), so no graft is robust over the uncertainty, and the
    answer says so (:func:`plan_study_answer`).

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
    case_function, progress, wait
        Passed to ``run_study`` (a stand-in case function in tests; the progress bar;
        whether to wait for the cases another process computes).

    Returns
    -------
    PlanStudy or None
        The answer, the pictures and what was run on rank 0; None on the other ranks.

    Raises
    ------
    StudyIncompleteError
        On every rank, when a case has no result that counts (it failed, or another
        process computes it and ``wait`` is false): there is no answer.
    """
    from valve_dolfinx.study.runner import run_study

    outcome = run_study(settings, out, comm, case_function=case_function, progress=progress,
                        wait=wait)
    why = comm.bcast(outcome.report.incomplete_text if comm.rank == 0 else None, root=0)
    if why:
        raise StudyIncompleteError(f"{out}: {why}")
    if comm.rank != 0:
        return None
    return plan_study_answer(patient, outcome.report)


def plan_study_answer(patient: PatientInput, report: StudyReport) -> PlanStudy:
    """The plan's answers, pictures and run from its study's report (what ``build_report``
    of the study folder finds): each comparison value's worst-case recommendation over the
    members mapped onto :class:`PlanRecommendation` and the closed valve of its
    recommended (or closest) graft at the measured diameter along the first path (the
    report draws the sizing maps, at the size its page prints them)."""
    layout = report.layout
    words = {member.label: member_words(member) for member in layout.members}
    # the answer's members are the root diameters, the paths being its replicates
    words.update({axis_label(m.values): f"root {dict(m.values)[ROOT_KEY]:.1f} mm"
                  for m in layout.members})
    beyond = reachable_roots(patient)[1]
    reason = ""
    if beyond:
        reason = free_edge_reach(patient.leaflet_free_edge_mm, beyond[-1],
                                 patient.pressure_mmhg).sentence()
    answers = PlanAnswers(tuple(_from_worst_case(rec, words, beyond, reason)
                                for rec in report.recommendations))
    out = report.out
    member = next(i for i, m in enumerate(layout.members)
                  if dict(m.values)[ROOT_KEY] == patient.root_diameter_mm
                  and m.path == layout.paths[0])
    figures = []
    for c, value in enumerate(answers.values):
        shown = value.template_graft
        name = layout.slots.get((c, member, None if shown is None else tuple(shown)))
        aortic, ventricular = _closed_views(out / CASES_DIR / name if name else None, out)
        figures.append(PlanFigures(closed_aortic=aortic,
                                   closed_ventricular=ventricular,
                                   closed_member=f"root {patient.root_diameter_mm:.1f} mm, "
                                                 f"path {layout.paths[0].number}"))
    rows = report.rows
    first = rows[0] if rows else {}
    run = RunInfo(versions=first.get("versions") or {},
                  mesh_size_mm=next(iter(layout.configs.values())).geometry.mesh_size,
                  cases=len(rows), converged=sum(bool(r.get("converged")) for r in rows),
                  wall_time_s=sum(float(r.get("wall_time_s") or 0.0) for r in rows),
                  design=report.next_round.text if report.next_round else "")
    return PlanStudy(answers, figures, run, out)


def member_words(member: Member) -> str:
    """A member of the plan's study as the report names it: ``root 22.0 mm, path 1 (...)``."""
    return f"root {dict(member.values)[ROOT_KEY]:.1f} mm, {member.path.label}"


def _existing(path: Path) -> Path | None:
    return path if path.is_file() else None


def _closed_views(case: Path | None, out: Path) -> tuple[Path | None, Path | None]:
    """The closed valve of a case from the aorta and the ventricle: the case's own
    figures, or drawn from its loaded state into ``out`` (a study's cases draw none)."""
    if case is None or not (case / RESULT_FILE).is_file():
        return None, None
    own = _existing(case / "closed_valve_aortic.png"), _existing(
        case / "closed_valve_ventricular.png")
    if all(own):
        return own
    from valve_dolfinx.plotting import draw_closed_views

    return draw_closed_views(case, out)


def _from_worst_case(rec: Recommendation, words: dict[str, str], beyond: tuple[float, ...],
                     reason: str) -> PlanRecommendation:
    """The plan's answer from the study's :class:`~valve_dolfinx.sizing.recommendation.
    Recommendation` (members named in ``words``; ``beyond``: the root diameters not
    computed, which no graft seals)."""
    source = ("the normal valve's at the same root" if rec.target_source.startswith(
        NORMAL_TARGET) else "given in the plan's inputs")
    for member, why in rec.incompetent_targets.items():
        source += f"; caution, the normal valve is {why} at {words[member]}"
    return PlanRecommendation(rec, words, source, beyond, reason)


# --- the plan ----------------------------------------------------------------------------
#: the files of a plan that state its answer (glob patterns): removed by ``--force`` before
#: anything is computed, and when the plan's study turns out incomplete
ANSWER_FILES = ("plan.md", "plan.pdf", SUMMARY_FILE, "sizing_map*.png")
#: the templates a plan draws (``--force`` removes them with the answer: they are cut
#: from the old inputs' leaflet)
TEMPLATE_FILES = ("template_*.svg", "template_*.pdf", "template_*.png")


def _check_folder(out: Path, patient: PatientInput, settings: StudySettings,
                  force: bool) -> None:
    """Refuse a folder that cannot hold the plan (``check_output_folder``), that holds
    another patient's plan, or whose study was computed with other settings (unless
    ``force``)."""
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
    from valve_dolfinx.study.report import read_settings

    try:
        ran = read_settings(out / STUDY_DIR)
    except (ValueError, OSError):  # an unreadable study.json: the study is rewritten
        ran = None
    if ran is not None and ran != settings:
        raise OutputConflictError(
            f"--out {out}: its study was computed with other settings than these inputs "
            f"give ({out / STUDY_DIR / SETTINGS_FILE}: mesh {ran.mesh_size_mm or 'default'}, "
            f"wall-clock limit {ran.wall_time_limit_s or 'default'}); rerun it with "
            f"`valve-dolfinx plan {saved} --out {out}`, or give --force to recompute it")


def _remove_answer(out: Path, patterns: Sequence[str]) -> None:
    for pattern in patterns:
        for path in out.glob(pattern):
            path.unlink(missing_ok=True)


def run_plan(patient: PatientInput, out: str | Path, comm: MPI.Comm | None = None, *,
             mesh_size_mm: float | None = None, wall_time_limit_s: float | None = None,
             templates: Sequence[GraftSize] = (), force: bool = False,
             case_function: Callable | None = None,
             progress: Callable[[dict], None] | None = None, wait: bool = True) -> PlanOutcome:
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
        The cases' mesh and wall-clock limit, set over the patient's (default: the
        patient's, else the case defaults); ``patient.toml`` records them.
    templates
        Grafts to draw besides the recommended (or closest) one (and those whose templates
        are in ``out`` already, which are redrawn).
    force
        Replace the plan of other inputs, or of other settings, in ``out``: the previous
        answer (plan, summary, templates, the study's report) is removed before anything
        is computed, and the cases of other settings are computed again.
    case_function, progress, wait
        Passed to the study (:func:`run_plan_study`).

    Raises
    ------
    ParameterError, OutputConflictError, OutputNotFolderError, OutputNotWritableError
        Before any computation: a setting out of range, an unusable ``out``.
    StudyIncompleteError
        When a case of the study has no result (it failed, or another process computes it
        and ``wait`` is false): no answer is written, and that of an earlier run removed.
    """
    comm = MPI.COMM_WORLD if comm is None else comm
    out = Path(out)
    t0 = time.perf_counter()
    numerics = {"mesh_size_mm": mesh_size_mm, "wall_time_limit_s": wall_time_limit_s}
    patient = replace(patient, **{k: v for k, v in numerics.items() if v is not None})
    settings = plan_study_settings(patient)
    error = None
    if comm.rank == 0:
        try:
            _check_folder(out, patient, settings, force)
            if force:
                from valve_dolfinx.study.report import remove_report

                _remove_answer(out, (*ANSWER_FILES, *TEMPLATE_FILES))
                remove_report(out / STUDY_DIR)
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
        try:
            study = run_plan_study(patient, settings, out / STUDY_DIR, comm,
                                   case_function=case_function, progress=progress, wait=wait)
        except StudyIncompleteError:
            if comm.rank == 0:
                _remove_answer(out, ANSWER_FILES)
            raise
    elif comm.rank == 0:
        log.warning("%s", reach.sentence())
    outcome = None
    if comm.rank == 0:
        outcome = _write_plan(out, patient, reach, study, templates)
        outcome.elapsed_s = time.perf_counter() - t0
    outcome = comm.bcast(outcome, root=0)
    return outcome


def rebuild_plan(out: str | Path) -> PlanOutcome:
    """Rewrite a plan folder's templates, ``plan.md``, ``plan.pdf`` and ``summary.json`` from
    ``patient.toml`` and the case folders of its study, computing nothing (serial).

    The templates drawn are the recommended (or closest) graft's and every template
    already in the folder (those of ``--template``), as :func:`run_plan` draws them.

    Raises
    ------
    InputFileError
        ``out`` holds no ``patient.toml``, or its study folder is missing or was run with
        other settings than ``patient.toml`` gives (rerun ``valve-dolfinx plan``).
    StudyIncompleteError
        A case of the study has no result that counts (not run, in progress, stale,
        damaged or failed: :func:`~valve_dolfinx.study.report.build_report`): the plan's
        answer is removed, not written.
    """
    from valve_dolfinx.study.report import build_report, read_settings

    out = Path(out)
    patient = read_patient(out / PATIENT_FILE)
    reach = free_edge_reach(patient.leaflet_free_edge_mm, patient.root_diameter_mm,
                            patient.pressure_mmhg)
    rerun = (f"run `valve-dolfinx plan {out / PATIENT_FILE} --out {out}` (it resumes the "
             "study)")
    study = None
    if reach.can_seal:
        folder = out / STUDY_DIR
        saved = read_settings(folder) if (folder / CASES_DIR).is_dir() else None
        if saved is None:
            raise InputFileError(f"{folder}: no study with its {SETTINGS_FILE} and "
                                 f"{CASES_DIR}/ folder; {rerun}")
        expected = plan_study_settings(patient)
        if patient.mesh_size_mm is None and patient.wall_time_limit_s is None:
            # a patient.toml written before it recorded the numerics: the study's
            expected = plan_study_settings(patient, saved.mesh_size_mm, saved.wall_time_limit_s)
        if saved != expected:
            raise InputFileError(f"{folder / SETTINGS_FILE}: the study was run with other "
                                 f"settings than {out / PATIENT_FILE} gives; {rerun}")
        report = build_report(folder, saved)
        if not report.complete:
            _remove_answer(out, ANSWER_FILES)
            raise StudyIncompleteError(f"{folder}: {report.incomplete_text} No plan is written: "
                                       f"{rerun}")
        study = plan_study_answer(patient, report)
    return _write_plan(out, patient, reach, study, ())


def _drawn_templates(out: Path) -> list[GraftSize]:
    """The grafts whose templates are in ``out`` (``template_W<w>_H<h>.svg``)."""
    grafts = []
    for svg in sorted(out.glob("template_*.svg")):
        try:
            grafts.append(GraftSize.parse(svg.stem.removeprefix("template_")))
        except ParameterError:
            log.debug("%s: not a template name, left alone", svg)
    return grafts


def _write_plan(out: Path, patient: PatientInput, reach: FreeEdgeReach,
                study: PlanStudy | None, extra: Sequence[GraftSize]) -> PlanOutcome:
    """Templates, plan.md, plan.pdf and summary.json (rank 0): the templates of the
    answers' grafts (:attr:`PlanAnswers.template_grafts`), of ``extra`` and of every graft
    already drawn in ``out``."""
    if study is None:
        answers = PlanAnswers((PlanRecommendation(cannot_seal=reach.sentence()),))
        figures, run = [PlanFigures()], RunInfo()
    else:
        answers, figures, run = study.answers, study.figures, study.run
    grafts = [*answers.template_grafts, *extra, *_drawn_templates(out)]
    line = (f"Measured leaflet: free edge {patient.leaflet_free_edge_mm:.1f} mm, height "
            f"{patient.leaflet_height_mm:.1f} mm; root {patient.root_diameter_mm:.1f} ± "
            f"{patient.root_uncertainty_mm:.1f} mm")
    drawn = [write_template(GraftTemplate(patient.native_shape, g, patient.graft_fibre_angle_deg,
                                          label=patient.label), out, line)
             for g in dict.fromkeys(grafts)]
    pictures = {t.graft: t.png for t in drawn}
    md, pdf = write_plan_report(out, patient, answers, figures, run, LIMITATIONS, reach,
                                templates=pictures)
    summary = write_json(out / SUMMARY_FILE, {
        "patient": patient.to_dict(), "answers": answers.to_dict(),
        "reach": reach.to_dict(), "templates": [t.to_dict() for t in drawn],
        "run": run.to_dict(), "study": STUDY_DIR if study is not None else None})
    files = [md, pdf, summary, *(p for t in drawn for p in (t.svg, t.pdf, t.png))]
    log.debug("plan %s: %s", patient.label, answers.headline())
    return PlanOutcome(out, answers, reach, drawn, files)
