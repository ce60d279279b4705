"""The benchmarks' tables (``benchmarks/result_tables.py``): every Markdown table in
``benchmarks/results/`` is the drawing of the CSV beside it, and shows that CSV's figures.

The figures a table shows are recomputed here from the CSV by their definitions (the
sphere's closed-form radius and convergence rates, the mesh ladder's changes and its
root-mean-square discretisation error); the other benchmarks' drawings are checked on
constructed rows with hand-worked entries.
"""

from __future__ import annotations

import csv
import importlib
import math
import sys
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
RESULTS = BENCHMARKS / "results"


def bench(name: str):
    """A module of benchmarks/ (they import their neighbours by plain name)."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(BENCHMARKS))


def markdown_rows(text: str) -> list[list[str]]:
    """The body rows of the Markdown tables in ``text``, as lists of cells."""
    lines = text.splitlines()
    rule = [set(line) <= set("|-: ") and line.startswith("|") for line in lines]
    return [[c.strip() for c in line.strip("|").split("|")]
            for k, line in enumerate(lines)
            if line.startswith("|") and not rule[k] and not (k + 1 < len(lines) and rule[k + 1])]


def csv_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def committed_tables() -> dict:
    """The tables of benchmarks/results/, by name."""
    return {"membrane": bench("membrane").TABLE,
            "contact_comparison": bench("contact_comparison").TABLE,
            "adaptive_plan": bench("adaptive_plan").TABLE,
            "answer_stability": bench("answer_stability").TABLE,
            "independence": bench("independence").TABLE,
            "closure": bench("closure").TABLE,
            "factorisation": bench("factorisation").TABLE,
            "contact": bench("contact").TABLE,
            "sensitivity": bench("sensitivity").TABLE,
            "bdf2": bench("bdf2").TABLE,
            "sweep": bench("sweep").TABLE,
            "mesh_convergence": bench("mesh_convergence").TABLE,
            "path_agreement": bench("path_agreement").TABLE,
            "mesh_ladder": bench("mesh_ladder").ladder_table(RESULTS / "mesh_ladder.csv")}


def test_a_csv_cell_reads_back_as_written():
    tables = bench("result_tables")
    for value in (None, True, False, 0, 42, 0.1 + 0.2, 2.9104652580876085, -1e-300,
                  "W21/H27", "mass x4"):
        assert tables.parse(tables.format_csv(value)) == value
    assert tables.format_csv(float("nan")) == "" and tables.format_csv(math.inf) == ""
    assert tables.cell(None) == tables.cell(float("nan")) == "–"
    assert tables.cell(12146, ",") == "12 146" and tables.cell(True) == "yes"


def test_every_committed_table_is_the_drawing_of_its_csv():
    """A hand edit of a table, or a CSV whose table was not redrawn, fails here."""
    tables = committed_tables()
    assert {p.stem for p in RESULTS.glob("*.md")} == set(tables)
    for name, table in tables.items():
        assert table.markdown_path.read_text() == table.render(), name
        assert table.render().startswith("_Written by `")


def test_the_sphere_table_shows_its_csv_and_the_closed_form():
    membrane = bench("membrane")
    rows = csv_rows(RESULTS / "membrane.csv")
    shown = markdown_rows((RESULTS / "membrane.md").read_text())
    assert len(shown) == len(rows) >= 3
    exact = membrane.exact_radius()  # closed form: t·S(E) = p·λR/2
    errors, sizes = [], []
    for row, line in zip(rows, shown, strict=True):
        h, radius = float(row["mesh_size_mm"]), float(row["radius_mm"])
        assert float(row["exact_radius_mm"]) == pytest.approx(exact, rel=1e-12)
        error = abs(radius / exact - 1.0)
        assert line[0] == f"{h:.1f}" and line[2] == f"{int(row['cells']):,}".replace(",", " ")
        assert line[6] == f"{radius:.6f}" and line[7] == f"{error:.3e}"
        if sizes:
            rate = math.log(errors[-1] / error) / math.log(sizes[-1] / h)
            assert line[8] == f"{rate:.2f}"
        else:
            assert line[8] == "–"
        errors.append(error)
        sizes.append(h)
    # a second-order method: the error falls about as h² (the sphere's chord error)
    slope = np.linalg.lstsq(np.vstack([np.log(sizes), np.ones(len(sizes))]).T,
                            np.log(errors), rcond=None)[0][0]
    assert 1.8 < slope < 2.3
    assert f"Least-squares rate over the {len(rows)} sizes {slope:.2f}" in (
        RESULTS / "membrane.md").read_text()


def test_the_mesh_ladder_table_shows_its_csv_and_the_rms_error():
    rows = csv_rows(RESULTS / "mesh_ladder.csv")
    text = (RESULTS / "mesh_ladder.md").read_text()
    shown = {line[0]: line for line in markdown_rows(text)}
    meshes = sorted({float(r["mesh_size_mm"]) for r in rows}, reverse=True)
    sound: dict[float, dict[str, float]] = {m: {} for m in meshes}
    for row in rows:
        w = row["graft_width_pct"]
        name = "normal" if not w else f"W{float(w):g}/H{float(row['graft_height_pct']):g}"
        mesh = float(row["mesh_size_mm"])
        y = float(row["min_coaptation_height_mm"])
        ok = row["converged"] == "true" and row["competent"] == "true"
        column = 2 + meshes.index(mesh)
        assert shown[name][column] == f"{y:.2f}" + ("" if ok else " (not sound)")
        if ok:
            sound[mesh][name] = y
    fine, coarser = meshes[-1], meshes[:-1]
    for k, coarse in enumerate(coarser):  # a column of changes from the finest per mesh
        both = sorted(set(sound[coarse]) & set(sound[fine]))
        for name in shown:
            expected = (f"{sound[coarse][name] - sound[fine][name]:+.2f}" if name in both
                        else "–")
            assert shown[name][2 + len(meshes) + k] == expected, (name, coarse)
        rms = math.sqrt(sum((sound[coarse][n] - sound[fine][n]) ** 2 for n in both)
                        / len(both))
        assert (f"Discretisation error at {coarse:g} mm: {rms:.3f} mm ({coarse:g} mm against "
                f"{fine:g} mm over {len(both)} cases") in text


def _drawn(table, rows: list[dict], tmp_path: Path) -> str:
    """Write constructed rows as the benchmark does; the Markdown drawn from the CSV."""
    return table.at(tmp_path).write(rows).read_text()


def test_the_bdf2_table_pairs_the_paths_of_each_case(tmp_path):
    bdf2 = bench("bdf2")
    common = {"case": "reference", "mesh_size_mm": 0.8, "converged": True}
    text = _drawn(bdf2.TABLE, [
        {**common, "solver": "ptc", "min_coaptation_height_mm": 2.9291, "time_steps": 9,
         "wall_time_s": 3.6},
        {**common, "solver": "bdf2", "min_coaptation_height_mm": 2.9283, "time_steps": 238,
         "wall_time_s": 51.94}], tmp_path)
    assert markdown_rows(text) == [["symmetric reference, 0.8 mm", "yes", "2.929", "9", "3.6",
                                    "yes", "2.928", "238", "51.9", "0.001"]]


def test_the_mesh_convergence_table_judges_the_change_of_spec_cells_only(tmp_path):
    """SPEC §8 bounds the change of the normal valve and W21/H27 by 0.1 mm; W0/H40 is shown
    beside them; the change is between the coarsest and the finest mesh."""
    module = bench("mesh_convergence")
    heights = {("normal", 0.8): (2.91, 1.87), ("normal", 0.6): (2.83, 1.95),
               ("W21/H27", 0.8): (2.57, 2.57), ("W21/H27", 0.6): (2.44, 2.40),
               ("W0/H40", 0.8): (2.29, 2.11), ("W0/H40", 0.6): (2.14, 1.67)}
    rows = [{"case": c, "mesh_size_mm": m, "converged": True, "competent": c != "W0/H40",
             "min_coaptation_height_mm": y, "min_coaptation_height_raw_mm": raw}
            for (c, m), (y, raw) in heights.items()]
    assert markdown_rows(_drawn(module.TABLE, rows, tmp_path)) == [
        ["normal", "2.91 (1.87)", "2.83 (1.95)", "0.08", "met"],
        ["W21/H27", "2.57 (2.57)", "2.44 (2.40)", "0.13", "not met"],
        ["W0/H40", "2.29 (2.11), not competent", "2.14 (1.67), not competent", "0.15",
         "beside the acceptance"]]


def test_the_independence_table_names_each_check(tmp_path):
    independence = bench("independence")
    heights = {("W27/H0", "mass x1"): 0.8390, ("W27/H0", "mass x4"): 0.8389,
               ("W21/H27", "mass x1"): 2.5659, ("W21/H27", "mass x4"): 2.5653,
               ("W21/H27", "billow +0.75"): 2.5650, ("W21/H27", "billow -0.75"): 2.5644}
    rows = [{"case": c, "variant": v, "mesh_size_mm": 0.8, "converged": True,
             "min_coaptation_height_mm": y} for (c, v), y in heights.items()]
    rows[-1].update(placement_apart_mm=1.5, nodal_distance_mm=0.0018, mirror_distance_mm=1.14)
    checks = markdown_rows(_drawn(independence.TABLE, rows, tmp_path))[:4]
    assert [c[2] for c in checks] == ["0.0001 mm (0.8390 / 0.8389 mm)",
                                      "0.0006 mm (2.5659 / 2.5653 mm)", "0.0006 mm",
                                      "0.0018 mm / 1.14 mm"]
    assert "(1.50 mm apart" in checks[2][0]


def test_the_sensitivity_table_has_a_column_per_value(tmp_path):
    sensitivity = bench("sensitivity")
    head = {"choice": "nodulus", "key": "nodulus_length_mm", "title": "nodulus length"}
    rows = []
    for value, target, height, answer in (("0", 1.87, 1.44, "W7/H13 (+0.34)"),
                                          ("1", 2.91, 2.93, "W7/H40 (+0.02)")):
        rows += [{**head, "kind": "normal", "value": value, "cell": "normal",
                  "target_low_mm": target, "target_high_mm": target},
                 {**head, "kind": "cell", "value": value, "cell": "W7/H40",
                  "worst_height_mm": height, "members": 1, "leaking": 0, "intersecting": 0,
                  "not_converged": 0},
                 {**head, "kind": "cell", "value": value, "cell": "W21/H0",
                  "worst_height_mm": 0.80, "members": 2, "leaking": 1,
                  "largest_orifice_mm2": 16.04, "intersecting": 2,
                  "most_intersecting_pairs": 30, "not_converged": 0},
                 {**head, "kind": "answer", "value": value, "answer": answer}]
    rows.append({**head, "kind": "wall", "wall_s": 355.2})
    text = _drawn(sensitivity.TABLE, rows, tmp_path)
    assert "| cell | 0 | 1 |" in text
    assert markdown_rows(text) == [
        ["normal", "1.87", "2.91"], ["W7/H40", "1.44", "2.93"],
        ["W21/H0"] + ["0.80, leaks 16 mm² in 1/2, intersects (30 edge–triangle pairs) in 2/2"]
        * 2, ["**recommended** (margin mm)", "W7/H13 (+0.34)", "W7/H40 (+0.02)"]]
    assert "Wall time of its study: 355 s." in text


def test_every_choice_of_the_sensitivity_table_holds_the_same_defaults_study():
    """Each choice's column at the package default is the one study at the defaults: the
    same 21 cells with the same heights, leaks and answer in every choice."""
    from valve_dolfinx.study.axes import value_text

    sensitivity = bench("sensitivity")
    rows = sensitivity.TABLE.read()
    columns = {}
    for choice in sensitivity.CHOICES:
        default = value_text(sensitivity._values(choice, 0.8)[1])
        at = [r for r in rows if r["choice"] == choice.name and r["kind"] != "wall"
              and sensitivity._value_text(r["value"]) == default]
        columns[choice.name] = {(r["cell"], r["kind"]): (r["worst_height_mm"], r["leaking"],
                                                         r["target_low_mm"], r["answer"])
                                for r in at}
    assert set(columns) == {c.name for c in sensitivity.CHOICES}
    first = columns["root"]
    assert len(first) == 1 + 20 + 1  # the normal valve, the grid's grafts, the answer
    for name, column in columns.items():
        assert column == first, name


def test_the_closure_table_takes_the_median_warm_run(tmp_path):
    closure = bench("closure")
    runs = [{"case": "normal", "run": k, "mesh_size_mm": 0.8, "converged": True,
             "total_s": total, "contact_pct": 10.0, "solve_s": total / 2}
            for k, total in ((1, 20.0), (2, 12.0), (3, 10.0), (4, 11.0))]
    text = _drawn(closure.TABLE, runs, tmp_path)
    whole = next(r for r in markdown_rows(text) if r[0] == "whole run s")
    assert whole[1:] == ["20.00", "11.00"]  # cold, then the median of 12, 10, 11
    assert ["normal: whole run <= 30 s", "11.0 s", "PASS"] in markdown_rows(text)


def test_the_contact_table_gives_the_growth_exponent(tmp_path):
    contact = bench("contact")
    figures = dict.fromkeys(contact.FIGURES, 1)
    rows = [{**figures, "series": "refine", "title": "Refinement", "triangles": n,
             "prism": n, "blocks": n, "detect+forces": 1e-6 * n ** 1.5, "total": 2e-6 * n,
             "load_before": "load 1", "load_after": "load 2"} for n in (1000, 4000, 16000)]
    text = _drawn(contact.TABLE, rows, tmp_path)
    assert "detection + forces 1.50, total 1.00" in text
    assert markdown_rows(text)[0][:1] == ["1 000"]


def test_the_factorisation_table_in_milliseconds(tmp_path):
    factorisation = bench("factorisation")
    row = {"case": "normal", "mesh_size_mm": 0.8, "converged": True, "unknowns": 4086,
           "stored_entries": 212000, "matrix_type": "seqbaij", "factorisation": "MUMPS, AMD",
           "first_s": 0.0251, "again_s": 0.0213, "flops": 3.2e7, "largest_front": 180}
    text = _drawn(factorisation.TABLE, [row, {**row, "factorisation": "PETSc LU",
                                              "flops": None, "largest_front": None}], tmp_path)
    assert markdown_rows(text) == [["MUMPS, AMD", "25.1", "21.3", "32", "180"],
                                   ["PETSc LU", "25.1", "21.3", "–", "–"]]


def test_the_newton_table_counts_accepted_and_failed_solves(tmp_path):
    newton = bench("newton_solves")
    figures = {"converged": True, "figure_of_merit_mm": 2.57,
               "solves": [{"accepted": True, "norms": [1.0, 0.1, 0.001]},
                          {"accepted": False, "norms": [1.0, 0.9, 0.95, 0.97]},
                          {"accepted": True, "norms": [0.5]}],
               "events": {"MatLUFactorNum": {"count": 4, "seconds": 0.2}}}
    text = _drawn(newton.TABLE, newton.case_rows("W21/H27", figures), tmp_path)
    assert "2 accepted (2 iterations), 1 failed (3 iterations); 4 factorisations" in text
    assert ["MatLUFactorNum", "4", "0.20", "50.00"] in markdown_rows(text)
    # the failed solve reached its last minimum at iteration 1: m = 1 cuts it after 2, saving 1
    assert ["1", "0", "1"] in markdown_rows(text)


def test_the_grid_and_sweep_tables_count_what_converged(tmp_path):
    grid, sweep = bench("grid"), bench("sweep")
    text = _drawn(grid.TABLE, [
        {"kind": "case", "case": "normal", "converged": True, "wall_time_s": 8.0},
        {"kind": "case", "case": "W21_H27", "converged": False, "wall_time_s": 5.0,
         "solver_message": "stopped"},
        {"kind": "run", "mesh_size_mm": 0.8, "jobs": 2, "elapsed_s": 9.0}], tmp_path)
    assert "1 of 2 cases converged" in text and "sum of case wall times 13 s" in text
    assert "- W21_H27: stopped" in text
    text = _drawn(sweep.TABLE, [
        {"kind": "case", "case": "normal", "converged": True, "competent": True,
         "newton_iterations": 28, "rejected_newton_iterations": 0, "wall_time_s": 8.0,
         "mesh_size_mm": 0.8},
        {"kind": "case", "case": "W0_H0", "converged": True, "competent": False,
         "newton_iterations": 135, "rejected_newton_iterations": 36, "wall_time_s": 12.0,
         "mesh_size_mm": 0.8},
        {"kind": "sweep", "computed": 2, "ranks": 2, "ranks_per_case": 1, "elapsed_s": 10.0}],
        tmp_path)
    assert markdown_rows(text)[1][:3] == ["W0_H0", "yes", "no"]
    assert markdown_rows(text)[1][7] == "135 + 36"
    assert "sum of case wall times 20 s (×2.00 from the rank groups)" in text
    # 28 + 135 accepted, 0 + 36 failed; one of the two competent
    assert "2 converged, 1 competent" in text and "163 + 36 in all" in text
    rows = sweep.TABLE.at(tmp_path).read()
    rows[-1]["elapsed_s"] = None  # a sweep whose own wall time was not kept
    text = _drawn(sweep.TABLE, rows, tmp_path)
    assert "Sum of case wall times 20 s (the sweep's own not recorded)" in text


def test_the_contact_comparison_pairs_two_studies_case_by_case(tmp_path):
    """Two stand-in studies: the rows pair each case's figures, the totals add them up."""
    import json

    module = bench("contact_comparison")
    runs = {}
    for side, pairs in (("before", (3, 0)), ("after", (0, 0))):
        folder = tmp_path / side
        for name, n, its in (("normal", pairs[1], 20), ("W21_H27", pairs[0], 300)):
            case = folder / "cases" / name
            case.mkdir(parents=True)
            (case / "result.json").write_text(json.dumps({
                "intersecting_pairs": n, "newton_iterations": its + (side == "after"),
                "rejected_newton_iterations": 5, "wall_time_s": 1.5,
                "min_coaptation_height_mm": 2.5, "competent": n == 0, "converged": True}))
        runs[side] = module.read_study(folder)
    rows = module.compare(runs["before"], runs["after"])
    assert [r["case"] for r in rows] == ["normal", "W21_H27", "total"]
    assert rows[1]["intersecting_pairs_before"] == 3 and rows[1]["intersecting_pairs_after"] == 0
    assert rows[2]["newton_iterations_before"] == 320
    assert rows[2]["newton_iterations_after"] == 322
    assert rows[2]["competent_before"] == 1 and rows[2]["competent_after"] == 2
    assert rows[2]["wall_time_s_after"] == pytest.approx(3.0)


def test_the_answer_stability_table_gives_the_share_and_leaves_one_path_blank(tmp_path):
    """A share of 0.82 reads 82 %; a study of one path has no resamples: its cells are –."""
    text = _drawn(bench("answer_stability").TABLE, [
        {"study": "two paths", "members": 3, "paths": 2, "graft_cases": 37,
         "answer": "W10/H19", "tolerance_mm": 0.28, "resamples": 50, "within_3_points": 0.82,
         "no_graft": 8, "resample_answers": "W11/H20 ×22, none ×8"},
        {"study": "one path", "members": 1, "paths": 1, "graft_cases": 21,
         "answer": "W10/H13", "tolerance_mm": 0.28}], tmp_path)
    two, one = markdown_rows(text)
    assert two[8:10] == ["82%", "8"] and one[7:10] == ["–", "–", "–"]


def test_path_agreement_pairs_the_paths_of_each_grid_cell(tmp_path):
    """Four cells (two grid sizes at two root diameters) and a confirmation size off the
    grid: differences 0.1 and 0.5 mm, one cell unconverged on path 2, one sealed on path 1
    only; the normal valve and the confirmation are left out.  The cells are paired by the
    table's axis and path columns, not by the case names."""
    import json

    root = "root.loaded_diameter_mm"
    (tmp_path / "study.json").write_text(json.dumps(
        {"settings": {"widths_pct": [0.0, 14.0], "heights_pct": [0.0, 27.0],
                      "vary": {}, "uncertain": {root: [19.0, 21.0]}}}))
    fields = ["case", "graft_width_pct", "graft_height_pct", "converged", "competent",
              "min_coaptation_height_mm", root, "path"]
    rows = [("normal", "", "", "true", "true", "2.9", "[19.0, 21.0]", "[1, 2]"),
            ("a", "0", "0", "true", "true", "1.0", "19.0", "1"),
            ("b", "0", "0", "true", "true", "1.1", "19.0", "2"),
            ("c", "0", "0", "true", "true", "2.0", "21.0", "1"),
            ("d", "0", "0", "true", "false", "1.5", "21.0", "2"),
            ("e", "14", "27", "true", "true", "2.0", "19.0", "1"),
            ("f", "14", "27", "false", "false", "0.4", "19.0", "2"),
            ("g", "14", "27", "true", "true", "2.5", "21.0", "1"),
            ("h", "10", "13", "true", "true", "9.0", "21.0", "1"),
            ("i", "10", "13", "true", "true", "0.0", "21.0", "2")]
    with open(tmp_path / "results.csv", "w") as fh:
        fh.write(",".join(fields) + "\n"
                 + "".join(",".join(f'"{v}"' for v in r) + "\n" for r in rows))
    row = bench("path_agreement").agreement_row(tmp_path)
    assert row["cells"] == 3 and row["both_converged"] == 2 and row["within"] == 1
    assert row["median_mm"] == pytest.approx(0.3)
    assert row["largest_mm"] == pytest.approx(0.5) and row["largest_cell"] == "c"
    assert row["not_converged"] == "e" and row["sealed_on_one_path"] == "c"
