"""Benchmark: closed sphere inflated to 80 mmHg (10.666 kPa) at three mesh sizes.

The sphere is solved by the closure's path, pseudo-transient continuation at the
full pressure (``PseudoTransientSolver``), to a static residual ‖R‖∞ < 1e-8 mN.
Prints, per mesh size: cells, dofs, pseudo-time steps, Newton iterations, wall
time of the solve (forms are compiled beforehand) and the peak resident memory
of the process.  Each size runs in a fresh process so the memory figures are its own.
The last columns are the relative error of the mean radius against the exact
membrane solution (T = pR/2, one scalar equation) and the observed convergence
rate between successive sizes (docs/verification.md, "Sphere convergence").  The figures go
to ``benchmarks/results/membrane.csv`` and the table drawn from them to ``membrane.md``
(``--tables-only`` redraws it from the CSV).

    python benchmarks/membrane.py [--sizes 2.0 1.4 1.0 0.7 0.5] [--np 1]
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys

import numpy as np

# benchmarks/result_tables.py, beside this script
from result_tables import Column, Table, markdown_table

R = 10.0  # sphere radius (mm)
P = 10.666  # 80 mmHg in kPa
MATERIAL = {"c": 9.7, "a": 20.0}  # isotropic Fung: Q = a·tr(E²)
RESIDUAL_TOLERANCE = 1e-8  # mN, ‖R‖∞ (nodal pressure forces are ~1-10 mN)
#: the sizes of the table in docs/verification.md (mm)
SIZES = (2.0, 1.4, 1.0, 0.7, 0.5)


def exact_radius() -> float:
    """r = λR with t·S(E) = p·λR/2, E = (λ² − 1)/2 equibiaxial (isotropic Fung law)."""
    from scipy.optimize import brentq

    from valve_dolfinx.materials import FungMaterial, pk2_stress_closed_form

    m = FungMaterial.isotropic(MATERIAL["c"], MATERIAL["a"])

    def balance(lam: float) -> float:
        e = 0.5 * (lam**2 - 1.0)
        return m.thickness * float(pk2_stress_closed_form(m, e, e)[0]) - P * lam * R / 2

    return R * brentq(balance, 1.0, 3.0, xtol=1e-15)


def mean_edge_length(mesh, comm) -> float:
    """The mean length of the mesh's edges (mm), each counted once over the ranks."""
    import dolfinx

    mesh.topology.create_entities(1)
    mesh.topology.create_connectivity(1, 2)
    imap = mesh.topology.index_map(1)
    nodes = dolfinx.mesh.entities_to_geometry(mesh, 1, np.arange(imap.size_local,
                                                                  dtype=np.int32))
    x = mesh.geometry.x
    total = float(np.linalg.norm(x[nodes[:, 0]] - x[nodes[:, 1]], axis=1).sum())
    return comm.allreduce(total) / imap.size_global


def run_one(h: float) -> dict:
    import resource
    import time

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
    return {"mesh_size_mm": h, "mean_edge_mm": mean_edge_length(domain.mesh, comm),
            "cells": domain.num_cells_global(),
            "dofs": model.V.dofmap.index_map.size_global * 3, "steps": report.steps,
            "newton_iterations": report.newton_iterations, "radius_mm": radius,
            "wall_s": wall, "peak_mb": peak, "ranks": comm.size}


def _error(row: dict) -> float:
    return abs(row["radius_mm"] / row["exact_radius_mm"] - 1.0)


def draw(rows: list[dict]) -> str:
    """The convergence table: per mesh size its figures, the relative error of the mean
    radius and the observed rate from the previous size; below, the least-squares rate
    over all sizes and the range of error/h²."""
    for previous, row in zip([None, *rows[:-1]], rows, strict=True):
        row["error"] = _error(row)
        row["rate"] = None if previous is None else (
            math.log(_error(previous) / row["error"])
            / math.log(previous["mesh_size_mm"] / row["mesh_size_mm"]))
    columns = [Column("h (mm)", "mesh_size_mm", ".1f"), Column("h̄ (mm)", "mean_edge_mm", ".3f"),
               Column("cells", "cells", ","), Column("dofs", "dofs", ","),
               Column("PTC steps", "steps"), Column("Newton", "newton_iterations"),
               Column("r_h (mm)", "radius_mm", ".6f"), Column("relative error", "error", ".3e"),
               Column("rate", "rate", ".2f"), Column("wall (s)", "wall_s", ".2f"),
               Column("peak memory (MB)", "peak_mb", ".0f")]
    h = np.log([row["mesh_size_mm"] for row in rows])
    e = np.log([row["error"] for row in rows])
    per_h2 = [row["error"] / row["mesh_size_mm"] ** 2 for row in rows]
    first = rows[0]
    lines = [f"Sphere R = {R:g} mm at p = {P:g} kPa, exact loaded radius "
             f"{first['exact_radius_mm']:.6f} mm; {first['ranks']} MPI rank(s).\n",
             markdown_table(columns, rows)]
    if len(rows) > 1:
        lines.append(f"Least-squares rate over the {len(rows)} sizes "
                     f"{float(np.polyfit(h, e, 1)[0]):.2f}; error/h² between "
                     f"{min(per_h2):.2e} and {max(per_h2):.2e} mm⁻².\n")
    return "\n".join(lines)


TABLE = Table("membrane", ".venv/bin/python benchmarks/membrane.py",
              ("mesh_size_mm", "mean_edge_mm", "cells", "dofs", "steps", "newton_iterations",
               "radius_mm", "exact_radius_mm", "wall_s", "peak_mb", "ranks"), draw)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=float, nargs="+", default=list(SIZES))
    parser.add_argument("--np", type=int, default=1, help="MPI ranks per run")
    parser.add_argument("--one", type=float, help=argparse.SUPPRESS)
    args = TABLE.arguments(parser)
    if args.one is not None:
        result = run_one(args.one)
        from valve_dolfinx._compat import MPI

        if MPI.COMM_WORLD.rank == 0:
            print("RESULT " + json.dumps(result))
        return
    exact = exact_radius()
    launcher = [] if args.np == 1 else ["mpirun", "-n", str(args.np)]
    rows = []
    for h in args.sizes:
        # warm the JIT cache first so the timing is the solve, not the compiler
        for _ in range(2):
            out = subprocess.run(launcher + [sys.executable, __file__, "--one", str(h)],
                                 capture_output=True, text=True, check=True).stdout
        line = next(line for line in out.splitlines() if line.startswith("RESULT"))
        rows.append({**json.loads(line[len("RESULT "):]), "exact_radius_mm": exact})
        print(f"h = {h:g} mm: {rows[-1]['wall_s']:.2f} s", flush=True)
    print(args.table.write(rows).read_text())


if __name__ == "__main__":
    main()
