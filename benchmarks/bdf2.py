"""The two paths to the loaded equilibrium: pseudo-transient continuation and BDF2 dynamics.

SPEC §4 asks that the quasi-static path reach the equilibrium of the damped BDF2 dynamics;
this prints, for the symmetric reference at the default mesh and the three-leaflet normal
valve at 1.0 mm, each path's figure of merit, central height, residual, steps and wall time,
and the difference of the figures of merit (target: within 0.05 mm).  The figures go to
``benchmarks/results/bdf2.csv`` and the table drawn from them to ``bdf2.md``
(``--tables-only`` redraws it from the CSV)::

    .venv/bin/python benchmarks/bdf2.py [--cases reference,normal] [--wall-time-limit S]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

# benchmarks/result_tables.py, beside this script
from result_tables import Column, Table, markdown_table

from valve_dolfinx.config import CaseConfig
from valve_dolfinx.geometry.valve import ValveParameters

CASES = {
    "reference": CaseConfig(symmetric_reference=True),
    "normal": CaseConfig(geometry=ValveParameters(mesh_size=1.0)),
}


#: how the table names the cases
LABELS = {"reference": "symmetric reference", "normal": "normal valve"}
FIELDS = ("case", "solver", "mesh_size_mm", "converged", "min_coaptation_height_mm",
          "central_coaptation_height_mm", "equilibrium_residual_mN", "time_steps",
          "wall_time_s")


def draw(rows: list[dict]) -> str:
    """A line per case: each path's figure of merit, steps and wall time, and their
    difference."""
    cases: dict[str, dict] = {}
    for row in rows:
        entry = cases.setdefault(row["case"], {
            "case": f"{LABELS.get(row['case'], row['case'])}, {row['mesh_size_mm']:g} mm"})
        entry.update({f"{row['solver']} {key}": value for key, value in row.items()})
    for entry in cases.values():
        a, b = (entry.get(f"{s} min_coaptation_height_mm") for s in ("ptc", "bdf2"))
        entry["difference"] = None if a is None or b is None else abs(a - b)
    columns = [Column("case", "case", text=True)]
    for solver, name in (("ptc", "PTC"), ("bdf2", "BDF2")):
        columns += [Column(f"{name}: converged", f"{solver} converged"),
                    Column(f"{name}: min (mm)", f"{solver} min_coaptation_height_mm", ".3f"),
                    Column("steps", f"{solver} time_steps"),
                    Column("wall (s)", f"{solver} wall_time_s", ".1f")]
    columns.append(Column("difference (mm)", "difference", ".3f"))
    return markdown_table(columns, list(cases.values()))


TABLE = Table("bdf2", ".venv/bin/python benchmarks/bdf2.py", FIELDS, draw)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="reference,normal")
    parser.add_argument("--wall-time-limit", type=float, default=3600.0)
    args = TABLE.arguments(parser)
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.case import run_case

    rows = []
    for name in args.cases.split(","):
        for solver in ("ptc", "bdf2"):
            config = replace(CASES[name], solver=solver,
                             wall_time_limit_s=args.wall_time_limit)
            r = run_case(config, comm=MPI.COMM_SELF, figures=False, fields_output=False)
            rows.append({"case": name, "solver": solver,
                         "mesh_size_mm": config.geometry.mesh_size,
                         **{key: getattr(r, key) for key in FIELDS[3:]}})
            print(f"{name} {solver}: {r.min_coaptation_height_mm:.3f} mm, {r.time_steps} "
                  f"steps, {r.wall_time_s:.1f} s", flush=True)
    print(args.table.write(rows).read_text())


if __name__ == "__main__":
    main()
