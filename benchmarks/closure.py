"""Speed of one closure: where the wall time of a case goes.

Runs the normal valve, W0/H0, W27/H0 and W21/H27 (``--cases``; default 0.8 mm mesh,
``--mesh-size``) one after the other, each in a fresh single-process subprocess, through
:func:`valve_dolfinx.case.run_case` with an output folder in a temporary directory, as
``valve-dolfinx run`` does (result, fields and figures written).  Each subprocess runs its
case ``--repeat`` times (default 2): the first run compiles the forms into an empty FFCx
cache (``--user-cache``: into the user's cache, which may already hold them), the later
runs find it warm; the table shows the first ("cold") and the median warm run.

The time of a run is split exclusively (nested calls are charged to the innermost) by
wrapping, inside the subprocess only: ``dolfinx.jit.ffcx_jit`` (form compilation),
the solver's residual and Jacobian callbacks (assembly), the contact and bending hooks
(contact includes putting its pairs into the Jacobian's pattern), the solver's post-step
(step control, diagnostics), ``analyse_case`` (coaptation analysis),
``output.write_case``/``write_result`` (output); what is left of the solve is
"linear solve + PETSc" (LU factorisation and solves, TS/SNES), what is left of the run is
"mesh, root, setup" (Gmsh, distribution, root step, function spaces, sparsity).  Peak
memory is the subprocess's ``ru_maxrss`` after the run.  The speed targets checked below
(warm run, one core): normal valve <= 30 s, each graft case <= 60 s, contact <= 25 % of the
solve.

The figures of every run go to ``benchmarks/results/closure.csv`` and the tables drawn from
them to ``closure.md`` (``--tables-only`` redraws them from the CSV).

Run: ``.venv/bin/python benchmarks/closure.py`` (``--mesh-size 1.6 --cases normal`` for a
quick look; ``--json FILE`` keeps the measured figures with each run's solver timings).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time

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

# benchmarks/result_tables.py, beside this script
from result_tables import Column, Table, cell, markdown_table

CASES = ("normal", "W0/H0", "W27/H0", "W21/H27")
#: rows of the table: (label, key of a run's figures, format)
ROWS = [("converged", "converged", "s"), ("TS steps", "time_steps", "d"),
        ("rejected steps", "rejected_steps", "d"), ("Newton iterations", "newton_iterations", "d"),
        ("Newton in rejected steps", "rejected_newton_iterations", "d"),
        ("form compilation s", "form compilation", ".2f"), ("assembly s", "assembly", ".2f"),
        ("linear solve + PETSc s", "linear solve + PETSc", ".2f"),
        ("contact hook s", "contact", ".2f"), ("bending hook s", "bending", ".2f"),
        ("post-step s", "post-step", ".2f"), ("analysis s", "analysis", ".2f"),
        ("output s", "output", ".2f"), ("mesh, root, setup s", "mesh, root, setup", ".2f"),
        ("solve s", "solve_s", ".2f"), ("whole run s", "total_s", ".2f"),
        ("contact % of solve", "contact_pct", ".1f"), ("peak memory MB", "peak_mb", ".0f"),
        ("residual mN", "equilibrium_residual_mN", ".3g")]


class ExclusiveClock:
    """Seconds per label of wrapped functions, each call charged net of wrapped callees."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self._children: list[float] = []

    def wrap(self, owner, name: str, label: str) -> None:
        original = getattr(owner, name, None)
        if original is None:
            return

        def timed(*args, **kwargs):
            self._children.append(0.0)
            t0 = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - t0
                net = elapsed - self._children.pop()
                self.seconds[label] = self.seconds.get(label, 0.0) + net
                if self._children:
                    self._children[-1] += elapsed

        setattr(owner, name, timed)


def worker(case: tuple[float, float] | None, mesh_size: float, repeat: int,
           user_cache: bool) -> list[dict]:
    """Run one case ``repeat`` times in this process; the figures of every run."""
    import logging
    import resource

    logging.basicConfig(level=logging.WARNING)
    from valve_dolfinx import case as closure
    from valve_dolfinx import output
    from valve_dolfinx._compat import MPI, dolfinx
    from valve_dolfinx.solvers.bending_hook import BendingHook
    from valve_dolfinx.solvers.contact_hook import ContactHook
    from valve_dolfinx.solvers.nodal import BlockPattern
    from valve_dolfinx.solvers.pseudo_transient import PseudoTransientSolver

    cache = tempfile.TemporaryDirectory(prefix="ffcx-cache-")
    if not user_cache:
        options = dolfinx.jit.DOLFINX_DEFAULT_JIT_OPTIONS
        options["cache_dir"] = (cache.name, options["cache_dir"][1])
    clock = ExclusiveClock()
    clock.wrap(dolfinx.jit, "ffcx_jit", "form compilation")
    for name in ("ifunction", "ijacobian"):
        clock.wrap(PseudoTransientSolver, name, "assembly")
    clock.wrap(PseudoTransientSolver, "_post_step", "post-step")
    clock.wrap(PseudoTransientSolver, "solve", "linear solve + PETSc")
    for hook, label in ((ContactHook, "contact"), (BendingHook, "bending")):
        for name in ("add_residual", "jacobian_couplings", "add_jacobian", "accept_state",
                     "diagnostics"):
            clock.wrap(hook, name, label)
    clock.wrap(BlockPattern, "include", "contact")  # the contact pairs' matrix entries
    clock.wrap(closure, "analyse_case", "analysis")
    for name in ("write_case", "write_result"):
        clock.wrap(output, name, "output")
    clock.wrap(closure, "run_case", "mesh, root, setup")
    reports = []  # the SolveReport of every run (run_case keeps only its scalars)
    solve_case = closure.solve_case

    def keep_report(*args, **kwargs):
        state = solve_case(*args, **kwargs)
        reports.append(state.report)
        return state

    closure.solve_case = keep_report
    config = case_config(case, mesh_size)
    runs = []
    for _ in range(repeat):
        clock.seconds.clear()
        with tempfile.TemporaryDirectory(prefix="closure-benchmark-") as out:
            t0 = time.perf_counter()
            result = closure.run_case(config, out, comm=MPI.COMM_WORLD)
            total = time.perf_counter() - t0
        report = reports[-1]
        contact_s = clock.seconds.get("contact", 0.0)
        runs.append({**clock.seconds, "total_s": total, "solve_s": report.wall_time_s,
                     "converged": result.converged, "time_steps": result.time_steps,
                     "rejected_steps": report.rejected_steps,
                     "newton_iterations": result.newton_iterations,
                     "rejected_newton_iterations": result.rejected_newton_iterations,
                     "equilibrium_residual_mN": result.equilibrium_residual_mN,
                     "contact_pct": 100.0 * contact_s / max(report.wall_time_s, 1e-12),
                     "report_timings": report.timings, "reason": result.solver_message,
                     "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024})
    cache.cleanup()
    return runs


def run_in_subprocess(case, args) -> list[dict]:
    options = ["--repeat", str(args.repeat)] + (["--user-cache"] if args.user_cache else [])
    try:
        return run_worker(__file__, case_label(case), args.mesh_size, options)
    except WorkerFailed as error:
        raise RuntimeError(f"{case_label(case)}: {error}") from error


FIELDS = ("case", "run", "mesh_size_mm", *(key for _, key, _ in ROWS), "reason")


def draw(rows: list[dict]) -> str:
    """A column per case's first ("cold") run and median warm run, a row per figure; below,
    the speed targets."""
    runs: dict[str, list[dict]] = {}
    for row in rows:
        runs.setdefault(row["case"], []).append(row)
    columns = {}
    for label, mine in runs.items():
        mine = sorted(mine, key=lambda r: r["run"])
        warm = sorted(mine[1:], key=lambda r: r["total_s"])
        columns[f"{label} cold"] = mine[0]
        if warm:
            columns[f"{label} warm"] = warm[(len(warm) - 1) // 2]
    figures = [{"figure": label, **{name: run.get(key) for name, run in columns.items()}}
               for label, key, _ in ROWS]
    formats = {label: fmt for label, _, fmt in ROWS}
    table = [Column("", "figure", text=True)] + [
        Column(name, lambda r, name=name: _shown(r[name], formats[r["figure"]]))
        for name in columns]
    checks = []
    for label in runs:
        run = columns.get(f"{label} warm", columns[f"{label} cold"])
        limit = 30.0 if label == "normal" else 60.0
        for text, value, bound, unit in (
                (f"{label}: whole run <= {limit:g} s", run["total_s"], limit, "s"),
                (f"{label}: contact <= 25 % of the solve", run["contact_pct"], 25.0, "%")):
            verdict = "PASS" if value <= bound and run["converged"] else "MISS"
            note = "" if run["converged"] else f" (not converged: {run['reason'] or ''})"
            checks.append({"target": text, "measured": f"{value:.1f} {unit}",
                           "result": verdict + note})
    mesh = rows[0]["mesh_size_mm"] if rows else None
    return "\n".join([
        f"Mesh {mesh:g} mm, one process per case, {max(r['run'] for r in rows)} runs each.\n",
        markdown_table(table, figures),
        "Targets (warm run, one core):\n",
        markdown_table([Column("target", "target", text=True), Column("measured", "measured"),
                        Column("result", "result", text=True)], checks)])


def _shown(value, fmt: str) -> str:
    """A figure as the table shows it (text, counts and booleans as they are)."""
    return cell(value, "" if fmt in ("s", "d") else fmt)


TABLE = Table("closure", ".venv/bin/python benchmarks/closure.py", FIELDS, draw)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_common_arguments(parser, [parse_case(c) for c in CASES])
    parser.add_argument("--repeat", type=int, default=2, help="runs per case and process")
    parser.add_argument("--user-cache", action="store_true",
                        help="compile into the user's FFCx cache instead of an empty one")
    args = TABLE.arguments(parser, argv, parse_arguments)
    if args.worker:
        report(worker(args.cases[0], args.mesh_size, args.repeat, args.user_cache))
        return 0
    measured = {}
    for case in args.cases:
        measured[case_label(case)] = run_in_subprocess(case, args)
        print(f"{case_label(case)}: " + ", ".join(f"{r['total_s']:.1f} s"
                                                 for r in measured[case_label(case)]),
              file=sys.stderr, flush=True)
    rows = [{**run, "case": label, "run": k, "mesh_size_mm": args.mesh_size}
            for label, runs in measured.items() for k, run in enumerate(runs, start=1)]
    print(args.table.write(rows).read_text())
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"mesh_size_mm": args.mesh_size, "cases": measured}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
