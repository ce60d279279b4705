"""The mesh ladder: the normal valve and the grafts of the grid at 0.8, 0.6 and 0.45 mm, the
default mesh's discretisation error of the minimum coaptation height (docs/study.md, "The
resolution, measured").

Runs one study (``--out``, default ``results/mesh_ladder``) whose comparison axis is the mesh
size (``geometry.mesh_size``), along the first ``--paths`` numerical paths, then writes the
table that the sizing answer reads (``--table``, default
``benchmarks/results/mesh_ladder.csv``: one row per case, its graft size, mesh size, path,
convergence, competence and minimum coaptation height) and prints, per cell, the height at
each mesh and its change from the finest, with the root-mean-square difference of each mesh
from the finest over the cells sound at both (what
:func:`valve_dolfinx.sizing.resolution.discretisation_error_mm` takes as the discretisation
error).  The study resumes: a rerun with the same ``--out`` computes only what is missing.

Run on the 2-core machine: ``.venv/bin/mpirun -n 2 .venv/bin/python benchmarks/mesh_ladder.py``
(the default grid at three meshes: many hours).  A smoke test:
``--meshes 2.0 1.6 --widths 14 --heights 13 --out /tmp/ladder --table /tmp/ladder.csv``.
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from pathlib import Path

from valve_dolfinx._compat import MPI
from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.interrupts import interrupt_on_signals
from valve_dolfinx.sizing.resolution import MESH_LADDER, discretisation_error_mm
from valve_dolfinx.study import STUDY_HEIGHTS_PCT, STUDY_WIDTHS_PCT, StudySettings
from valve_dolfinx.study.runner import run_study
from valve_dolfinx.study.table import write_csv

#: the ladder's mesh sizes (mm), coarsest (the default) first
MESHES_MM = (0.8, 0.6, 0.45)
#: the columns of the ladder's table
COLUMNS = ("case", "graft_width_pct", "graft_height_pct", "mesh_size_mm", "path", "converged",
           "competent", "min_coaptation_height_mm", "regurgitant_orifice_area_mm2",
           "wall_time_s")
MESH_KEY = "geometry.mesh_size"


def ladder_rows(rows: list[dict]) -> list[dict]:
    """The table's rows from the study's: finished cases only, with their mesh size."""
    out = []
    for row in rows:
        if row.get("status") != "finished":
            continue
        mesh = row.get(MESH_KEY, row.get("mesh_size_mm"))
        out.append({**{k: row.get(k) for k in COLUMNS}, "mesh_size_mm": mesh})
    return out


def _cell(row: dict) -> str:
    w = row["graft_width_pct"]
    return "normal" if w is None else GraftSize(w, row["graft_height_pct"]).label


def print_ladder(rows: list[dict], meshes: list[float]) -> None:
    """Markdown: per cell and path, the height at each mesh, and its change from the finest."""
    finest = min(meshes)
    heights: dict[tuple, dict[float, str]] = {}
    values: dict[tuple, dict[float, float]] = {}
    for row in rows:
        key = (_cell(row), row["path"] if not isinstance(row["path"], list) else 1)
        y = row["min_coaptation_height_mm"]
        sound = row["converged"] and row["competent"]
        text = "–" if y is None else f"{y:.2f}" + ("" if sound else " (not sound)")
        heights.setdefault(key, {})[row["mesh_size_mm"]] = text
        if sound and y is not None:
            values.setdefault(key, {})[row["mesh_size_mm"]] = y
    others = [m for m in meshes if m != finest]
    print("| cell | path | " + " | ".join(f"{m:g} mm" for m in meshes) + " | "
          + " | ".join(f"{m:g} − {finest:g}" for m in others) + " |")
    print("|---|---:|" + "---:|" * (len(meshes) + len(others)))
    for key in sorted(heights, key=lambda k: (k[0] != "normal", k)):
        change = [values.get(key, {}).get(m, math.nan) - values.get(key, {}).get(finest, math.nan)
                  for m in others]
        print(f"| {key[0]} | {key[1]} | "
              + " | ".join(heights[key].get(m, "–") for m in meshes) + " | "
              + " | ".join("–" if math.isnan(c) else f"{c:+.2f}" for c in change) + " |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/mesh_ladder"))
    parser.add_argument("--table", type=Path, default=MESH_LADDER,
                        help="where the ladder's table goes (default: %(default)s)")
    parser.add_argument("--meshes", type=float, nargs="+", default=list(MESHES_MM),
                        metavar="MM")
    parser.add_argument("--widths", type=float, nargs="+", default=list(STUDY_WIDTHS_PCT))
    parser.add_argument("--heights", type=float, nargs="+", default=list(STUDY_HEIGHTS_PCT))
    parser.add_argument("--paths", type=int, default=1, help="numerical paths per cell")
    parser.add_argument("--wall-time-limit", type=float, default=None, metavar="S")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    comm = MPI.COMM_WORLD
    if comm.rank == 0:  # one line per finished case
        logging.getLogger("valve_dolfinx.study").setLevel(logging.INFO)
    settings = StudySettings(widths_pct=tuple(args.widths), heights_pct=tuple(args.heights),
                             paths=args.paths, mesh_size_mm=None, panel_cases=(),
                             vary={MESH_KEY: list(args.meshes)},
                             wall_time_limit_s=args.wall_time_limit)
    t0 = time.perf_counter()
    outcome = run_study(settings, args.out, comm)
    if comm.rank != 0:
        return 0
    rows = ladder_rows(outcome.report.rows)
    args.table.parent.mkdir(parents=True, exist_ok=True)
    write_csv(args.table, rows, COLUMNS)
    print(f"\nMesh ladder: the normal valve and {len(args.widths)} × {len(args.heights)} grafts "
          f"at {', '.join(f'{m:g}' for m in args.meshes)} mm, {args.paths} path(s), "
          f"{comm.size} MPI rank(s); minimum coaptation height (mm).\n")
    print_ladder(rows, sorted(args.meshes, reverse=True))
    finest = min(args.meshes)
    for mesh in (m for m in args.meshes if m != finest):
        error, source = discretisation_error_mm(args.table, mesh)
        shown = "not measured" if error is None else f"{error:.3f} mm"
        print(f"\ndiscretisation error at {mesh:g} mm: {shown} ({source})")
    print(f"\nwall time {time.perf_counter() - t0:.0f} s -> {args.out}; table {args.table}")
    return 0


if __name__ == "__main__":
    with interrupt_on_signals():  # an interrupted ladder resumes with the same --out
        raise SystemExit(main())
