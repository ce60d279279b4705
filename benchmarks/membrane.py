"""Benchmark: closed sphere inflated to 80 mmHg (10.666 kPa) at three mesh sizes.

The sphere is solved by the closure's path, pseudo-transient continuation at the
full pressure (``PseudoTransientSolver``), to a static residual ‖R‖∞ < 1e-8 mN.
Prints, per mesh size: cells, dofs, pseudo-time steps, Newton iterations, wall
time of the solve (forms are compiled beforehand) and the peak resident memory
of the process.  Each size runs in a fresh process so the memory figures are its own.
The last columns are the relative error of the mean radius against the exact
membrane solution (T = pR/2, one scalar equation) and the observed convergence
rate between successive sizes (docs/verification.md, "Sphere convergence").

    python benchmarks/membrane.py [--sizes 2.0 1.0 0.5] [--np 1]
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys

R = 10.0  # sphere radius (mm)
P = 10.666  # 80 mmHg in kPa
MATERIAL = {"c": 9.7, "a": 20.0}  # isotropic Fung: Q = a·tr(E²)
RESIDUAL_TOLERANCE = 1e-8  # mN, ‖R‖∞ (nodal pressure forces are ~1-10 mN)


def exact_radius() -> float:
    """r = λR with t·S(E) = p·λR/2, E = (λ² − 1)/2 equibiaxial (isotropic Fung law)."""
    from scipy.optimize import brentq

    from valve_dolfinx.materials import FungMaterial, pk2_stress_closed_form

    m = FungMaterial.isotropic(MATERIAL["c"], MATERIAL["a"])

    def balance(lam: float) -> float:
        e = 0.5 * (lam**2 - 1.0)
        return m.thickness * float(pk2_stress_closed_form(m, e, e)[0]) - P * lam * R / 2

    return R * brentq(balance, 1.0, 3.0, xtol=1e-15)


def run_one(h: float) -> dict:
    import resource
    import time

    import numpy as np

    from valve_dolfinx._compat import MPI
    from valve_dolfinx.geometry.verification import sphere_domain
    from valve_dolfinx.materials import FungMaterial
    from valve_dolfinx.mechanics.boundary_conditions import point_supports
    from valve_dolfinx.mechanics.membrane import MembraneModel
    from valve_dolfinx.solvers.parameters import PseudoTransientParameters
    from valve_dolfinx.solvers.pseudo_transient import PseudoTransientSolver

    comm = MPI.COMM_WORLD
    domain = sphere_domain(R, h, comm=comm)
    model = MembraneModel(domain, {1: FungMaterial.isotropic(MATERIAL["c"], MATERIAL["a"])})
    bcs = point_supports(model.V, [((0, 0, -R), (0, 1, 2)), ((0, 0, R), (0, 1)),
                                   ((R, 0, 0), (1,))])
    solver = PseudoTransientSolver(model, bcs, P, PseudoTransientParameters(
        residual_tolerance=RESIDUAL_TOLERANCE))
    t0 = time.perf_counter()
    report = solver.solve()
    wall = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    if not report.converged:
        raise RuntimeError(f"h = {h} mm: {report.reason}")
    n = domain.mesh.geometry.index_map().size_local
    x = domain.mesh.geometry.x[:n] + model.u.x.array.reshape(-1, 3)[:n]
    X = np.concatenate(comm.allgather(x))
    radius = float(np.linalg.norm(X - X.mean(axis=0), axis=1).mean())
    peak = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, op=MPI.SUM)
    return {"mesh_size": h, "cells": domain.num_cells_global(),
            "dofs": model.V.dofmap.index_map.size_global * 3, "steps": report.steps,
            "newton": report.newton_iterations, "wall_s": wall, "peak_mb": peak,
            "radius": radius, "ranks": comm.size}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=float, nargs="+", default=[2.0, 1.0, 0.5])
    parser.add_argument("--np", type=int, default=1, help="MPI ranks per run")
    parser.add_argument("--one", type=float, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one is not None:
        result = run_one(args.one)
        from valve_dolfinx._compat import MPI

        if MPI.COMM_WORLD.rank == 0:
            print("RESULT " + json.dumps(result))
        return
    exact = exact_radius()
    print(f"sphere R = {R:g} mm, p = {P:g} kPa, exact loaded radius {exact:.6f} mm")
    print(f"{'h (mm)':>7} {'cells':>7} {'dofs':>7} {'steps':>6} {'Newton':>7} {'wall (s)':>9} "
          f"{'peak (MB)':>10} {'radius (mm)':>12} {'rel. error':>11} {'rate':>5}")
    launcher = [] if args.np == 1 else ["mpirun", "-n", str(args.np)]
    previous = None
    for h in args.sizes:
        # warm the JIT cache first so the timing is the solve, not the compiler
        for _ in range(2):
            out = subprocess.run(launcher + [sys.executable, __file__, "--one", str(h)],
                                 capture_output=True, text=True, check=True).stdout
        r = json.loads(next(line for line in out.splitlines() if line.startswith("RESULT"))[7:])
        error = abs(r["radius"] / exact - 1.0)
        rate = ("" if previous is None
                else f"{math.log(previous[1] / error) / math.log(previous[0] / h):5.2f}")
        previous = (h, error)
        print(f"{r['mesh_size']:7.2f} {r['cells']:7d} {r['dofs']:7d} {r['steps']:6d} "
              f"{r['newton']:7d} {r['wall_s']:9.2f} {r['peak_mb']:10.0f} {r['radius']:12.6f} "
              f"{error:11.3e} {rate:>5}", flush=True)


if __name__ == "__main__":
    main()
