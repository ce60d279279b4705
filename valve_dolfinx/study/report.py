"""Tables, figures, recommendations and ``report.md`` of a study folder, from the case folders.

:func:`build_report` is what a sweep does when its cases are done, and what
``valve-dolfinx report DIR`` does after a partial run or a job array: it reads
``cases/*/result.json`` and ``case.json`` and ``study.json`` (the settings: the
grid, the axes, the paths and the target), and writes ``results.csv``,
``results.json``, ``summary.json``, per comparison value a sizing map and a
coaptation-against-width plot of the worst case, ``panels/<case>.png``, the
nomogram when the study compares loaded root diameters
(:mod:`~valve_dolfinx.study.nomogram`), and ``report.md``.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from valve_dolfinx.io import atomic_write, write_json
from valve_dolfinx.plotting.study import (
    plot_case_panel,
    plot_coaptation_vs_width,
    plot_sizing_map,
)
from valve_dolfinx.result import competence_text, margin_text
from valve_dolfinx.sizing.recommendation import CONFIRM_ROUNDS, Recommendation, recommend_all
from valve_dolfinx.sizing.surface import CV_FOLDS
from valve_dolfinx.study.axes import axis_label, value_text
from valve_dolfinx.study.grid import DEFAULT_PANEL_CASES, StudySettings
from valve_dolfinx.study.layout import (
    StudyLayout,
    layout_tables,
    read_rounds,
)
from valve_dolfinx.study.nomogram import is_nomogram, write_nomogram
from valve_dolfinx.study.rounds import RoundPlan, plan_round
from valve_dolfinx.study.store import CASES_DIR, SETTINGS_FILE, claim_owner, owner_text
from valve_dolfinx.study.table import case_rows, write_tables

__all__ = ["StudyReport", "build_report", "read_settings", "figure_suffix",
           "remove_report", "SWEEP_LOG", "ANSWER_FILES", "REPORT_FILES"]

log = logging.getLogger(__name__)

#: one JSON line per sweep run (start, end, ranks), appended by the runner
SWEEP_LOG = "sweeps.jsonl"
#: the files of a study that state its answer (glob patterns): written only for a complete
#: study, and removed by a report of an incomplete one
ANSWER_FILES = ("coaptation_vs_width*.png", "sizing_map*.png", "nomogram.csv", "nomogram.png")
#: every file :func:`build_report` writes (glob patterns)
REPORT_FILES = (*ANSWER_FILES, "summary.json", "report.md", "results.csv", "results.json",
                "panels/*.png")


@dataclass
class StudyReport:
    """What :func:`build_report` wrote and found.

    ``recommendations`` holds one :class:`Recommendation` per comparison value (one in a
    study that varies nothing), in the order of ``layout.comparisons``, and only for a
    :attr:`complete` study.  ``missing`` are the study's cases with no result that counts
    (no folder, or one whose result is stale or damaged); ``in_progress`` those of them a
    live process computes right now, with who.  :attr:`unfinished` lists every case without
    a result that counts, by why (the table says why for each): a study with any of them, or
    without any case, is not :attr:`complete`, and has no answer.
    """

    out: Path
    rows: list[dict]
    layout: StudyLayout | None
    recommendations: list[Recommendation]
    missing: list[str] = field(default_factory=list)
    in_progress: dict[str, str] = field(default_factory=dict)
    files: list[Path] = field(default_factory=list)
    #: the next round decided from the answers, and why the study stops (complete
    #: studies only)
    next_round: RoundPlan | None = None

    @property
    def unfinished(self) -> dict[str, list[str]]:
        """The cases that hold no result that counts, by why: ``failed``, ``damaged``,
        ``stale`` (computed with other settings), ``in progress`` (a live process computes
        it), ``not run yet``."""
        groups = {status: [r["case"] for r in self.rows if r.get("status") == status
                           and r["case"] not in self.in_progress]
                  for status in ("failed", "damaged", "stale")}
        groups["in progress"] = list(self.in_progress)
        have = {r["case"] for r in self.rows}
        groups["not run yet"] = [name for name in self.missing
                                 if name not in have and name not in self.in_progress]
        return {why: names for why, names in groups.items() if names}

    @property
    def complete(self) -> bool:
        return bool(self.rows) and not self.unfinished

    @property
    def incomplete_text(self) -> str:
        """Why the study has no answer, naming its cases (empty for a complete study)."""
        if self.complete:
            return ""
        if not self.rows:
            return "No answer: no case has finished yet."
        groups = self.unfinished
        held = sum(len(names) for names in groups.values())
        parts = []
        for why, names in groups.items():
            if why == "in progress":
                names = [f"{n} ({self.in_progress[n]})" for n in names]
            parts.append(f"{why}: {', '.join(names)}")
        return (f"No answer: the study is incomplete ({held} case(s) without a result that "
                f"counts: {'; '.join(parts)}).")

    @property
    def text(self) -> str:
        """Every recommendation's text, each headed by its comparison values; or why there
        is no answer."""
        if not self.complete:
            return self.incomplete_text
        parts = []
        for rec in self.recommendations:
            head = axis_label(rec.comparison.items())
            parts.append(f"[{head}] {rec.text}" if head else rec.text)
        return "\n".join(parts) or "No cases yet."


def read_settings(out: Path) -> StudySettings | None:
    """The settings a study folder was started with (``study.json``), if any."""
    path = Path(out) / SETTINGS_FILE
    if not path.is_file():
        return None
    data = json.loads(path.read_text())
    return StudySettings.from_dict(data.get("settings", data), source=str(path))


def _settings_from_rows(rows: list[dict]) -> StudySettings | None:
    """The grid of a folder without ``study.json``: its graft sizes, one member."""
    widths = sorted({r["graft_width_pct"] for r in rows if r.get("graft_width_pct") is not None})
    heights = sorted({r["graft_height_pct"] for r in rows
                      if r.get("graft_height_pct") is not None})
    if not widths:
        return None
    return StudySettings(widths_pct=tuple(widths), heights_pct=tuple(heights))


def figure_suffix(rec: Recommendation) -> str:
    """``""``, or ``__key=value`` per comparison value: the figures' file-name suffix."""
    return "".join(f"__{k}={value_text(v)}" for k, v in rec.comparison.items())


def _sweeps(out: Path) -> list[dict]:
    path = Path(out) / SWEEP_LOG
    if not path.is_file():
        return []
    runs = []
    for line in path.read_text().splitlines():
        try:
            runs.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return runs


def _fmt(value, digits: int = 2) -> str:
    if value is None or isinstance(value, float) and not math.isfinite(value):
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def _competence(row: dict) -> str:
    """``yes``, or ``no (leaks 0.40 mm²)`` with the case's reason; ``–`` without a result."""
    if row.get("competent") is None:
        return "–"
    return "yes" if row["competent"] else competence_text(row).replace("not competent", "no")


def _table(rows: list[dict]) -> list[str]:
    head = ("case", "W %", "H %", "converged", "competent", "min h (mm)", "central h (mm)",
            "area (mm²)", "ROA (mm²)", "root d (mm)", "wall (s)", "reason")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        reason = (r.get("reason") or "").replace("|", "/")
        if len(reason) > 90:
            reason = reason[:87] + "..."
        cells = (r["case"], _fmt(r.get("graft_width_pct"), 0), _fmt(r.get("graft_height_pct"), 0),
                 _fmt(r.get("converged")), _competence(r),
                 _fmt(r.get("min_coaptation_height_mm")),
                 _fmt(r.get("central_coaptation_height_mm")), _fmt(r.get("coaptation_area_mm2"), 1),
                 _fmt(r.get("regurgitant_orifice_area_mm2"), 3), _fmt(r.get("root_diameter_mm")),
                 _fmt(r.get("wall_time_s"), 0), reason)
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _worst_case_table(rec: Recommendation) -> list[str]:
    """One line per graft: its worst case over the members."""
    n = len(rec.members)
    head = ("graft", "worst min h (mm)", "spread (mm)", "margin (mm)", "limiting member",
            "not converged", "leaks", "intersects", "qualifies")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in rec.cells:
        counts = [f"{len(m)}/{n}" if m else "–" for m in (c.unconverged + c.missing,
                                                          c.leaking, c.intersecting)]
        label = f"{c.label} (confirmation)" if c.confirmation else c.label
        cells = (label, _fmt(c.worst_height_mm), _fmt(c.spread_mm),
                 "–" if c.margin_mm is None else margin_text(c.margin_mm, signed=True),
                 c.limiting_member or "–", *counts, _fmt(c.qualifies))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _what_was_run(out: Path, rows: list[dict], layout: StudyLayout | None,
                  settings: StudySettings | None, unfinished: dict[str, list[str]]
                  ) -> list[str]:
    first = rows[0] if rows else {}
    params = first.get("parameters") or {}
    mesh = first.get("mesh_size_mm", (params.get("geometry") or {}).get("mesh_size_mm"))
    versions = first.get("versions") or {}
    compute = sum(float(r.get("wall_time_s") or 0.0) * int(r.get("n_ranks") or 1) for r in rows)
    converged = sum(bool(r.get("converged")) for r in rows)
    lines = []
    if settings is not None:
        lines.append(f"- grid: widths +{', +'.join(f'{w:g}' for w in settings.widths_pct)} %; "
                     f"heights +{', +'.join(f'{h:g}' for h in settings.heights_pct)} %"
                     + ("; and the normal valve" if settings.include_normal else ""))
    if layout is not None:
        for axis in layout.axes:
            values = ", ".join(value_text(v) for v in axis.values)
            lines.append(f"- {axis.kind} axis `{axis.key}`: {values}")
        paths = "; ".join(f"{p.number}. {p.name}: {p.description}" for p in layout.paths)
        lines.append(f"- numerical paths (uncertainty): {paths}")
        lines.append(f"- {len(layout.members)} member(s) per cell, {len(layout.comparisons)} "
                     f"comparison value(s), {len(layout.cases)} cases")
    lines += [f"- mesh: target edge length {_fmt(mesh)} mm",
              f"- cases: {len(rows)} in the table, {converged} converged"
              + "".join(f"; {why}: {', '.join(names)}" for why, names in unfinished.items()),
              f"- compute time: {compute:.0f} rank·s summed over the cases"]
    for run in _sweeps(out)[-3:]:
        lines.append(f"- sweep run {run.get('started', '?')}: {run.get('n_ranks')} ranks, "
                     f"{run.get('ranks_per_case')} per case, {run.get('cases_run')} cases "
                     f"computed, {run.get('elapsed_s', 0):.0f} s wall time")
    if versions:
        keys = ("valve_dolfinx", "dolfinx", "petsc", "numpy")
        lines.append("- versions: " + ", ".join(f"{k} {versions[k]}" for k in keys
                                                 if k in versions))
    return lines


def _write_markdown(out: Path, report: StudyReport, settings: StudySettings | None,
                    panels: list[Path], nomogram: bool) -> Path:
    rows = report.rows
    params = (rows[0].get("parameters") or {}) if rows else {}
    lines = ["# Graft sizing study", "",
             "Normal valve and pericardial grafts of the non-coronary leaflet, closed under "
             f"{_fmt((params.get('loading') or {}).get('pressure_mmhg'), 0)} mmHg (SPEC §7).", "",
             "## What was run", "",
             *_what_was_run(out, rows, report.layout, settings, report.unfinished), ""]
    if report.complete:
        lines += ["## Recommendation", ""]
        if report.next_round is not None and report.next_round.text:
            lines += [report.next_round.text, ""]
    else:
        lines += ["## No answer: the study is incomplete", "", report.incomplete_text, "",
                  "No recommendation, sizing map or nomogram is written until every case has "
                  "a result computed with the study's settings: run the sweep again with the "
                  "study's settings (it computes exactly those cases), then `valve-dolfinx "
                  "report`.", ""]
    for rec in report.recommendations:
        head = axis_label(rec.comparison.items())
        suffix = figure_suffix(rec)
        if head:
            lines += [f"### {head}", ""]
        members = (f"Worst case of each graft over its {len(rec.members)} members "
                   f"({'; '.join(rec.members)})." if len(rec.members) > 1 else
                   "Each graft's result.")
        lines += [rec.text, "", members, "", *_worst_case_table(rec), "",
                  f"![minimum coaptation height against graft width{', ' + head if head else ''}]"
                  f"(coaptation_vs_width{suffix}.png)", "",
                  f"![sizing map{', ' + head if head else ''}](sizing_map{suffix}.png)", ""]
    if nomogram and report.complete:
        lines += ["## Nomogram", "", "![sizing nomogram](nomogram.png)", "",
                  "Numbers: [nomogram.csv](nomogram.csv).", ""]
    lines += ["## Results", "", *_table(rows), "",
              "Full table: [results.csv](results.csv), [results.json](results.json).", "",
              "## Panels", ""]
    for panel in panels:
        lines += [f"### {panel.stem}", "", f"![{panel.stem}](panels/{panel.name})", ""]
    lines += ["", f"_Report written {time.strftime('%Y-%m-%d %H:%M:%S')} by "
              "`valve-dolfinx report` from the case folders._", ""]
    text = "\n".join(lines)
    return atomic_write(out / "report.md", lambda tmp: tmp.write_text(text))


def _panels(out: Path, layout: StudyLayout, settings: StudySettings | None,
            skip: list[str]) -> list[Path]:
    """The panel of the first case (in the study's order) of the normal valve and of each
    panel graft (``W0_H0``), unless it is one of the cases ``skip`` (no result that counts)."""
    panels = []
    grafts = settings.panel_cases if settings else DEFAULT_PANEL_CASES
    for case in layout.panel_cases(grafts):
        if case.name in skip:
            continue
        panel = out / "panels" / f"{case.name}.png"
        title = _panel_title(case.width_pct, case.height_pct)
        values = axis_label((k, v) for k, v in case.values if not isinstance(v, tuple)
                            and (k != "path" or v > 1))
        if plot_case_panel(out / CASES_DIR / case.name, panel,
                           title=f"{title}, {values}" if values else title) is not None:
            panels.append(panel)
    return panels


def build_report(out: str | Path, settings: StudySettings | None = None,
                 target_mm: float | None = None, *, draft: bool = False) -> StudyReport:
    """Rebuild every study-level file of ``out`` from its case folders (serial; rank 0).

    ``draft``: the answers and the next round only, as a sweep decides its rounds (no
    cross-validation of the surface, no figures, ``report.md`` and ``summary.json`` not
    rewritten); the answers are those of the full report.

    Parameters
    ----------
    out
        The study folder.
    settings
        The study's settings; default: ``study.json`` (without it, one member on the
        graft sizes found).
    target_mm
        Minimum coaptation height every graft must reach in every member; default: the
        settings' ``target_coaptation_mm``, else each member's normal valve's.

    Every reader of a study's cases reads them this way: a case counts only when its folder
    holds it finished, whole (each file's SHA-256 as recorded) and with the identity the
    study's layout expects (:func:`~valve_dolfinx.result.check_case`, as the sweep resumes).
    A study with a case that does not count (:attr:`StudyReport.unfinished`: failed,
    damaged, stale, in progress, not run) gets its tables and a ``report.md`` that names
    them, but no answer: no recommendation, sizing map, coaptation plot or nomogram (those of
    an earlier report are removed), and ``summary.json`` says ``complete: false``.
    """
    out = Path(out)
    if not (out / CASES_DIR).is_dir():
        raise FileNotFoundError(f"{out} has no {CASES_DIR}/ folder: it is not a study folder "
                                "(run `valve-dolfinx sweep --out DIR` first)")
    settings = settings or read_settings(out)
    rows = case_rows(out)
    inferred = settings or _settings_from_rows(rows)
    layout = inferred.layout(read_rounds(out)) if inferred is not None else None
    if target_mm is None and settings is not None:
        target_mm = settings.target_coaptation_mm
    report = StudyReport(out, rows, layout, [])
    if layout is not None:
        # the cases' identity is checked against the settings the study ran with, not
        # against a grid guessed from the folders (a folder without study.json)
        report.rows = rows = case_rows(out, layout, identity=settings is not None)
        counted = {r["case"] for r in rows if r.get("status") not in ("damaged", "stale")}
        report.missing = [c.name for c in layout.cases if c.name not in counted]
        owners = {name: claim_owner(out, name) for name in report.missing}
        report.in_progress = {name: owner_text(owner) for name, owner in owners.items()
                              if owner is not None}
        if report.complete:
            report.recommendations = recommend_all(
                [layout_tables(layout, c, rows) for c in range(len(layout.comparisons))],
                target_mm, n_paths=len(layout.paths), confirmed=layout.confirm,
                cv_folds=0 if draft else CV_FOLDS,
                confirm_rounds=None if inferred.design == "adaptive" else CONFIRM_ROUNDS)
            report.next_round = plan_round(report.recommendations, layout, inferred.design,
                                           inferred.budget)
    if draft:
        return report
    files = list(write_tables(out, rows))
    files.append(write_json(out / "summary.json", {
        "settings": settings.to_dict() if settings else None, "complete": report.complete,
        "recommendations": [rec.to_dict() for rec in report.recommendations],
        "design": report.next_round.to_dict() if report.next_round else None,
        "cases": len(rows), "missing": report.missing, "unfinished": report.unfinished}))
    if not report.complete:
        remove_report(out, ANSWER_FILES)
    for rec in report.recommendations:
        head = axis_label(rec.comparison.items())
        suffix = figure_suffix(rec)
        for name, plot in (("coaptation_vs_width", plot_coaptation_vs_width),
                           ("sizing_map", plot_sizing_map)):
            plot(rec, out / f"{name}{suffix}.png", title=head)
            files.append(out / f"{name}{suffix}.png")
    panels = _panels(out, layout, settings, report.missing) if layout is not None else []
    files += panels
    nomogram = layout is not None and is_nomogram(layout) and report.complete
    if nomogram:
        files += write_nomogram(out, report.recommendations, layout, rows)
    files.append(_write_markdown(out, report, settings, panels, nomogram))
    report.files = files
    log.debug("report: %d cases, %d recommendation(s) -> %s", len(rows),
              len(report.recommendations), out / "report.md")
    return report


def remove_report(out: Path, patterns: tuple[str, ...] = REPORT_FILES) -> None:
    """Remove the study report's files matching ``patterns`` from ``out`` (the cases stay)."""
    for pattern in patterns:
        for path in Path(out).glob(pattern):
            path.unlink(missing_ok=True)


def _panel_title(width_pct: float | None, height_pct: float | None) -> str:
    if width_pct is None:
        return "normal valve"
    return f"graft W +{width_pct:g} %, H +{height_pct:g} %"
