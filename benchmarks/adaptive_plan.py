"""A patient's plan by the adaptive design against the full grid: cases, time, answer.

For each patient below, plans the repair twice with ``mpirun -n 2 valve-dolfinx plan``:
with ``--full-grid`` (every graft of the 5 × 4 grid in every member: 3 root diameters ×
2 paths) and with the adaptive design (the default), each into its own folder under
``--root`` (a folder that already holds a finished plan is read, not rerun: give the
full-grid plans computed before, they take 20-50 min each).  Prints and writes one row per
patient and design: graft cases, rounds, why the design stopped, the case time, the wall
time of the plan (measured only when this script ran it), the answer with its predicted
worst-case margin and the one its confirmation solves give, and the agreement
of the two answers, read from the full grid's surfaces: the adaptive answer's predicted
worst-case margin there within the tolerance of the full grid's own answer's, and its
probability of sealing there at least the threshold; a second agreement takes the sealing
from the answer's own solves instead (its size solved in every member, each converged and
sealed), since between the grid's cells the grid's sealing is an interpolation.  Each
answer's cut check (``sizing.answer.trim_check``) says whether a cut half a millimetre off
its template still qualifies::

    .venv/bin/python benchmarks/adaptive_plan.py --root /scratch/plans

The table goes to ``benchmarks/results/adaptive_plan.{csv,md}``; with ``--patients``, the
rows of the other patients already there stay.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from result_tables import Column, Table, markdown_table

import valve_dolfinx  # noqa: F401  (dolfinx_solver before anything else)

BIN = Path(sys.executable).parent
#: the patients: the README's plan, a narrower root and one too wide to seal, each with
#: the default leaflet
PATIENTS = {
    "readme 21±1": ["--root-diameter", "21", "--root-uncertainty", "1"],
    "20±1": ["--root-diameter", "20", "--root-uncertainty", "1"],
    "23±1": ["--root-diameter", "23", "--root-uncertainty", "1"],
}
FIELDS = ("patient", "design", "graft_cases", "rounds", "stop", "case_time_s", "wall_time_s",
          "answer", "margin_mm", "solved_margin_mm", "tolerance_mm", "solves_sealed",
          "cut_robust", "cut_seal_probability", "margin_on_grid_mm", "seals_on_grid",
          "grid_answer_margin_mm", "grid_tolerance_mm", "area_ratio", "agrees",
          "agrees_with_its_solves")


def folder_name(patient: str, design: str) -> str:
    stem = patient.split(",")[0].replace(" ", "_").replace("±", "pm")
    return f"{stem}_{design}"


#: where the wall time of a plan this script ran is kept, in the plan's folder
WALL_FILE = "benchmark_wall_time_s.txt"


def run_plan(args: list[str], out: Path, design: str) -> float | None:
    """Run the plan unless ``out`` holds a finished one; its wall time (s), as measured
    when this script ran it (None for a plan computed otherwise)."""
    if (out / "summary.json").is_file():
        wall = out / WALL_FILE
        return float(wall.read_text()) if wall.is_file() else None
    cmd = [str(BIN / "mpirun"), "-n", "2", str(BIN / "valve-dolfinx"), "plan", *args,
           "--out", str(out), "--no-progress", "-q"]
    if design == "grid":
        cmd.append("--full-grid")
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True)
    wall = time.perf_counter() - t0
    (out / WALL_FILE).write_text(f"{wall!r}\n")
    return wall


def study_answer(plan: Path):
    """The plan's study report (its answers and layout), rebuilt in memory, writing
    nothing."""
    from valve_dolfinx.study.report import build_report, read_settings

    study = plan / "study"
    return build_report(study, read_settings(study), draft=True)


def at(answer, size) -> tuple[float | None, bool]:
    """The predicted worst-case margin of ``size`` on ``answer``'s lattice, and whether it
    seals there."""
    lattice = answer.lattice
    if lattice is None or size is None:
        return None, False
    i = list(lattice.heights_pct).index(size.height_pct)
    j = list(lattice.widths_pct).index(size.width_pct)
    return (float(lattice.worst_margin_mm[i, j]),
            bool(lattice.seal_probability[i, j] >= answer.seal_threshold))


def solves_sealed(report, size) -> str | None:
    """How many of the cases solved at ``size`` converged and sealed, of how many."""
    if size is None:
        return None
    cases = [r for r in report.rows if r.get("graft_width_pct") is not None
             and (float(r["graft_width_pct"]), float(r["graft_height_pct"])) == tuple(size)]
    sealed = sum(bool(r.get("converged")) and bool(r.get("competent")) for r in cases)
    return f"{sealed}/{len(cases)}"


def solved_margin(rec) -> float | None:
    """The answer's worst-case margin as its confirmation solves give it (None unless
    solved): what the plan's headline prints."""
    margin, _, solved = rec.margin
    return margin if solved else None


def row_of(patient: str, design: str, report, wall: float | None, grid) -> dict:
    rec = report.recommendations[0]
    answer = rec.answer
    size = answer.size
    rows = report.rows
    plan = report.next_round
    row = {"patient": patient, "design": design, "graft_cases": report.layout.graft_cases,
           "rounds": len(report.layout.rounds), "stop": plan.stop if plan else None,
           "case_time_s": sum(float(r.get("wall_time_s") or 0.0) for r in rows),
           "wall_time_s": wall, "answer": size.label if size else f"none ({answer.why})",
           "margin_mm": answer.margin_mm, "tolerance_mm": answer.tolerance_mm,
           "solved_margin_mm": solved_margin(rec),
           "area_ratio": size.area_ratio if size else None,
           "solves_sealed": solves_sealed(report, size),
           "cut_robust": answer.trim["robust"] if answer.trim else None,
           "cut_seal_probability": answer.trim["seal_probability"] if answer.trim else None}
    reference = grid.recommendations[0].answer
    row["grid_answer_margin_mm"] = reference.margin_mm
    row["grid_tolerance_mm"] = reference.tolerance_mm
    if size is None or reference.size is None:
        row["agrees"] = row["agrees_with_its_solves"] = size is None and reference.size is None
        return row
    margin, seals = at(reference, size)
    row["margin_on_grid_mm"], row["seals_on_grid"] = margin, seals
    close = margin is not None and abs(margin - reference.margin_mm) <= reference.tolerance_mm
    sealed, solved = map(int, row["solves_sealed"].split("/"))
    row["agrees"] = bool(seals and close)
    row["agrees_with_its_solves"] = bool(close and solved and sealed == solved)
    return row


def draw(rows: list[dict]) -> str:
    columns = [Column("patient", "patient", text=True), Column("design", "design", text=True),
               Column("graft cases", "graft_cases", "d"), Column("rounds", "rounds", "d"),
               Column("stop", "stop", text=True), Column("case time (s)", "case_time_s", ".0f"),
               Column("plan wall time (s)", "wall_time_s", ".0f"),
               Column("answer", "answer", text=True),
               Column("predicted margin (mm)", "margin_mm", "+.2f"),
               Column("solved margin (mm)", "solved_margin_mm", "+.2f"),
               Column("tolerance (mm)", "tolerance_mm", ".2f"),
               Column("its solves sealed", "solves_sealed", text=True),
               Column("robust to a 0.5 mm cut", "cut_robust"),
               Column("least sealing of the cut sizes", "cut_seal_probability", ".2f"),
               Column("margin on the grid's surface (mm)", "margin_on_grid_mm", "+.2f"),
               Column("seals on the grid's surface", "seals_on_grid"),
               Column("grid answer's margin (mm)", "grid_answer_margin_mm", "+.2f"),
               Column("flat area ×", "area_ratio", ".3f"),
               Column("agrees with the grid's surface", "agrees"),
               Column("agrees, sealing from its solves", "agrees_with_its_solves")]
    return markdown_table(columns, rows)


TABLE = Table("adaptive_plan", "benchmarks/adaptive_plan.py --root DIR", FIELDS, draw)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--root", type=Path, default=Path("results/adaptive_plan"),
                        help="folder of the plans (default %(default)s)")
    parser.add_argument("--patients", nargs="*", default=list(PATIENTS),
                        choices=list(PATIENTS), metavar="NAME",
                        help=f"which patients (default all: {', '.join(PATIENTS)})")
    args = TABLE.arguments(parser, argv)
    table = args.table
    rows = [row for row in (table.read() if table.csv_path.is_file() else [])
            if row["patient"] not in args.patients]  # the other patients' rows stand
    for patient in args.patients:
        reports, walls = {}, {}
        for design in ("grid", "adaptive"):
            out = args.root / folder_name(patient, design)
            walls[design] = run_plan(PATIENTS[patient], out, design)
            reports[design] = study_answer(out)
        for design in ("grid", "adaptive"):
            row = row_of(patient, design, reports[design], walls[design], reports["grid"])
            rows.append(row)
            print(json.dumps(row))
    order = {name: k for k, name in enumerate(PATIENTS)}
    rows.sort(key=lambda row: order.get(row["patient"], len(order)))  # (stable: grid first)
    print(table.write(rows).read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
