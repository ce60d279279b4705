"""How far two numerical paths of the same cell end apart, over a finished study.

Reads a study folder's ``results.csv`` and ``study.json`` and pairs, for every graft of the
study's grid and every combination of its other axes (the comparison and uncertainty
values), the case of each path (path 1 from the closed normal valve, path 2 from the open
valve; confirmation sizes off the grid are left out).  Writes one row per study: the cells
with two paths, how many converged along both, how many of those end within 0.3 mm of each
other in the minimum coaptation height (the README's reading resolution), the median and
largest difference and where it is, and the cells sealed along one path and not along the
other::

    .venv/bin/python benchmarks/path_agreement.py results/nomogram

The table goes to ``benchmarks/results/path_agreement.{csv,md}``.
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import sys
from pathlib import Path

from result_tables import Column, Table, markdown_table, parse

#: a difference the README reads as within the default mesh's resolution (mm)
WITHIN_MM = 0.3
FIELDS = ("study", "cells", "both_converged", "within", "median_mm", "largest_mm",
          "largest_cell", "not_converged", "sealed_on_one_path")


def _flag(text: str) -> bool:
    """A CSV cell that reads true (:func:`result_tables.parse`)."""
    return parse(text) is True


def agreement_row(folder: Path) -> dict:
    """The row of the study in ``folder``.

    A cell is a grid size and a value of every comparison and uncertainty axis, read from
    the table's own columns (the axis keys and ``path``); it is named by its path-1 case.
    """
    study = json.loads((folder / "study.json").read_text())["settings"]
    grid = {(float(w), float(h)) for w in study["widths_pct"] for h in study["heights_pct"]}
    axes = [*(study.get("vary") or {}), *(study.get("uncertain") or {})]
    with open(folder / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    cells: dict[tuple, dict[int, dict]] = {}
    for row in rows:
        if not row["graft_width_pct"]:
            continue  # a normal valve, shared by the paths
        size = (float(row["graft_width_pct"]), float(row["graft_height_pct"]))
        if size not in grid:
            continue  # a confirmation size
        cell = (size, tuple(row[key] for key in axes))
        cells.setdefault(cell, {})[int(row.get("path") or 1)] = row
    paired = {paths[1]["case"]: paths for paths in cells.values() if {1, 2} <= set(paths)}
    differences, unconverged, flips = [], [], []
    for name, paths in sorted(paired.items()):
        one, two = paths[1], paths[2]
        if not (_flag(one["converged"]) and _flag(two["converged"])):
            unconverged.append(name)
            continue
        difference = abs(float(one["min_coaptation_height_mm"])
                         - float(two["min_coaptation_height_mm"]))
        differences.append((difference, name))
        if _flag(one["competent"]) != _flag(two["competent"]):
            flips.append(name)
    values = [d for d, _ in differences]
    largest = max(differences, default=(None, None))
    return {"study": folder.name, "cells": len(paired), "both_converged": len(differences),
            "within": sum(d <= WITHIN_MM for d in values),
            "median_mm": statistics.median(values) if values else None,
            "largest_mm": largest[0], "largest_cell": largest[1],
            "not_converged": " ".join(unconverged), "sealed_on_one_path": " ".join(flips)}


def draw(rows: list[dict]) -> str:
    columns = [Column("study", "study", text=True), Column("cells with 2 paths", "cells", "d"),
               Column("converged on both", "both_converged", "d"),
               Column(f"within {WITHIN_MM} mm", "within", "d"),
               Column("median (mm)", "median_mm", ".3f"),
               Column("largest (mm)", "largest_mm", ".2f"),
               Column("largest at", "largest_cell", text=True),
               Column("not converged on a path", "not_converged", text=True),
               Column("sealed on one path only", "sealed_on_one_path", text=True)]
    return ("Minimum coaptation height, path 1 (from the closed normal valve) against path 2 "
            "(from the open valve), per cell of the grid.\n\n" + markdown_table(columns, rows))


TABLE = Table("path_agreement", "benchmarks/path_agreement.py STUDY ...", FIELDS, draw)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("studies", nargs="*", type=Path, help="finished study folders")
    args = TABLE.arguments(parser, argv)
    if not args.studies:
        parser.error("give at least one finished study folder (or --tables-only)")
    rows = [agreement_row(folder) for folder in args.studies]
    print(args.table.write(rows).read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
