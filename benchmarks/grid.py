"""Every case of the study grid, one process each: the results and wall time of each case.

Runs the normal valve and every graft of the study grid (widths 0, 7, 14, 21, 27 % x
heights 0, 13, 27, 40 %; ``--cases`` for a subset) at the default mesh (``--mesh-size``),
each case in its own single-process subprocess (``--jobs N`` at a time, default 1)
through :func:`valve_dolfinx.case.run_case` with an output folder (a temporary one,
or ``--keep DIR``), as ``valve-dolfinx run`` does.  Prints a line per case as it ends,
then a Markdown table in grid order: converged, static residual (mN), penetration (mm),
the intersecting edge–triangle pairs of the loaded surface (``intersecting_pairs``), figure
of merit (``min_coaptation_height_mm``), raw minimum, central height, coaptation area,
regurgitant orifice area, root diameter, Newton iterations, wall time (s, the case's own, output
included).  The figures go to ``benchmarks/results/grid.csv`` and the table drawn from them to
``grid.md`` (``--tables-only`` redraws it from the CSV); ``--json FILE`` keeps them as JSON.

Run: ``.venv/bin/python benchmarks/grid.py --jobs 2`` (the whole grid on 2 cores;
``--mesh-size 1.6 --cases normal,W21/H27`` for a quick look; ``--wall-time-limit S`` is
the solver's limit per case).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor, as_completed

# benchmarks/cases.py, beside this script
from cases import (
    WorkerFailed,
    add_common_arguments,
    case_config,
    cell,
    parse_arguments,
    report,
    run_worker,
)
from result_tables import Column, Table, markdown_table

from valve_dolfinx.study.grid import STUDY_HEIGHTS_PCT, STUDY_WIDTHS_PCT, case_name

#: columns of the table: (header, result key, format)
COLUMNS = [("converged", "converged", "s"), ("residual mN", "equilibrium_residual_mN", ".3g"),
           ("penetration mm", "max_penetration_mm", ".3f"),
           ("intersecting pairs", "intersecting_pairs", "d"),
           ("min h mm", "min_coaptation_height_mm", ".2f"),
           ("raw min mm", "min_coaptation_height_raw_mm", ".2f"),
           ("central mm", "central_coaptation_height_mm", ".2f"),
           ("area mm²", "coaptation_area_mm2", ".0f"),
           ("orifice mm²", "regurgitant_orifice_area_mm2", ".2f"),
           ("root mm", "root_diameter_mm", ".2f"), ("Newton", "newton_iterations", "d"),
           ("wall s", "wall_time_s", ".0f")]
FIELDS = [key for _, key, _ in COLUMNS] + ["time_steps", "solver_message", "n_cells"]


def study_grid() -> list[tuple[float, float] | None]:
    return [None] + [(w, h) for w in STUDY_WIDTHS_PCT for h in STUDY_HEIGHTS_PCT]


def worker(case, mesh_size: float, limit: float | None, out: str) -> dict:
    """Run one case in this process; its result's fields."""
    import logging
    from dataclasses import replace

    logging.basicConfig(level=logging.WARNING)
    from valve_dolfinx.case import run_case

    config = case_config(case, mesh_size)
    if limit is not None:
        config = replace(config, wall_time_limit_s=limit)
    result = run_case(config, out).to_dict()
    return {key: result[key] for key in FIELDS}


def run_in_subprocess(case, args, root: str) -> dict:
    name = case_name(*(case or (None, None)))
    options = ["--keep", os.path.join(root, name)]
    options += [] if args.wall_time_limit is None else ["--wall-time-limit",
                                                        str(args.wall_time_limit)]
    # a hard stop beyond the solver's own limit (mesh, analysis, output)
    timeout = None if args.wall_time_limit is None else args.wall_time_limit + 600.0
    t0 = time.perf_counter()
    try:
        return {"case": name, **run_worker(__file__, name, args.mesh_size, options, timeout)}
    except WorkerFailed as error:
        return {"case": name, "converged": False, "wall_time_s": time.perf_counter() - t0,
                "solver_message": str(error)}


def draw(rows: list[dict]) -> str:
    """A line per case in grid order, the failures' messages, and the run: how many
    converged, the elapsed time against the sum of the cases' wall times."""
    cases = [r for r in rows if r["kind"] == "case"]
    run = next(r for r in rows if r["kind"] == "run")
    columns = [Column("case", "case", text=True)] + [
        Column(h, k, "" if f in ("s", "d") else f) for h, k, f in COLUMNS]
    failed = [f"- {r['case']}: {r['solver_message'] or ''}" for r in cases if not r["converged"]]
    total = sum(float(r["wall_time_s"] or 0.0) for r in cases)
    summary = (f"{sum(bool(r['converged']) for r in cases)} of {len(cases)} cases converged; "
               f"mesh {run['mesh_size_mm']:g} mm, {run['jobs']} at a time; elapsed "
               f"{run['elapsed_s']:.0f} s, sum of case wall times {total:.0f} s.\n")
    return "\n".join([markdown_table(columns, cases), *(["\n".join(failed) + "\n"] if failed
                                                         else []), summary])


TABLE = Table("grid", ".venv/bin/python benchmarks/grid.py --jobs 2",
              ("kind", "case", *FIELDS, "mesh_size_mm", "jobs", "elapsed_s"), draw)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_common_arguments(parser, study_grid())
    parser.add_argument("--jobs", type=int, default=1, help="cases run at a time")
    parser.add_argument("--wall-time-limit", type=float, default=None, metavar="SECONDS")
    parser.add_argument("--keep", type=str, default=None, help="keep the case folders in DIR")
    args = TABLE.arguments(parser, argv, parse_arguments)
    if args.worker:
        report(worker(args.cases[0], args.mesh_size, args.wall_time_limit, args.keep))
        return 0
    scratch = tempfile.TemporaryDirectory(prefix="grid-benchmark-")
    root = args.keep or scratch.name
    t0 = time.perf_counter()
    rows = {}
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = {pool.submit(run_in_subprocess, case, args, root): case for case in args.cases}
        for future in as_completed(futures):
            row = future.result()
            rows[futures[future]] = row
            figures = " ".join(f"{h} {cell(row.get(k), f)}" for h, k, f in COLUMNS)
            failure = "" if row.get("converged") else f"  ({row.get('solver_message', '')})"
            print(f"{row['case']:<8} {figures}{failure}", flush=True)
    elapsed = time.perf_counter() - t0
    scratch.cleanup()
    ordered = [{"kind": "case", **rows[case]} for case in args.cases]
    run = {"kind": "run", "mesh_size_mm": args.mesh_size, "jobs": args.jobs,
           "elapsed_s": elapsed}
    print("\n" + args.table.write([*ordered, run]).read_text(), end="")
    if args.json:
        args.json.write_text(json.dumps({"mesh_size_mm": args.mesh_size, "jobs": args.jobs,
                                         "elapsed_s": elapsed, "cases": ordered}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
