"""Geometry of the flat leaflet, the wrapped valve and the graft (SPEC §1).

Expected numbers are worked out from the SPEC's formulas, not from the code:
free edge π·d/3 = 20.944 mm; commissure rise d·sin²(π/6)/tan 34° = 7.413 mm;
midline height 7.413 + 5 = 12.413 mm.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from valve_dolfinx.exceptions import MeshError, ParameterError
from valve_dolfinx.geometry.flat_mesh import mesh_flat_leaflet, triangle_angles
from valve_dolfinx.geometry.outline import LeafletShape
from valve_dolfinx.geometry.valve import (
    ATTACHMENT,
    DEFAULT_MESH_SIZE,
    FREE_EDGE,
    LEAFLET_TAGS,
    ValveParameters,
    build_valve,
)

D = 20.0
FREE_EDGE_MM = math.pi * D / 3
RISE_MM = D * 0.25 / math.tan(math.radians(34.0))
HEIGHT_MM = RISE_MM + 5.0


@pytest.fixture(scope="module")
def flat():
    return mesh_flat_leaflet(LeafletShape(), DEFAULT_MESH_SIZE)


def _edge_lengths(points, triangles):
    p = points[triangles]
    return np.stack([np.linalg.norm(p[:, (i + 1) % 3] - p[:, i], axis=1) for i in range(3)], 1)


def test_flat_leaflet_dimensions(flat):
    p = flat.points
    free_len = np.sum(np.linalg.norm(np.diff(p[flat.free], axis=0), axis=1))
    assert free_len == pytest.approx(FREE_EDGE_MM, rel=5e-3)
    assert p[:, 1].max() - p[:, 1].min() == pytest.approx(HEIGHT_MM, rel=5e-3)
    assert p[flat.left[0], 1] - p[:, 1].min() == pytest.approx(RISE_MM, rel=5e-3)
    assert np.allclose(p[flat.right, 1], p[flat.left, 1], atol=1e-12)
    assert p[flat.right[-1], 1] - p[flat.right[0], 1] == pytest.approx(5.0, rel=1e-12)
    # the numbers quoted by the SPEC
    assert FREE_EDGE_MM == pytest.approx(20.94, abs=0.005)
    assert RISE_MM == pytest.approx(7.41, abs=0.005)


def _angles_deg(points, triangles):
    """Interior angles by the law of cosines from the three side lengths (2-D or 3-D)."""
    p = points[triangles]
    side = [np.linalg.norm(p[:, (i + 1) % 3] - p[:, (i + 2) % 3], axis=1) for i in range(3)]
    out = []
    for i in range(3):  # angle at vertex i, opposite side[i]
        a, b, c = side[i], side[(i + 1) % 3], side[(i + 2) % 3]
        out.append(np.degrees(np.arccos(np.clip((b * b + c * c - a * a) / (2 * b * c), -1, 1))))
    return np.stack(out, axis=1)


def test_mesh_quality_and_orientation(flat):
    assert triangle_angles(flat.points, flat.triangles).min() >= 20.0
    assert _angles_deg(flat.points, flat.triangles).min() >= 20.0
    assert np.allclose(np.sort(_angles_deg(flat.points, flat.triangles)),
                       np.sort(triangle_angles(flat.points, flat.triangles)), atol=1e-8)
    t = flat.points[flat.triangles]
    cross = ((t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1])
             - (t[:, 2, 0] - t[:, 0, 0]) * (t[:, 1, 1] - t[:, 0, 1]))
    assert np.all(cross > 0)
    # the triangles tile the outline: total area = ∫ (y_free - y_lower) dx, computed here
    # with the closed form ∫ d·sin²(x/d) dx = d·(x/2 - d·sin(2x/d)/4) over [-πd/6, πd/6]
    a = math.pi * D / 6
    lower_area = D * (a - D * math.sin(2 * a / D) / 2) / math.tan(math.radians(34))
    exact = 2 * a * HEIGHT_MM - lower_area
    # (chords of the convex lower edge cut off O(h²) of area: 1e-3 at h = 0.8 mm)
    assert 0.5 * cross.sum() == pytest.approx(exact, rel=1e-3)


@pytest.fixture(scope="module")
def valve():
    return build_valve(mesh_size=DEFAULT_MESH_SIZE)


def test_valve_attachment_on_cylinder(valve):
    att = valve.attachment_nodes()
    r = np.linalg.norm(valve.points[att, :2], axis=1)
    assert np.max(np.abs(r / (D / 2) - 1)) < 1e-9


def test_wrapping_is_isometry(valve):
    for patch in valve.leaflets:
        flat_len = _edge_lengths(patch.flat, patch.triangles)
        wrapped = _edge_lengths(valve.points[patch.nodes], patch.triangles)
        # a chord of the cylinder is shorter than the flat edge by O(h²/R²); compare the
        # geodesic (helix) length: horizontal arc + axial rise
        p = valve.points[patch.nodes][patch.triangles]
        theta = np.arctan2(p[..., 1], p[..., 0])
        dtheta = np.stack([theta[:, (i + 1) % 3] - theta[:, i] for i in range(3)], 1)
        dtheta = (dtheta + np.pi) % (2 * np.pi) - np.pi
        dz = np.stack([p[:, (i + 1) % 3, 2] - p[:, i, 2] for i in range(3)], 1)
        geodesic = np.hypot(dtheta * D / 2, dz)
        assert np.max(np.abs(geodesic / flat_len - 1)) < 1e-9
        assert np.all(wrapped <= flat_len * (1 + 1e-12))


def test_commissures_shared(valve):
    # each commissure is one set of nodes used by two leaflets
    a, b, c = (set(p.nodes[p.attachment]) for p in valve.leaflets)
    ncomm = len(valve.leaflets[0].nodes[valve.leaflets[0].attachment]) - len(
        valve.leaflets[0].free_edge)
    for s, t in ((a, b), (b, c), (c, a)):
        shared = s & t
        assert len(shared) >= 3
        z = valve.points[list(shared), 2]
        assert z.min() == pytest.approx(RISE_MM, rel=1e-9)
        assert z.max() == pytest.approx(HEIGHT_MM, rel=1e-9)
    assert ncomm > 0
    # no two distinct nodes at the same place
    from scipy.spatial import cKDTree

    assert len(cKDTree(valve.points).query_pairs(1e-6)) == 0


@pytest.fixture(scope="module")
def graft_valve():
    return build_valve(mesh_size=DEFAULT_MESH_SIZE, graft_width_pct=21, graft_height_pct=27)


# SPEC §1: leaflet k spans θ ∈ [120k − 60, 120k + 60] degrees, so the commissure posts shared
# by leaflets k and k+1 stand at θ = 120k + 60: 60°, 180° and 300°, from the commissure bottom
# (RISE_MM above the nadir) to the free edge (HEIGHT_MM), on the d = 20 mm cylinder.
POST_DEG = (60.0, 180.0, 300.0)


def _commissure_nodes(valve, k, side):
    """3-D positions of leaflet k's left (-1) or right (+1) commissure, found from its flat
    outline: the nodes at x = ±(1+W)·πd/6 (W = 0 for a native leaflet), sorted by height."""
    patch = valve.leaflets[k]
    half_width = (1 + patch.shape.width_pct / 100) * math.pi * D / 6
    on = np.abs(patch.flat[:, 0] - side * half_width) < 1e-9 * D
    xyz = valve.points[patch.nodes[on]]
    return xyz[np.argsort(xyz[:, 2])]


@pytest.mark.parametrize("which", ["normal", "graft"])
def test_commissure_nodes_of_neighbours_coincide(which, valve, graft_valve):
    v = valve if which == "normal" else graft_valve
    for k in range(3):
        right = _commissure_nodes(v, k, +1.0)
        left = _commissure_nodes(v, (k + 1) % 3, -1.0)
        # both sides carry the same nodes, at the same places (shared or tied)
        assert len(right) == len(left) >= 3
        assert np.max(np.linalg.norm(right - left, axis=1)) < 1e-9 * D
        # ... on the commissure post of SPEC §1, worked out here from the angles
        theta = math.radians(POST_DEG[k])
        post = np.array([0.5 * D * math.cos(theta), 0.5 * D * math.sin(theta)])
        assert np.max(np.linalg.norm(right[:, :2] - post, axis=1)) < 1e-9 * D
        assert right[0, 2] == pytest.approx(RISE_MM, rel=1e-9)
        assert right[-1, 2] == pytest.approx(HEIGHT_MM, rel=1e-9)
        assert np.all(np.diff(right[:, 2]) > 0.1)  # distinct nodes up the post
        # no other node of either leaflet sits on the post
        for j in (k, (k + 1) % 3):
            xyz = v.points[v.leaflets[j].nodes]
            on_post = np.linalg.norm(xyz[:, :2] - post, axis=1) < 1e-6 * D
            assert on_post.sum() == len(right)


@pytest.mark.parametrize("which", ["native flat", "graft flat", "normal valve", "graft valve"])
def test_minimum_angle_at_default_size(which, valve, graft_valve):
    """Gmsh mesh quality: no triangle angle below 20° (the flat reference meshes, and the
    assembled 3-D valve meshes, including the slack-placed W21/H27 graft)."""
    if which == "native flat":
        patch = valve.leaflet("left_coronary")
        points, tris = patch.flat, patch.triangles
    elif which == "graft flat":
        patch = graft_valve.leaflet("non_coronary")
        assert patch.is_graft
        points, tris = patch.flat, patch.triangles
    else:
        v = valve if which == "normal valve" else graft_valve
        points, tris = v.points, v.cells
    assert _angles_deg(points, tris).min() >= 20.0


def test_leaflet_angular_span(valve):
    for k, patch in enumerate(valve.leaflets):
        p = valve.points[patch.nodes]
        theta = np.arctan2(p[:, 1], p[:, 0]) - 2 * math.pi * k / 3
        theta = (theta + math.pi) % (2 * math.pi) - math.pi
        assert theta.min() == pytest.approx(-math.pi / 3, abs=1e-9)
        assert theta.max() == pytest.approx(math.pi / 3, abs=1e-9)


def test_tags_cover_cells_and_boundary(valve):
    assert set(np.unique(valve.cell_tags)) == set(LEAFLET_TAGS.values())
    # every boundary edge (edge of exactly one triangle) carries a tag
    e = np.sort(np.concatenate([valve.cells[:, [0, 1]], valve.cells[:, [1, 2]],
                                valve.cells[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    boundary = {tuple(x) for x in uniq[counts == 1]}
    tagged = {tuple(x) for x in valve.edges}
    assert boundary <= tagged
    # the only tagged interior edges are the shared commissures (attachment)
    interior_tagged = tagged - boundary
    tags = dict(zip(map(tuple, valve.edges), valve.edge_tags, strict=True))
    assert all(tags[e] == ATTACHMENT for e in interior_tagged)
    free = valve.edges[valve.edge_tags == FREE_EDGE]
    assert np.allclose(valve.points[free.ravel(), 2], HEIGHT_MM)
    free_len = np.linalg.norm(valve.points[free[:, 0]] - valve.points[free[:, 1]], axis=1).sum()
    assert free_len == pytest.approx(math.pi * D, rel=5e-3)


def test_fibres_unit_and_tangent(valve):
    f = valve.fibres_3d()
    assert np.allclose(np.linalg.norm(f, axis=1), 1.0, atol=1e-12)
    p = valve.points[valve.cells]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert np.max(np.abs(np.einsum("ij,ij->i", f, n))) < 1e-12
    # near the free edge the native fibres run parallel to it (circumferential)
    centre = valve.flat[:, :, :].mean(axis=1)
    native = valve.cell_tags != LEAFLET_TAGS["non_coronary"]
    top = native & (centre[:, 1] > HEIGHT_MM - 0.5) & (np.abs(centre[:, 0]) < 5.0)
    assert top.sum() > 10 and np.all(np.abs(valve.fibres[top, 1]) < 0.05)
    # ... and arc down towards the commissures: fibres rise towards the nearer commissure
    low = native & (centre[:, 1] < 4.0) & (np.abs(centre[:, 0]) > 3.0)
    assert np.all(np.sign(valve.fibres[low, 1] * valve.fibres[low, 0]) == np.sign(
        centre[low, 0]))


def test_normals_point_to_aortic_side(valve):
    # outward (away from the axis) in the open, wrapped valve
    p = valve.points[valve.cells]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    c = p.mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", n[:, :2], c[:, :2]) > 0)


@pytest.mark.parametrize("w,h", [(21.0, 27.0), (0.0, 40.0), (27.0, 0.0)])
def test_graft_dimensions_and_attachment(w, h):
    valve = build_valve(mesh_size=0.8, graft_width_pct=w, graft_height_pct=h)
    graft = valve.leaflet("non_coronary")
    native = valve.leaflet("left_coronary")
    assert graft.is_graft and not native.is_graft
    sx, sy = 1 + w / 100, 1 + h / 100
    gw = np.ptp(graft.flat[graft.free_edge, 0])
    assert gw == pytest.approx(sx * FREE_EDGE_MM, rel=1e-12)
    assert graft.flat[:, 1].max() == pytest.approx(sy * HEIGHT_MM, rel=1e-12)
    # its lower edge is the native curve scaled by (sx, sy)
    lower = graft.attachment[graft.flat[graft.attachment, 1] < sy * RISE_MM - 1e-9]
    xg, yg = graft.flat[lower].T
    expected = sy * D * np.sin(xg / sx / D) ** 2 / math.tan(math.radians(34))
    assert np.max(np.abs(yg - expected)) < 1e-9
    assert len(lower) > 10
    # graft attachment nodes lie on the native attachment locus of the NC position:
    # on the cylinder, inside its angular span, at the native height for their angle
    att = valve.points[graft.nodes[graft.attachment]]
    assert np.max(np.abs(np.linalg.norm(att[:, :2], axis=1) - D / 2)) < 1e-9
    theta = np.arctan2(att[:, 1], att[:, 0]) - 4 * math.pi / 3
    theta = (theta + math.pi) % (2 * math.pi) - math.pi
    x = theta * D / 2  # native flat abscissa
    on_lower = att[:, 2] < RISE_MM - 1e-9
    expected = D * np.sin(x[on_lower] / D) ** 2 / math.tan(math.radians(34))
    assert np.max(np.abs(att[on_lower, 2] - expected)) < 1e-9
    on_comm = ~on_lower
    assert np.allclose(np.abs(x[on_comm]), math.pi * D / 6, atol=1e-9)
    # the graft's reference is its own flat shape: no node of it is stretched when placed
    assert np.all(np.isfinite(valve.points))


@pytest.mark.parametrize("free_edge,height", [(22.0, 13.0), (18.0, 16.0), (30.0, 11.0)])
def test_measured_leaflet_is_the_default_outline_scaled(free_edge, height):
    """A measured leaflet (L, H) is the SPEC §1 outline scaled by (L/L0, H/H0): its lower
    edge is y(x) = ky·y0(x/kx), with y0 the SPEC's curve on the 20 mm cylinder."""
    kx, ky = free_edge / FREE_EDGE_MM, height / HEIGHT_MM
    measured = LeafletShape.measured(free_edge, height)
    assert measured.free_edge_length == pytest.approx(free_edge, rel=1e-13)
    assert measured.height == pytest.approx(height, rel=1e-13)
    assert measured.root_diameter == pytest.approx(3 * free_edge / math.pi, rel=1e-13)
    x = np.linspace(-measured.half_width, measured.half_width, 101)
    spec_curve = D * np.sin(x / kx / D) ** 2 / math.tan(math.radians(34.0))
    assert np.allclose(measured.lower_edge(x), ky * spec_curve, rtol=0, atol=1e-12)
    assert measured.commissure_bottom == pytest.approx(ky * RISE_MM, rel=1e-13)
    assert measured.commissure_height == pytest.approx(5.0 * ky, rel=1e-13)


def test_measured_default_leaflet_is_the_default_outline_exactly():
    default = LeafletShape()
    assert LeafletShape.measured(default.free_edge_length, default.height) == default
    # a uniformly scaled leaflet keeps the attachment angle exactly
    assert LeafletShape.measured(1.1 * default.free_edge_length,
                                 1.1 * default.height).gamma_deg == 34.0


def test_graft_placement_is_slack(graft_valve):
    valve = graft_valve
    from valve_dolfinx.geometry.valve import reference_jacobians

    tag = LEAFLET_TAGS["non_coronary"]
    J = reference_jacobians(valve.points, valve.cells, valve.flat)[valve.cell_tags == tag]
    stretches = np.linalg.svd(J, compute_uv=False)
    assert stretches.max() < 1.0  # compressed in every direction: slack


def test_billowed_placement_differs_inside_only():
    a = build_valve(mesh_size=0.8, graft_width_pct=14, graft_height_pct=13)
    b = build_valve(mesh_size=0.8, graft_width_pct=14, graft_height_pct=13,
                    graft_placement="billowed", billow_mm=2.0)
    att = a.attachment_nodes()
    assert np.allclose(a.points[att], b.points[att])
    shift = np.linalg.norm(a.points - b.points, axis=1)
    assert shift.max() == pytest.approx(2.0, rel=1e-6)
    assert np.allclose(a.flat, b.flat)


@pytest.mark.parametrize("kwargs,name", [
    ({"graft_width_pct": -5.0, "graft_height_pct": 0.0}, "graft_width_pct"),
    ({"graft_width_pct": 10.0, "graft_height_pct": float("nan")}, "graft_height_pct"),
    ({"graft_width_pct": 1e4, "graft_height_pct": 0.0}, "graft_width_pct"),
    ({"graft_width_pct": 10.0, "graft_height_pct": None}, "graft_height_pct"),
    ({"mesh_size": 50.0}, "mesh_size"),
    ({"mesh_size": -1.0}, "mesh_size"),
    ({"mesh_size": float("inf")}, "mesh_size"),
    ({"root_diameter": 0.0}, "root_diameter"),
    ({"gamma_deg": 95.0}, "gamma_deg"),
    ({"graft_placement": "upside-down", "graft_width_pct": 0.0, "graft_height_pct": 0.0},
     "graft_placement"),
])
def test_bad_input_names_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name) as err:
        ValveParameters(**kwargs)
    assert isinstance(err.value, ParameterError)
    if "allowed range" in str(err.value):
        assert "[" in str(err.value) or "(" in str(err.value)


def test_broken_mesh_rejected(valve):
    import copy

    bad = copy.deepcopy(valve)
    bad.cells[0, 1] = bad.cells[0, 0]
    with pytest.raises(MeshError, match="repeats a node"):
        bad.validate()
    bad = copy.deepcopy(valve)
    bad.flat[3] = bad.flat[3][::-1]
    with pytest.raises(MeshError, match="inverted"):
        bad.validate()
    bad = copy.deepcopy(valve)
    bad.points[5] = np.nan
    with pytest.raises(MeshError, match="NaN"):
        bad.validate()


def test_save_load_roundtrip(valve, tmp_path):
    from valve_dolfinx.geometry.valve import load_valve_mesh
    from valve_dolfinx.io import export_valve_vtu

    path = valve.save(tmp_path / "valve.npz")
    back = load_valve_mesh(path)
    assert np.array_equal(back.cells, valve.cells)
    assert np.allclose(back.points, valve.points)
    assert back.parameters == valve.parameters
    assert [p.name for p in back.leaflets] == [p.name for p in valve.leaflets]
    assert export_valve_vtu(valve, tmp_path / "valve.vtu").stat().st_size > 0
    with pytest.raises(FileNotFoundError, match="valve-dolfinx mesh"):
        load_valve_mesh(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a mesh")
    with pytest.raises(MeshError, match="regenerate"):
        load_valve_mesh(tmp_path / "junk.npz")


def test_graft_valve_states_compare_up_to_its_mirror_symmetry(graft_valve):
    """The graft valve is its own mirror image in the plane through the axis and the graft's
    midline (θ = 240°).  A state a = x + 1 mm across that plane and its mirror image
    b = x − 1 mm across it (node by node) are 2 mm apart directly and 0 up to the mirror."""
    from valve_dolfinx.geometry.symmetry import distance_up_to_mirror

    x = graft_valve.points
    theta = np.radians(240.0)
    across = np.array([-np.sin(theta), np.cos(theta), 0.0])
    a, b = x + across, x - across
    direct, mirror = distance_up_to_mirror(graft_valve, a, b)
    assert direct == pytest.approx(2.0, abs=1e-12)
    assert mirror < 1e-9
    assert distance_up_to_mirror(graft_valve, a, a) == (0.0, pytest.approx(2.0, abs=1e-9))
