"""Tables, figures, recommendation and ``report.md`` of a study folder, from the case folders alone.

:func:`build_report` is what a sweep does when its cases are done, and what
``valve-dolfinx report DIR`` does after a partial run or a job array: it reads
``cases/*/result.json`` and ``case.json`` (and ``study.json``, if present, for
the grid and the target), and writes ``results.csv``, ``results.json``,
``summary.json``, ``coaptation_vs_width.png``, ``sizing_map.png``,
``panels/<case>.png`` and ``report.md``.
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
from valve_dolfinx.result import competence_text
from valve_dolfinx.study.grid import NORMAL_CASE, StudySettings
from valve_dolfinx.study.recommend import Recommendation, recommend
from valve_dolfinx.study.store import CASES_DIR, SETTINGS_FILE
from valve_dolfinx.study.table import case_rows, write_tables

__all__ = ["StudyReport", "build_report", "read_settings", "SWEEP_LOG"]

log = logging.getLogger(__name__)

#: one JSON line per sweep run (start, end, ranks), appended by the runner
SWEEP_LOG = "sweeps.jsonl"


@dataclass
class StudyReport:
    """What :func:`build_report` wrote and found.

    ``missing`` are the cases of the study's grid with no folder yet; ``incomplete``
    lists them with the cases that failed or whose files are damaged (the report's table
    says why): a study without them all, or without any case, is not complete.
    """

    out: Path
    rows: list[dict]
    recommendation: Recommendation
    missing: list[str] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)

    @property
    def unfinished(self) -> dict[str, list[str]]:
        """The cases that hold no result, by why: ``failed``, ``damaged``, ``not run yet``."""
        groups = {status: [r["case"] for r in self.rows if r.get("status") == status]
                  for status in ("failed", "damaged")}
        groups["not run yet"] = list(self.missing)
        return {why: names for why, names in groups.items() if names}

    @property
    def complete(self) -> bool:
        return bool(self.rows) and not self.unfinished


def read_settings(out: Path) -> StudySettings | None:
    """The settings a study folder was started with (``study.json``), if any."""
    path = Path(out) / SETTINGS_FILE
    if not path.is_file():
        return None
    data = json.loads(path.read_text())
    return StudySettings.from_dict(data.get("settings", data), source=str(path))


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


def _write_markdown(out: Path, rows: list[dict], rec: Recommendation,
                    settings: StudySettings | None, unfinished: dict[str, list[str]],
                    panels: list[Path]) -> Path:
    first = rows[0] if rows else {}
    params = first.get("parameters") or {}
    mesh = first.get("mesh_size_mm", (params.get("geometry") or {}).get("mesh_size"))
    versions = first.get("versions") or {}
    widths = sorted({r["graft_width_pct"] for r in rows if r.get("graft_width_pct") is not None})
    heights = sorted({r["graft_height_pct"] for r in rows
                      if r.get("graft_height_pct") is not None})
    if settings is not None:
        widths, heights = list(settings.widths_pct), list(settings.heights_pct)
    compute = sum(float(r.get("wall_time_s") or 0.0) * int(r.get("n_ranks") or 1) for r in rows)
    converged = sum(bool(r.get("converged")) for r in rows)
    lines = ["# Graft sizing study", "",
             "Normal valve and pericardial grafts of the non-coronary leaflet, closed under "
             f"{_fmt(params.get('pressure_mmhg'), 0)} mmHg (SPEC §7).", "",
             "## What was run", "",
             f"- grid: widths +{', +'.join(f'{w:g}' for w in widths)} %; heights "
             f"+{', +'.join(f'{h:g}' for h in heights)} %"
             + ("; and the normal valve" if settings is None or settings.include_normal else ""),
             f"- mesh: target edge length {_fmt(mesh)} mm",
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
    lines += ["", "## Recommendation", "", rec.text or "No cases yet.", "",
              "## Results", "", *_table(rows), "",
              "Full table: [results.csv](results.csv), [results.json](results.json).", "",
              "## Figures", "",
              "![minimum coaptation height against graft width](coaptation_vs_width.png)", "",
              "![sizing map](sizing_map.png)", ""]
    for panel in panels:
        lines += [f"### {panel.stem}", "", f"![{panel.stem}](panels/{panel.name})", ""]
    lines += ["", f"_Report written {time.strftime('%Y-%m-%d %H:%M:%S')} by "
              "`valve-dolfinx report` from the case folders._", ""]
    text = "\n".join(lines)
    return atomic_write(out / "report.md", lambda tmp: tmp.write_text(text))


def build_report(out: str | Path, settings: StudySettings | None = None,
                 target_mm: float | None = None) -> StudyReport:
    """Rebuild every study-level file of ``out`` from its case folders (serial; rank 0)."""
    out = Path(out)
    if not (out / CASES_DIR).is_dir():
        raise FileNotFoundError(f"{out} has no {CASES_DIR}/ folder: it is not a study folder "
                                "(run `valve-dolfinx sweep --out DIR` first)")
    settings = settings or read_settings(out)
    if target_mm is None and settings is not None:
        target_mm = settings.target_coaptation_mm
    rows = case_rows(out)
    missing = []
    if settings is not None:
        have = {r["case"] for r in rows}
        missing = [c.name for c in settings.cases() if c.name not in have]
    rec = recommend(rows, target_mm)
    report = StudyReport(out, rows, rec, missing)
    files = report.files
    files += write_tables(out, rows)
    files.append(write_json(out / "summary.json", {
        "settings": settings.to_dict() if settings else None, "recommendation": rec.to_dict(),
        "cases": len(rows), "missing": missing, "unfinished": report.unfinished}))
    plot_coaptation_vs_width(rows, out / "coaptation_vs_width.png", target_mm=target_mm)
    plot_sizing_map(rows, out / "sizing_map.png", recommended=rec.recommended, best=rec.best)
    files += [out / "coaptation_vs_width.png", out / "sizing_map.png"]
    panels = []
    wanted = [NORMAL_CASE, *(settings.panel_cases if settings else ())]
    for name in dict.fromkeys(wanted):
        panel = out / "panels" / f"{name}.png"
        if plot_case_panel(out / CASES_DIR / name, panel, title=_panel_title(name)) is not None:
            panels.append(panel)
    files += panels
    files.append(_write_markdown(out, rows, rec, settings, report.unfinished, panels))
    log.debug("report: %d cases, %s -> %s", len(rows), rec.recommended or
             (f"none qualifies (best {rec.best})" if rec.best else "no recommendation"),
             out / "report.md")
    return report


def _panel_title(name: str) -> str:
    if name == NORMAL_CASE:
        return "normal valve"
    width, height = name[1:].split("_H")
    return f"graft W +{width} %, H +{height} %"

