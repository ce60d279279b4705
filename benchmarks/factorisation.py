"""Speed of the closure's linear solves: one LU factorisation of a loaded valve's Jacobian.

Runs one case (default: the normal valve at the default mesh) through
:func:`valve_dolfinx.case.run_case`, keeps the last Jacobian the pseudo-transient solver
assembled (the closed valve, contact included), and factorises it with MUMPS under each of
its fill-reducing orderings and with PETSc's own LU: the first factorisation (analysis and
numeric factorisation, what a Newton iteration pays after contact has grown the matrix's
pattern) and the median of ``--repeat`` refactorisations with a solve (what it pays
otherwise), with MUMPS's operation count and largest front.  One BLAS thread, as the
closure benchmarks measure a case on one core.

Run: ``.venv/bin/python benchmarks/factorisation.py`` (``--case W21/H27``, ``--mesh-size``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

# benchmarks/cases.py, beside this script
from cases import SINGLE_THREAD, case_config, parse_arguments, parse_case

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


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=parse_case, default=None,
                        help="'normal' (default) or W<w>/H<h>")
    parser.add_argument("--mesh-size", type=float, default=None, help="mesh size (mm)")
    parser.add_argument("--repeat", type=int, default=10, help="refactorisations timed")
    args = parse_arguments(parser, argv)
    A, result = last_jacobian(args.case, args.mesh_size)
    info = A.getInfo()
    print(f"Jacobian of the loaded valve (converged: {result.converged}): "
          f"{A.getSize()[0]} unknowns, {info['nz_used']:.0f} stored entries, "
          f"type {A.getType()}\n")
    print(f"{'factorisation':42s} {'first (ms)':>11s} {'again + solve (ms)':>19s} "
          f"{'Mflop':>7s} {'largest front':>14s}")
    for label, options in CHOICES:
        first, again, flops, front = factorise(A, options, args.repeat)
        print(f"{label:42s} {first * 1e3:11.1f} {again * 1e3:19.1f} "
              f"{'' if flops is None else f'{flops / 1e6:.0f}':>7s} "
              f"{'' if front is None else front:>14}")


if __name__ == "__main__":
    main()
