"""The mesh ladder: the normal valve and the inner grafts of the grid at 0.8, 0.6 and 0.45 mm,
the default mesh's discretisation error of the minimum coaptation height (docs/study.md, "The
resolution, measured").

Runs one study (``--out``, default ``results/mesh_ladder``) whose comparison axis is the mesh
size (``geometry.mesh_size_mm``), along the first ``--paths`` numerical paths, then writes the
table that the sizing answer reads (``--table``, default
``benchmarks/results/mesh_ladder.csv``: one row per case, its graft size, mesh size, path,
convergence, competence and minimum coaptation height) and prints, per cell, the height at
each mesh and its change from the finest, with the root-mean-square difference of each mesh
from the finest over the cells sound at both (what
:func:`valve_dolfinx.sizing.resolution.discretisation_error_mm` takes as the discretisation
error).  The study resumes: a rerun with the same ``--out`` computes only what is missing.

The table, drawn from the CSV, goes beside it (``mesh_ladder.md``; ``--tables-only``
redraws it from the CSV without running the study).

The grafts are the grid's inner 3 × 3 cells (W 7, 14, 21 %, H 13, 27, 40 %), where the
answers fall; the narrowest and the lowest grafts mostly leak, and a case that is not sound
at both meshes does not enter the error.  A 0.45 mm graft case takes 10-20 min on a loaded
core, hence the wall-clock limit of an hour.

Run on the 2-core machine: ``.venv/bin/mpirun -n 2 .venv/bin/python benchmarks/mesh_ladder.py``
(about two hours).  A smoke test:
``--meshes 2.0 1.6 --widths 14 --heights 13 --out /tmp/ladder --table /tmp/ladder.csv``.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

# benchmarks/result_tables.py, beside this script
from result_tables import Column, Table, add_tables_only, cell, markdown_table

from valve_dolfinx._compat import MPI
from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.interrupts import interrupt_on_signals
from valve_dolfinx.sizing.resolution import MESH_LADDER, discretisation_error_mm
from valve_dolfinx.study import StudySettings
from valve_dolfinx.study.runner import run_study
from valve_dolfinx.study.table import case_rows

#: the ladder's mesh sizes (mm), coarsest (the default) first
MESHES_MM = (0.8, 0.6, 0.45)
#: its grafts: the grid's inner cells
WIDTHS_PCT, HEIGHTS_PCT = (7.0, 14.0, 21.0), (13.0, 27.0, 40.0)
#: wall-clock limit of a case (s)
WALL_TIME_LIMIT_S = 3600.0
#: the columns of the ladder's table
COLUMNS = ("case", "graft_width_pct", "graft_height_pct", "mesh_size_mm", "path", "converged",
           "competent", "min_coaptation_height_mm", "regurgitant_orifice_area_mm2",
           "wall_time_s")
MESH_KEY = "geometry.mesh_size_mm"


def ladder_rows(rows: list[dict]) -> list[dict]:
    """The table's rows from the study's: the finished cases of the ladder's grid only (a
    case folder the layout does not hold has no round), with their mesh size."""
    out = []
    for row in rows:
        if row.get("status") != "finished" or row.get("round") is None:
            continue
        mesh = row.get(MESH_KEY, row.get("mesh_size_mm"))
        out.append({**{k: row.get(k) for k in COLUMNS}, "mesh_size_mm": mesh})
    return out


def _cell(row: dict) -> str:
    w = row["graft_width_pct"]
    return "normal" if w is None else GraftSize(w, row["graft_height_pct"]).label


def draw_ladder(rows: list[dict], table: Path) -> str:
    """Markdown: per cell and path, the minimum coaptation height at each mesh (``not
    sound`` where the case did not converge or is not competent) and its change from the
    finest mesh; below, each mesh's discretisation error as the sizing answer reads it from
    ``table`` (:func:`discretisation_error_mm`)."""
    meshes = sorted({row["mesh_size_mm"] for row in rows}, reverse=True)
    finest = min(meshes)
    others = [m for m in meshes if m != finest]
    cells: dict[tuple, dict] = {}
    for row in rows:
        key = (_cell(row), row["path"])
        y = row["min_coaptation_height_mm"]
        sound = bool(row["converged"] and row["competent"]) and y is not None
        order = (-1.0, -1.0) if row["graft_width_pct"] is None else (
            row["graft_width_pct"], row["graft_height_pct"])
        entry = cells.setdefault(key, {"cell": key[0], "path": key[1], "order": order})
        entry[row["mesh_size_mm"]] = cell(y, ".2f") + ("" if sound or y is None
                                                       else " (not sound)")
        if sound:
            entry[("sound", row["mesh_size_mm"])] = y
    for entry in cells.values():
        for m in others:
            a, b = entry.get(("sound", m)), entry.get(("sound", finest))
            entry[("change", m)] = None if a is None or b is None else a - b
    columns = [Column("cell", "cell", text=True), Column("path", "path")]
    columns += [Column(f"{m:g} mm", lambda e, m=m: e.get(m)) for m in meshes]
    columns += [Column(f"{m:g} − {finest:g}", lambda e, m=m: e[("change", m)], "+.2f")
                for m in others]
    ordered = sorted(cells.values(), key=lambda e: (e["order"], e["path"]))
    grafts = len({k[0] for k in cells} - {"normal"})
    lines = [f"Mesh ladder: the normal valve and {grafts} graft{'s' * (grafts != 1)} at "
             f"{', '.join(f'{m:g}' for m in meshes)} mm; minimum coaptation height (mm), "
             f"{sum(row['wall_time_s'] or 0.0 for row in rows):.0f} s of case time.\n",
             markdown_table(columns, ordered)]
    for mesh in others:
        error, source = discretisation_error_mm(table, mesh)
        lines.append(f"Discretisation error at {mesh:g} mm: "
                     f"{'not measured' if error is None else f'{error:.3f} mm'} ({source}).\n")
    return "\n".join(lines)


def ladder_table(path: Path) -> Table:
    """The ladder's table, its CSV at ``path`` (what the sizing answer reads)."""
    return Table(path.stem, ".venv/bin/mpirun -n 2 .venv/bin/python benchmarks/mesh_ladder.py",
                 COLUMNS, lambda rows: draw_ladder(rows, path), folder=path.parent)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/mesh_ladder"))
    parser.add_argument("--table", type=Path, default=MESH_LADDER,
                        help="where the ladder's table goes (default: %(default)s)")
    parser.add_argument("--meshes", type=float, nargs="+", default=list(MESHES_MM),
                        metavar="MM")
    parser.add_argument("--widths", type=float, nargs="+", default=list(WIDTHS_PCT))
    parser.add_argument("--heights", type=float, nargs="+", default=list(HEIGHTS_PCT))
    parser.add_argument("--paths", type=int, default=1, help="numerical paths per cell")
    parser.add_argument("--wall-time-limit", type=float, default=WALL_TIME_LIMIT_S,
                        metavar="S", help="of each case (default %(default)g)")
    add_tables_only(parser)
    args = parser.parse_args(argv)
    if args.tables_only:
        print(ladder_table(args.table).redraw())
        return 0
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    comm = MPI.COMM_WORLD
    if comm.rank == 0:  # one line per finished case
        logging.getLogger("valve_dolfinx.study").setLevel(logging.INFO)
    settings = StudySettings(widths_pct=tuple(args.widths), heights_pct=tuple(args.heights),
                             paths=args.paths, mesh_size_mm=None, panel_cases=(),
                             vary={MESH_KEY: list(args.meshes)},
                             wall_time_limit_s=args.wall_time_limit)
    t0 = time.perf_counter()
    # the grid's cases only: no report, hence no confirmation rounds (the ladder answers
    # nothing)
    run_study(settings, args.out, comm, report=False)
    if comm.rank != 0:
        return 0
    rows = ladder_rows(case_rows(args.out, settings.layout(())))
    written = ladder_table(args.table).write(rows)
    print(written.read_text())
    print(f"wall time {time.perf_counter() - t0:.0f} s -> {args.out}; table {args.table}")
    return 0


if __name__ == "__main__":
    with interrupt_on_signals():  # an interrupted ladder resumes with the same --out
        raise SystemExit(main())
