"""How far the answer of a finished study moves when its paths are resampled.

For each study folder given, reads the answer of every comparison value (as ``report``
does, without writing) and refits it on bootstrap resamples of the replicates
(``sizing.answer.bootstrap_stability``: in every cell each path's case is replaced by one
drawn with replacement from the cell's paths).  Prints and writes one row per study and
comparison value: the answer, the tolerance, how many resamples, the share whose answer
stays within 3 points of width and height of the study's (a "no graft" matches only "no
graft"), how many said "no graft", and the resamples' answers by how often::

    .venv/bin/python benchmarks/answer_stability.py results/graft_sweep DIR2 ...

The table goes to ``benchmarks/results/answer_stability.{csv,md}``.  A study with one path
has no replicates to resample: its share is 1 by construction and is not reported.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

from result_tables import Column, Table, markdown_table

import valve_dolfinx  # noqa: F401  (dolfinx_solver before anything else)

FIELDS = ("study", "comparison", "members", "paths", "graft_cases", "answer", "tolerance_mm",
          "resamples", "within_3_points", "no_graft", "resample_answers")


def stability_rows(folder: Path, resamples: int, seed: int = 0) -> list[dict]:
    """One row per comparison value of the study in ``folder``."""
    from valve_dolfinx.sizing.answer import SAME_SIZE_PCT, bootstrap_stability
    from valve_dolfinx.study.report import build_report, read_settings

    settings = read_settings(folder)
    report = build_report(folder, settings, draft=True)
    rows = []
    for rec in report.recommendations:
        answer = rec.answer
        paths = len({t.path for t in rec.tables})
        comparison = ", ".join(f"{k}={v}" for k, v in answer.comparison.items())
        name = folder.parent.name if folder.name == "study" else folder.name  # a plan's
        row = {"study": name, "comparison": comparison,
               "members": len(answer.members), "paths": paths,
               "graft_cases": sum(1 for t in rec.tables for r in t.rows
                                  if r.get("graft_width_pct") is not None),
               "answer": answer.size.label if answer.size else f"none ({answer.why})",
               "tolerance_mm": answer.tolerance_mm}
        if paths > 1 and answer.lattice is not None:
            share, sizes = bootstrap_stability(rec.tables, answer, resamples, seed=seed,
                                               points=SAME_SIZE_PCT, target_mm=rec.target_mm)
            counts = Counter(s.label if s else "none" for s in sizes)
            row.update(resamples=resamples, within_3_points=share,
                       no_graft=counts.get("none", 0),
                       resample_answers=", ".join(f"{k} ×{n}" for k, n in counts.most_common()))
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def draw(rows: list[dict]) -> str:
    columns = [Column("study", "study", text=True), Column("comparison", "comparison", text=True),
               Column("members", "members", "d"), Column("paths", "paths", "d"),
               Column("graft cases", "graft_cases", "d"), Column("answer", "answer", text=True),
               Column("tolerance (mm)", "tolerance_mm", ".2f"),
               Column("resamples", "resamples", "d"),
               Column("within 3 points", "within_3_points", ".0%"),
               Column("no graft", "no_graft", "d"),
               Column("resamples' answers", "resample_answers", text=True)]
    return markdown_table(columns, rows)


TABLE = Table("answer_stability", "benchmarks/answer_stability.py STUDY ...", FIELDS, draw)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("studies", nargs="*", type=Path, help="finished study folders")
    parser.add_argument("--resamples", type=int, default=50,
                        help="bootstrap resamples per answer (default %(default)s)")
    args = TABLE.arguments(parser, argv)
    table = args.table
    if not args.studies:
        parser.error("give at least one finished study folder")
    rows = [row for folder in args.studies for row in stability_rows(folder, args.resamples)]
    print(table.write(rows).read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
