"""Mesh convergence of the figure of merit (SPEC §8): each case at the default mesh and a finer one.

Closes the normal valve and W21/H27 -- the cells SPEC §8 names: their minimum coaptation
heights at 0.8 and 0.6 mm within 0.1 mm -- and W0/H40 beside them (``--cases``), each
graft valve from the open valve, as ``valve-dolfinx run --mesh-size M [--graft-width W
--graft-height H]`` does, one after the other in this process.  Per case and mesh the
figure of merit and the raw height (the tip inside the nodulus included) go to
``benchmarks/results/mesh_convergence.csv``, and the table drawn from them, each case's
change between the meshes against the acceptance, to ``mesh_convergence.md``
(``--tables-only`` redraws it from the CSV)::

    .venv/bin/python benchmarks/mesh_convergence.py [--meshes 0.8 0.6] [--cases normal,W21/H27]

Every cell of the grid at both meshes, along one path: ``benchmarks/mesh_ladder.py``.
"""

from __future__ import annotations

import argparse

# benchmarks/cases.py and result_tables.py, beside this script
from cases import case_config, case_label, parse_cases
from result_tables import Column, Table, cell, markdown_table

#: SPEC §8's cells and one beside them
CASES = "normal,W21/H27,W0/H40"
#: the cells whose change SPEC §8 bounds, and the bound (mm)
ACCEPTANCE_CASES, ACCEPTANCE_MM = ("normal", "W21/H27"), 0.1
FIELDS = ("case", "mesh_size_mm", "converged", "competent", "min_coaptation_height_mm",
          "min_coaptation_height_raw_mm", "wall_time_s")


def _height(row: dict | None) -> str:
    """``min (raw)`` in mm, or what went wrong."""
    if row is None or row["min_coaptation_height_mm"] is None:
        return "–"
    text = (f"{row['min_coaptation_height_mm']:.2f} "
            f"({cell(row['min_coaptation_height_raw_mm'], '.2f')})")
    if row["converged"] is False:
        return text + ", not converged"
    return text + ", not competent" if row["competent"] is False else text


def draw(rows: list[dict]) -> str:
    """A line per case: the figure of merit (raw) at each mesh, coarsest first, and the
    change between the coarsest and the finest; whether the acceptance is met."""
    meshes = sorted({r["mesh_size_mm"] for r in rows}, reverse=True)
    at = {(r["case"], r["mesh_size_mm"]): r for r in rows}
    lines = []
    for case in dict.fromkeys(r["case"] for r in rows):
        coarse, fine = at.get((case, meshes[0])), at.get((case, meshes[-1]))
        change = (None if coarse is None or fine is None
                  or None in (coarse["min_coaptation_height_mm"], fine["min_coaptation_height_mm"])
                  else abs(coarse["min_coaptation_height_mm"] - fine["min_coaptation_height_mm"]))
        if case not in ACCEPTANCE_CASES:
            verdict = "beside the acceptance"
        elif change is None:
            verdict = "not measured"
        else:
            verdict = "met" if change <= ACCEPTANCE_MM else "not met"
        lines.append({"case": case, **{m: _height(at.get((case, m))) for m in meshes},
                      "change": change, "verdict": verdict})
    columns = ([Column("case", "case", text=True)]
               + [Column(f"{m:g} mm: min (raw) (mm)", lambda r, m=m: r[m]) for m in meshes]
               + [Column("change (mm)", "change", ".2f"),
                  Column(f"within {ACCEPTANCE_MM:g} mm", "verdict", text=True)])
    return markdown_table(columns, lines)


TABLE = Table("mesh_convergence", ".venv/bin/python benchmarks/mesh_convergence.py", FIELDS,
              draw)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=parse_cases, default=parse_cases(CASES),
                        help=f"comma-separated (default {CASES})")
    parser.add_argument("--meshes", type=float, nargs="+", default=[0.8, 0.6], metavar="MM")
    args = TABLE.arguments(parser, argv)
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.case import run_case

    rows = []
    for case in args.cases:
        for mesh in args.meshes:
            r = run_case(case_config(case, mesh), comm=MPI.COMM_SELF, figures=False,
                         fields_output=False)
            rows.append({"case": case_label(case), "mesh_size_mm": mesh,
                         **{key: getattr(r, key) for key in FIELDS[2:]}})
            print(f"{case_label(case)} at {mesh:g} mm: {r.min_coaptation_height_mm:.3f} mm, "
                  f"{r.wall_time_s:.0f} s", flush=True)
    print(args.table.write(rows).read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
