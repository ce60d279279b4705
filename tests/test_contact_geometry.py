"""Point–triangle geometry and the broad phase against brute-force references.

* closest points: an independent construction (plane projection if it falls
  inside, else the best of the three clamped segment projections) and dense
  barycentric sampling;
* plane projections: the 3×3 linear system ``p - a = v·(b-a) + w·(c-a) + d·n``;
* broad phase: every (node, box) pair of an all-pairs box test.
"""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx.contact import (
    CellGrid,
    barycentric_gradients,
    candidate_pairs,
    closest_point_on_triangles,
    plane_projection,
)
from valve_dolfinx.contact.broadphase import _cell_keys
from valve_dolfinx.contact.geometry import triangle_frames


def random_triangles(rng: np.random.Generator, k: int) -> tuple[np.ndarray, ...]:
    """Triangles of assorted shapes (including slivers) and points around them."""
    a = rng.normal(size=(k, 3))
    b = a + rng.normal(size=(k, 3))
    c = a + rng.normal(size=(k, 3))
    sliver = rng.random(k) < 0.2
    off_line = 0.05 * rng.normal(size=(sliver.sum(), 3))
    c[sliver] = a[sliver] + 0.5 * (b[sliver] - a[sliver]) + off_line
    centre = (a + b + c) / 3
    p = centre + 1.5 * rng.normal(size=(k, 3))
    return p, a, b, c


def segment_closest(p, a, b):
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    return a + t[:, None] * ab


def reference_closest(p, a, b, c):
    """Projection on the plane if inside, else the nearest of the three edges."""
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    q = p - np.einsum("ij,ij->i", p - a, n)[:, None] * n
    M = np.stack([b - a, c - a, n], axis=2)
    vwd = np.linalg.solve(M, (q - a)[..., None])[..., 0]
    inside = (vwd[:, 0] >= 0) & (vwd[:, 1] >= 0) & (vwd[:, 0] + vwd[:, 1] <= 1)
    edges = np.stack([segment_closest(p, a, b), segment_closest(p, b, c),
                      segment_closest(p, c, a)], axis=1)
    best = np.argmin(np.linalg.norm(edges - p[:, None], axis=2), axis=1)
    return np.where(inside[:, None], q, edges[np.arange(len(p)), best])


def test_closest_point_matches_independent_construction():
    rng = np.random.default_rng(1)
    p, a, b, c = random_triangles(rng, 4000)
    q, bary = closest_point_on_triangles(p, a, b, c)
    q_ref = reference_closest(p, a, b, c)
    dist, dist_ref = np.linalg.norm(q - p, axis=1), np.linalg.norm(q_ref - p, axis=1)
    np.testing.assert_allclose(dist, dist_ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(q, q_ref, atol=1e-8)
    np.testing.assert_allclose(bary.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(bary[:, [0]] * a + bary[:, [1]] * b + bary[:, [2]] * c, q,
                               atol=1e-12)
    # the sample visits every Voronoi region: vertices, edges and the face
    zeros = np.sum(np.isclose(bary, 0.0, atol=1e-12), axis=1)
    assert np.sum(zeros == 2) > 200 and np.sum(zeros == 1) > 200 and np.sum(zeros == 0) > 200


def test_closest_point_is_never_beaten_by_dense_sampling():
    rng = np.random.default_rng(2)
    p, a, b, c = random_triangles(rng, 60)
    q, _ = closest_point_on_triangles(p, a, b, c)
    s = np.linspace(0.0, 1.0, 201)
    v, w = (g.ravel() for g in np.meshgrid(s, s, indexing="ij"))
    ok = v + w <= 1.0
    v, w = v[ok], w[ok]
    for i in range(len(p)):
        samples = a[i] + v[:, None] * (b[i] - a[i]) + w[:, None] * (c[i] - a[i])
        best = np.linalg.norm(samples - p[i], axis=1).min()
        got = np.linalg.norm(q[i] - p[i])
        spacing = np.linalg.norm(np.stack([b[i] - a[i], c[i] - a[i]]), axis=1).max() / 200
        assert got <= best + 1e-12
        assert got >= best - spacing


def test_plane_projection_matches_linear_solve():
    rng = np.random.default_rng(3)
    p, a, b, c = random_triangles(rng, 2000)
    d, bary, n = plane_projection(p, a, b, c)
    n_ref = np.cross(b - a, c - a)
    n_ref /= np.linalg.norm(n_ref, axis=1)[:, None]
    M = np.stack([b - a, c - a, n_ref], axis=2)
    vwd = np.linalg.solve(M, (p - a)[..., None])[..., 0]
    np.testing.assert_allclose(n, n_ref, atol=1e-12)
    np.testing.assert_allclose(d, vwd[:, 2], rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(bary[:, 1:], vwd[:, :2], rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(bary.sum(axis=1), 1.0, atol=1e-12)


def test_barycentric_gradients_give_the_plane_projection():
    rng = np.random.default_rng(4)
    p, a, b, c = random_triangles(rng, 2000)
    n, grad = barycentric_gradients(a, b, c)
    r = p - a
    lam = np.einsum("kji,ki->kj", grad, r) + np.array([1.0, 0.0, 0.0])
    d_ref, bary_ref, n_ref = plane_projection(p, a, b, c)
    np.testing.assert_allclose(n, n_ref, atol=1e-14)
    np.testing.assert_allclose(np.einsum("ij,ij->i", r, n), d_ref, atol=1e-12)
    np.testing.assert_allclose(lam, bary_ref, rtol=1e-8, atol=1e-9)
    # dual basis: g_i·e_j = δ_ij and g_i ⊥ n
    e = np.stack([b - a, c - a], axis=1)
    np.testing.assert_allclose(np.einsum("kij,klj->kil", grad[:, 1:], e),
                               np.broadcast_to(np.eye(2), (len(p), 2, 2)), atol=1e-8)
    np.testing.assert_allclose(np.einsum("kij,kj->ki", grad, n), 0.0, atol=1e-8)


# -- broad phase ---------------------------------------------------------------------------


def test_triangle_frames_are_the_unit_normal_the_dual_edge_basis_and_the_altitudes():
    rng = np.random.default_rng(8)
    a, b, c = (rng.normal(size=(3, 25)) for _ in range(3))
    normal, grad, altitudes, collapsed = triangle_frames(a, b, c)
    assert not collapsed.any()
    for t in range(25):
        e1, e2 = b[:, t] - a[:, t], c[:, t] - a[:, t]
        n = np.cross(e1, e2)
        assert np.allclose(normal[:, t], n / np.linalg.norm(n), atol=1e-14)
        g = grad[:, :, t]
        # g_j·e_k = δ_jk (j, k = 1, 2), g_j ⊥ n, g_0 = -g_1 - g_2
        assert np.allclose([[g[1] @ e1, g[1] @ e2], [g[2] @ e1, g[2] @ e2]], np.eye(2),
                           atol=1e-10)
        assert np.allclose(g @ n, 0.0, atol=1e-10)
        assert np.allclose(g[0], -g[1] - g[2], atol=1e-14)
        # altitude at vertex j: twice the area over the opposite edge's length
        area2 = np.linalg.norm(n)
        opposite = [c[:, t] - b[:, t], e2, e1]
        assert np.allclose(altitudes[:, t], area2 / np.linalg.norm(opposite, axis=1),
                           rtol=1e-10)


def test_collapsed_triangles_are_flagged_and_not_divided_by():
    """Coincident vertices, exactly collinear ones and a sliver of height 1e-6 on a unit base
    are collapsed; a sliver of height 2e-6 is not.  For a base (0,0)-(1,0) and apex (0.5, h)
    the Gram determinant is h² and Σℓ² = 1.5 + 2h², so the threshold
    h² ≤ COLLAPSE_TOLERANCE·(Σℓ²)² lies at h ≈ 1.5e-6.  The other triangles' frames are
    those computed without the collapsed ones, bit for bit."""
    rng = np.random.default_rng(3)
    good = [rng.normal(size=(3, 3)) for _ in range(4)]
    corners = [
        [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 2.0, 0.0]],    # a = b
        [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.5, 0.5, 0.5]],    # collinear
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 1e-6, 0.0]],   # quality 2.3e-6
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 2e-6, 0.0]],   # quality 4.6e-6
        [[2.0, 3.0, 1.0], [2.0, 3.0, 1.0], [2.0, 3.0, 1.0]],    # a point
    ]
    triangles = np.array(good[:2] + corners + good[2:])         # (M, vertex, axis)
    a, b, c = (np.ascontiguousarray(triangles[:, j].T) for j in range(3))
    normal, grad, altitudes, collapsed = triangle_frames(a, b, c)
    expected = np.array([False, False, True, True, True, False, True, False, False])
    np.testing.assert_array_equal(collapsed, expected)
    assert np.isnan(grad[:, :, collapsed]).all() and np.isnan(altitudes[:, collapsed]).all()
    kept = triangles[~collapsed]
    alone = triangle_frames(*(np.ascontiguousarray(kept[:, j].T) for j in range(3)))
    for got, ref in zip((normal, grad, altitudes), alone[:3], strict=True):
        np.testing.assert_array_equal(got[..., ~collapsed], ref)
    assert np.isfinite(grad[..., ~collapsed]).all()
    # the sliver above the threshold: the altitude at its apex is its height, to the
    # determinant's rounding (1e-16·(Σℓ²)²/h² ≈ 1e-5 relative)
    assert altitudes[2, 5] == pytest.approx(2e-6, rel=1e-4)


def brute_force_pairs(x, triangles, nodes, pad, prism=False):
    corners = x[triangles]
    margin = np.full((len(triangles), 3), pad)
    if prism:
        n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        n /= np.linalg.norm(n, axis=1)[:, None]
        extent = corners.max(axis=1) - corners.min(axis=1)
        rounding = 1e-13 * (1.0 + np.abs(x).max())
        margin = pad * np.abs(n) + (1e-9 * (extent.max(axis=1) + pad) + rounding)[:, None]
    lo, hi = corners.min(axis=1) - margin, corners.max(axis=1) + margin
    xn = x[nodes]
    inside = np.all((xn[:, None] >= lo[None]) & (xn[:, None] <= hi[None]), axis=2)
    i, t = np.nonzero(inside)
    return {(int(n), int(m)) for n, m in zip(nodes[i], t, strict=True)}


def as_set(node, tri):
    pairs = set(zip(node.tolist(), tri.tolist(), strict=True))
    assert len(pairs) == len(node), "duplicate pairs"
    return pairs


def grid_sheet(n: int, z: float = 0.0, spacing: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    u = np.arange(n + 1) * spacing
    X, Y = np.meshgrid(u, u, indexing="ij")
    x = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], axis=1)
    v = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    quads = np.stack([v, v + n + 1, v + n + 2, v + 1], axis=1)
    return x, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


@pytest.mark.parametrize("prism", [False, True])
def test_broad_phase_random_soup(prism):
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 10.0, (1500, 3))
    triangles = rng.integers(0, 400, (600, 3))             # a few large, many small boxes
    small = rng.random(600) < 0.9
    for j in (1, 2):
        x[triangles[small, j]] = x[triangles[small, 0]] + rng.normal(0.0, 0.3, (small.sum(), 3))
    distinct = (triangles[:, 0] != triangles[:, 1]) & (triangles[:, 1] != triangles[:, 2]) \
        & (triangles[:, 0] != triangles[:, 2])
    triangles = triangles[distinct]
    nodes = np.arange(len(x))
    got = as_set(*candidate_pairs(x, triangles, None, 0.2, prism=prism))
    assert got == brute_force_pairs(x, triangles, nodes, 0.2, prism=prism)
    assert len(got) > 1000


def test_broad_phase_structured_nodes_on_box_faces():
    # integer grid, pad 0.5: many nodes sit exactly on box faces (closed boxes count them)
    x1, t1 = grid_sheet(12)
    x2, t2 = grid_sheet(12, z=0.5)
    x = np.concatenate([x1, x2])
    triangles = np.concatenate([t1, t2 + len(x1)])
    nodes = np.arange(len(x))
    got = as_set(*candidate_pairs(x, triangles, nodes, 0.5))
    assert got == brute_force_pairs(x, triangles, nodes, 0.5)
    # a node of the upper sheet on the face z = 0.5 of a lower box is included
    assert (len(x1) + 0, 0) in got


def test_broad_phase_subsets_of_nodes_partition_the_pairs():
    rng = np.random.default_rng(6)
    x, triangles = grid_sheet(20, spacing=0.25)
    x[:, 2] = 0.1 * np.sin(x[:, 0]) + 0.05 * rng.normal(size=len(x))
    everything = as_set(*candidate_pairs(x, triangles, None, 0.2))
    part = rng.random(len(x)) < 0.4
    first = as_set(*candidate_pairs(x, triangles, np.flatnonzero(part), 0.2))
    second = as_set(*candidate_pairs(x, triangles, np.flatnonzero(~part), 0.2))
    assert first | second == everything and not first & second
    assert first == brute_force_pairs(x, triangles, np.flatnonzero(part), 0.2)


def test_broad_phase_degenerate_inputs():
    x, triangles = grid_sheet(3)
    node, tri = candidate_pairs(x, triangles[:0], None, 0.1)
    assert node.size == tri.size == 0
    node, tri = candidate_pairs(x, triangles, np.array([], dtype=int), 0.1)
    assert node.size == tri.size == 0
    # flat scene (zero thickness along z) with zero pad still finds vertices of their triangles
    node, tri = candidate_pairs(x, triangles, None, 0.0)
    assert as_set(node, tri) == brute_force_pairs(x, triangles, np.arange(len(x)), 0.0)


def test_grid_cells_cover_every_box_corner():
    # decimal coordinates (0.1, 0.3, ...) are where floor(a / b) and a // b disagree
    for seed in range(300):
        rng = np.random.default_rng(seed)
        lo = rng.uniform(0.0, 1.0, (3, 5)).round(1)
        hi = lo + rng.choice([0.1, 0.2, 0.3], (3, 5))
        grid = CellGrid.covering(lo, hi, 10**6)
        for corner in (lo, hi):
            keys = _cell_keys(np.ascontiguousarray(corner), *grid.kernel_arguments)
            assert (keys >= 0).all()  # inside the grid
            assert keys.max() < grid.num_cells


def test_broad_phase_decimal_lattice():
    rng = np.random.default_rng(9)
    x = rng.integers(0, 12, (400, 3)) / 10.0
    triangles = np.array([rng.choice(400, 3, replace=False) for _ in range(300)])
    small = np.abs(x[triangles] - x[triangles][:, :1]).max(axis=(1, 2)) < 0.45
    triangles = triangles[small]
    nodes = np.arange(len(x))
    got = as_set(*candidate_pairs(x, triangles, None, 0.1))
    assert got == brute_force_pairs(x, triangles, nodes, 0.1)
