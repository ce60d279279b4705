"""The study table: one row per case, read from the case folders alone (SPEC §7 schema).

A row is a case's ``result.json`` (whatever fields ``CaseResult`` has) with the
study's bookkeeping (case name, status, reason, settings hash).  The SPEC §7
columns come first, then the bookkeeping, then every other field of the
result in its own order.  A case folder whose files are damaged
(:func:`~valve_dolfinx.result.check_case`) is a row with status ``damaged`` and the
reason, its result fields empty.  ``results.json`` keeps the nested fields (per-leaflet
numbers, parameters, versions) as they are; ``results.csv`` flattens them into
dotted column names (``parameters.geometry.mesh_size``), so both hold the
same numbers.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import re
from pathlib import Path
from typing import Any

from valve_dolfinx.io import atomic_write, write_json
from valve_dolfinx.study.grid import NORMAL_CASE
from valve_dolfinx.study.store import CASES_DIR, check_study_case

__all__ = ["SPEC_COLUMNS", "case_rows", "flatten", "write_tables",
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
    return (0, 0.0, 0.0) if w is None else (1, float(w), float(h if h is not None else 0.0))


#: a graft case's folder name
_GRAFT_NAME = re.compile(r"W(\d+(?:\.\d+)?)_H(\d+(?:\.\d+)?)")


def _reason(record: dict, result: dict) -> str:
    if record.get("status") == "failed":
        return str(record.get("reason") or result.get("error") or "failed")
    if not result.get("converged", False):
        return str(result.get("solver_message") or record.get("reason") or "not converged")
    return ""


def case_rows(out: Path) -> list[dict]:
    """Rows of every case folder under ``out/cases`` (normal first, then W, H).

    A case whose files are missing, unreadable or disagree is a row with status
    ``damaged`` and the reason; a folder whose name is no case's is skipped with a warning.
    """
    rows = []
    root = Path(out) / CASES_DIR
    for folder in sorted(root.iterdir()) if root.is_dir() else []:
        if folder.name.startswith(".") or not folder.is_dir():
            continue
        size = _graft_size(folder.name)
        if size is False:
            log.warning("skipping %s: not a case folder of a study", folder)
            continue
        check = check_study_case(out, folder.name)
        if check.finished:
            rows.append(_row(folder.name, check.record, check.result))
            continue
        reason = check.reason or "no result.json or case.json"
        log.warning("%s: %s", folder, reason)
        rows.append(_damaged_row(folder.name, size, reason))
    return sorted(rows, key=_sort_key)


def _graft_size(name: str) -> tuple[float | None, float | None] | bool:
    """(W, H) of a case folder's name, (None, None) for the normal valve, False for others."""
    if name == NORMAL_CASE:
        return None, None
    match = _GRAFT_NAME.fullmatch(name)
    return (float(match[1]), float(match[2])) if match else False


def _damaged_row(name: str, size: tuple, reason: str) -> dict:
    row: dict[str, Any] = dict.fromkeys(SPEC_COLUMNS)
    row["graft_width_pct"], row["graft_height_pct"] = size
    row.update(case=name, status="damaged", reason=reason, settings_hash=None)
    return row


def _row(name: str, record: dict, result: dict) -> dict:
    row: dict[str, Any] = {key: result.get(key) for key in SPEC_COLUMNS}
    row.update(case=name, status=record.get("status", "finished"),
               reason=_reason(record, result), settings_hash=record.get("settings_hash"))
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


def write_tables(out: Path, rows: list[dict]) -> tuple[Path, Path]:
    """Write ``results.json`` (rows as they are) and ``results.csv`` (flattened), atomically."""
    out = Path(out)
    json_path = write_json(out / "results.json", rows)
    flat = [flatten(row) for row in rows]
    columns = list(dict.fromkeys(key for row in flat for key in row))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in flat:
        writer.writerow([_cell(row.get(key)) for key in columns])
    csv_path = atomic_write(out / "results.csv", lambda tmp: tmp.write_text(buffer.getvalue()))
    return csv_path, json_path


def read_csv_rows(path: Path) -> list[dict[str, str]]:
    """``results.csv`` as a list of {column: text} (for tests and quick looks)."""
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))
