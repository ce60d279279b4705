"""Figures: no global plotting state, every figure of a case written, the orifice drawn to scale.

The case figures are drawn once per session from a real closure at 1.6 mm of the
width-only graft W27/H0, which leaks at that mesh (17 mm²) and folds through its
neighbours: the drawn orifice is measured from the figures' own geometry (polygon areas
in mm²) and compared with the area the analysis reported; the intersections drawn are the
ones the result counts.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from valve_dolfinx._compat import MPI
from valve_dolfinx.plotting import CASE_FIGURES
from valve_dolfinx.plotting.orifice import ORIFICE_GID, orifice_rectangles, plot_orifice_map

ROOT = Path(__file__).resolve().parents[1]


def _shoelace(xy: np.ndarray) -> float:
    x, y = np.asarray(xy, float).T
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _drawn_orifice_area(fig) -> float:
    """Area (data units², mm²) of the orifice patches drawn on the first axes that has them."""
    for ax in fig.axes:
        for artist in ax.collections:
            if artist.get_gid() == ORIFICE_GID:
                return sum(_shoelace(path.vertices[:4]) for path in artist.get_paths())
    return 0.0


def test_importing_and_drawing_leave_global_plotting_state_alone(tmp_path):
    """In a fresh process with the pdf backend and PyVista on screen, importing every module
    of the package and drawing a 2-D and a 3-D figure change neither setting."""
    script = textwrap.dedent(f"""
        import importlib, pkgutil
        import matplotlib
        matplotlib.use("pdf")
        import pyvista
        pyvista.OFF_SCREEN = False
        import valve_dolfinx
        for info in pkgutil.walk_packages(valve_dolfinx.__path__, "valve_dolfinx."):
            importlib.import_module(info.name)
        assert matplotlib.get_backend() == "pdf", matplotlib.get_backend()
        assert pyvista.OFF_SCREEN is False
        from valve_dolfinx.geometry.valve import build_valve
        from valve_dolfinx.plotting import plot_cut_planes, plot_valve_3d
        valve = build_valve(mesh_size=2.0)
        plot_cut_planes(valve.points, valve, {str(tmp_path / "cuts.png")!r})
        plot_valve_3d(valve.points, valve, {str(tmp_path / "valve.png")!r}, view="aortic")
        assert matplotlib.get_backend() == "pdf", matplotlib.get_backend()
        assert pyvista.OFF_SCREEN is False
        print("unchanged")
    """)
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "unchanged" in proc.stdout
    for name in ("cuts.png", "valve.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name


def _synthetic_orifice(n: int = 200, pixel: float = 0.1) -> tuple[dict, float]:
    """A raster with a ring-shaped orifice, a slit and a single pixel; its exact area."""
    origin = -0.5 * n * pixel
    c = origin + (np.arange(n) + 0.5) * pixel
    x, y = np.meshgrid(c, c)
    r = np.hypot(x, y)
    in_disk = r <= 9.5
    open_ = (r > 3.0) & (r < 5.0)
    channel = (np.abs(y - 7.05) < 0.1 * pixel) & (np.abs(x) < 2.0)  # one row of 40 pixels
    channel[10, 100] = True
    cover = np.stack([in_disk & (x > 0) & ~open_, in_disk & (x <= 0) & ~open_, ~in_disk])
    area = float((open_ | channel).sum() * pixel**2)
    return {"open": open_, "channel": channel, "dead_end": np.zeros_like(open_),
            "in_disk": in_disk, "cover": cover, "origin_mm": origin, "pixel_mm": pixel,
            "radius_mm": 9.5}, area


def test_drawn_synthetic_orifice_has_its_area(tmp_path):
    from valve_dolfinx.geometry.valve import build_valve
    from valve_dolfinx.plotting.scene import orifice_surface

    diagnostics, area = _synthetic_orifice()
    rects = orifice_rectangles(diagnostics)
    assert sum(_shoelace(r) for r in rects) == pytest.approx(area, rel=1e-12)
    fig = plot_orifice_map(diagnostics, build_valve(mesh_size=2.0), tmp_path / "orifice.png")
    assert _drawn_orifice_area(fig) == pytest.approx(area, rel=1e-9)
    assert orifice_surface(diagnostics, -1.0).area == pytest.approx(area, rel=1e-9)
    # a ring between r = 3 and 5 mm: close to π (5² − 3²) on a 0.1 mm raster
    assert area == pytest.approx(np.pi * 16 + 0.4 + 0.01, rel=0.02)


def _yellow_pixels(image: np.ndarray) -> int:
    """Pixels of the intersection marks' hue (Okabe & Ito's yellow, 56°, lit or shaded; the
    orange leaflet's is 41°)."""
    from matplotlib.colors import rgb_to_hsv

    hsv = rgb_to_hsv(image[..., :3] / 255.0)
    return int(np.sum((np.abs(hsv[..., 0] * 360 - 56) < 6) & (hsv[..., 1] > 0.5)
                      & (hsv[..., 2] > 0.3)))


def test_an_intersection_is_marked_in_the_3d_view():
    """A point given as an intersection, on the left-coronary leaflet's belly, is drawn as a
    yellow ball over the leaflet, which has no yellow of its own."""
    from valve_dolfinx.geometry.valve import build_valve
    from valve_dolfinx.plotting import plot_valve_3d

    valve = build_valve(mesh_size=2.0)
    x = valve.points[valve.leaflets[0].nodes]
    middle = np.abs(x[:, 2] - x[:, 2].mean()) + np.abs(np.arctan2(x[:, 1], x[:, 0]))
    mark = x[[np.argmin(middle)]]
    plain = plot_valve_3d(valve.points, valve, view="side")
    marked = plot_valve_3d(valve.points, valve, view="side", intersections=mark)
    assert _yellow_pixels(plain) == 0
    assert _yellow_pixels(marked) > 100  # a ball 0.6 mm across, half of it in the leaflet


@pytest.fixture(scope="module")
def leaking_case(tmp_path_factory):
    """W27/H0 closed at 1.6 mm through run_case, its figures written; what they were drawn
    from is recorded on the way.  The contact's guard is switched off here (a guard that
    never pushes and lets every step through), so that the graft folds through its
    neighbours as under the contact law alone and the figures have intersections to mark."""
    import valve_dolfinx.case
    from valve_dolfinx import CaseConfig, plotting, run_case
    from valve_dolfinx.contact.guard import SurfaceGuard
    from valve_dolfinx.geometry.valve import ValveParameters

    class NoGuard(SurfaceGuard):
        def gradient(self, x):
            return None

        def hessian_blocks(self, x, rows):
            empty = np.empty(0, dtype=np.int64)
            return empty, empty, np.empty((0, 3, 3))

        def free_fraction(self, x0, x1):
            return 1.0

    out = tmp_path_factory.mktemp("W27_H0")
    drawn = {}
    real = plotting.write_case_figures

    def record(out_dir, positions, valve, coaptation, result, **kwargs):
        drawn.update(positions=positions, valve=valve, coaptation=coaptation,
                     intersections=kwargs.get("intersections"))
        return real(out_dir, positions, valve, coaptation, result, **kwargs)

    config = CaseConfig(geometry=ValveParameters(mesh_size=1.6)).with_graft(27.0, 0.0)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(plotting, "write_case_figures", record)
        patch.setattr(valve_dolfinx.case, "SurfaceGuard", NoGuard)
        result = run_case(config, out, comm=MPI.COMM_SELF, fields_output=False)
    return out, result, drawn


@pytest.mark.slow
def test_every_case_figure_is_written(leaking_case):
    out, result, _ = leaking_case
    assert result.converged and result.regurgitant_orifice_area_mm2 > 1.0  # it leaks
    for name in CASE_FIGURES:
        assert (out / name).stat().st_size > 20_000, name
    assert json.loads((out / "result.json").read_text())["graft_width_pct"] == 27.0


@pytest.mark.slow
def test_case_figures_mark_every_intersection(leaking_case):
    """The graft folds through its neighbours at 1.6 mm: the 3-D views are given every
    intersecting pair the result counts, where the check finds them."""
    from valve_dolfinx.analysis.intersection import valve_intersections

    _, result, drawn = leaking_case
    assert result.intersecting_pairs > 0
    assert len(drawn["intersections"]) == result.intersecting_pairs
    found = valve_intersections(drawn["positions"], drawn["valve"])
    # the same points (the library's broad phase may list the pairs in another order)
    assert np.array_equal(np.unique(drawn["intersections"], axis=0),
                          np.unique(found.points, axis=0))


@pytest.mark.slow
def test_aortic_and_ventricular_views_differ(leaking_case):
    import matplotlib.image

    out, _, _ = leaking_case
    aortic = matplotlib.image.imread(out / "closed_valve_aortic.png")
    ventricular = matplotlib.image.imread(out / "closed_valve_ventricular.png")
    assert aortic.shape == ventricular.shape
    assert np.abs(aortic - ventricular).mean() > 0.02


@pytest.mark.slow
def test_drawn_orifice_matches_the_reported_area(leaking_case):
    """The orifice drawn on the orifice map, on the horizontal sections and in the
    ventricular view has the area result.json reports, within 10 %."""
    from valve_dolfinx.plotting import plot_cross_sections
    from valve_dolfinx.plotting.scene import orifice_surface

    out, result, drawn = leaking_case
    reported = json.loads((out / "result.json").read_text())["regurgitant_orifice_area_mm2"]
    assert reported == pytest.approx(result.regurgitant_orifice_area_mm2)
    diagnostics = drawn["coaptation"].orifice
    fig = plot_orifice_map(diagnostics, drawn["valve"])
    assert _drawn_orifice_area(fig) == pytest.approx(reported, rel=0.1)
    sections = plot_cross_sections(drawn["positions"], drawn["valve"], orifice=diagnostics)
    assert _drawn_orifice_area(sections) == pytest.approx(reported, rel=0.1)
    z = drawn["positions"][:, 2].min() - 0.5
    assert orifice_surface(diagnostics, z).area == pytest.approx(reported, rel=0.1)
    # drawn inside the orifice disk, where the graft meets its neighbours (below y = 0.5 mm)
    corners = orifice_rectangles(diagnostics).reshape(-1, 2)
    assert np.hypot(*corners.T).max() <= diagnostics["radius_mm"] + 2 * diagnostics["pixel_mm"]
    assert corners[:, 1].max() < 0.5


@pytest.mark.slow
def test_closed_views_drawn_from_a_case_folder_are_the_case_own(leaking_case, tmp_path):
    """A case that drew no figures gets its closed views from its loaded state: the same
    pictures run_case draws (identical pixels: the same positions, valve and orifice)."""
    import matplotlib.image

    from valve_dolfinx.plotting import draw_closed_views

    out, _, _ = leaking_case
    aortic, ventricular = draw_closed_views(out, tmp_path)
    assert (aortic.name, ventricular.name) == (f"{out.name}_aortic.png",
                                               f"{out.name}_ventricular.png")
    for drawn, own in ((aortic, "closed_valve_aortic.png"),
                       (ventricular, "closed_valve_ventricular.png")):
        a, b = matplotlib.image.imread(drawn), matplotlib.image.imread(out / own)
        assert a.shape == b.shape and np.array_equal(a, b)
