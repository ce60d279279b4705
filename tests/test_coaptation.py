"""Coaptation measures on constructed surfaces with known answers (SPEC §6).

Every expected number is worked out by hand below from the construction, not
taken from the code:

* Band: sheet A is the flat rectangle [-10, 10] × [0, 12] (1 mm grid, plus a
  grid line at y = 8.2).  In 3-D its part y >= 8.2 lies in the plane z = 0,
  0.3 mm below the large sheet B (z = 0.3); below y = 8.2 it folds straight
  down, so a point at flat height y < 8.2 is 0.3 + (8.2 - y) from B.  That is
  <= 0.5 mm exactly for y >= 8.0, a grid line, and the distance is affine on
  every triangle, so the P1 region is exactly y ∈ [8, 12]: height 4 mm at
  every x, flat area 20·4 = 80 mm², and with the 3-D map stretched by 1.1
  across, loaded area 22·4 = 88 mm² (the fold is an isometry in y).
* Dip: the fold line raised by d over a strip |x - c| <= w/2 of the flat
  sheet (grid lines at c ± w/2 and at c ± (w/2 + 0.05), where the fold comes
  back down to 8.2, and at y = 8 + d, 8.2 + d).  Every node column of the
  strip is then at distance 0.3 + max(8.2 + d - y, 0) from B, so the region
  there is y ∈ [8 + d, 12], height 4 - d; beside the 0.05 mm ramps it is 4,
  and on a ramp the gap lies between the two, so the height does too.  The
  minimum on a side of the midline is 4 - d if the strip reaches into that
  side (outside the nodulus length l, centred on the midline), else 4.
* Orifice: three 120° sectors of radius 10 mm in z = 0.  The orifice disk is
  the attachment circle less two pixels: radius 10 - 2·0.05 = 9.9 mm.
  Truncating each sector by the chord at distance ρ from the centre leaves an
  equilateral hole of inradius ρ; gaps within threshold/2 = 0.25 mm of a
  leaflet count as sealed, so the open area is the hole eroded by 0.25 mm,
  an equilateral triangle of inradius ρ - 0.25 and area 3√3(ρ - 0.25)².
* Overlap: one sector widened by α = 10° on each side and lifted overlaps each
  neighbour in a wedge of angle α: overlap area 2·(α/2)·9.9² = α·9.9².
* Dead end: two half-disks in z = 0 (their straight edges meet on the y axis)
  close the whole orifice; a third sector of half-angle 20° lies 0.8 mm above
  one of them.  In projection it overlaps its floor, apart, over a 40° wedge
  of area (40°/2)·9.9² = 34.2 mm², but no path leads through the floor: the
  orifice is 0.  Moving the half-disks apart by a slit of width g opens a path
  exactly when g exceeds the threshold (up to √3 voxels, see
  ``valve_dolfinx.analysis.sealing``).
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from valve_dolfinx.analysis import (
    analyse_coaptation,
    coaptation_height_profile,
    distance_to_surface,
    fraction_below,
    regurgitant_orifice_area,
    through_flow,
)
from valve_dolfinx.analysis.distance import within_distance
from valve_dolfinx.analysis.sealing import crossed_distances
from valve_dolfinx.contact.geometry import closest_point_on_triangles
from valve_dolfinx.exceptions import MeshError, ParameterError
from valve_dolfinx.geometry.outline import LeafletShape
from valve_dolfinx.geometry.valve import LEAFLET_NAMES, LeafletPatch, ValveMesh, build_valve
from valve_dolfinx.plotting import plot_coaptation_map

THRESHOLD = 0.5
PIXEL = 0.05
R_SECTOR = 10.0
R_ORIFICE = R_SECTOR - 2 * PIXEL  # attachment circle less two pixels


# --- hand-built meshes ---------------------------------------------------------------------
def _grid(xs: np.ndarray, ys: np.ndarray) -> dict:
    """Structured triangulation of the rectangle xs × ys with its boundary chains."""
    nx, ny = len(xs), len(ys)
    X, Y = np.meshgrid(xs, ys)  # node (j, i) -> j*nx + i
    ids = np.arange(nx * ny).reshape(ny, nx)
    a, b = ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel()
    c, d = ids[1:, 1:].ravel(), ids[1:, :-1].ravel()
    triangles = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    attachment = np.concatenate([ids[::-1, 0], ids[0, 1:], ids[1:, -1]])
    return {"flat": np.stack([X.ravel(), Y.ravel()], 1), "triangles": triangles,
            "free": ids[-1], "attachment": attachment}


def _sector(beta_deg: float, half_deg: float, z: float, rho: float = 0.0, n_r: int = 40,
            n_a: int = 40) -> dict:
    """A flat sector of radius R_SECTOR in the plane ``z``, bisector at ``beta_deg``.

    ``rho > 0`` truncates it by the chord at distance ``rho`` from the centre
    (that chord is then the free edge).  Flat coordinates are the planar ones
    rotated so that the bisector points down.
    """
    beta, half = math.radians(beta_deg), math.radians(half_deg)
    phi = beta + np.linspace(-half, half, n_a + 1)
    s = np.linspace(0.0, 1.0, n_r + 1)
    if rho > 0:
        inner = (rho / np.cos(phi - beta))[None, :]
    else:
        inner = np.zeros((1, n_a + 1))
        s = s[1:]
    r = inner + s[:, None] * (R_SECTOR - inner)  # (rings, angles)
    xy = np.stack([r * np.cos(phi), r * np.sin(phi)], -1).reshape(-1, 2)
    ids = np.arange(r.size).reshape(r.shape)
    a, b = ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel()
    c, d = ids[1:, 1:].ravel(), ids[1:, :-1].ravel()
    tris = [np.stack([a, c, b], 1), np.stack([a, d, c], 1)]
    attachment = ids[-1]  # the arc on the root wall
    if rho > 0:
        free = ids[0]
    else:  # apex fan; the "free edge" runs along both radial edges through the apex
        apex = len(xy)
        xy = np.vstack([xy, [0.0, 0.0]])
        tris.append(np.stack([np.full(n_a, apex), ids[0, :-1], ids[0, 1:]], 1))
        free = np.concatenate([ids[::-1, 0], [apex], ids[:, -1]])
    triangles = np.concatenate(tris)
    e, t = np.array([math.cos(beta), math.sin(beta)]), np.array([-math.sin(beta), math.cos(beta)])
    flat = np.stack([xy @ t, R_SECTOR - xy @ e], 1)
    p = flat[triangles]
    cross = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
             - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    triangles[cross < 0] = triangles[cross < 0][:, ::-1]
    xyz = np.column_stack([xy, np.full(len(xy), z)])
    return {"flat": flat, "triangles": triangles, "free": free, "attachment": attachment,
            "xyz": xyz}


def _valve(sheets: list[dict]) -> tuple[ValveMesh, np.ndarray]:
    """A ValveMesh of separate leaflets (no shared nodes) and their 3-D positions."""
    points, cells, tags, flat, patches = [], [], [], [], []
    offset = 0
    for k, sh in enumerate(sheets):
        n = len(sh["flat"])
        nodes = np.arange(offset, offset + n)
        points.append(sh["xyz"])
        cells.append(nodes[sh["triangles"]])
        tags.append(np.full(len(sh["triangles"]), k + 1, dtype=np.int32))
        flat.append(sh["flat"][sh["triangles"]])
        patches.append(LeafletPatch(
            name=LEAFLET_NAMES[k], tag=k + 1, shape=LeafletShape(), nodes=nodes,
            flat=sh["flat"], triangles=sh["triangles"], free_edge=sh["free"],
            attachment=sh["attachment"], is_graft=sh.get("is_graft", False)))
        offset += n
    cells = np.concatenate(cells)
    valve = ValveMesh(points=np.concatenate(points), cells=cells, cell_tags=np.concatenate(tags),
                      flat=np.concatenate(flat), fibres=np.tile([1.0, 0.0], (len(cells), 1)),
                      edges=np.empty((0, 2), np.int64), edge_tags=np.empty(0, np.int32),
                      leaflets=tuple(patches))
    return valve, valve.points.copy()


def _band_valve(b_x_from: float = -15.0, dip_at: float | None = None, depth: float = 0.0,
                width: float = 0.5, ramp: float = 0.05) -> tuple[ValveMesh, np.ndarray]:
    """Sheet A folded under sheet B (see the module docstring); B spans x >= b_x_from.

    With ``dip_at = c`` the fold line is raised by ``depth`` over the node columns
    ``|x - c| <= width/2`` (and comes back to 8.2 at ``|x - c| = width/2 + ramp``).
    """
    xs, ys = np.linspace(-10.0, 10.0, 21), np.union1d(np.arange(13.0), [8.2])
    if dip_at is not None:
        half = 0.5 * width
        xs = np.union1d(xs, [dip_at + s * d for s in (-1, 1) for d in (half, half + ramp)])
        ys = np.union1d(ys, [8.0 + depth, 8.2 + depth])
    a = _grid(xs, ys)
    x, y = a["flat"].T
    fold = np.full_like(x, 8.2)
    if dip_at is not None:
        fold[np.abs(x - dip_at) <= 0.5 * width + 1e-12] += depth
    a["xyz"] = np.stack([1.1 * x, np.maximum(y, fold), np.minimum(y - fold, 0.0)], 1)
    b = _grid(np.linspace(b_x_from, 15.0, int(round(15.0 - b_x_from)) + 1),
              np.linspace(-2.0, 16.0, 19))
    b["xyz"] = np.column_stack([b["flat"], np.full(len(b["flat"]), 0.3)])
    b["is_graft"] = True  # B's own region is a patch in its middle: min height 0
    return _valve([a, b])


def _three_sectors(rho: float = 0.0, widen_deg: float = 0.0, lift: float = 0.0):
    sheets = [_sector(0.0, 60.0 + widen_deg, lift, rho)]
    sheets += [_sector(beta, 60.0, 0.0, rho) for beta in (120.0, 240.0)]
    return _valve(sheets)


# --- primitives ------------------------------------------------------------------------------
def test_fraction_below_linear_triangle():
    # gap 0 at one vertex, 1 at the others: {gap <= 1/2} is the corner triangle of
    # side ratio 1/2 -> area fraction 1/4; two vertices at 0 -> 1 - 1/4
    g = np.array([[0.0, 1.0, 1.0], [1.0, 0.0, 0.0], [0.2, 0.3, 0.4], [0.6, 0.7, 0.9]])
    assert fraction_below(g, 0.5) == pytest.approx([0.25, 0.75, 1.0, 0.0], abs=1e-15)


def test_distance_to_surface_matches_brute_force():
    rng = np.random.default_rng(3)
    g = _grid(np.linspace(0, 5, 11), np.linspace(0, 4, 9))
    verts = np.column_stack([g["flat"], 0.3 * np.sin(g["flat"][:, 0])])
    pts = rng.uniform([-3, -3, -6], [8, 7, 6], size=(200, 3))  # many far from the sheet
    tri = verts[g["triangles"]]
    pp = np.repeat(pts, len(tri), axis=0)
    tt = np.tile(tri, (len(pts), 1, 1))
    q, _ = closest_point_on_triangles(pp, tt[:, 0], tt[:, 1], tt[:, 2])
    brute = np.linalg.norm(pp - q, axis=1).reshape(len(pts), -1).min(axis=1)
    assert distance_to_surface(pts, verts, g["triangles"]) == pytest.approx(brute, abs=1e-12)


def test_within_distance_is_the_exact_distance_test():
    rng = np.random.default_rng(4)
    g = _grid(np.linspace(0, 5, 11), np.linspace(0, 4, 9))
    verts = np.column_stack([g["flat"], 0.3 * np.sin(g["flat"][:, 0])])
    pts = rng.uniform([-1, -1, -1.5], [6, 5, 1.5], size=(3000, 3))
    exact = distance_to_surface(pts, verts, g["triangles"])
    for reach in (0.25, 0.6):
        got = within_distance(pts, verts, g["triangles"], reach)
        assert 100 < got.sum() < len(pts) - 100  # both answers occur
        assert np.array_equal(got, exact <= reach)
    # points exactly at the limit: straight above the vertices of a flat sheet
    flat = np.column_stack([g["flat"], np.zeros(len(g["flat"]))])
    on = flat + [0.0, 0.0, 0.25]
    assert within_distance(on, flat, g["triangles"], 0.25).all()
    assert not within_distance(on, flat, g["triangles"], 0.2499).any()


def test_crossed_distances_are_the_distance_transform_up_to_the_radius():
    rng = np.random.default_rng(6)
    crossed = rng.random((30, 25, 20)) < 0.004
    voxel, radius = 0.1, 0.355
    reference = distance_transform_edt(~crossed, sampling=voxel)
    got = crossed_distances(crossed, radius, voxel)
    close = reference <= radius
    assert 1000 < close.sum() < close.size - 1000
    assert np.allclose(got[close], reference[close], rtol=0.0, atol=1e-15)
    assert np.isinf(got[~close]).all()


# --- coaptation height and area on two parallel sheets ----------------------------------------
def test_parallel_band_height_and_area_exact():
    valve, x = _band_valve()
    res = analyse_coaptation(x, valve, THRESHOLD, orifice=False)  # no orifice here
    a = res.leaflets["left_coronary"]
    assert np.allclose(a.height_mm, 4.0, atol=1e-9)  # including lines on vertical mesh edges
    assert a.x_mm[0] == -10.0 and a.x_mm[-1] == 10.0
    assert a.min_height_mm == pytest.approx(4.0, abs=1e-9)
    assert a.central_height_mm == pytest.approx(4.0, abs=1e-9)
    assert a.reference_area_mm2 == pytest.approx(80.0, abs=1e-9)
    assert a.area_mm2 == pytest.approx(88.0, abs=1e-9)
    band = valve.leaflets[0].flat[:, 1] >= 8.2
    assert np.allclose(a.node_gap_mm[band], 0.3, atol=1e-12)
    # the figure of merit is over native leaflets only; B (the "graft") is wider than A, its
    # columns |x| > 11.4 never come within 0.5 mm of A, so its min height is 0
    assert res.leaflets["right_coronary"].min_height_mm == 0.0
    assert res.min_native_height_mm == pytest.approx(4.0, abs=1e-9)
    assert res.central_native_height_mm == pytest.approx(4.0, abs=1e-9)
    assert res.coaptation_area_mm2 == pytest.approx(
        88.0 + res.leaflets["right_coronary"].area_mm2)


def test_band_missing_on_one_side_shows_on_that_side_only():
    # B now covers 3-D x >= 0 only: A's columns x >= 0 keep the 4 mm band; A's nodes at
    # flat x <= -1 (3-D x <= -1.1) are >= sqrt(0.3² + 1.1²) > 0.5 from B, so h = 0 there.
    valve, x = _band_valve(b_x_from=0.0)
    res = analyse_coaptation(x, valve, THRESHOLD, orifice=False, nodulus_length_mm=0.0)
    a = res.leaflets["left_coronary"]
    assert np.allclose(a.height_mm[a.x_mm >= -1e-9], 4.0, atol=1e-9)
    assert np.all(a.height_mm[a.x_mm <= -1.0] == 0.0)
    assert a.min_height_left_mm == 0.0
    assert a.min_height_right_mm == pytest.approx(4.0, abs=1e-9)
    assert a.min_height_mm == 0.0 and a.min_height_raw_mm == 0.0
    assert a.min_height_x_mm <= -1.0
    assert a.central_height_mm == pytest.approx(4.0, abs=1e-9)
    assert a.midline_height_mm == pytest.approx(4.0, abs=1e-9)
    assert res.min_native_height_mm == 0.0 and res.min_native_height_raw_mm == 0.0


# --- a narrow dip in the coaptation region ---------------------------------------------------
DIP_DEPTH = 1.5  # h = 4 - 1.5 = 2.5 mm over the dip (module docstring)
DIP_WIDTH = 0.5


@pytest.mark.parametrize("dip_at, low_sides", [(0.0, {"left", "right"}), (3.0, {"right"}),
                                                (-3.0, {"left"})])
def test_narrow_dip_is_found_on_its_own_side(dip_at, low_sides):
    """A 0.5 mm wide dip at the midline or 3 mm off it, with no nodulus (l = 0)."""
    valve, x = _band_valve(dip_at=dip_at, depth=DIP_DEPTH, width=DIP_WIDTH)
    res = analyse_coaptation(x, valve, THRESHOLD, orifice=False, nodulus_length_mm=0.0)
    a = res.leaflets["left_coronary"]
    low = 4.0 - DIP_DEPTH
    for side in ("left", "right"):
        expected = low if side in low_sides else 4.0
        assert getattr(a, f"min_height_{side}_mm") == pytest.approx(expected, abs=0.05)
    assert a.min_height_raw_mm == pytest.approx(low, abs=0.05)
    assert a.min_height_mm == pytest.approx(low, abs=0.05)
    assert abs(a.min_height_x_mm - dip_at) <= 0.5 * DIP_WIDTH + 1e-9
    central = low if dip_at == 0.0 else 4.0
    assert a.central_height_mm == pytest.approx(central, abs=0.05)
    assert a.midline_height_mm == pytest.approx(central, abs=0.05)
    fields = res.result_fields()
    assert fields["min_coaptation_height_mm"] == pytest.approx(low, abs=0.05)
    assert fields["min_coaptation_height_raw_mm"] == fields["min_coaptation_height_mm"]
    assert fields["central_coaptation_height_mm"] == pytest.approx(central, abs=0.05)


@pytest.mark.parametrize("nodulus", [0.3, 1.0, None])
@pytest.mark.parametrize("dip_at", [0.0, 3.0])
def test_nodulus_hides_only_a_dip_narrower_than_itself(nodulus, dip_at):
    """The main minimum finds the dip when it is wider than the nodulus, the raw one always.
    ``None``: the default nodulus, one leaflet thickness (0.5 mm) either side of the
    triple point."""
    valve, x = _band_valve(dip_at=dip_at, depth=DIP_DEPTH, width=DIP_WIDTH)
    if nodulus is None:
        res = analyse_coaptation(x, valve, THRESHOLD, orifice=False)
        nodulus = 2 * 0.5
    else:
        res = analyse_coaptation(x, valve, THRESHOLD, orifice=False, nodulus_length_mm=nodulus)
    a = res.leaflets["left_coronary"]
    low = 4.0 - DIP_DEPTH
    # the dip is seen outside the nodulus if it is off the midline or wider than the nodulus
    seen = dip_at != 0.0 or DIP_WIDTH > nodulus
    assert a.min_height_raw_mm == pytest.approx(low, abs=0.05)
    assert a.min_height_mm == pytest.approx(low if seen else 4.0, abs=0.05)
    assert res.min_native_height_raw_mm == pytest.approx(low, abs=0.05)
    assert res.min_native_height_mm == pytest.approx(low if seen else 4.0, abs=0.05)
    assert res.result_fields()["min_coaptation_height_raw_mm"] == pytest.approx(low, abs=0.05)
    # the central height is read at the edge of the nodulus, x = ±l/2
    central = low if dip_at == 0.0 and seen else 4.0
    assert a.central_height_mm == pytest.approx(central, abs=0.05)
    assert a.midline_height_mm == pytest.approx(low if dip_at == 0.0 else 4.0, abs=0.05)
    assert a.to_dict()["nodulus_length_mm"] == nodulus


def test_dip_between_profile_samples_is_found_exactly():
    # a V-shaped dip: one node column at x = 3.03 raised by d, back to the band 0.05 mm either
    # side.  The evenly spaced samples (every 0.1 mm) fall at 3.0 and 3.1, on its flanks, but
    # the profile is also evaluated at every vertex abscissa, where h = 4 - d exactly.
    valve, x = _band_valve(dip_at=3.03, depth=DIP_DEPTH, width=0.0)
    a = analyse_coaptation(x, valve, THRESHOLD, orifice=False).leaflets["left_coronary"]
    assert a.min_height_right_mm == pytest.approx(4.0 - DIP_DEPTH, abs=1e-9)
    assert a.min_height_x("right") == pytest.approx(3.03, abs=1e-12)
    assert a.min_height_left_mm == pytest.approx(4.0, abs=1e-9)
    flank = a.height_mm[np.isclose(a.x_mm, 3.0)][0]
    assert flank > 4.0 - DIP_DEPTH + 0.5  # what a sampled minimum would have reported


def test_coaptation_height_profile_counts_vertical_edges_once():
    g = _grid(np.linspace(0, 2, 3), np.linspace(0, 3, 4))
    h = coaptation_height_profile(g["flat"], g["triangles"], np.zeros(len(g["flat"])), 0.5,
                                  np.array([0.0, 0.5, 1.0, 2.0]))
    assert h == pytest.approx([3.0, 3.0, 3.0, 3.0], abs=1e-12)


# --- regurgitant orifice area ------------------------------------------------------------------
def test_sealed_sectors_have_no_orifice():
    valve, x = _three_sectors()
    area, diag = regurgitant_orifice_area(x, valve, THRESHOLD, PIXEL)
    assert area == 0.0
    assert diag["radius_mm"] == pytest.approx(R_ORIFICE, abs=1e-9)
    res = analyse_coaptation(x, valve, THRESHOLD, PIXEL)
    assert res.sealed and res.regurgitant_orifice_area_mm2 == 0.0


def test_gap_narrower_than_threshold_is_sealed():
    valve, x = _three_sectors(rho=0.2)  # hole of inradius 0.2 < threshold/2
    # (each free edge is 0.69 mm long, shorter than the default nodulus)
    with pytest.raises(ParameterError, match="nodulus_length_mm = 1 mm is not shorter"):
        analyse_coaptation(x, valve, THRESHOLD, PIXEL)
    res = analyse_coaptation(x, valve, THRESHOLD, PIXEL, nodulus_length_mm=0.0)
    assert res.sealed and res.regurgitant_orifice_area_mm2 == 0.0


@pytest.mark.parametrize("rho", [pytest.param(1.0, marks=pytest.mark.slow), 1.5])
def test_central_hole_area(rho):
    valve, x = _three_sectors(rho=rho)
    expected = 3.0 * math.sqrt(3.0) * (rho - THRESHOLD / 2) ** 2  # 2.923 / 5.846 mm²
    area, diag = regurgitant_orifice_area(x, valve, THRESHOLD, PIXEL)
    assert area == pytest.approx(expected, rel=0.01)  # pixel resolution (0.3 % seen)
    assert diag["channel_area_mm2"] == 0.0
    res = analyse_coaptation(x, valve, THRESHOLD, PIXEL)
    assert not res.sealed
    assert res.regurgitant_orifice_area_mm2 == area


@pytest.mark.parametrize("lift", [pytest.param(2.0, marks=pytest.mark.slow), 0.6])
def test_overlap_without_touching_is_a_leak(lift):
    alpha = math.radians(10.0)
    valve, x = _three_sectors(widen_deg=10.0, lift=lift)
    area, diag = regurgitant_orifice_area(x, valve, THRESHOLD, PIXEL)
    assert diag["open_area_mm2"] == 0.0  # fully covered in projection ...
    assert area == pytest.approx(alpha * R_ORIFICE**2, rel=0.01)  # ... but a 17.1 mm² leak
    assert area == diag["channel_area_mm2"]
    assert not analyse_coaptation(x, valve, THRESHOLD, PIXEL).sealed


@pytest.mark.parametrize("lift", [0.45, 0.2])
def test_overlap_within_threshold_is_sealed(lift):
    valve, x = _three_sectors(widen_deg=10.0, lift=lift)
    area, _ = regurgitant_orifice_area(x, valve, THRESHOLD, PIXEL)
    assert area == 0.0


@pytest.mark.parametrize("z_between, channel_wedges", [(0.4, 0), (-0.4, 1)])
def test_third_leaflet_touching_both_closes_the_channel(z_between, channel_wedges):
    """A (z = 0.8, widened to ±70°) overlaps B (z = 0) over the 10° wedge [60°, 70°], 0.8 mm
    apart; C, a sector covering exactly that wedge, lies 0.4 mm from both (between them)
    and closes it, or lies below B (0.4 mm from B, 1.2 mm from A) and does not: channel
    area 0 or the wedge's (α/2)·R², α = 10°."""
    valve, x = _valve([_sector(0.0, 70.0, 0.8), _sector(120.0, 60.0, 0.0),
                       _sector(65.0, 5.0, z_between)])
    _, diag = regurgitant_orifice_area(x, valve, THRESHOLD, PIXEL)
    wedge = 0.5 * math.radians(10.0) * R_ORIFICE**2
    assert diag["channel_area_mm2"] == pytest.approx(channel_wedges * wedge, rel=0.02, abs=0.01)


def _half_disks_and_lid(slit: float, lid_z: float = 0.8):
    """Half-disks moved to ``x > slit/2`` and ``x < -slit/2`` in z = 0; a 40° lid above one."""
    floor = [_sector(0.0, 90.0, 0.0), _sector(180.0, 90.0, 0.0)]
    floor[0]["xyz"][:, 0] += slit / 2
    floor[1]["xyz"][:, 0] -= slit / 2
    return _valve([*floor, _sector(0.0, 20.0, lid_z)])


def test_pocket_above_a_sealed_floor_is_a_dead_end():
    valve, x = _half_disks_and_lid(slit=0.0)
    area, diag = regurgitant_orifice_area(x, valve, THRESHOLD, PIXEL)
    wedge = 0.5 * math.radians(40.0) * R_ORIFICE**2  # 34.2 mm²
    assert diag["through_flow"] is False
    assert diag["dead_end_area_mm2"] == pytest.approx(wedge, rel=0.01)
    assert area == 0.0 and diag["channel_area_mm2"] == 0.0
    assert analyse_coaptation(x, valve, THRESHOLD, PIXEL).sealed


def test_slit_in_the_floor_makes_the_pocket_a_leak():
    """A 1 mm slit: an open strip and the lid's wedge as a channel, all counted."""
    valve, x = _half_disks_and_lid(slit=1.0)
    area, diag = regurgitant_orifice_area(x, valve, THRESHOLD, PIXEL)
    assert diag["through_flow"] is True and diag["dead_end_area_mm2"] == 0.0
    assert diag["channel_area_mm2"] > 0.9 * 0.5 * math.radians(40.0) * (R_ORIFICE - 0.5) ** 2
    assert diag["open_area_mm2"] > 0.0
    assert area == diag["open_area_mm2"] + diag["channel_area_mm2"]


@pytest.mark.parametrize("slit, passes", [(0.3, False), (0.48, False), (0.7, True), (1.2, True)])
def test_three_d_path_opens_at_the_threshold(slit, passes):
    valve, x = _half_disks_and_lid(slit, lid_z=3.0)
    assert through_flow(x, valve, THRESHOLD, R_ORIFICE) is passes


# --- input checks --------------------------------------------------------------------------------
@pytest.mark.parametrize("mutate, match", [
    (lambda x: x[:-1], "positions"),
    (lambda x: x[:, :2], "positions"),
    (lambda x: np.where(np.arange(len(x))[:, None] == 3, np.nan, x), "positions"),
])
def test_bad_positions_raise(mutate, match):
    valve, x = _three_sectors(rho=1.0)
    with pytest.raises(ParameterError, match=match):
        analyse_coaptation(mutate(x), valve)
    with pytest.raises(ParameterError, match=match):
        regurgitant_orifice_area(mutate(x), valve)


@pytest.mark.parametrize("kwargs, match", [
    ({"threshold_mm": 0.0}, "threshold_mm"),
    ({"threshold_mm": -0.5}, "threshold_mm"),
    ({"threshold_mm": float("nan")}, "threshold_mm"),
    ({"pixel_mm": 0.0}, "pixel_mm"),
    ({"pixel_mm": 0.4}, "pixel_mm"),
    ({"nodulus_length_mm": -0.5}, "nodulus_length_mm"),
    ({"nodulus_length_mm": float("nan")}, "nodulus_length_mm"),
])
def test_bad_parameters_raise(kwargs, match):
    valve, x = _three_sectors(rho=1.0)
    with pytest.raises(ParameterError, match=match):
        analyse_coaptation(x, valve, **kwargs)


def test_single_leaflet_valve_is_rejected():
    valve, x = _valve([_sector(0.0, 60.0, 0.0, 1.0)])
    with pytest.raises(MeshError, match="valve"):
        analyse_coaptation(x, valve)


# --- a real valve ------------------------------------------------------------------------------
def _folded_valve_positions(valve: ValveMesh) -> np.ndarray:
    """Each leaflet's free edge laid along its two coaptation lines (rays through the
    commissures), the rest blended linearly from the wrapped position; z unchanged."""
    r = 0.5 * valve.parameters.root_diameter
    x = valve.points.copy()
    for k, p in enumerate(valve.leaflets):
        fx, fy = p.flat.T
        hw, top = p.shape.half_width, p.shape.height
        low = np.where(np.abs(fx) >= hw - 1e-12, p.shape.commissure_bottom,
                       p.shape.lower_edge(fx))
        t = np.clip((fy - low) / (top - low), 0.0, 1.0)[:, None]
        ray = 2 * math.pi * k / 3 + np.sign(fx) * math.pi / 3
        free = (r * np.abs(fx) / hw)[:, None] * np.stack([np.cos(ray), np.sin(ray)], 1)
        x[p.nodes, :2] = (1 - t) * valve.points[p.nodes, :2] + t * free
    return x


def test_folded_real_valve_smoke(tmp_path):
    valve = build_valve(mesh_size=1.0)
    x = _folded_valve_positions(valve)
    t0 = time.perf_counter()
    res = analyse_coaptation(x, valve)
    elapsed = time.perf_counter() - t0
    assert elapsed < 5.0
    assert set(res.leaflets) == set(LEAFLET_NAMES)
    heights = [lc.central_height_mm for lc in res.leaflets.values()]
    assert all(0.0 < h < 12.5 for h in heights)
    assert np.ptp(heights) < 1e-6  # the fold is three-fold symmetric, so is the mesh
    assert math.isfinite(res.regurgitant_orifice_area_mm2) and res.regurgitant_orifice_area_mm2 >= 0
    assert 0.0 < res.min_native_height_mm <= res.central_native_height_mm
    # the default nodulus (1 mm) leaves the tip out of the figure of merit only
    assert res.nodulus_length_mm == 1.0
    assert res.min_native_height_raw_mm <= res.min_native_height_mm
    for lc in res.leaflets.values():
        assert 0.0 < lc.area_mm2 and np.all(np.isfinite(lc.node_gap_mm))
    json.dumps(res.to_dict())
    assert set(res.result_fields()) >= {"min_coaptation_height_mm",
                                        "min_coaptation_height_raw_mm",
                                        "central_coaptation_height_mm", "coaptation_area_mm2",
                                        "regurgitant_orifice_area_mm2"}
    plot_coaptation_map(res, valve, tmp_path / "coaptation_map.png")
    assert (tmp_path / "coaptation_map.png").stat().st_size > 20_000
