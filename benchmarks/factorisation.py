"""Speed of the closure's linear solves: one LU factorisation of a loaded valve's Jacobian.

Runs one case (default: the normal valve at the default mesh) through
:func:`valve_dolfinx.case.run_case`, keeps the last Jacobian the pseudo-transient solver
assembled (the closed valve, contact included), and factorises it with MUMPS under each of
its fill-reducing orderings and with PETSc's own LU: the first factorisation (analysis and
numeric factorisation, what a Newton iteration pays after contact has grown the matrix's
pattern) and the median of ``--repeat`` refactorisations with a solve (what it pays
otherwise), with MUMPS's operation count and largest front.  One BLAS thread, as the
closure benchmarks measure a case on one core.

The figures go to ``benchmarks/results/factorisation.csv`` and the table drawn from them to
``factorisation.md`` (``--tables-only`` redraws it from the CSV).

Run: ``.venv/bin/python benchmarks/factorisation.py`` (``--case W21/H27``, ``--mesh-size``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

# benchmarks/cases.py, beside this script
from cases import SINGLE_THREAD, case_config, case_label, parse_arguments, parse_case
from result_tables import Column, Table, markdown_table

# one BLAS thread, set before NumPy and PETSc load their libraries
for _name, _value in SINGLE_THREAD.items():
    os.environ.setdefault(_name, _value)

#: (label, PETSc options of the factorisation)
CHOICES = [
    ("MUMPS, automatic ordering (the solver's)", {"pc_factor_mat_solver_type": "mumps"}),
    ("MUMPS, METIS", {"pc_factor_mat_solver_type": "mumps", "mat_mumps_icntl_7": 5}),
    ("MUMPS, AMD", {"pc_factor_mat_solver_type": "mumps", "mat_mumps_icntl_7": 0}),
    ("MUMPS, AMF", {"pc_factor_mat_solver_type": "mumps", "mat_mumps_icntl_7": 2}),
    ("MUMPS, QAMD", {"pc_factor_mat_solver_type": "mumps", "mat_mumps_icntl_7": 6}),
    ("PETSc LU, nested dissection", {"pc_factor_mat_solver_type": "petsc",
                                     "pc_factor_mat_ordering_type": "nd"}),
]


def last_jacobian(case, mesh_size: float):
    """A copy of the last Jacobian the pseudo-transient solver assembled in ``case``."""
    from valve_dolfinx import case as closure
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.solvers.pseudo_transient import PseudoTransientSolver

    kept = {}
    assemble = PseudoTransientSolver.ijacobian

    def keeping(self, ts, t, X, Xdot, a, J, P):
        assemble(self, ts, t, X, Xdot, a, J, P)
        kept["J"] = J.copy()

    PseudoTransientSolver.ijacobian = keeping
    config = case_config(case, mesh_size)
    with tempfile.TemporaryDirectory() as out:
        result = closure.run_case(config, out, comm=MPI.COMM_WORLD)
    PseudoTransientSolver.ijacobian = assemble
    return kept["J"], result


def factorise(A, options: dict, repeat: int) -> tuple[float, float, float | None, int | None]:
    """(first factorisation s, median refactorisation + solve s, flops, largest front)."""
    from valve_dolfinx._compat import PETSc

    prefix = f"bench{id(options)}_"
    opts = PETSc.Options()
    for key, value in {"ksp_type": "preonly", "pc_type": "lu", **options}.items():
        opts[prefix + key] = value
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    b, x = A.createVecs()
    b.set(1.0)
    t0 = time.perf_counter()
    ksp.setUp()
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeat):
        A.assemble()  # a new state: the next set-up factorises again, on the same analysis
        t0 = time.perf_counter()
        ksp.setUp()
        ksp.solve(b, x)
        times.append(time.perf_counter() - t0)
    flops = front = None
    if options["pc_factor_mat_solver_type"] == "mumps":
        F = ksp.getPC().getFactorMatrix()
        flops, front = F.getMumpsRinfog(3), F.getMumpsInfog(11)
    ksp.destroy()
    for key in list(opts.getAll()):
        if key.startswith(prefix):
            opts.delValue(key)
    return first, statistics.median(times), flops, front


FIELDS = ("case", "mesh_size_mm", "converged", "unknowns", "stored_entries", "matrix_type",
          "factorisation", "first_s", "again_s", "flops", "largest_front")


def draw(rows: list[dict]) -> str:
    """The Jacobian, then a line per factorisation: first, again with a solve, MUMPS's
    operation count and largest front."""
    first = rows[0]
    columns = [Column("factorisation", "factorisation", text=True),
               Column("first (ms)", lambda r: 1e3 * r["first_s"], ".1f"),
               Column("again + solve (ms)", lambda r: 1e3 * r["again_s"], ".1f"),
               Column("Mflop", lambda r: None if r["flops"] is None else r["flops"] / 1e6, ".0f"),
               Column("largest front", "largest_front")]
    return (f"The last Jacobian of {first['case']} at {first['mesh_size_mm']:g} mm (converged: "
            f"{first['converged']}): {first['unknowns']} unknowns, {first['stored_entries']} "
            f"stored entries, type {first['matrix_type']}.\n\n" + markdown_table(columns, rows))


TABLE = Table("factorisation", ".venv/bin/python benchmarks/factorisation.py", FIELDS, draw)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=parse_case, default=None,
                        help="'normal' (default) or W<w>/H<h>")
    parser.add_argument("--mesh-size", type=float, default=None, help="mesh size (mm)")
    parser.add_argument("--repeat", type=int, default=10, help="refactorisations timed")
    args = TABLE.arguments(parser, argv, parse_arguments)
    A, result = last_jacobian(args.case, args.mesh_size)
    info = A.getInfo()
    jacobian = {"case": case_label(args.case), "mesh_size_mm": args.mesh_size,
                "converged": result.converged, "unknowns": A.getSize()[0],
                "stored_entries": int(info["nz_used"]), "matrix_type": A.getType()}
    rows = []
    for label, options in CHOICES:
        first, again, flops, front = factorise(A, options, args.repeat)
        rows.append({**jacobian, "factorisation": label, "first_s": first, "again_s": again,
                     "flops": flops, "largest_front": front})
        print(f"{label}: {first * 1e3:.1f} ms, again {again * 1e3:.1f} ms", flush=True)
    print(args.table.write(rows).read_text())


if __name__ == "__main__":
    main()
