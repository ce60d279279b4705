"""The plan on one page: ``plan.md`` and ``plan.pdf`` (A4) for the surgeon (SPEC §9).

:func:`write_plan_report` lays out, top to bottom: the answer (the recommended graft with
its margin and the member that limits it, or the plain statement that no graft on the
grid is robust with the closest one, or that the native leaflets cannot seal the root),
the measured inputs beside the graft template's thumbnail, the worst-case sizing map and
the closed valve from the aorta and from the ventricle, what the leaflets can reach,
what was run, and the limitations.  With comparison axes (``--vary``) the answer opens
with whether the size depends on them and gives each value's answer; the page shows each
value's sizing map side by side, and ``plan.md`` each value's pictures and table.  A
picture that was not made (no study, a case that failed) is a grey box that says so.
This module says what the page shows; the page is drawn by
:func:`valve_dolfinx.plotting.plan.draw_plan_page` (exactly A4, its parts placed in
millimetres).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.io import atomic_write
from valve_dolfinx.plan.patient import PatientInput
from valve_dolfinx.plan.reach import FreeEdgeReach
from valve_dolfinx.plan.recommendation import PlanAnswers, PlanRecommendation
from valve_dolfinx.plotting.plan import PlanPage, draw_plan_page
from valve_dolfinx.plotting.study import plot_sizing_map, sizing_map_key
from valve_dolfinx.result import margin_text
from valve_dolfinx.sizing.answer import trim_text
from valve_dolfinx.sizing.cells import cell_state
from valve_dolfinx.sizing.surface import ROOT_KEY
from valve_dolfinx.study.axes import value_text
from valve_dolfinx.study.paths import study_paths

__all__ = ["PLAN_MD", "PLAN_PDF", "PlanFigures", "RunInfo", "input_lines", "reach_text",
           "sizing_map_name", "write_plan_report"]

log = logging.getLogger(__name__)

PLAN_MD = "plan.md"
PLAN_PDF = "plan.pdf"
_VERSIONS = ("valve_dolfinx", "dolfinx", "petsc", "numpy", "gmsh")


@dataclass(frozen=True)
class PlanFigures:
    """The closed-valve pictures of one comparison value (PNG files; None: not made) and
    what they show (the sizing maps are drawn by :func:`write_plan_report`)."""

    closed_aortic: Path | None = None
    closed_ventricular: Path | None = None
    #: the member the closed-valve pictures show, in words (e.g. "root 22.0 mm")
    closed_member: str = ""


@dataclass(frozen=True)
class RunInfo:
    """What was run: package versions, the mesh, the cases and their wall time (summed)."""

    versions: dict[str, str] = field(default_factory=dict)
    mesh_size_mm: float | None = None
    cases: int = 0
    converged: int = 0
    wall_time_s: float | None = None
    #: how the study chose its cases and why it stopped (an adaptive design's state)
    design: str = ""

    def lines(self) -> list[str]:
        if not self.cases:
            out = ["No finite element case was run."]
        else:
            mesh = f"a {self.mesh_size_mm:g} mm mesh" if self.mesh_size_mm else "the default mesh"
            wall = (f", {self.wall_time_s:.0f} s of wall time summed over the cases"
                    if self.wall_time_s is not None else "")
            out = [f"{self.cases} finite element cases ({self.converged} converged) on "
                   f"{mesh}{wall}."]
            if self.design:
                out.append(self.design)
        versions = ", ".join(f"{k} {self.versions[k]}" for k in _VERSIONS if k in self.versions)
        if versions:
            out.append(f"Versions: {versions}.")
        return out

    def to_dict(self) -> dict:
        return asdict(self)


def sizing_map_name(rec: PlanRecommendation) -> str:
    """The plan folder's sizing map of one comparison value: ``sizing_map.png``, or
    ``sizing_map__KEY=VALUE.png`` with comparison axes (the study's figure suffix)."""
    from valve_dolfinx.study.report import figure_suffix

    return f"sizing_map{figure_suffix(rec.recommendation)}.png"


def input_lines(patient: PatientInput) -> list[tuple[str, str]]:
    """The measured inputs as (what, value) rows."""
    target = ("the normal valve's at the same root" if patient.target_coaptation_mm is None
              else f"{patient.target_coaptation_mm:.2f} mm")
    shape = patient.native_shape
    return [
        ("root diameter, loaded, at the base",
         f"{patient.root_diameter_mm:.1f} ± {patient.root_uncertainty_mm:.1f} mm"),
        ("excised leaflet, measured flat", f"free edge {patient.leaflet_free_edge_mm:.1f} mm, "
         f"height {patient.leaflet_height_mm:.1f} mm"),
        ("model leaflets wrapped on", f"a {shape.root_diameter:.2f} mm cylinder (3L/π)"),
        ("diastolic pressure", f"{patient.pressure_mmhg:g} mmHg"),
        (("graft grid", f"W {', '.join(f'{w:g}' for w in patient.graft_widths_pct)} %; "
          f"H {', '.join(f'{h:g}' for h in patient.graft_heights_pct)} %")
         if patient.design == "grid" else
         ("graft sizes studied", f"W {patient.graft_widths_pct[0]:g}–"
          f"{patient.graft_widths_pct[-1]:g} %, H {patient.graft_heights_pct[0]:g}–"
          f"{patient.graft_heights_pct[-1]:g} % (adaptive, ≤ {patient.budget} cases)")),
        ("graft fibres", f"{patient.graft_fibre_angle_deg:g}° from the free edge"),
        ("numerical paths", ", ".join(p.label for p in study_paths(patient.paths))),
        ("target coaptation", target),
        *(("compared (--vary)", f"{key}: {', '.join(value_text(v) for v in values)}")
          for key, values in patient.vary.items()),
    ]


def reach_text(patient: PatientInput, reach: FreeEdgeReach) -> str:
    """What the native free edges can span, and whether the root's upper bound is beyond it."""
    text = reach.sentence()
    upper = max(patient.root_diameters_mm)
    if upper > reach.largest_root_mm:
        text += (f" The root's upper bound, {upper:.1f} mm, is beyond that: no graft can be "
                 "robust over the measurement's uncertainty, and that root is not computed.")
    return text


def _targets(rec: PlanRecommendation) -> str:
    """The targets when they differ between members: their range."""
    study = rec.recommendation
    values = [t for t in study.targets_mm.values() if t is not None]
    if study.target_mm is not None or not values:
        return ""
    return (f"Targets: {rec.target_source}, {min(values):.2f}–{max(values):.2f} mm over the "
            "members.")


def _members(rec: PlanRecommendation) -> str:
    """The members in words: ``roots 20.0, 21.0, 22.0 mm × paths 1, 2 (6)`` when they are
    every root diameter along every path (the paths are named in the inputs), else each
    one by its name."""
    study = rec.recommendation
    tables = study.tables
    roots = sorted({dict(t.uncertain).get(ROOT_KEY) for t in tables}, key=lambda d: d or 0.0)
    paths = sorted({t.path for t in tables})
    if (None not in roots and all(len(t.uncertain) == 1 for t in tables)
            and len(study.members) == len(tables) == len(roots) * len(paths) > 1):
        return (f"{'roots' if len(roots) > 1 else 'root'} "
                f"{', '.join(f'{d:.1f}' for d in roots)} mm × "
                f"{'paths' if len(paths) > 1 else 'path'} {', '.join(map(str, paths))} "
                f"({len(tables)})")
    return "; ".join(rec.name(m) for m in study.members)


def _details(rec: PlanRecommendation) -> list[str]:
    """What stands behind the headline: members, targets, margin, what was not computed."""
    if rec.recommendation is None:
        return []
    study, answer = rec.recommendation, rec.recommendation.answer
    out = []
    if study.members:
        out.append(f"Members (each solved on its own): {_members(rec)}.")
    if _targets(rec):
        out.append(_targets(rec))
    margin, member, solved = study.margin
    if answer.size is not None and member:
        out.append(f"Smallest {'solved ' if solved else ''}margin over the target: "
                   f"{margin_text(margin)} mm, in {rec.name(member)}.")
    if trim_text(answer):
        out.append(trim_text(answer))
    if rec.unsealable_roots_mm:
        roots = " and ".join(f"{d:.1f}" for d in rec.unsealable_roots_mm)
        out.append(f"Not computed: the {roots} mm root, beyond what the native free edges "
                   "can span (below).")
    return out


def _number(value: float | None) -> str:
    return "–" if value is None else f"{value:.2f}"


def _margin(value: float | None) -> str:
    return "–" if value is None else margin_text(value, signed=True)


def _grafts_table(rec: PlanRecommendation, where: str = "") -> list[str]:
    """Every graft's worst case over the members, and each member's target (plan.md);
    ``where`` names the comparison value."""
    if rec.recommendation is None or not rec.recommendation.cells:
        return []
    lines = [f"## Every graft over the members{where}", "",
             "| graft | worst min. coaptation (mm) | spread (mm) | margin (mm) | limiting member "
             "| over the members | qualifies |", "|---|---|---|---|---|---|---|"]
    for c in rec.recommendation.cells:
        label = f"{c.label} (confirmation)" if c.confirmation else c.label
        lines.append(f"| {label} | {_number(c.worst_height_mm)} | "
                     f"{_number(c.spread_mm)} | {_margin(c.margin_mm)} | "
                     f"{rec.name(c.limiting_member) or '–'} | {cell_state(c)} | "
                     f"{'yes' if c.qualifies else 'no'} |")
    lines += ["", "| member | target (mm) |", "|---|---|",
              *(f"| {rec.name(m)} | {_number(t)} |"
                for m, t in rec.recommendation.targets_mm.items()), ""]
    return lines


def _shown(rec: PlanRecommendation, figures: PlanFigures) -> str:
    """The graft and member the closed-valve pictures show ("W14/H13, root 22.0 mm, ...")."""
    return ", ".join(x for x in (rec.template_graft.label if rec.template_graft else "",
                                 figures.closed_member) if x)


def _template_line(answers: PlanAnswers) -> str:
    """Where the templates are, at true size (plan.md's links are added there)."""
    grafts = answers.template_grafts
    if not grafts:
        return ""
    files = ", ".join(f"template_{g.stem}.pdf" for g in grafts)
    many = len(grafts) > 1
    return (f"Template{'s' if many else ''}: {files}, true size; print at 100 % and check "
            f"{'each' if many else 'its'} 50 mm bar.")


def _at(answers: PlanAnswers, rec: PlanRecommendation) -> str:
    """`` at key=value`` of a comparison value ("" when nothing is varied)."""
    return f" at {answers.label(rec)}" if answers.varied else ""


# --- plan.md ---------------------------------------------------------------------------------
def _markdown(patient: PatientInput, answers: PlanAnswers, reach: FreeEdgeReach | None,
              figures: Sequence[PlanFigures], run: RunInfo, limitations: str, out: Path,
              templates: Mapping[GraftSize, Path], maps: Mapping[int, Path]) -> str:
    def image(path: Path | None, alt: str) -> list[str]:
        if path is None:
            return [f"_{alt}: not made._", ""]
        return [f"![{alt}]({_relative(path, out)})", ""]

    lines = [f"# Repair plan: {patient.label}", "",
             "Pericardial graft for the non-coronary leaflet, sized with the finite element "
             "model of the closed valve (valve_dolfinx).", "",
             "## Answer", "", f"**{answers.headline()}**", ""]
    for rec in answers.values:
        if answers.varied:
            lines += [f"### At {answers.label(rec)}", "", f"**{rec.headline()}**", ""]
        lines += [*(f"- {d}" for d in _details(rec)), ""]
    for graft in answers.template_grafts:
        stem = f"template_{graft.stem}"
        lines += [f"Template {graft.label} at true size: [{stem}.pdf]({stem}.pdf) "
                  f"([{stem}.svg]({stem}.svg)); print at 100 % and check its 50 mm bar.", ""]
    lines += ["## Inputs", "", "| | |", "|---|---|",
              *(f"| {k} | {v} |" for k, v in input_lines(patient)), ""]
    if reach is not None and answers.kind != "cannot_seal":
        lines += [reach_text(patient, reach), ""]
    lines += ["## Pictures", ""]
    grafts = answers.template_grafts
    lines += image(templates.get(grafts[0]) if grafts else None,
                   f"graft template {grafts[0].label}" if grafts else "graft template")
    for k, (rec, fig) in enumerate(zip(answers.values, figures, strict=True)):
        at = _at(answers, rec)
        lines += image(maps.get(k), f"sizing map{at} (worst case over the members)")
        shown = _shown(rec, fig)
        shown = f" ({shown})" if shown else ""
        lines += image(fig.closed_aortic, f"closed valve seen from the aorta{at}{shown}")
        lines += image(fig.closed_ventricular,
                       f"closed valve seen from the ventricle{at}{shown}")
    for rec in answers.values:
        lines += _grafts_table(rec, _at(answers, rec))
    lines += ["## What was run", "", *(f"- {line}" for line in run.lines()), "",
              "## Limitations", "", limitations, ""]
    return "\n".join(lines)


def _relative(path: Path, out: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(out.resolve()))
    except ValueError:
        return str(path)


# --- plan.pdf --------------------------------------------------------------------------------
def _map_caption(answers: PlanAnswers, rec: PlanRecommendation) -> str:
    n = len(rec.recommendation.members) if rec.recommendation else 0
    what = ("minimum coaptation height per graft" if n < 2 else
            f"worst case of each graft over its {n} members")
    if answers.varied:
        return f"Sizing map at {answers.label(rec)}: {what}"
    return f"Sizing map: {what}"


def _page(patient: PatientInput, answers: PlanAnswers, reach: FreeEdgeReach | None,
          figures: Sequence[PlanFigures], run: RunInfo, limitations: str,
          templates: Mapping[GraftSize, Path]) -> PlanPage:
    """What the page says (:func:`~valve_dolfinx.plotting.plan.draw_plan_page` draws it)."""
    first, shown = answers.values[0], figures[0]
    details = answers.lines() if answers.varied else _details(first)
    if answers.varied:
        details += [d for d in _details(first) if d.startswith(("Members", "Not computed"))]
        details.append("The closed valve of each value's graft: plan.md.")
    if _template_line(answers):
        details.append(_template_line(answers))
    grafts = answers.template_grafts
    graft = grafts[0] if grafts else None
    cannot = answers.kind == "cannot_seal"
    return PlanPage(
        title=f"Repair plan: {patient.label}",
        subtitle="Pericardial graft for the non-coronary leaflet, sized with the finite "
                 "element model of the closed valve (valve_dolfinx).",
        kind=answers.kind, headline=answers.headline(), details=details,
        inputs=input_lines(patient),
        reach=reach_text(patient, reach) if reach is not None and not cannot else "",
        nothing_computed="" if not cannot else (
            "Nothing was computed: a graft replaces the non-coronary leaflet only, and the two "
            "native leaflets left cannot reach the centre of this root however they are loaded "
            "(closed-form bound on the free edge's stretch, docs/plan.md)."),
        template=templates.get(graft) if graft else None,
        template_caption=f"Graft template {graft.label}" if graft else "Graft template",
        template_missing="not made" if graft else "no template: no graft to draw",
        sizing_captions=[_map_caption(answers, rec) for rec in answers.values],
        sizing_key=next((sizing_map_key(v.recommendation, names=True) for v in answers.values
                         if v.recommendation is not None and v.recommendation.cells), ""),
        closed_aortic=None if answers.varied else shown.closed_aortic,
        closed_ventricular=None if answers.varied else shown.closed_ventricular,
        shown=_shown(first, shown), run=run.lines(), limitations=limitations,
        footer="A model's prediction to inform the surgeon's judgement, not to replace it. "
               "Method and sources: docs/plan.md.")


def write_plan_report(out: str | Path, patient: PatientInput, answers: PlanAnswers,
                      figures: Sequence[PlanFigures], run: RunInfo, limitations: str,
                      reach: FreeEdgeReach | None = None, *,
                      templates: Mapping[GraftSize, Path] | None = None) -> tuple[Path, Path]:
    """Write ``plan.md`` and the one-page ``plan.pdf`` into ``out`` (atomically).

    Parameters
    ----------
    out
        The plan folder; pictures inside it are linked relative to it in ``plan.md``.
    patient
        The measured inputs.
    answers
        The plan's answer at each comparison value.
    figures
        Per comparison value (as ``answers.values``): the closed valve from the aorta and
        from the ventricle (each optional).  Each value's sizing map is drawn here, at the
        size the page prints it (:func:`sizing_map_name`).
    run
        What was run.
    limitations
        One line saying what the answer does not cover.
    reach
        The closed-form check at the measured diameter (how far the free edges reach).
    templates
        The templates' thumbnails (PNG) by graft; the page shows the first of
        ``answers.template_grafts``.
    """
    out = Path(out)
    templates = templates or {}
    maps: dict[int, Path] = {}

    def draw_map(k: int, width_mm: float, height_mm: float) -> Path | None:
        """Comparison value ``k``'s sizing map at the size the page prints it (its texts
        at least :data:`~valve_dolfinx.plotting.study.MIN_PRINT_PT` at 100 %)."""
        rec = answers.values[k]
        if rec.recommendation is None or not rec.recommendation.cells:
            return None
        path = out / sizing_map_name(rec)
        plot_sizing_map(rec.recommendation, path, size_in=(width_mm / 25.4, height_mm / 25.4),
                        caption=False, dpi=200)
        maps[k] = path
        return path

    fig = draw_plan_page(_page(patient, answers, reach, figures, run, limitations, templates),
                         draw_map)
    pdf = atomic_write(out / PLAN_PDF, lambda tmp: fig.savefig(
        tmp, format="pdf", metadata={"Title": f"Repair plan: {patient.label}"}))
    text = _markdown(patient, answers, reach, figures, run, limitations, out, templates, maps)
    md = atomic_write(out / PLAN_MD, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    log.info("plan report -> %s, %s", md, pdf)
    return md, pdf
