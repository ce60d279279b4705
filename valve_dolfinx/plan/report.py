"""The plan on one page: ``plan.md`` and ``plan.pdf`` (A4) for the surgeon (SPEC §9).

:func:`write_plan_report` lays out, top to bottom: the answer (the recommended graft with
its margin and the member that limits it, or the plain statement that no graft on the
grid is robust with the closest one, or that the native leaflets cannot seal the root),
the measured inputs beside the graft template's thumbnail, the worst-case sizing map and
the closed valve from the aorta and from the ventricle, what the leaflets can reach,
what was run, and the limitations.  A picture that was not made (no study, a case that
failed) is a grey box that says so.  This module says what the page shows; the page is
drawn by :func:`valve_dolfinx.plotting.plan.draw_plan_page` (exactly A4, its parts placed
in millimetres).
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field
from pathlib import Path

from valve_dolfinx.io import atomic_write
from valve_dolfinx.plan.patient import PatientInput
from valve_dolfinx.plan.reach import FreeEdgeReach
from valve_dolfinx.plan.recommendation import PlanRecommendation
from valve_dolfinx.plotting.plan import PlanPage, draw_plan_page
from valve_dolfinx.result import margin_text
from valve_dolfinx.sizing.cells import cell_state
from valve_dolfinx.study.paths import study_paths

__all__ = ["PLAN_MD", "PLAN_PDF", "PlanFigures", "RunInfo", "input_lines", "reach_text",
           "write_plan_report"]

log = logging.getLogger(__name__)

PLAN_MD = "plan.md"
PLAN_PDF = "plan.pdf"
_VERSIONS = ("valve_dolfinx", "dolfinx", "petsc", "numpy", "gmsh")


@dataclass(frozen=True)
class PlanFigures:
    """The pictures of the page (PNG files; None: not made) and what they show."""

    sizing_map: Path | None = None
    closed_aortic: Path | None = None
    closed_ventricular: Path | None = None
    template: Path | None = None
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

    def lines(self) -> list[str]:
        if not self.cases:
            out = ["No finite element case was run."]
        else:
            mesh = f"a {self.mesh_size_mm:g} mm mesh" if self.mesh_size_mm else "the default mesh"
            wall = (f", {self.wall_time_s:.0f} s of wall time summed over the cases"
                    if self.wall_time_s is not None else "")
            out = [f"{self.cases} finite element cases ({self.converged} converged) on "
                   f"{mesh}{wall}."]
        versions = ", ".join(f"{k} {self.versions[k]}" for k in _VERSIONS if k in self.versions)
        if versions:
            out.append(f"Versions: {versions}.")
        return out

    def to_dict(self) -> dict:
        return asdict(self)


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
        ("graft grid", f"W {', '.join(f'{w:g}' for w in patient.graft_widths_pct)} %; "
         f"H {', '.join(f'{h:g}' for h in patient.graft_heights_pct)} %"),
        ("graft fibres", f"{patient.graft_fibre_angle_deg:g}° from the free edge"),
        ("numerical paths", ", ".join(p.label for p in study_paths(patient.paths))),
        ("target coaptation", target),
    ]


def reach_text(patient: PatientInput, reach: FreeEdgeReach) -> str:
    """What the native free edges can span, and whether the root's upper bound is beyond it."""
    text = reach.sentence()
    upper = max(patient.root_diameters_mm)
    if upper > reach.largest_root_mm:
        text += (f" The root's upper bound, {upper:.1f} mm, is beyond that: no graft can be "
                 "robust over the measurement's uncertainty, and that root is not computed.")
    return text


def _kind(rec: PlanRecommendation) -> str:
    if rec.cannot_seal is not None:
        return "cannot_seal"
    return "graft" if rec.graft is not None else "closest"


def _targets(rec: PlanRecommendation) -> str:
    """The targets when they differ between members: their range."""
    study = rec.recommendation
    values = [t for t in study.targets_mm.values() if t is not None]
    if study.target_mm is not None or not values:
        return ""
    return (f"Targets: {rec.target_source}, {min(values):.2f}–{max(values):.2f} mm over the "
            "members.")


def _details(rec: PlanRecommendation) -> list[str]:
    """What stands behind the headline: members, targets, margin, what was not computed."""
    if rec.recommendation is None:
        return []
    study, answer = rec.recommendation, rec.recommendation.answer
    out = []
    if study.members:
        out.append(f"Members (each solved on its own): "
                   f"{'; '.join(rec.name(m) for m in study.members)}.")
    if _targets(rec):
        out.append(_targets(rec))
    if answer.size is not None and answer.limiting_member:
        out.append(f"Smallest margin over the target: {margin_text(answer.margin_mm)} mm, in "
                   f"{rec.name(answer.limiting_member)}.")
    if rec.unsealable_roots_mm:
        roots = " and ".join(f"{d:.1f}" for d in rec.unsealable_roots_mm)
        out.append(f"Not computed: the {roots} mm root, beyond what the native free edges "
                   "can span (below).")
    return out


def _number(value: float | None) -> str:
    return "–" if value is None else f"{value:.2f}"


def _margin(value: float | None) -> str:
    return "–" if value is None else margin_text(value, signed=True)


def _grafts_table(rec: PlanRecommendation) -> list[str]:
    """Every graft's worst case over the members, and each member's target (plan.md)."""
    if rec.recommendation is None or not rec.recommendation.cells:
        return []
    lines = ["## Every graft over the members", "",
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


# --- plan.md ---------------------------------------------------------------------------------
def _markdown(patient: PatientInput, rec: PlanRecommendation, reach: FreeEdgeReach | None,
              figures: PlanFigures, run: RunInfo, limitations: str, out: Path) -> str:
    def image(path: Path | None, alt: str) -> list[str]:
        if path is None:
            return [f"_{alt}: not made._", ""]
        return [f"![{alt}]({_relative(path, out)})", ""]

    lines = [f"# Repair plan: {patient.label}", "",
             "Pericardial graft for the non-coronary leaflet, sized with the finite element "
             "model of the closed valve (valve_dolfinx).", "",
             "## Answer", "", f"**{rec.headline()}**", "", *(f"- {d}" for d in _details(rec))]
    if rec.template_graft is not None:
        stem = f"template_{rec.template_graft.stem}"
        lines += ["", f"Template at true size: [{stem}.pdf]({stem}.pdf) "
                  f"([{stem}.svg]({stem}.svg)); print at 100 % and check its 50 mm bar."]
    lines += ["", "## Inputs", "", "| | |", "|---|---|",
              *(f"| {k} | {v} |" for k, v in input_lines(patient)), ""]
    if reach is not None and rec.cannot_seal is None:
        lines += [reach_text(patient, reach), ""]
    lines += ["## Pictures", ""]
    lines += image(figures.template, "graft template")
    lines += image(figures.sizing_map, "sizing map (worst case over the members)")
    shown = _shown(rec, figures)
    shown = f" ({shown})" if shown else ""
    lines += image(figures.closed_aortic, f"closed valve seen from the aorta{shown}")
    lines += image(figures.closed_ventricular, f"closed valve seen from the ventricle{shown}")
    lines += _grafts_table(rec)
    lines += ["## What was run", "", *(f"- {line}" for line in run.lines()), "",
              "## Limitations", "", limitations, ""]
    return "\n".join(lines)


def _relative(path: Path, out: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(out.resolve()))
    except ValueError:
        return str(path)


# --- plan.pdf --------------------------------------------------------------------------------
def _page(patient: PatientInput, rec: PlanRecommendation, reach: FreeEdgeReach | None,
          figures: PlanFigures, run: RunInfo, limitations: str) -> PlanPage:
    """What the page says (:func:`~valve_dolfinx.plotting.plan.draw_plan_page` draws it)."""
    details = _details(rec)
    graft = rec.template_graft
    if graft is not None:
        details.append(f"Template: template_{graft.stem}.pdf, true size; print at 100 % and "
                       "check its 50 mm bar.")
    n = len(rec.recommendation.members) if rec.recommendation else 0
    return PlanPage(
        title=f"Repair plan: {patient.label}",
        subtitle="Pericardial graft for the non-coronary leaflet, sized with the finite "
                 "element model of the closed valve (valve_dolfinx).",
        kind=_kind(rec), headline=rec.headline(), details=details,
        inputs=input_lines(patient),
        reach=reach_text(patient, reach) if reach is not None and rec.cannot_seal is None
        else "",
        nothing_computed="" if rec.cannot_seal is None else (
            "Nothing was computed: a graft replaces the non-coronary leaflet only, and the two "
            "native leaflets left cannot reach the centre of this root however they are loaded "
            "(closed-form bound on the free edge's stretch, docs/plan.md)."),
        template=figures.template,
        template_caption=f"Graft template {graft.label}" if graft else "Graft template",
        template_missing="not made" if graft else "no template: no graft to draw",
        sizing_map=figures.sizing_map,
        sizing_caption=("Sizing map: minimum coaptation height per graft" if n < 2 else
                        f"Sizing map: worst case of each graft over its {n} members"),
        closed_aortic=figures.closed_aortic, closed_ventricular=figures.closed_ventricular,
        shown=_shown(rec, figures), run=run.lines(), limitations=limitations,
        footer="A model's prediction to inform the surgeon's judgement, not to replace it. "
               "Method and sources: docs/plan.md.")


def write_plan_report(out: str | Path, patient: PatientInput, recommendation: PlanRecommendation,
                      figures: PlanFigures, run: RunInfo, limitations: str,
                      reach: FreeEdgeReach | None = None) -> tuple[Path, Path]:
    """Write ``plan.md`` and the one-page ``plan.pdf`` into ``out`` (atomically).

    Parameters
    ----------
    out
        The plan folder; pictures inside it are linked relative to it in ``plan.md``.
    patient
        The measured inputs.
    recommendation
        The plan's answer.
    figures
        The sizing map, the closed valve from the aorta and from the ventricle, the
        template's thumbnail (each optional).
    run
        What was run.
    limitations
        One line saying what the answer does not cover.
    reach
        The closed-form check at the measured diameter (how far the free edges reach).
    """
    out = Path(out)
    text = _markdown(patient, recommendation, reach, figures, run, limitations, out)
    md = atomic_write(out / PLAN_MD, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    fig = draw_plan_page(_page(patient, recommendation, reach, figures, run, limitations))
    pdf = atomic_write(out / PLAN_PDF, lambda tmp: fig.savefig(
        tmp, format="pdf", metadata={"Title": f"Repair plan: {patient.label}"}))
    log.info("plan report -> %s, %s", md, pdf)
    return md, pdf
