"""Where a closure's Newton iterations go: accepted steps, failed solves, and whether a failed
solve could be ended sooner without changing the path.

Runs each case (``--cases``; default W21/H27 and W21/H40 at the default mesh) once, in a
single-process subprocess, through :func:`valve_dolfinx.case.run_case` (no figures or fields
written), with PETSc's event log on and an SNES monitor that records the residual norms of
every Newton solve.  A solve is *accepted* when the pseudo-time step it solved was accepted;
a *failed* one is retried from the start of its step with half the Δτ.  Printed per case:

* the solves and their Newton iterations, accepted and failed, and the cost of a factorised
  Jacobian with everything counted (PETSc's MUMPS numeric and symbolic factorisations,
  triangular solves, Jacobian and residual evaluations);
* the iteration at which the accepted solves converged, the largest relative residual
  r_k/r_0 of an accepted solve still running at iteration k, and the failed solves' median;
* the stall test: cutting a solve once its residual has reached no new minimum for ``m``
  iterations.  Since a failed solve's step is retried from its start, cutting only solves
  that would have failed leaves the path bit for bit as it is; the table gives, for each
  ``m``, the accepted solves such a cut would have ended (each one changes the path) and the
  failed-solve iterations it would have saved.

The figures go to ``benchmarks/results/newton_solves.csv`` (a row per case, per Newton solve
with its residual norms, and per PETSc event) and what is drawn from them to
``newton_solves.md`` (``--tables-only`` redraws it from the CSV).

Run: ``.venv/bin/python benchmarks/newton_solves.py [--cases normal,W21/H27]``.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
from collections import Counter

# benchmarks/cases.py, beside this script
from cases import (
    WorkerFailed,
    add_common_arguments,
    case_config,
    case_label,
    parse_arguments,
    parse_case,
    report,
    run_worker,
)
from result_tables import Column, Table, cell, markdown_table

CASES = ("W21/H27", "W21/H40")
#: PETSc events whose time is charged to a factorised Jacobian
EVENTS = ("MatLUFactorNum", "MatLUFactorSym", "MatSolve", "SNESJacobianEval",
          "SNESFunctionEval")
STALLS = range(1, 13)


def worker(case, mesh_size: float) -> dict:
    """Run one case; every Newton solve's residual norms and whether its step was accepted,
    and the PETSc events' counts and seconds."""
    import logging

    logging.basicConfig(level=logging.WARNING)
    from valve_dolfinx._compat import MPI, PETSc
    from valve_dolfinx.case import run_case
    from valve_dolfinx.solvers.pseudo_transient import PseudoTransientSolver

    solves: list[dict] = []

    def record(snes, its, fnorm):
        if its == 0:
            solves.append({"norms": [], "accepted": False})
        solves[-1]["norms"].append(float(fnorm))

    make_ts, post_step = PseudoTransientSolver._make_ts, PseudoTransientSolver._post_step

    def make_ts_recorded(self):
        ts = make_ts(self)
        ts.getSNES().setMonitor(record)
        return ts

    def post_step_recorded(self, ts):
        solves[-1]["accepted"] = True
        return post_step(self, ts)

    PseudoTransientSolver._make_ts = make_ts_recorded
    PseudoTransientSolver._post_step = post_step_recorded
    PETSc.Log.begin()
    config = case_config(case, mesh_size)
    with tempfile.TemporaryDirectory(prefix="newton-solves-") as out:
        result = run_case(config, out, comm=MPI.COMM_WORLD, figures=False,
                          fields_output=False)
    events = {}
    for name in EVENTS:
        info = PETSc.Log.Event(name).getPerfInfo()
        events[name] = {"count": int(info["count"]), "seconds": float(info["time"])}
    return {"solves": solves, "events": events, "converged": result.converged,
            "figure_of_merit_mm": result.min_coaptation_height_mm}


def stall_lengths(norms: list[float]) -> list[int]:
    """After each iteration k ≥ 1: for how many iterations the residual has reached no new
    minimum (0 when iterate k set one)."""
    out, run, lowest = [], 0, norms[0]
    for value in norms[1:]:
        run = 0 if value < lowest else run + 1
        lowest = min(lowest, value)
        out.append(run)
    return out


FIELDS = ("kind", "case", "converged", "figure_of_merit_mm", "accepted", "norms", "event",
          "count", "seconds")


def case_rows(label: str, figures: dict) -> list[dict]:
    """The CSV rows of one case: the case, each Newton solve (its residual norms separated
    by spaces), each PETSc event."""
    rows = [{"kind": "case", "case": label, "converged": figures["converged"],
             "figure_of_merit_mm": figures["figure_of_merit_mm"]}]
    rows += [{"kind": "solve", "case": label, "accepted": solve["accepted"],
              "norms": " ".join(repr(float(n)) for n in solve["norms"])}
             for solve in figures["solves"]]
    rows += [{"kind": "event", "case": label, "event": name, **event}
             for name, event in figures["events"].items()]
    return rows


def _norms(row: dict) -> list[float]:
    return [float(n) for n in str(row["norms"]).split()]


def draw_case(rows: list[dict]) -> str:
    """One case: its Newton solves and their cost, how the accepted solves converged, how
    the failed ones progressed, and the stall test."""
    head = next(r for r in rows if r["kind"] == "case")
    accepted = [_norms(r) for r in rows if r["kind"] == "solve" and r["accepted"]]
    failed = [_norms(r) for r in rows if r["kind"] == "solve" and not r["accepted"]]
    iterations = [sum(len(n) - 1 for n in group) for group in (accepted, failed)]
    events = [r for r in rows if r["kind"] == "event"]
    factorisations = next((e["count"] for e in events if e["event"] == "MatLUFactorNum"), 0)
    per = max(factorisations, 1)
    total = sum(e["seconds"] for e in events)
    events.append({"event": "all of these", "count": None, "seconds": total})
    converged_at = Counter(len(n) - 1 for n in accepted)
    worst = [max((n[k] / n[0] for n in accepted if len(n) > k + 1), default=float("nan"))
             for k in range(1, 10)]
    typical = [statistics.median([n[k] / n[0] for n in failed if len(n) > k] or [math.nan])
               for k in range(1, 10)]
    stalls = []
    for m in STALLS:
        cut = sum(any(s >= m for s in stall_lengths(n)[:-1]) for n in accepted)
        saved = 0
        for norms in failed:
            first = next((k for k, s in enumerate(stall_lengths(norms), start=1) if s >= m),
                         None)
            if first is not None:
                saved += len(norms) - 1 - first
        stalls.append({"m": m, "cut": cut, "saved": saved})
    return "\n".join([
        f"### {head['case']}: converged {cell(head['converged'])}, figure of merit "
        f"{head['figure_of_merit_mm']:.3f} mm\n",
        f"Newton solves: {len(accepted)} accepted ({iterations[0]} iterations), {len(failed)} "
        f"failed ({iterations[1]} iterations); {factorisations} factorisations.\n",
        markdown_table([Column("PETSc event", "event", text=True), Column("calls", "count"),
                        Column("s", "seconds", ".2f"),
                        Column("ms per factorisation", lambda e: 1e3 * e["seconds"] / per,
                               ".2f")], events),
        "- accepted solves by iterations: "
        + ", ".join(f"{k}: {converged_at[k]}" for k in sorted(converged_at)),
        "- largest r_k/r_0 of an accepted solve still running, k = 1..9: "
        + ", ".join(f"{w:.3g}" for w in worst),
        "- median r_k/r_0 of the failed solves, k = 1..9: "
        + ", ".join(f"{t:.3g}" for t in typical) + "\n",
        markdown_table([Column("stall m", "m"), Column("accepted solves cut", "cut"),
                        Column("failed-solve iterations saved", "saved")], stalls)])


def draw(rows: list[dict]) -> str:
    """Every case, in the CSV's order."""
    cases = dict.fromkeys(r["case"] for r in rows)
    return "\n".join(draw_case([r for r in rows if r["case"] == case]) for case in cases)


TABLE = Table("newton_solves", ".venv/bin/python benchmarks/newton_solves.py", FIELDS, draw)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_common_arguments(parser, [parse_case(c) for c in CASES])
    args = TABLE.arguments(parser, argv, parse_arguments)
    if args.worker:
        report(worker(args.cases[0], args.mesh_size))
        return 0
    measured = {}
    for case in args.cases:
        label = case_label(case)
        try:
            measured[label] = run_worker(__file__, label, args.mesh_size)
        except WorkerFailed as error:
            print(f"{label}: {error}", file=sys.stderr)
            return 1
    rows = [row for label, figures in measured.items() for row in case_rows(label, figures)]
    print(args.table.write(rows).read_text())
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"mesh_size_mm": args.mesh_size, "cases": measured}, f)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
