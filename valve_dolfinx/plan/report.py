"""The plan on one page: ``plan.md`` and ``plan.pdf`` (A4) for the surgeon (SPEC §9).

:func:`write_plan_report` lays out, top to bottom: the answer (the recommended graft with
its margin and the member that limits it, or the plain statement that no graft on the
grid is robust with the closest one, or that the native leaflets cannot seal the root),
the measured inputs beside the graft template's thumbnail, the worst-case sizing map and
the closed valve from the aorta and from the ventricle, what the leaflets can reach,
what was run, and the limitations.  A picture that was not made (no study, a case that
failed) is a grey box that says so.  The page is a matplotlib figure of exactly A4 on its
own canvas (:func:`valve_dolfinx.plotting.style.new_figure`), its parts placed in
millimetres.
"""

from __future__ import annotations

import logging
import textwrap
from dataclasses import asdict, dataclass, field
from pathlib import Path

from valve_dolfinx.io import atomic_write
from valve_dolfinx.plan.patient import PatientInput
from valve_dolfinx.plan.reach import FreeEdgeReach
from valve_dolfinx.plan.recommendation import PlanRecommendation
from valve_dolfinx.plotting.style import OKABE_ITO
from valve_dolfinx.result import margin_text
from valve_dolfinx.study.paths import study_paths

__all__ = ["PLAN_MD", "PLAN_PDF", "PlanFigures", "RunInfo", "input_lines", "reach_text",
           "write_plan_report"]

log = logging.getLogger(__name__)

PLAN_MD = "plan.md"
PLAN_PDF = "plan.pdf"
_A4 = (210.0, 297.0)
_BOX = {"graft": "#e3f1ea", "closest": "#fbefd9", "cannot_seal": "#f8dfd6"}
_EDGE = {"graft": OKABE_ITO["bluish_green"], "closest": OKABE_ITO["orange"],
         "cannot_seal": OKABE_ITO["vermillion"]}
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
    values = [t for t in rec.targets_mm.values() if t is not None]
    if rec.target_mm is not None or not values:
        return ""
    return (f"Targets: {rec.target_source}, {min(values):.2f}–{max(values):.2f} mm over the "
            "members.")


def _details(rec: PlanRecommendation) -> list[str]:
    """What stands behind the headline: members, targets, margin, what was not computed."""
    out = []
    if rec.members:
        out.append(f"Members (each solved on its own): {'; '.join(rec.members)}.")
    if _targets(rec):
        out.append(_targets(rec))
    if rec.margin_mm is not None and rec.limiting_member:
        out.append(f"Smallest margin over the target: {margin_text(rec.margin_mm)} mm, in "
                   f"{rec.limiting_member}.")
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
    if not rec.grafts:
        return []
    lines = ["## Every graft over the members", "",
             "| graft | worst min. coaptation (mm) | spread (mm) | margin (mm) | limiting member "
             "| over the members | qualifies |", "|---|---|---|---|---|---|---|"]
    for g in rec.grafts:
        lines.append(f"| {g.graft.label} | {_number(g.worst_height_mm)} | "
                     f"{_number(g.spread_mm)} | {_margin(g.margin_mm)} | "
                     f"{g.limiting_member or '–'} | {g.state} | {'yes' if g.qualifies else 'no'} |")
    lines += ["", "| member | target (mm) |", "|---|---|",
              *(f"| {m} | {_number(t)} |" for m, t in rec.targets_mm.items()), ""]
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
def _axes_mm(fig, x: float, y: float, w: float, h: float):
    """Axes at (x, y) of width w and height h, in millimetres from the lower left corner."""
    return fig.add_axes((x / _A4[0], y / _A4[1], w / _A4[0], h / _A4[1]))


def _picture(fig, box: tuple[float, float, float, float], path: Path | None, caption: str,
             missing: str) -> None:
    """A PNG fitted into ``box`` (mm) with its caption above, or a grey box saying why not."""
    import matplotlib.image

    x, y, w, h = box
    fig.text(x / _A4[0], (y + h + 1.0) / _A4[1], caption, fontsize=8, fontweight="bold",
             parse_math=False)
    ax = _axes_mm(fig, x, y, w, h)
    ax.set_axis_off()
    if path is not None and Path(path).is_file():
        ax.imshow(matplotlib.image.imread(path), interpolation="antialiased")
        ax.set_anchor("N")
        return
    ax.add_patch(_rounded(0.0, 0.0, 1.0, 1.0, "#eeeeee", "#bbbbbb", ax.transAxes))
    ax.text(0.5, 0.5, textwrap.fill(missing, 38), ha="center", va="center", fontsize=8,
            color="#555555", transform=ax.transAxes, parse_math=False)


def _rounded(x, y, w, h, face, edge, transform):
    from matplotlib.patches import FancyBboxPatch

    return FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0,rounding_size=0.02",
                          facecolor=face, edgecolor=edge, linewidth=1.0, transform=transform)


def _text(fig, x: float, y: float, text: str, size: float = 9.0, spacing: float = 1.3,
          **kw) -> float:
    """Text whose first line's top is at ``y`` (mm), as written (a ``$`` is a dollar sign, not
    math); returns the y below its last line."""
    fig.text(x / _A4[0], y / _A4[1], text, fontsize=size, va="top", linespacing=spacing,
             parse_math=False, **kw)
    return y - (text.count("\n") + 1) * size * spacing * 25.4 / 72.0


def _answer_box(fig, rec: PlanRecommendation, top: float) -> float:
    """The answer, framed in the colour of its kind; returns the y below the box."""
    kind = _kind(rec)
    details = _details(rec)
    if rec.template_graft is not None:
        details.append(f"Template: template_{rec.template_graft.stem}.pdf, true size; print "
                       "at 100 % and check its 50 mm bar.")
    y = _text(fig, 16, top - 4.0, textwrap.fill(rec.headline(), 80), size=10.5,
              spacing=1.35, fontweight="bold")
    if details:
        y = _text(fig, 16, y - 2.0, "\n".join(textwrap.fill(d, 116) for d in details),
                  size=8)
    bottom = y - 3.0
    fig.patches.append(_rounded(12 / _A4[0], bottom / _A4[1], 186 / _A4[0],
                                (top - bottom) / _A4[1], _BOX[kind], _EDGE[kind],
                                fig.transFigure))
    return bottom


def _pictures(fig, rec: PlanRecommendation, figures: PlanFigures, top: float,
              height: float) -> None:
    """The sizing map on the left, the closed valve from the aorta and from the ventricle
    stacked on the right, in a row ``height`` mm high below ``top``."""
    which = _shown(rec, figures)
    which = f"\n{which}" if which else ""
    n = len(rec.members)
    caption = ("Sizing map: minimum coaptation height per graft" if n < 2 else
               f"Sizing map: worst case of each graft over its {n} members")
    _picture(fig, (12, top - height, 116, height), figures.sizing_map, caption, "not made")
    half = 0.5 * (height - 10.0)
    _picture(fig, (134, top - half, 64, half), figures.closed_aortic,
             f"Closed valve from the aorta{which}", "not made")
    _picture(fig, (134, top - height, 64, half), figures.closed_ventricular,
             f"Closed valve from the ventricle{which}", "not made")


def _figure(patient: PatientInput, rec: PlanRecommendation, reach: FreeEdgeReach | None,
            figures: PlanFigures, run: RunInfo, limitations: str):
    from valve_dolfinx.plotting.style import new_figure

    fig = new_figure(_A4[0] / 25.4, _A4[1] / 25.4, layout=None)
    y = _text(fig, 12, 288, f"Repair plan: {patient.label}", size=16, fontweight="bold")
    y = _text(fig, 12, y - 1.0, "Pericardial graft for the non-coronary leaflet, sized with "
              "the finite element model of the closed valve (valve_dolfinx).", size=8,
              color="#333333")
    y = _answer_box(fig, rec, y - 3.0)

    top = y - 6.0
    _text(fig, 12, top, "Measured inputs", size=10, fontweight="bold")
    rows = input_lines(patient)
    _text(fig, 12, top - 6.0, "\n".join(k for k, _ in rows), size=8, spacing=1.55,
          color="#333333")
    y = _text(fig, 64, top - 6.0, "\n".join(textwrap.shorten(v, 50) for _, v in rows),
              size=8, spacing=1.55)
    if reach is not None and rec.cannot_seal is None:
        y = _text(fig, 12, y - 2.0, textwrap.fill(reach_text(patient, reach), 76), size=7.5,
                  color="#333333")
    if rec.cannot_seal is not None:
        y = _text(fig, 12, y - 8.0, textwrap.fill(
            "Nothing was computed: a graft replaces the non-coronary leaflet only, and the two "
            "native leaflets left cannot reach the centre of this root however they are loaded "
            "(closed-form bound on the free edge's stretch, docs/plan.md).", 100), size=9)
        height = 0.0
    else:
        thumb = 44.0
        _picture(fig, (136, top - 4.0 - thumb, 62, thumb), figures.template,
                 f"Graft template {rec.template_graft.label}" if rec.template_graft
                 else "Graft template", "not made" if rec.template_graft else
                 "no template: no graft to draw")
        y = min(y, top - 4.0 - thumb) - 8.0
        height = min(100.0, y - 74.0)
        _pictures(fig, rec, figures, y, height)
    y = _text(fig, 12, y - height - 8.0, "What was run", size=10, fontweight="bold")
    y = _text(fig, 12, y - 1.5, "\n".join(textwrap.fill(line, 118) for line in run.lines()),
              size=8)
    y = _text(fig, 12, y - 4.0, "Limitations", size=10, fontweight="bold")
    _text(fig, 12, y - 1.5, textwrap.fill(limitations, 118), size=8, style="italic")
    _text(fig, 12, 14, "A model's prediction to inform the surgeon's judgement, not to "
          "replace it. Method and sources: docs/plan.md.", size=7, color="#555555")
    return fig


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
    fig = _figure(patient, recommendation, reach, figures, run, limitations)
    pdf = atomic_write(out / PLAN_PDF, lambda tmp: fig.savefig(
        tmp, format="pdf", metadata={"Title": f"Repair plan: {patient.label}"}))
    log.info("plan report -> %s, %s", md, pdf)
    return md, pdf
