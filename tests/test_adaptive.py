"""The adaptive design of a study (valve_dolfinx.sizing.design, valve_dolfinx.study.rounds)
on stand-in cases: a known smooth truth with a deterministic scatter of known size.

The truth, over the graft's width and height enlargements W, H (per cent), the loaded root
diameter D (mm) and the numerical path p::

    normal valve    t(D)          = 3.0 − 0.5 (D − 21)
    graft           g(W, H, D, p) = t(D) + m(W, H) − 0.15 (D − 21) − 0.05 (p − 1) + e
    m(W, H)       = −1.6 + 1.4 (1 − exp(−W / 10)) + 1.0 (1 − exp(−H / 15))

with ``e`` uniform in ±0.1 mm, a fixed function of the case (:func:`scatter`); W0 grafts
leak.  The worst case over D ∈ {20, 21, 22} is at 22 mm, with margin
``m(W, H) − 0.15 − 0.025`` (paths averaged).
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import pytest
from test_study import cli_with, stable_csv

from valve_dolfinx._compat import MPI

DIAMETERS = [20.0, 21.0, 22.0]


def true_margin(w: float, h: float) -> float:
    """The noise-free worst-case margin over the diameters, paths averaged (mm)."""
    m = -1.6 + 1.4 * (1 - math.exp(-w / 10)) + 1.0 * (1 - math.exp(-h / 15))
    return m - 0.15 * (22 - 21) - 0.05 * 0.5


def scatter(w: float, h: float, d: float, path: int) -> float:
    """A deterministic draw, uniform in ±0.1 mm, of the case (W, H, D, path)."""
    digest = hashlib.sha256(f"{w:g}/{h:g}/{d:g}/{path}".encode()).digest()
    return 0.2 * (int.from_bytes(digest[:8], "big") / 2**64 - 0.5)


def _path(config) -> int:
    return 1 if config.geometry.graft_placement == "conformal" else 2


def truth_case(config, out_dir: Path, comm, *, start: Path | None = None) -> dict:
    """A result of the closed-form truth (module docstring)."""
    g = config.geometry
    d = config.root.loaded_diameter
    height = 3.0 - 0.5 * (d - 21)
    w, h = g.graft_width_pct, g.graft_height_pct
    if g.has_graft:
        p = _path(config)
        m = -1.6 + 1.4 * (1 - math.exp(-w / 10)) + 1.0 * (1 - math.exp(-h / 15))
        height += m - 0.15 * (d - 21) - 0.05 * (p - 1) + scatter(w, h, d, p)
    leaks = g.has_graft and w == 0.0
    log = Path(out_dir).parents[2] / "runs.log"
    if comm.rank == 0:
        with open(log, "a") as fh:
            fh.write(f"{Path(out_dir).name.split('@')[0]}\n")
    return {"graft_width_pct": w, "graft_height_pct": g.graft_height_pct, "converged": True,
            "min_coaptation_height_mm": height, "competent": not leaks,
            "regurgitant_orifice_area_mm2": 0.5 if leaks else 0.0, "intersecting_pairs": 0,
            "mesh_size_mm": g.mesh_size, "root_diameter_mm": d, "n_ranks": comm.size,
            "parameters": config.to_dict()}


@pytest.fixture(autouse=True)
def two_paths(monkeypatch):
    """Paths the stand-in tells apart by the graft's placement, none with a start."""
    from valve_dolfinx.study import paths

    defined = (paths.StudyPath(1, "conformal", "the graft conformal", {}),
               paths.StudyPath(2, "billowed", "the graft billowed",
                               {"graft.placement": "billowed",
                                "graft.billow_mm": 2.0}))
    monkeypatch.setattr(paths, "PATHS", defined)
    return defined


def settings(**kw):
    from valve_dolfinx.study.grid import StudySettings

    kw.setdefault("mesh_size_mm", 2.0)
    kw.setdefault("panel_cases", ())
    kw.setdefault("uncertain", {"root.loaded_diameter_mm": DIAMETERS})
    kw.setdefault("paths", 2)
    return StudySettings(**kw)


def runs(out: Path) -> list[str]:
    log = out / "runs.log"
    return log.read_text().split() if log.exists() else []


def test_the_initial_design_is_a_latin_square_with_replicated_diagonal():
    """3 diameters × 2 paths over W 0–27, H 0–40: a 3 × 3 lattice (0, 14, 27) × (0, 20, 40),
    each size once along path 1, every diameter seeing each width level and each height
    level exactly once; the diagonal once more along path 2, one size per diameter."""
    from valve_dolfinx.sizing.design import initial_design

    design = initial_design((0.0, 27.0), (0.0, 40.0), n_uncertain=3, n_paths=2)
    first = [(m, s) for m, s in design if m % 2 == 0]
    second = [(m, s) for m, s in design if m % 2 == 1]
    assert sorted(tuple(s) for _, s in first) == [(w, h) for w in (0.0, 14.0, 27.0)
                                                  for h in (0.0, 20.0, 40.0)]
    for u in range(3):
        mine = [s for m, s in first if m // 2 == u]
        assert sorted(s.width_pct for s in mine) == [0.0, 14.0, 27.0]
        assert sorted(s.height_pct for s in mine) == [0.0, 20.0, 40.0]
    assert sorted((m // 2, tuple(s)) for m, s in second) == sorted(
        (m // 2, tuple(s)) for m, s in first if s.width_pct == {0: 0.0, 20: 14.0, 40: 27.0}[
            s.height_pct])
    assert len({m // 2 for m, _ in second}) == 3


def test_a_round_spreads_its_sizes():
    """Candidates the likeliest first: a round takes at most 4, none within 0.2 of the
    scaled range of one taken before (W over 27 %, H over 40 %)."""
    from valve_dolfinx.sizing.cells import GraftSize
    from valve_dolfinx.sizing.design import Candidate, next_points

    sizes = [(10, 10), (11, 11), (10, 20), (20, 10), (12, 30), (25, 35), (26, 36)]
    candidates = [Candidate(GraftSize(*s), 0.5 - 0.01 * k, 0.1, "", 0)
                  for k, s in enumerate(sizes)]
    chosen = [tuple(c.size) for c in next_points(candidates, ((0, 27), (0, 40)))]
    # (11, 11) is 0.045 from (10, 10); (26, 36) 0.042 from (25, 35); (12, 30) is the 4th
    assert chosen == [(10, 10), (10, 20), (20, 10), (12, 30)]


def adaptive_sweep(out: Path, comm=None, **kw):
    from valve_dolfinx.study.runner import run_study

    return run_study(settings(design="adaptive", **kw), out, comm or MPI.COMM_SELF,
                     case_function=truth_case, poll_s=0.05)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The adaptive study of the truth, swept serially once for the module."""
    from valve_dolfinx.study import paths

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(paths, "PATHS", (
            paths.StudyPath(1, "conformal", "the graft conformal", {}),
            paths.StudyPath(2, "billowed", "the graft billowed",
                            {"graft.placement": "billowed", "graft.billow_mm": 2.0})))
        out = tmp_path_factory.mktemp("adaptive") / "serial"
        outcome = adaptive_sweep(out)
    return out, outcome


def smallest_adequate(tolerance: float) -> tuple[float, float]:
    """The true smallest flat area whose noise-free worst-case margin reaches −tolerance on
    the 1 % lattice (W > 0: W0 leaks), worked out from :func:`true_margin` alone."""
    sizes = [(w, h) for w in range(1, 28) for h in range(0, 41)
             if true_margin(w, h) >= -tolerance]
    return min(sizes, key=lambda s: ((1 + s[0] / 100) * (1 + s[1] / 100), s))


def area(size) -> float:
    return (1 + size[0] / 100) * (1 + size[1] / 100)


def test_the_adaptive_design_reaches_the_full_grid_answer_with_under_half_the_cases(
        tmp_path, reference):
    """Over 3 diameters × 2 paths, the full grid solves 20 grafts in every member (120
    graft cases and the confirmation); the adaptive design settles on fewer than half.  Its
    answer is the full grid's within the resolution: each one's predicted worst case on the
    other's surface is within twice the tolerance of the target, and both lie on the
    truth's boundary: their noise-free worst-case margin reaches the target within the
    tolerance, with a flat area within 3 % of the true smallest adequate size's, and the
    two answers' within 2 % of each other (the boundary is nearly a line of equal area, so
    W and H alone may differ)."""
    from valve_dolfinx.sizing.design import EXPECTED_SAVING, INITIAL_LEVELS
    from valve_dolfinx.study.runner import run_study

    out, outcome = reference
    grid = run_study(settings(), tmp_path / "grid", MPI.COMM_SELF, case_function=truth_case)
    adaptive, full = outcome.report, grid.report
    plan = adaptive.next_round
    assert plan.stop == "settled" and not plan.points
    assert "settled: the answer" in plan.text and "settled" in (out / "report.md").read_text()
    assert full.layout.graft_cases >= 120
    assert adaptive.layout.graft_cases <= full.layout.graft_cases / 2
    # round 0: the 3 × 3 Latin square, its diagonal also along path 2
    initial = [c for c in adaptive.layout.cases if c.round == 0 and not c.is_normal]
    assert len(initial) == INITIAL_LEVELS**2 + INITIAL_LEVELS
    answers = [r.recommendations[0].answer for r in (adaptive, full)]
    for mine, other in ((answers[0], answers[1]), (answers[1], answers[0])):
        lattice = other.lattice
        i = list(lattice.heights_pct).index(mine.size.height_pct)
        j = list(lattice.widths_pct).index(mine.size.width_pct)
        assert lattice.worst_margin_mm[i, j] >= -2 * other.tolerance_mm, (mine, other)
        tolerance = mine.tolerance_mm
        assert 0.05 < tolerance < 0.1  # the scatter: uniform ±0.1 mm, sd 0.058 mm
        assert true_margin(*mine.size) >= -tolerance - 0.02
        # the design stops when no smaller size's expected saving reaches EXPECTED_SAVING
        # (1 %): it may leave a few per cent of flat area on a boundary it is unsure of
        assert area(mine.size) == pytest.approx(area(smallest_adequate(tolerance)),
                                                rel=3 * EXPECTED_SAVING)
    assert area(answers[0].size) == pytest.approx(area(answers[1].size), rel=0.02)
    # the last round is the cut round: sizes a 0.5 mm cut off the answer makes, each in
    # one member (the one where its interpolated sealing was least)
    last = adaptive.layout.rounds[-1]
    assert last and all(p.member is not None for p in last)
    assert {f"W{p.size[0]:g}/H{p.size[1]:g}" for p in last} <= set(answers[0].trim["sizes"])
    # the answer is solved in every member, and its confirmation held
    rec = adaptive.recommendations[0]
    assert rec.confirm == [] and rec.confirmations[-1]["holds"]
    assert rec.confirmations[-1]["graft"] == answers[0].size.label


def test_job_array_rounds_equal_one_sweep(tmp_path, reference, capsys, quiet_cli):
    """A job array: each task runs one case of the listed round (`--case-index`), `report`
    writes the next round (exit status 10) until the design stops (0): the same cases,
    rounds and results as one serial sweep."""
    serial, _ = reference
    out = tmp_path / "array"
    args = ["--adaptive", "--uncertain", "root.loaded_diameter_mm=20,21,22", "--paths", "2",
            "--mesh-size", "2", "--no-progress", "--out", str(out)]
    main = lambda argv: cli_with(truth_case, argv)  # noqa: E731
    for _ in range(10):
        capsys.readouterr()
        assert main(["sweep", *args, "--list"]) == 0
        listing = capsys.readouterr().out.splitlines()[1:]
        for line in listing:
            if line.split()[-1] != "finished":
                assert main(["sweep", *args, "--case-index", line.split()[0]]) == 0
        status = main(["report", str(out)])
        if status == 0:
            break
        assert status == 10
    assert status == 0
    assert json.loads((out / "rounds.json").read_text()) == json.loads(
        (serial / "rounds.json").read_text())
    assert sorted(runs(out)) == sorted(runs(serial))  # every case once
    assert stable_csv(out / "results.csv") == stable_csv(serial / "results.csv")


def test_the_budget_stops_the_design_saying_what_is_not_settled(tmp_path):
    """With a budget of 15 graft cases, round 0 (12 cases) leaves no room for the answer's
    confirmation in 6 members: the design stops, and says so and what is open."""
    outcome = adaptive_sweep(tmp_path / "budget", budget=15)
    plan = outcome.report.next_round
    assert outcome.report.layout.graft_cases == 12
    assert plan.stop == "budget" and not plan.points
    rec = outcome.report.recommendations[0]
    assert rec.answer.size is not None and len(rec.confirm) >= 5
    assert "stopped at the case budget, not settled" in plan.text
    assert f"{rec.answer.size.label} is not solved in {len(rec.confirm)} of its 6 members" \
        in plan.text
    # its confirmations are bounded by the budget, not by a grid's rounds of confirmation
    assert rec.next_confirmation == rec.answer.size
    assert "the adaptive design solves it there next" in rec.text
    assert "rounds of confirmation are spent" not in rec.text
    summary = json.loads((tmp_path / "budget" / "summary.json").read_text())
    assert summary["design"]["stop"] == "budget" and summary["design"]["budget"] == 15


def test_an_interrupted_design_resumes_to_the_same_answer(tmp_path, reference):
    """Interrupted within round 0 and again within round 1 (after the rounds file holds
    it), each rerun resumes: the same rounds, cases and answer as the uninterrupted
    sweep, no case recorded for the interrupted ones."""
    from valve_dolfinx.exceptions import Interrupted
    from valve_dolfinx.study.runner import run_study

    serial, reference_outcome = reference
    out = tmp_path / "resumed"
    calls = {"n": 0}

    def interrupted_at(n):
        def case(config, out_dir, comm, *, start=None):
            calls["n"] += 1
            if calls["n"] == n:
                raise Interrupted(2)
            return truth_case(config, out_dir, comm, start=start)
        return case

    study = settings(design="adaptive")
    with pytest.raises(Interrupted):
        run_study(study, out, MPI.COMM_SELF, case_function=interrupted_at(6))
    assert not (out / "rounds.json").exists()
    calls["n"] = 0
    with pytest.raises(Interrupted):  # round 0's 10 remaining cases, then into round 1
        run_study(study, out, MPI.COMM_SELF, case_function=interrupted_at(12))
    assert len(json.loads((out / "rounds.json").read_text())["rounds"]) == 1
    outcome = run_study(study, out, MPI.COMM_SELF, case_function=truth_case)
    assert (json.loads((out / "rounds.json").read_text())
            == json.loads((serial / "rounds.json").read_text()))
    assert stable_csv(out / "results.csv") == stable_csv(serial / "results.csv")
    mine, theirs = (o.report.recommendations[0].answer for o in (outcome, reference_outcome))
    assert mine.size == theirs.size and mine.margin_mm == pytest.approx(theirs.margin_mm)


@pytest.mark.mpi
def test_mpi_rounds_equal_the_serial_rounds(tmp_path_factory, parallel_world):
    """Under mpirun -n 2 the ranks share each round's cases: the same rounds, cases and
    answer as a serial sweep."""
    comm = parallel_world
    root = Path(comm.bcast(str(tmp_path_factory.mktemp("rounds")) if comm.rank == 0 else None))
    outcome = adaptive_sweep(root / "world", comm)
    if comm.rank == 0:
        serial = adaptive_sweep(root / "serial")
        assert sorted(runs(root / "world")) == sorted(runs(root / "serial"))
        assert (json.loads((root / "world" / "rounds.json").read_text())
                == json.loads((root / "serial" / "rounds.json").read_text()))
        assert (stable_csv(root / "world" / "results.csv")
                == stable_csv(root / "serial" / "results.csv"))
        assert (outcome.report.recommendations[0].answer.size
                == serial.report.recommendations[0].answer.size)
    comm.barrier()
