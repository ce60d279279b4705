"""The sizing answer (valve_dolfinx.sizing): surfaces, resolution and the answer read from them.

Synthetic studies without solving: a known smooth truth of the minimum coaptation height
over the graft size (and the root diameter), solved along two "paths" that add independent
noise of known size; the target is the normal valve's height.  Every fit is small (tens of
cases) so that the file runs in well under a minute.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from valve_dolfinx.sizing import (
    GraftSize,
    MemberTable,
    bootstrap_stability,
    fit_study,
    read_answer,
    sizes_to_confirm,
)
from valve_dolfinx.sizing.resolution import discretisation_error_mm, path_scatter_mm
from valve_dolfinx.sizing.surface import SurfacePoint, fit_sealing

WIDTHS = (0.0, 7.0, 14.0, 21.0, 27.0)
HEIGHTS = (0.0, 13.0, 27.0, 40.0)
NOISE_MM = 0.08
TARGET_MM = 3.0


def truth(w, h, d=20.0):
    """A smooth coaptation height (mm) that needs both width and height (a smoothed minimum of
    two saturating gains, so that the smallest adequate flat area is one sharp size) and
    falls with the root diameter."""
    gain_w = 1 - np.exp(-np.asarray(w, dtype=float) / 8)
    gain_h = 1 - np.exp(-np.asarray(h, dtype=float) / 12)
    both = -np.log(np.exp(-30 * gain_w) + np.exp(-30 * gain_h)) / 30
    return 1.3 + 2.4 * both - 0.4 * (d - 20.0)


def _rows(heights: dict, target: float, leaks=lambda w, h: False) -> list[dict]:
    rows = [{"graft_width_pct": None, "graft_height_pct": None, "converged": True,
             "competent": True, "min_coaptation_height_mm": target, "mesh_size_mm": 0.8}]
    for (w, h), y in heights.items():
        rows.append({"graft_width_pct": w, "graft_height_pct": h, "converged": True,
                     "competent": not leaks(w, h), "min_coaptation_height_mm": float(y),
                     "mesh_size_mm": 0.8})
    return rows


def study(seed: int = 0, shift: float = 0.0, diameters=(None,), leaks=lambda w, h: False,
          noise: float = NOISE_MM) -> list[MemberTable]:
    """Two paths per uncertainty member; the truth shifted by ``shift`` mm."""
    rng = np.random.default_rng(seed)
    tables = []
    for d in diameters:
        uncertain = () if d is None else (("root.loaded_diameter_mm", d),)
        for path in (1, 2):
            heights = {(w, h): truth(w, h, d or 20.0) + shift + rng.normal(0, noise)
                       for w in WIDTHS for h in HEIGHTS}
            label = ", ".join(p for p in (f"D={d:g}" if d else "", f"path {path}") if p)
            tables.append(MemberTable(label, _rows(heights, TARGET_MM, leaks),
                                      uncertain=uncertain, path=path))
    return tables


def true_answer(tolerance: float, shift: float = 0.0, diameters=(None,),
                leaks=lambda w, h: False) -> GraftSize | None:
    """The rule applied to the truth itself on the same 1 % lattice."""
    best = None
    for w in range(0, 28):
        for h in range(0, 41):
            worst = min(truth(w, h, d or 20.0) + shift for d in diameters) - TARGET_MM
            if worst >= -tolerance and not leaks(w, h):
                size = GraftSize(float(w), float(h))
                if best is None or (size.area_ratio, *size) < (best.area_ratio, *best):
                    best = size
    return best


def test_surface_recovers_the_truth_within_its_stated_uncertainty():
    tables = study(seed=1)
    fit = fit_study(tables, ladder=None)
    assert fit.surface is not None and fit.surface.n_cases == 40 and fit.surface.n_cells == 20
    # the noise term finds the paths' noise; held-out cells are predicted worse than the
    # noise (the gaps between grid cells are part of the error) but far better than by the
    # mean of the heights
    assert 0.5 * NOISE_MM < fit.surface.noise_mm < 2.0 * NOISE_MM
    heights = [r["min_coaptation_height_mm"] for t in tables for r in t.rows[1:]]
    assert fit.surface.noise_mm < fit.surface.cv_rmse_mm < 0.5 * np.std(heights)
    # the pooled scatter between the two paths estimates the same noise
    assert 0.5 * NOISE_MM < fit.resolution.path_scatter_mm < 1.6 * NOISE_MM
    # the truth lies in the surface's 95 % band (2 sd of the smooth surface) at about 95 %
    # of a lattice between the solved cells, pooled over four noisy studies (the misses are
    # near W 0-7 %, where the truth turns faster than the grid samples)
    from valve_dolfinx.sizing.surface import SurfacePoint

    w, h = np.meshgrid(np.arange(0, 28, 3.0), np.arange(0, 41, 4.0))
    points = [SurfacePoint(a, b) for a, b in zip(w.ravel(), h.ravel(), strict=True)]
    within_2, within_3 = [], []
    for seed in range(4):
        surface = fit_study(study(seed=seed), ladder=None, cv_folds=0).surface
        mean, sd = surface.predict(points)
        error = np.abs(mean - truth(w.ravel(), h.ravel()))
        within_2 += list(error <= 2 * sd)
        within_3 += list(error <= 3 * sd)
    assert np.mean(within_2) >= 0.9 and np.mean(within_3) >= 0.95


def test_recommended_size_is_within_two_points_of_the_true_smallest_adequate_size():
    tables = study(seed=2, leaks=lambda w, h: h == 0 and w >= 14)
    fit = fit_study(tables, ladder=None)
    answer = read_answer(fit, tables)
    tolerance = answer.tolerance_mm
    assert tolerance == pytest.approx(max(fit.resolution.path_scatter_mm,
                                          fit.surface.noise_mm))
    expected = true_answer(tolerance, leaks=lambda w, h: h == 0 and w >= 14)
    assert answer.size is not None and answer.why == ""
    assert abs(answer.size.width_pct - expected.width_pct) <= 2
    assert abs(answer.size.height_pct - expected.height_pct) <= 2
    assert answer.margin_mm >= -tolerance and answer.seal_probability >= 0.9
    # the graft in mm: the default outline's free edge 20π/3 mm and height 12.41 mm, scaled
    assert answer.free_edge_mm == pytest.approx(20 * math.pi / 3 * (1 + answer.size[0] / 100))
    assert answer.height_mm == pytest.approx(12.41 * (1 + answer.size[1] / 100), abs=0.01)
    # cut 0.5 mm off: 2 % of the 20.9 mm free edge, 4 % of the 12.41 mm height; the size cut
    # short in both has a smaller flat area than the smallest qualifying one, so fails
    trim = answer.trim
    assert (trim["width_pct"], trim["height_pct"]) == (
        round(0.5 / (20 * math.pi / 300)), round(0.5 / 0.1241))
    w, h = answer.size
    assert GraftSize(w - 2, h - 4).label in trim["failing"] and not trim["robust"]
    band = answer.band
    assert band["sizes"] > 1 and band["area_ratio"][0] == pytest.approx(answer.size.area_ratio)
    assert answer.highest.width_pct >= 21 and answer.highest.height_pct >= 27
    for text in (f"**{answer.size.label}**", f"within the resolution of {tolerance:.2f} mm",
                 "cross-validated error", "discretisation error not measured"):
        assert text in answer.text
    # it is off the grid: the confirmations are that size in every member
    confirm = sizes_to_confirm(answer, tables)
    assert [t.label for _, t in confirm] == ["path 1", "path 2"]
    assert {s for s, _ in confirm} == {answer.size}


def test_bootstrap_of_the_paths_barely_moves_the_recommendation():
    """Resampling each cell's two paths with replacement moves the answer by at most 3
    points in W and H in at least 90 % of 20 resamples."""
    from valve_dolfinx.sizing.answer import resample_paths

    tables = study(seed=3, diameters=(19.5, 20.5))
    reference = read_answer(fit_study(tables, ladder=None), tables)
    assert reference.size is not None
    # a resample keeps each cell's cases among its own paths' and the normal valves
    drawn = resample_paths(tables, np.random.default_rng(1))
    for table, original in zip(drawn, tables, strict=True):
        assert table.rows[0] is original.rows[0] and len(table.rows) == len(original.rows)
        pool = {id(r) for t in tables if t.uncertain == table.uncertain for r in t.rows}
        assert all(id(r) in pool for r in table.rows)
    share, sizes = bootstrap_stability(tables, reference, resamples=20, seed=7)
    assert len(sizes) == 20 and share >= 0.9, sizes


def test_a_shortfall_within_the_resolution_gets_the_graft_with_its_shortfall():
    """The truth tops out 0.03 mm (less than the resolution) below the target: a graft,
    with its shortfall shown."""
    top = float(truth(27, 40)) - TARGET_MM
    tables = study(seed=4, shift=-top - 0.03)
    fit = fit_study(tables, ladder=None)
    answer = read_answer(fit, tables)
    assert answer.tolerance_mm > 0.03
    assert answer.size is not None and answer.margin_mm < 0
    assert -answer.margin_mm <= answer.tolerance_mm
    assert f"{-answer.margin_mm:.2f} mm short of the target" in answer.text
    assert "within the resolution" in answer.text


def test_a_shortfall_of_several_resolutions_is_no_graft():
    top = float(truth(27, 40)) - TARGET_MM
    tables = study(seed=5, shift=-top - 0.6)
    answer = read_answer(fit_study(tables, ladder=None), tables)
    assert answer.size is None and answer.why == "short"
    assert answer.shortfall_mm == pytest.approx(0.6, abs=0.2)
    assert answer.shortfall_mm > 3 * answer.tolerance_mm
    assert answer.text.startswith("No graft:")
    assert f"times the resolution of {answer.tolerance_mm:.2f} mm" in answer.text
    assert answer.highest.width_pct >= 20 and answer.highest.height_pct >= 30
    assert sizes_to_confirm(answer, tables) == []


def test_a_held_confirmation_stays_the_answer_within_three_points_though_off_the_band():
    """A size whose confirmation held (``prefer``) is the answer while it lies within
    SAME_SIZE_PCT of the smallest qualifying size, even where the surface puts it beyond
    the tolerance: its solves passed the confirmation's own test.  A held size further
    away is not kept."""
    from valve_dolfinx.sizing.answer import SAME_SIZE_PCT

    tables = study(seed=8)
    fit = fit_study(tables, ladder=None)
    smallest = read_answer(fit, tables).size
    assert smallest is not None and smallest.width_pct >= 2 and smallest.height_pct >= 1
    # smaller in flat area than the smallest qualifying size: it does not qualify, and as
    # every size seals here, its predicted worst case is beyond the tolerance
    near = GraftSize(smallest.width_pct - 2, smallest.height_pct - 1)
    answer = read_answer(fit, tables, prefer=[near])
    assert answer.size == near and answer.smallest == smallest
    assert -answer.margin_mm > answer.tolerance_mm
    assert f"within {SAME_SIZE_PCT:g} points in width and height of {smallest.label}" \
        in answer.text
    assert "beyond the resolution" in answer.text and "passed the confirmation" in answer.text
    far = GraftSize(smallest.width_pct + SAME_SIZE_PCT + 1, smallest.height_pct)
    assert read_answer(fit, tables, prefer=[far]).size == smallest
    # a held size that still qualifies comes before one that does not, whatever the order
    qualifying = GraftSize(smallest.width_pct + 1, smallest.height_pct + 1)
    assert read_answer(fit, tables, prefer=[near, far, qualifying]).size == qualifying


def test_no_size_seals_is_no_graft():
    tables = study(seed=6, leaks=lambda w, h: True)
    answer = read_answer(fit_study(tables, ladder=None), tables)
    assert answer.size is None and answer.why == "none seals"
    # every case leaks: every cell's share of sealed cases is 0, and so is the interpolation
    assert "the highest is 0.00" in answer.text


def test_too_few_cells_give_no_surface():
    rows = _rows({(0.0, 0.0): 2.0, (7.0, 0.0): 2.9}, TARGET_MM)
    fit = fit_study([MemberTable("", rows)], ladder=None)
    answer = read_answer(fit, [MemberTable("", rows)])
    assert fit.surface is None and answer.why == "no surface" and answer.size is None
    assert "at least 6 solved cells" in answer.text


def test_path_scatter_and_the_mesh_ladder(tmp_path):
    scatter, cells = path_scatter_mm([[1.0, 1.2], [2.0, 2.0], [3.0], [4.0, 4.4]])
    # pooled: (0.02 + 0 + 0.08) / 3 degrees of freedom
    assert cells == 3 and scatter == pytest.approx(math.sqrt(0.1 / 3))
    assert path_scatter_mm([[1.0], [2.0]]) == (None, 0)
    ladder = tmp_path / "mesh_ladder.csv"
    ladder.write_text(
        "case,graft_width_pct,graft_height_pct,mesh_size_mm,converged,competent,"
        "min_coaptation_height_mm\n"
        "normal,,,0.8,true,true,2.91\nnormal,,,0.6,true,true,2.83\nnormal,,,0.45,true,true,2.85\n"
        "W14_H13,14,13,0.8,true,true,2.90\nW14_H13,14,13,0.45,true,true,2.40\n"
        "W21_H13,21,13,0.8,true,true,2.20\nW21_H13,21,13,0.45,true,false,2.30\n")
    error, source = discretisation_error_mm(ladder, 0.8)
    # normal 0.06, W14/H13 0.50; W21/H13 is not sound at 0.45 mm
    assert error == pytest.approx(math.sqrt((0.06**2 + 0.5**2) / 2))
    assert "0.8 mm against 0.45 mm over 2 cases" in source
    assert discretisation_error_mm(ladder, 1.6)[0] is None
    assert "not measured at the 1.6 mm mesh" in discretisation_error_mm(ladder, 1.6)[1]
    tables = study(seed=1)
    fit = fit_study(tables, ladder=ladder)
    assert fit.resolution.discretisation_mm == pytest.approx(error)
    assert fit.resolution.tolerance_mm == pytest.approx(error)  # the largest of the three


def test_sizing_map_draws_the_answer(tmp_path):
    """The study's recommendation of a synthetic study drawn as the continuous sizing map
    (looked at by eye; here: it is written, with the answer's lattice behind it)."""
    from valve_dolfinx.plotting.study import plot_sizing_map
    from valve_dolfinx.sizing import recommend

    rec = recommend(study(seed=2, leaks=lambda w, h: h == 0 and w >= 14), n_paths=2,
                    ladder=None)
    assert rec.answer.lattice.worst_margin_mm.shape == (41, 28)
    fig = plot_sizing_map(rec, tmp_path / "sizing_map.png", title="synthetic")
    assert (tmp_path / "sizing_map.png").stat().st_size > 50_000
    labels = [t.get_text() for t in fig.axes[0].texts]
    assert f"answer {rec.answer.size.label}" in labels and len(rec.cells) == 20


def test_sizing_map_labels_stay_inside_the_axes_and_apart(tmp_path):
    """Drawn at a plan page's print size, with a solved cell 1 % above a grid cell (as a
    confirmation lands): every label (the answer, the highest size, each cell's height) lies
    inside the axes and no two overlap; the map carries no title (the page prints its
    key)."""
    from matplotlib.text import Annotation, Text

    from valve_dolfinx.plotting.study import MIN_PRINT_PT, plot_sizing_map
    from valve_dolfinx.sizing import recommend

    tables = study(seed=2)
    for table in tables:  # a cell at W14/H14, beside the grid's W14/H13
        table.rows.append({"graft_width_pct": 14.0, "graft_height_pct": 14.0,
                           "converged": True, "competent": True,
                           "min_coaptation_height_mm": float(truth(14.0, 14.0)),
                           "mesh_size_mm": 0.8})
    rec = recommend(tables, n_paths=2, ladder=None)
    assert rec.cell("W14/H14") is not None
    fig = plot_sizing_map(rec, tmp_path / "map.png", size_in=(91 / 25.4, 62 / 25.4),
                          caption=False)
    ax = fig.axes[0]
    assert ax.get_title() == ""
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    labels = [t for t in ax.texts if isinstance(t, Annotation)]
    assert len(labels) == len(rec.cells) + 2  # the cells' heights, the answer, the highest
    boxes = []
    for label in labels:
        label.update_positions(renderer)
        box = Text.get_window_extent(label, renderer)
        assert label.get_fontsize() >= MIN_PRINT_PT
        assert (frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0
                and box.y1 <= frame.y1), label.get_text()
        boxes.append((label.get_text(), box))
    for i, (a, box) in enumerate(boxes):
        for b, other in boxes[i + 1:]:
            assert not box.overlaps(other), (a, b)


def test_design_scales_the_inputs_root_first_and_choices_as_indicators():
    """W, H, then the root diameter before the other axes; a choice is one 0/1 input per
    value after its first; an input that takes one value is left out; all scaled to [0, 1]."""
    from valve_dolfinx.sizing.surface import Design, SurfacePoint

    def point(w, h, e, d, tension):
        return SurfacePoint(w, h, (("bending_modulus_kpa", e), ("root.loaded_diameter_mm", d),
                                   ("graft_tension_field", tension), ("nodulus_length_mm", 1.0)))

    points = [point(0.0, 0.0, 200.0, 20.0, True), point(27.0, 40.0, 800.0, 22.0, False),
              point(14.0, 13.0, 200.0, 21.0, True)]
    design = Design.of(points)
    assert design.columns == ("graft_width_pct", "graft_height_pct", "root.loaded_diameter_mm",
                              "bending_modulus_kpa", "graft_tension_field=False")
    x = design.matrix(points + [point(7.0, 20.0, 500.0, 21.5, False)])
    assert x.min() == 0.0 and x[:3].max() == 1.0
    assert x[2] == pytest.approx([14 / 27, 13 / 40, 0.5, 0.0, 0.0])
    assert x[3] == pytest.approx([7 / 27, 0.5, 0.75, 0.5, 1.0])


def test_sealing_is_read_from_the_solved_cells_not_smoothed():
    """Sealing is interpolated piecewise-linearly between the solved cells' shares of
    sealed cases: a solved cell gives its own share (two paths that disagree: 0.5), a size
    between sealed cells seals, and between a sealed and a leaking cell the probability
    falls linearly with the distance (halfway: 0.5); an isolated leaking cell does not
    spoil sealed cells two grid steps away, as a smooth classifier would."""
    widths, heights = (0.0, 10.0, 20.0, 30.0), (0.0, 20.0, 40.0)
    leaking = {(30.0, 40.0)}
    points, sealed = [], []
    for w in widths:
        for h in heights:
            points.append(SurfacePoint(w, h))
            sealed.append((w, h) not in leaking)
    points.append(SurfacePoint(0.0, 0.0))  # a second path of W0/H0 that leaks
    sealed.append(False)
    model = fit_sealing(points, sealed)
    p = model.probability([SurfacePoint(0.0, 0.0), SurfacePoint(10.0, 20.0),
                           SurfacePoint(15.0, 30.0), SurfacePoint(30.0, 30.0),
                           SurfacePoint(30.0, 40.0), SurfacePoint(10.0, 40.0)])
    np.testing.assert_allclose(p, [0.5, 1.0, 1.0, 0.5, 0.0, 1.0], atol=1e-12)
    assert model.summary()["cells"] == len(widths) * len(heights)


def test_a_confirmation_misses_beyond_the_tolerance_and_twice_a_solves_scatter():
    """A single solve scatters about the surface by the larger of the path scatter and the
    surface's noise: it misses only when short by more than the tolerance plus twice that
    (worked: 0.28 + 2 x 0.08 = 0.44 mm; with paths scattering 0.12 mm, 0.28 + 0.24)."""
    from valve_dolfinx.sizing.recommendation import miss_limit_mm
    from valve_dolfinx.sizing.resolution import Resolution

    assert miss_limit_mm(Resolution(None, 0, 0.08, 0.28, "ladder")) == pytest.approx(0.44)
    assert miss_limit_mm(Resolution(0.12, 6, 0.08, 0.28, "ladder")) == pytest.approx(0.52)
    assert miss_limit_mm(Resolution(None, 0, None, None, "none")) == 0.0


def _lattice_answer(size: GraftSize, qualifies, margin=lambda w, h: 0.1,
                    seal=lambda w, h: 1.0):
    """A SizingAnswer holding ``size`` on a hand-made 1 % lattice over W 0–27, H 0–40."""
    from valve_dolfinx.sizing.answer import Lattice, SizingAnswer
    from valve_dolfinx.sizing.resolution import Resolution

    widths, heights = np.arange(0.0, 28.0), np.arange(0.0, 41.0)
    ww, hh = np.meshgrid(widths, heights)
    answer = SizingAnswer({}, [""], {"": TARGET_MM}, "given",
                          Resolution(0.2, 2, None, None, "not measured"))
    answer.size = size
    answer.lattice = Lattice(widths, heights, np.vectorize(margin)(ww, hh),
                             np.vectorize(seal)(ww, hh), np.vectorize(qualifies)(ww, hh))
    return answer


def test_a_cut_half_a_millimetre_off_is_read_at_the_sizes_it_makes():
    """The trim check reads the eight sizes whose free edge and height are each 0.5 mm
    shorter, as cut, or longer (the default leaflet's own dimensions give the offsets),
    names the least margin and sealing among them, and is robust only when all qualify."""
    from valve_dolfinx.geometry.outline import LeafletShape
    from valve_dolfinx.sizing.answer import trim_check, trim_text

    leaflet, size = LeafletShape(), GraftSize(14.0, 26.0)
    trim = trim_check(_lattice_answer(size, lambda w, h: True), leaflet, 0.5)
    dw, dh = trim["width_pct"], trim["height_pct"]
    free_edge = LeafletShape(width_pct=14.0, height_pct=26.0).free_edge_length
    wider = LeafletShape(width_pct=14.0 + dw, height_pct=26.0).free_edge_length
    taller = LeafletShape(width_pct=14.0, height_pct=26.0 + dh).height
    height = LeafletShape(width_pct=14.0, height_pct=26.0).height
    step_w = wider - LeafletShape(width_pct=13.0 + dw, height_pct=26.0).free_edge_length
    step_h = taller - LeafletShape(width_pct=14.0, height_pct=25.0 + dh).height
    assert abs(wider - free_edge - 0.5) <= step_w / 2 + 1e-9
    assert abs(taller - height - 0.5) <= step_h / 2 + 1e-9
    assert len(trim["sizes"]) == 8 and trim["robust"]
    sound = _lattice_answer(size, lambda w, h: True)
    sound.trim = trim
    assert "all 8 such sizes still qualify" in trim_text(sound)

    def leaky(w, h):
        return not (w == 14 - dw and h == 26 - dh)

    answer = _lattice_answer(size, leaky, margin=lambda w, h: 0.01 * (w + h) - 0.5,
                             seal=lambda w, h: 0.3 if not leaky(w, h) else 1.0)
    trim = answer.trim = trim_check(answer, leaflet, 0.5)
    corner = GraftSize(14 - dw, 26 - dh).label
    assert not trim["robust"] and trim["failing"] == [corner]
    assert trim["seal_size"] == corner and trim["seal_probability"] == pytest.approx(0.3)
    assert trim["worst_margin_size"] == corner
    assert trim["worst_margin_mm"] == pytest.approx(0.01 * (40 - dw - dh) - 0.5)
    assert "1 of the 8 such sizes do not qualify" in trim_text(answer)
    assert "not robust to the cut" in trim_text(answer)


def test_the_trim_check_keeps_to_the_studied_range():
    """At the corner of the range only the three sizes inside it are read."""
    from valve_dolfinx.geometry.outline import LeafletShape
    from valve_dolfinx.sizing.answer import trim_check

    trim = trim_check(_lattice_answer(GraftSize(0.0, 0.0), lambda w, h: True), LeafletShape())
    assert len(trim["sizes"]) == 3
