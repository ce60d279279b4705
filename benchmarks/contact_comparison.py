"""Two runs of the same study, case by case: intersections, Newton iterations, wall time,
coaptation and competence.

Reads the ``cases/*/result.json`` of two study folders -- e.g. the default study
(``make run``'s sweep) computed by two versions of the contact -- and writes one row per
case present in both, with the totals in a last row::

    .venv/bin/python benchmarks/contact_comparison.py BEFORE_DIR AFTER_DIR \\
        --labels "law alone" "law + guard"

The table goes to ``benchmarks/results/contact_comparison.{csv,md}``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from result_tables import Column, Table, markdown_table

FIGURES = ("intersecting_pairs", "newton_iterations", "rejected_newton_iterations",
           "wall_time_s", "min_coaptation_height_mm", "competent", "converged")
FIELDS = ("case", "label_before", "label_after",
          *(f"{f}_{side}" for f in FIGURES for side in ("before", "after")))


def read_study(folder: Path) -> dict[str, dict]:
    """``{case name: result.json}`` of a study folder's finished cases."""
    out = {}
    for path in sorted(Path(folder).glob("cases/*/result.json")):
        out[path.parent.name] = json.loads(path.read_text())
    if not out:
        raise SystemExit(f"{folder}: no cases/*/result.json; give a study folder")
    return out


def compare(before: dict[str, dict], after: dict[str, dict]) -> list[dict]:
    """A row per case in both runs, then the totals (sums; the number of competent and
    converged cases)."""
    rows = []
    for name in sorted(set(before) & set(after), key=lambda n: (n != "normal", n)):
        row = {"case": name}
        for f in FIGURES:
            row[f"{f}_before"], row[f"{f}_after"] = before[name].get(f), after[name].get(f)
        rows.append(row)
    total = {"case": "total"}
    for f in FIGURES:
        if f == "min_coaptation_height_mm":
            continue
        for side in ("before", "after"):
            values = [r[f"{f}_{side}"] for r in rows if r[f"{f}_{side}"] is not None]
            total[f"{f}_{side}"] = int(sum(values)) if f in ("competent", "converged") \
                else sum(values)
    return [*rows, total]


def draw(rows: list[dict]) -> str:
    """The Markdown table, its headings naming the two runs as the CSV's labels do."""
    labels = (rows[0]["label_before"], rows[0]["label_after"]) if rows else ("", "")

    def pair(field, fmt=""):
        return [Column(f"{heading} ({label})", f"{field}_{side}", fmt)
                for label, side in zip(labels, ("before", "after"), strict=True)
                for heading in [HEADINGS[field]]]
    columns = [Column("case", "case", text=True)]
    for field, fmt in (("intersecting_pairs", "d"), ("newton_iterations", "d"),
                       ("rejected_newton_iterations", "d"), ("wall_time_s", ".1f"),
                       ("min_coaptation_height_mm", ".2f"), ("competent", "")):
        columns += pair(field, fmt)
    return markdown_table(columns, rows)


HEADINGS = {"intersecting_pairs": "pairs", "newton_iterations": "Newton",
            "rejected_newton_iterations": "failed Newton", "wall_time_s": "wall (s)",
            "min_coaptation_height_mm": "min height (mm)", "competent": "competent"}


TABLE = Table("contact_comparison", "benchmarks/contact_comparison.py BEFORE AFTER", FIELDS,
              draw)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path, nargs="?", help="study folder (the reference)")
    parser.add_argument("after", type=Path, nargs="?", help="study folder (the change)")
    parser.add_argument("--labels", nargs=2, default=("before", "after"),
                        help="what to call the two runs in the headings")
    args = TABLE.arguments(parser)
    table = args.table
    if args.before is None or args.after is None:
        parser.error("give the two study folders (or --tables-only)")
    rows = compare(read_study(args.before), read_study(args.after))
    for row in rows:
        row["label_before"], row["label_after"] = args.labels
    path = table.write(rows)
    print(path.read_text())


if __name__ == "__main__":
    main()
