"""Wall time of the graft sizing study: per case, in total, and how many cases converged.

Runs the study of SPEC §7 (normal valve + 5 × 4 grafts, default mesh unless
``--mesh-size``) into a fresh folder through :func:`valve_dolfinx.study.runner.run_study`,
as ``valve-dolfinx sweep`` does, and prints one line per case (rank group that
ran it is not tracked; the wall time is the case's own) and the totals: the
sweep's elapsed wall time, the sum of the case times and the speed-up the MPI
rank groups gave over running the cases one after the other.

The figures go to ``benchmarks/results/sweep.csv`` (a row per case and one for the sweep) and
the table drawn from them to ``sweep.md`` (``--tables-only`` redraws it from the CSV).

Run on the 2-core machine: ``.venv/bin/mpirun -n 2 .venv/bin/python benchmarks/sweep.py``
(``--mesh-size 1.6`` for a quick coarse figure; ``--widths``/``--heights`` for a
smaller grid; ``--out DIR`` to keep the cases, default ``results/benchmark_sweep/<time>``;
``--results DIR`` for the table of such a run).
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

# benchmarks/result_tables.py, beside this script
from result_tables import Column, Table, markdown_table

from valve_dolfinx._compat import MPI
from valve_dolfinx.interrupts import interrupt_on_signals
from valve_dolfinx.study import STUDY_HEIGHTS_PCT, STUDY_WIDTHS_PCT, StudySettings
from valve_dolfinx.study.runner import run_study

#: a case's figures in the table
CASE_FIELDS = ("case", "converged", "competent", "min_coaptation_height_mm",
               "central_coaptation_height_mm", "regurgitant_orifice_area_mm2",
               "intersecting_pairs", "newton_iterations", "rejected_newton_iterations",
               "n_cells", "mesh_size_mm", "wall_time_s", "reason")
FIELDS = ("kind", *CASE_FIELDS, "computed", "ranks", "ranks_per_case", "elapsed_s")


def draw(rows: list[dict]) -> str:
    """A line per case; below, the sweep: cases, how many converged, its elapsed time
    against the sum of the cases' wall times."""
    cases = [r for r in rows if r["kind"] == "case"]
    sweep = next(r for r in rows if r["kind"] == "sweep")
    columns = [Column("case", "case", text=True), Column("converged", "converged"),
               Column("competent", "competent"),
               Column("min height (mm)", "min_coaptation_height_mm", ".2f"),
               Column("central (mm)", "central_coaptation_height_mm", ".2f"),
               Column("orifice (mm²)", "regurgitant_orifice_area_mm2", ".2f"),
               Column("intersecting pairs", "intersecting_pairs"),
               Column("Newton", lambda r: None if r["newton_iterations"] is None else
                      f"{r['newton_iterations']} + {r['rejected_newton_iterations'] or 0}"),
               Column("cells", "n_cells", ","), Column("wall (s)", "wall_time_s", ".0f"),
               Column("reason", lambda r: (r["reason"] or "")[:60], text=True)]
    total = sum(float(r["wall_time_s"] or 0.0) for r in cases)
    elapsed = sweep["elapsed_s"]
    mesh = cases[0]["mesh_size_mm"] if cases else None
    accepted = sum(r["newton_iterations"] or 0 for r in cases)
    failed = sum(r["rejected_newton_iterations"] or 0 for r in cases)
    timing = (f"Sweep wall time {elapsed:.0f} s; sum of case wall times {total:.0f} s "
              f"(×{total / max(elapsed, 1e-9):.2f} from the rank groups)" if elapsed is not None
              else f"Sum of case wall times {total:.0f} s (the sweep's own not recorded)")
    return (markdown_table(columns, cases) + "\n"
            f"{len(cases)} cases ({sweep['computed']} computed in this run), "
            f"{sum(bool(r['converged']) for r in cases)} converged, "
            f"{sum(bool(r['competent']) for r in cases)} competent; mesh {mesh} mm; "
            f"{sweep['ranks']} MPI ranks, {sweep['ranks_per_case']} per case.  {timing}.  "
            f"Newton: iterations in accepted steps + in failed solves, {accepted} + {failed} "
            "in all.\n")


TABLE = Table("sweep", ".venv/bin/mpirun -n 2 .venv/bin/python benchmarks/sweep.py", FIELDS,
              draw)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh-size", type=float, default=None)
    parser.add_argument("--widths", type=float, nargs="+", default=list(STUDY_WIDTHS_PCT))
    parser.add_argument("--heights", type=float, nargs="+", default=list(STUDY_HEIGHTS_PCT))
    parser.add_argument("--wall-time-limit", type=float, default=None, metavar="SECONDS")
    parser.add_argument("--out", type=Path, default=None)
    args = TABLE.arguments(parser, argv)
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    comm = MPI.COMM_WORLD
    if comm.rank == 0:  # one line per finished case
        logging.getLogger("valve_dolfinx.study").setLevel(logging.INFO)
    out = args.out
    if out is None:
        stamp = comm.bcast(time.strftime("%Y%m%d-%H%M%S"), root=0)
        out = Path("results/benchmark_sweep") / stamp
    settings = StudySettings(widths_pct=tuple(args.widths), heights_pct=tuple(args.heights),
                             mesh_size_mm=args.mesh_size, wall_time_limit_s=args.wall_time_limit)
    with interrupt_on_signals():  # an interrupted benchmark resumes with the same --out
        outcome = run_study(settings, out, comm)
    if comm.rank != 0:
        return 0
    rows = [{"kind": "case", **{key: row.get(key) for key in CASE_FIELDS}}
            for row in outcome.report.rows]
    rows.append({"kind": "sweep", "computed": len(outcome.computed), "ranks": comm.size,
                 "ranks_per_case": settings.ranks_per_case, "elapsed_s": outcome.elapsed_s})
    print(args.table.write(rows).read_text())
    print(f"-> {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
