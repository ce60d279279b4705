"""Wall time of the graft sizing study: per case, in total, and how many cases converged.

Runs the study of SPEC §7 (normal valve + 5 × 4 grafts, default mesh unless
``--mesh-size``) into a fresh folder through :func:`valve_dolfinx.study.runner.run_study`,
as ``valve-dolfinx sweep`` does, and prints one line per case (rank group that
ran it is not tracked; the wall time is the case's own) and the totals: the
sweep's elapsed wall time, the sum of the case times and the speed-up the MPI
rank groups gave over running the cases one after the other.

Run on the 2-core machine: ``.venv/bin/mpirun -n 2 .venv/bin/python benchmarks/sweep.py``
(``--mesh-size 1.6`` for a quick coarse figure; ``--widths``/``--heights`` for a
smaller grid; ``--out DIR`` to keep the cases, default ``results/benchmark_sweep/<time>``).
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from valve_dolfinx._compat import MPI
from valve_dolfinx.interrupts import interrupt_on_signals
from valve_dolfinx.study import STUDY_HEIGHTS_PCT, STUDY_WIDTHS_PCT, StudySettings
from valve_dolfinx.study.runner import run_study


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh-size", type=float, default=None)
    parser.add_argument("--widths", type=float, nargs="+", default=list(STUDY_WIDTHS_PCT))
    parser.add_argument("--heights", type=float, nargs="+", default=list(STUDY_HEIGHTS_PCT))
    parser.add_argument("--wall-time-limit", type=float, default=None, metavar="SECONDS")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
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
    rows = outcome.report.rows
    print(f"{'case':<8} {'conv':>5} {'sealed':>6} {'min h':>6} {'centr':>6} {'cells':>6} "
          f"{'wall s':>7}  reason")
    for r in rows:
        def f(key, fmt=".2f", row=r):
            v = row.get(key)
            return format(v, fmt) if isinstance(v, int | float) else "-"
        print(f"{r['case']:<8} {str(r['converged']):>5} {str(r['competent']):>6} "
              f"{f('min_coaptation_height_mm'):>6} {f('central_coaptation_height_mm'):>6} "
              f"{f('n_cells', 'd'):>6} {f('wall_time_s', '.0f'):>7}  {(r['reason'] or '')[:60]}")
    total = sum(float(r.get("wall_time_s") or 0.0) for r in rows)
    converged = sum(bool(r["converged"]) for r in rows)
    print(f"\n{len(rows)} cases ({len(outcome.computed)} computed now), {converged} converged; "
          f"mesh {rows[0].get('mesh_size_mm') if rows else '-'} mm; {comm.size} MPI ranks, "
          f"{settings.ranks_per_case} per case")
    print(f"sweep wall time {outcome.elapsed_s:.0f} s; sum of case wall times {total:.0f} s "
          f"(x{total / max(outcome.elapsed_s, 1e-9):.2f} from the rank groups) -> {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
