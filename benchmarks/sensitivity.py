"""Which modelling choices the sizing answer depends on: the study grid under each choice that
the published method does not fix, one at a time around the defaults (docs/sensitivity.md).

Runs into one results folder (``--out``, default ``results/sensitivity``):

* ``defaults/``: the study at the package defaults (the normal valve and the W × H grid);
* ``<choice>/``: per choice of :data:`CHOICES`, the same study with the choice's other
  values as a comparison axis (``vary``); its default value is the ``defaults/`` study.

Then prints, per choice, a Markdown table per cell (the minimum coaptation height, and
whether it leaks, has leaflets that intersect or did not converge; the worst case over the
members with ``--paths 2``), a row of the recommendation each value gives, and the wall
time of its study.  Every study is resumable: a rerun with the same ``--out`` computes only what is
missing.  The figures go to ``benchmarks/results/sensitivity.csv`` (a row per choice, value and
cell, one per value for the normal valve's target and for the recommendation, and one per
study for its wall time) and the tables drawn from them to ``sensitivity.md``
(``--tables-only`` redraws them from the CSV).

Run on the 2-core machine: ``.venv/bin/mpirun -n 2 .venv/bin/python benchmarks/sensitivity.py``
(the default grid and mesh: hours).  A smoke test: ``--mesh-size 2.0 --widths 0 14
--heights 0 27 --choices nodulus``.
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# benchmarks/result_tables.py, beside this script
from result_tables import Table, cell

from valve_dolfinx._compat import MPI
from valve_dolfinx.config import CaseConfig, get_dotted
from valve_dolfinx.geometry.valve import DEFAULT_MESH_SIZE
from valve_dolfinx.interrupts import interrupt_on_signals
from valve_dolfinx.result import margin_text
from valve_dolfinx.study import STUDY_HEIGHTS_PCT, STUDY_WIDTHS_PCT, StudySettings
from valve_dolfinx.study.axes import check_axis_values, value_text
from valve_dolfinx.study.runner import run_study


@dataclass(frozen=True)
class Choice:
    """One modelling choice: a case setting and the values to compare (the default among
    them), as a function of the setting's default and the study's mesh size."""

    name: str
    title: str
    key: str
    values: Callable[[Any, float], tuple]


#: The choices of docs/sensitivity.md, in its order
CHOICES = (
    Choice("root", "loaded root diameter (mm; none: the wall law, 20.09 mm)",
           "root.loaded_diameter_mm", lambda d, mesh: (19.0, None, 21.0, 22.0)),
    Choice("native_bending", "the native leaflets' bending modulus (kPa)",
           "native.bending_modulus_kpa", lambda d, mesh: (0.0, 200.0, 800.0)),
    Choice("graft_bending", "the graft's bending modulus (kPa): a decade either side",
           "graft.bending_modulus_kpa", lambda d, mesh: (d / 10, d, d * 10)),
    Choice("graft_compression", "the graft's compressive response (true: tension field; "
           "false: the plain Fung law)", "graft.tension_field", lambda d, mesh: (True, False)),
    Choice("graft_thickness", "graft thickness (mm)", "graft.material.thickness_mm",
           lambda d, mesh: (0.3, 0.5)),
    Choice("nodulus", "nodulus length left out of the coaptation heights (mm)",
           "analysis.nodulus_length_mm", lambda d, mesh: (0.0, 1.0)),
    Choice("contact_thickness", "contact thickness (mm): half and double",
           "contact.thickness_mm", lambda d, mesh: (d / 2, d, d * 2)),
    Choice("mesh", "mesh size (mm)", "geometry.mesh_size_mm",
           lambda d, mesh: (mesh, round(0.75 * mesh, 3))),
)


def _values(choice: Choice, mesh: float) -> tuple[tuple, Any]:
    """The choice's values (checked) and its default."""
    if choice.key == "geometry.mesh_size_mm":
        default = mesh
    else:
        default = get_dotted(CaseConfig().to_dict(), choice.key)
    values = check_axis_values(f"choice {choice.name}", choice.key,
                               list(choice.values(default, mesh)), {})
    return values, default


FIELDS = ("kind", "choice", "key", "title", "value", "cell", "worst_height_mm", "members",
          "leaking", "largest_orifice_mm2", "intersecting", "most_intersecting_pairs",
          "not_converged", "target_low_mm", "target_high_mm", "answer", "wall_s")


def _value_text(value) -> str:
    """A value as ``value_text`` wrote it (the CSV reads ``true`` back as a bool)."""
    return ("true" if value else "false") if isinstance(value, bool) else str(value)


def choice_rows(choice: Choice, columns: list[tuple[Any, Any]], wall_s: float) -> list[dict]:
    """The CSV rows of one choice: ``columns`` are ``(value, Recommendation)``."""
    head = {"choice": choice.name, "key": choice.key, "title": choice.title}
    rows = []
    for value, rec in columns:
        at = {**head, "value": value_text(value)}
        targets = sorted(t for t in rec.targets_mm.values() if t is not None)
        rows.append({**at, "kind": "normal", "cell": "normal",
                     "target_low_mm": targets[0] if targets else None,
                     "target_high_mm": targets[-1] if targets else None})
        for c in rec.cells:
            rows.append({**at, "kind": "cell", "cell": c.label,
                         "worst_height_mm": c.worst_height_mm, "members": len(c.members),
                         "leaking": len(c.leaking), "largest_orifice_mm2": c.largest_orifice_mm2,
                         "intersecting": len(c.intersecting),
                         "most_intersecting_pairs": c.most_intersecting_pairs,
                         "not_converged": len(c.unconverged) + len(c.missing)})
        rows.append({**at, "kind": "answer", "answer": _answer(rec)})
    rows.append({**head, "kind": "wall", "wall_s": wall_s})
    return rows


def _entry(row: dict) -> str:
    """One table entry: the worst-case height and what went wrong in any member."""
    if row is None or row["worst_height_mm"] is None:
        return "–"
    text = f"{row['worst_height_mm']:.2f}"
    n = row["members"]

    def members(count: int) -> str:
        return "" if n == 1 else f" in {count}/{n}"

    if row["leaking"]:
        text += f", leaks {row['largest_orifice_mm2']:.2g} mm²" + members(row["leaking"])
    if row["intersecting"]:
        pairs = row["most_intersecting_pairs"]
        text += (", intersects" + (f" ({pairs} edge–triangle pairs)" if pairs else "")
                 + members(row["intersecting"]))
    if row["not_converged"]:
        text += ", not converged" + members(row["not_converged"])
    return text


def _answer(rec) -> str:
    answer = rec.answer
    if answer.size is not None:
        return f"{answer.size.label} ({margin_text(answer.margin_mm, signed=True)})"
    if answer.closest is not None and answer.shortfall_mm is not None:
        return (f"none (best {answer.closest.label}, "
                f"{margin_text(-answer.shortfall_mm, signed=True)})")
    return "none"


def _target(row: dict) -> str:
    low, high = row["target_low_mm"], row["target_high_mm"]
    if low is None:
        return "–"
    return cell(low, ".2f") if low == high else f"{low:.2f}–{high:.2f}"


def draw(rows: list[dict]) -> str:
    """Per choice, in the CSV's order: a Markdown table per cell (a column per value), the
    normal valve's height (the target), the recommendation with its margin, and the wall
    time of the choice's study."""
    parts = []
    for name in dict.fromkeys(row["choice"] for row in rows):
        mine = [row for row in rows if row["choice"] == name]
        values = list(dict.fromkeys(_value_text(r["value"]) for r in mine if r["kind"] != "wall"))
        at = {(r["kind"], r["cell"], _value_text(r["value"])): r for r in mine}
        cells = list(dict.fromkeys(r["cell"] for r in mine if r["kind"] == "cell"))
        lines = [f"### {mine[0]['title']} (`{mine[0]['key']}`)\n",
                 "| cell | " + " | ".join(values) + " |", "|---|" + "---:|" * len(values),
                 "| normal | " + " | ".join(_target(at["normal", "normal", v]) for v in values)
                 + " |"]
        lines += [f"| {c} | " + " | ".join(_entry(at.get(("cell", c, v))) for v in values)
                  + " |" for c in cells]
        lines.append("| **recommended** (margin mm) | "
                     + " | ".join(at["answer", None, v]["answer"] for v in values) + " |")
        wall = next((r["wall_s"] for r in mine if r["kind"] == "wall"), None)
        lines.append("\nWall time of its study: "
                     + (f"{wall:.0f} s.\n" if wall is not None else "not recorded.\n"))
        parts.append("\n".join(lines))
    return "\n".join(parts)


TABLE = Table("sensitivity", ".venv/bin/mpirun -n 2 .venv/bin/python benchmarks/sensitivity.py",
              FIELDS, draw)


def _run(settings: StudySettings, out: Path, comm) -> tuple[Any, float]:
    outcome = run_study(settings, out, comm)
    return outcome.report, outcome.elapsed_s


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/sensitivity"))
    parser.add_argument("--mesh-size", type=float, default=DEFAULT_MESH_SIZE, metavar="MM")
    parser.add_argument("--widths", type=float, nargs="+", default=list(STUDY_WIDTHS_PCT))
    parser.add_argument("--heights", type=float, nargs="+", default=list(STUDY_HEIGHTS_PCT))
    parser.add_argument("--paths", type=int, default=1, help="numerical paths per cell")
    parser.add_argument("--choices", nargs="+", default=[c.name for c in CHOICES],
                        choices=[c.name for c in CHOICES], metavar="NAME",
                        help=f"a subset of {', '.join(c.name for c in CHOICES)}")
    args = TABLE.arguments(parser, argv)
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    comm = MPI.COMM_WORLD
    if comm.rank == 0:  # one line per finished case
        logging.getLogger("valve_dolfinx.study").setLevel(logging.INFO)
    grid = {"widths_pct": tuple(args.widths), "heights_pct": tuple(args.heights),
            "paths": args.paths, "panel_cases": ()}
    t0 = time.perf_counter()
    defaults, wall = _run(StudySettings(mesh_size_mm=args.mesh_size, **grid),
                          args.out / "defaults", comm)
    walls = {"defaults": wall}
    tables = []
    for choice in (c for c in CHOICES if c.name in args.choices):
        values, default = _values(choice, args.mesh_size)
        others = [v for v in values if v != default]
        mesh = None if choice.key == "geometry.mesh_size_mm" else args.mesh_size
        settings = StudySettings(mesh_size_mm=mesh, vary={choice.key: others}, **grid)
        report, walls[choice.name] = _run(settings, args.out / choice.name, comm)
        if comm.rank == 0:
            by_value = dict(zip(others, report.recommendations, strict=True))
            by_value[default] = defaults.recommendations[0]
            tables.append((choice, [(v, by_value[v]) for v in values]))
    if comm.rank != 0:
        return 0
    rows = [row for choice, columns in tables
            for row in choice_rows(choice, columns, walls[choice.name])]
    print(f"\nStudies of {len(args.widths)} × {len(args.heights)} grafts and the normal valve, "
          f"mesh {args.mesh_size:g} mm, {args.paths} path(s), {comm.size} MPI rank(s); "
          "minimum coaptation height in mm (the worst member's with several paths), the "
          "recommendation with its margin (mm).\n")
    print(args.table.write(rows).read_text())
    total = time.perf_counter() - t0
    print(f"wall time: defaults {walls['defaults']:.0f} s; all studies {total:.0f} s "
          f"({total / 3600:.2f} h) -> {args.out}")
    return 0


if __name__ == "__main__":
    with interrupt_on_signals():  # an interrupted benchmark resumes with the same --out
        raise SystemExit(main())
