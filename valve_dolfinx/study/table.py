"""The study table: one row per case, read from the case folders alone (SPEC §7 schema).

A row is a case's ``result.json`` (whatever fields ``CaseResult`` has) with the
study's bookkeeping (case name, its axis values, status, reason, configuration
hash).  The SPEC §7 columns come first, then the case name, one column per axis
key (``root.loaded_diameter_mm``, ...) and ``path`` (a list where the case serves
several values, as the normal valve serves every path), then the rest of the
bookkeeping, then every other field of the result in its own order.  A case
folder whose files are damaged (:func:`~valve_dolfinx.result.check_case`) is a
row with status ``damaged`` and the reason, and a case computed with other settings than
the study's (another identity, or not converged under another wall-clock limit) a row with
status ``stale``; the result fields of both are empty, so that no number of theirs enters
a table, figure or recommendation.
``results.json`` keeps the nested fields (per-leaflet numbers, parameters,
versions) as they are; ``results.csv`` flattens them into
dotted column names (``parameters.geometry.mesh_size_mm``), so both hold the
same numbers.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from valve_dolfinx.io import atomic_write, write_json
from valve_dolfinx.study.grid import NORMAL_CASE
from valve_dolfinx.study.store import CASES_DIR, check_study_case

if TYPE_CHECKING:
    from valve_dolfinx.study.layout import StudyLayout

__all__ = ["SPEC_COLUMNS", "case_rows", "flatten", "write_tables", "write_csv",
           "read_csv_rows"]

log = logging.getLogger(__name__)

#: The columns SPEC §7 requires of every case, in its order
SPEC_COLUMNS = (
    "graft_width_pct", "graft_height_pct", "converged", "min_coaptation_height_mm",
    "central_coaptation_height_mm", "coaptation_area_mm2", "regurgitant_orifice_area_mm2",
    "competent", "root_diameter_mm", "max_penetration_mm", "n_dofs", "n_ranks", "wall_time_s",
)


def _sort_key(row: dict) -> tuple:
    w, h = row.get("graft_width_pct"), row.get("graft_height_pct")
    size = (0, 0.0, 0.0) if w is None else (1, float(w), float(h if h is not None else 0.0))
    return (*size, row["case"])


#: a graft case's folder name: its size, then any axis values (``W14_H13__path=2``)
_GRAFT_NAME = re.compile(r"W(\d+(?:\.\d+)?)_H(\d+(?:\.\d+)?)(?:__.*)?")


def _reason(record: dict, result: dict) -> str:
    if record.get("status") == "failed":
        return str(record.get("reason") or result.get("error") or "failed")
    if not result.get("converged", False):
        return str(result.get("solver_message") or record.get("reason") or "not converged")
    return ""


def case_rows(out: Path, layout: StudyLayout | None = None, *, identity: bool = True
              ) -> list[dict]:
    """Rows of every case folder under ``out/cases``.

    With ``layout`` (the study's cases): in its order, then any other case folder, each
    marked ``confirmation`` when it confirms an answer (a size off the grid), and (with
    ``identity``) each of its cases checked against the identity the layout expects;
    without it, the normal valve first, then by W and H, every whole case taken as it is.
    A case whose files are missing, unreadable or disagree is a row with status ``damaged``
    and the reason, one of other settings a row with status ``stale``; a folder whose name
    is no case's is skipped with a warning.
    """
    rows = []
    root = Path(out) / CASES_DIR
    for folder in sorted(root.iterdir()) if root.is_dir() else []:
        if folder.name.startswith(".") or not folder.is_dir():
            continue
        size = _graft_size(folder.name)
        if size is None:
            log.warning("skipping %s: not a case folder of a study", folder)
            continue
        name = folder.name
        if identity and layout is not None and name in layout.configs:
            check = check_study_case(out, name, layout.configs[name], layout.digests[name])
        else:
            check = check_study_case(out, name)
        if check.finished:
            rows.append(_row(name, check.record, check.result))
            continue
        status = "damaged" if check.state in ("damaged", "empty") else "stale"
        reason = check.reason or "no result.json or case.json"
        if status == "stale":
            reason = (f"computed with other settings than the study's ({reason}); a sweep "
                      "computes it again")
        log.warning("%s: %s", folder, reason)
        rows.append(_unusable_row(name, size, status, reason))
    rows.sort(key=_sort_key)
    if layout is not None:
        place = {case.name: i for i, case in enumerate(layout.cases)}
        rows.sort(key=lambda row: place.get(row["case"], len(place)))
        by_name = {case.name: case for case in layout.cases}
        for row in rows:
            case = by_name.get(row["case"])
            row["confirmation"] = case is not None and case.confirmation
            row["round"] = None if case is None else case.round
    return rows


def _graft_size(name: str) -> tuple[float | None, float | None] | None:
    """(W, H) of a case folder's name, (None, None) for a normal valve, None for others."""
    if name == NORMAL_CASE or name.startswith(f"{NORMAL_CASE}__"):
        return None, None
    match = _GRAFT_NAME.fullmatch(name)
    return (float(match[1]), float(match[2])) if match else None


def _unusable_row(name: str, size: tuple, status: str, reason: str) -> dict:
    """The row of a case folder whose result does not count (``damaged`` or ``stale``)."""
    row: dict[str, Any] = dict.fromkeys(SPEC_COLUMNS)
    row["graft_width_pct"], row["graft_height_pct"] = size
    row.update(case=name, status=status, reason=reason, config_hash=None)
    return row


def _row(name: str, record: dict, result: dict) -> dict:
    row: dict[str, Any] = {key: result.get(key) for key in SPEC_COLUMNS}
    row["case"] = name
    row.update(record.get("axes") or {})
    row.update(status=record.get("status", "finished"), reason=_reason(record, result),
               config_hash=record.get("config_hash"))
    for key, value in result.items():
        if key not in row:
            row[key] = value
    if name == NORMAL_CASE:
        row["graft_width_pct"] = row["graft_height_pct"] = None
    return row


def flatten(row: dict, prefix: str = "") -> dict:
    """Nested dicts to dotted keys; lists become JSON text (one CSV cell)."""
    flat: dict[str, Any] = {}
    for key, value in row.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, f"{name}."))
        elif isinstance(value, list | tuple):
            flat[name] = json.dumps(value)
        else:
            flat[name] = value
    return flat


def _cell(value: Any) -> str:
    """CSV text of a value: floats in full (round-trip) precision, booleans lower case."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "" if not math.isfinite(value) else repr(value)
    return str(value)


def write_csv(path: Path, rows: Sequence[dict], columns: Sequence[str] | None = None) -> Path:
    """Write flat ``rows`` as CSV, atomically (``columns``: every key in order of appearance)."""
    if columns is None:
        columns = list(dict.fromkeys(key for row in rows for key in row))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(key)) for key in columns])
    return atomic_write(Path(path), lambda tmp: tmp.write_text(buffer.getvalue()))


def write_tables(out: Path, rows: list[dict]) -> tuple[Path, Path]:
    """Write ``results.json`` (rows as they are) and ``results.csv`` (flattened), atomically."""
    out = Path(out)
    json_path = write_json(out / "results.json", rows)
    csv_path = write_csv(out / "results.csv", [flatten(row) for row in rows])
    return csv_path, json_path


def read_csv_rows(path: Path) -> list[dict[str, str]]:
    """``results.csv`` as a list of {column: text} (for tests and quick looks)."""
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))
