"""The two paths to the loaded equilibrium: pseudo-transient continuation and BDF2 dynamics.

SPEC §4 asks that the quasi-static path reach the equilibrium of the damped BDF2 dynamics;
this prints, for the symmetric reference at the default mesh and the three-leaflet normal
valve at 1.0 mm, each path's figure of merit, central height, residual, steps and wall time,
and the difference of the figures of merit (target: within 0.05 mm)::

    .venv/bin/python benchmarks/bdf2.py [--cases reference,normal] [--wall-time-limit S]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from valve_dolfinx._compat import MPI
from valve_dolfinx.case import run_case
from valve_dolfinx.config import CaseConfig
from valve_dolfinx.geometry.valve import ValveParameters

CASES = {
    "reference": CaseConfig(symmetric_reference=True),
    "normal": CaseConfig(geometry=ValveParameters(mesh_size=1.0)),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="reference,normal")
    parser.add_argument("--wall-time-limit", type=float, default=3600.0)
    args = parser.parse_args()
    print(f"{'case':10s} {'solver':6s} {'conv':5s} {'min h':>7s} {'central':>8s} "
          f"{'residual':>9s} {'steps':>6s} {'wall s':>7s}")
    for name in args.cases.split(","):
        fom = {}
        for solver in ("ptc", "bdf2"):
            config = replace(CASES[name], solver=solver)
            config = replace(config,
                             dynamics=replace(config.dynamics,
                                              wall_time_limit_s=args.wall_time_limit),
                             pseudo_transient=replace(config.pseudo_transient,
                                                      wall_time_limit_s=args.wall_time_limit))
            r = run_case(config, comm=MPI.COMM_SELF, figures=False, fields_output=False)
            fom[solver] = r.min_coaptation_height_mm
            print(f"{name:10s} {solver:6s} {str(r.converged):5s} "
                  f"{r.min_coaptation_height_mm:7.3f} {r.central_coaptation_height_mm:8.3f} "
                  f"{r.equilibrium_residual_mN:9.2e} {r.time_steps:6d} {r.wall_time_s:7.1f}",
                  flush=True)
        print(f"{name:10s} |Δ figure of merit| = {abs(fom['ptc'] - fom['bdf2']):.3f} mm "
              "(target 0.05 mm)", flush=True)


if __name__ == "__main__":
    main()
