"""Closure of the normal valve: full three-leaflet valve against the symmetric reference.

Runs, at each mesh size given,

* the symmetric reference of SPEC §4 (one leaflet against the ±60° planes),
* optionally (``--full``) the full three-leaflet valve with leaflet–leaflet
  contact,

and prints for each: converged, central (midline) and minimum coaptation
height of every leaflet, regurgitant orifice area, mid-surface penetration,
time steps and wall time; then the mesh-convergence steps of the reference
and the full-vs-reference differences.  These are the figures of the mesh
study and the full-valve comparison in docs/closure.md (the full valve takes
~10 min at 1.0 mm and ~25 min at 0.8 mm on one core, too long for the test
suite).

Run: ``.venv/bin/python benchmarks/closure.py --mesh-sizes 1.0 0.8 0.6 [--full]``
(add ``--out DIR`` to keep each case's outputs and figures; ``--solver relaxation``
for the explicit dynamic relaxation instead of the BDF2 dynamics, whose "steps"
are then iterations).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from valve_dolfinx._compat import MPI
from valve_dolfinx.closure import SOLVERS, CaseConfig, run_case
from valve_dolfinx.geometry.valve import ValveParameters


def _row(label: str, mesh: float, result) -> str:
    heights = " ".join(f"{name[:5]} {lc['midline_height_mm']:.3f}/{lc['min_height_mm']:.3f}"
                       for name, lc in result.leaflets.items()
                       if "mirror" not in name)
    return (f"{label:<10} {mesh:5.2f} {str(result.converged):>5} "
            f"{result.central_coaptation_height_mm:8.3f} {result.min_coaptation_height_mm:8.3f} "
            f"{result.regurgitant_orifice_area_mm2:7.3f} {result.max_penetration_mm:7.4f} "
            f"{result.time_steps:6d} {result.wall_time_s:8.1f}   {heights}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh-sizes", type=float, nargs="+", default=[1.0, 0.8, 0.6])
    parser.add_argument("--full", action="store_true", help="also run the three-leaflet valve")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--solver", choices=SOLVERS, default=CaseConfig.solver)
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    print(f"{'case':<10} {'mesh':>5} {'conv':>5} {'central':>8} {'min':>8} {'RO mm2':>7} "
          f"{'pen mm':>7} {'steps':>6} {'wall s':>8}   per leaflet: midline/min (mm)")
    reference, full = {}, {}
    for mesh in args.mesh_sizes:
        for label, symmetric in (("reference", True), ("full", False)):
            if not symmetric and not args.full:
                continue
            config = CaseConfig(geometry=ValveParameters(mesh_size=mesh),
                                symmetric_reference=symmetric, solver=args.solver)
            out = None if args.out is None else args.out / f"{label}_{mesh:g}"
            t0 = time.perf_counter()
            result = run_case(config, out, comm=comm, figures=out is not None,
                              fields_output=out is not None)
            result.wall_time_s = time.perf_counter() - t0
            (reference if symmetric else full)[mesh] = result
            if comm.rank == 0:
                print(_row(label, mesh, result), flush=True)
    if comm.rank == 0:
        meshes = sorted(reference, reverse=True)
        for coarse, fine in zip(meshes, meshes[1:], strict=False):
            a, b = reference[coarse], reference[fine]
            print(f"reference {coarse:g} -> {fine:g} mm: central height changes by "
                  f"{b.central_coaptation_height_mm - a.central_coaptation_height_mm:+.3f} mm")
        for mesh, result in sorted(full.items()):
            spread = [lc["central_height_mm"] for lc in result.leaflets.values()]
            difference = (result.central_coaptation_height_mm
                          - reference[mesh].central_coaptation_height_mm)
            print(f"full valve {mesh:g} mm: three leaflets within {max(spread) - min(spread):.3f}"
                  f" mm; full - reference = {difference:+.3f} mm")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
