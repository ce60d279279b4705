"""Compiled contact loops against plain reference computations.

The Jacobian blocks they build are checked against finite differences with the contact
models (test_contact_model.py); here: the block sums and the narrow-phase tests on their
own, against loops written from the definitions."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx.contact.geometry import triangle_frames
from valve_dolfinx.contact.kernels import (
    group_blocks,
    group_index,
    narrow_rows,
    near_pairs,
    nearest_inside,
    row_block_sums,
    sum_blocks,
)
from valve_dolfinx.contact.linearisation import turning_load

# the closest point from the definitions, tests/test_contact_geometry.py
from test_contact_geometry import reference_closest


def test_block_sums_per_pair_in_input_order_sorted_and_without_zero_sums():
    rng = np.random.default_rng(3)
    n = 7
    rows, cols = rng.integers(0, n, 400), rng.integers(0, n, 400)
    blocks = rng.normal(size=(400, 3, 3)) * 10.0 ** rng.integers(-8, 8, (400, 1, 1))
    # a pair whose two blocks cancel exactly gives no block
    rows = np.append(rows, [n + 1, n + 1])
    cols = np.append(cols, [2, 2])
    blocks = np.concatenate([blocks, [np.eye(3), -np.eye(3)]])
    out_rows, out_cols, summed = sum_blocks(rows, cols, blocks, n + 2)
    expected = {}
    for r, c, b in zip(rows, cols, blocks, strict=True):  # left to right, as documented
        expected[(r, c)] = expected.get((r, c), 0.0) + b
    expected = {key: value for key, value in expected.items() if np.any(value != 0.0)}
    assert (n + 1, 2) not in expected
    assert list(zip(out_rows, out_cols, strict=True)) == sorted(expected)
    for r, c, s in zip(out_rows, out_cols, summed, strict=True):
        assert np.array_equal(s, expected[(r, c)])  # bit for bit


@pytest.mark.parametrize("count, largest", [(0, 0), (1, 0), (500, 40), (300, 10_000)])
def test_group_index_is_the_rank_among_the_distinct_labels_and_their_counts(count, largest):
    labels = np.random.default_rng(count).integers(0, largest + 1, count)
    inverse, counts = group_index(labels)
    distinct = sorted(set(labels.tolist()))
    assert inverse.tolist() == [distinct.index(g) for g in labels]
    assert counts.tolist() == [int(np.sum(labels == g)) for g in distinct]


def _summed_in_order(rows, cols, blocks):
    """{(row, col): sum of its blocks, left to right}, the all-zero sums left out."""
    expected = {}
    for r, c, b in zip(rows, cols, blocks, strict=True):
        expected[(r, c)] = expected.get((r, c), 0.0) + b
    return {key: value for key, value in expected.items() if np.any(value != 0.0)}


@pytest.mark.parametrize("geometric", [True, False])
def test_row_block_sums_are_the_row_blocks_from_their_formula_summed_in_order(geometric):
    rng = np.random.default_rng(11)
    count, m, n = 60, 4, 15
    ids = np.stack([rng.choice(n, m, replace=False) for _ in range(count)])
    B = np.concatenate([np.ones((count, 1)), -rng.uniform(0, 1, (count, m - 1))], axis=1)
    normal = rng.normal(size=(count, 3))
    own = rng.normal(size=(count, m, 3))
    magnitude = rng.uniform(0, 2, count)
    dn, dlam = rng.normal(size=(count, m, 3, 3)), rng.normal(size=(count, m - 1, m, 3))
    live = np.flatnonzero(rng.uniform(size=count) < 0.8)
    extra_rows, extra_cols = rng.integers(0, n, 50), rng.integers(0, n, 50)
    extra = rng.normal(size=(50, 3, 3))
    rows, cols, blocks = row_block_sums(live, ids, B, normal, own, magnitude, geometric, dn,
                                        dlam, extra_rows, extra_cols, extra, n)
    # the blocks one by one from the documented formula, then the extra ones
    ref_rows, ref_cols, ref_blocks = [], [], []
    for i in live:
        for r in range(m):
            for c in range(m):
                if geometric:
                    T = B[i, r] * own[i, c] - (magnitude[i] * dlam[i, r - 1, c] if r else 0.0)
                    block = np.outer(normal[i], T) + (B[i, r] * magnitude[i]) * dn[i, c]
                else:
                    block = np.outer(B[i, r] * normal[i], own[i, c])
                ref_rows.append(ids[i, r])
                ref_cols.append(ids[i, c])
                ref_blocks.append(block)
    expected = _summed_in_order([*ref_rows, *extra_rows], [*ref_cols, *extra_cols],
                                [*ref_blocks, *extra])
    assert list(zip(rows, cols, strict=True)) == sorted(expected)
    for r, c, s in zip(rows, cols, blocks, strict=True):
        assert np.allclose(s, expected[(r, c)], rtol=1e-14, atol=1e-13)


def test_group_blocks_are_the_pairwise_group_sums():
    rng = np.random.default_rng(2)
    count, m, n = 40, 4, 12
    group = rng.integers(0, 6, count)
    ids = np.stack([rng.choice(n, m, replace=False) for _ in range(count)])
    Bn, U, V = (rng.normal(size=(count, m, 3)) for _ in range(3))
    alpha, beta = rng.normal(size=count), rng.normal(size=count)
    alpha[:3] = beta[:3] = 0.0  # rows that push nothing
    rows, cols, blocks = group_blocks(group, ids, Bn, alpha, beta, U, V, n)
    expected = {}
    for i in range(count):
        for k in range(count):
            if group[i] != group[k]:
                continue
            for r in range(m):
                for c in range(m):
                    key = (group[i], ids[i, r], ids[k, c])
                    block = np.outer(alpha[i] * Bn[i, r], U[k, c]) \
                        + np.outer(beta[i] * Bn[i, r], V[k, c])
                    expected[key] = expected.get(key, 0.0) + block
    got = {}  # the blocks come per group: sum them per node pair
    for r, c, b in zip(rows, cols, blocks, strict=True):
        got[(r, c)] = got.get((r, c), 0.0) + b
    summed = {}
    for (_, r, c), b in expected.items():
        summed[(r, c)] = summed.get((r, c), 0.0) + b
    assert set(got) <= set(summed)
    for key, value in summed.items():
        assert np.allclose(got.get(key, 0.0), value, rtol=1e-12, atol=1e-12)


def test_turning_load_is_minus_the_slope_times_the_transposed_direction_derivative():
    rng = np.random.default_rng(4)
    dn, load, slope = rng.normal(size=(20, 4, 3, 3)), rng.normal(size=(20, 3)), rng.normal(size=20)
    expected = np.array([[-slope[a] * dn[a, m].T @ load[a] for m in range(4)]
                         for a in range(20)])
    assert np.allclose(turning_load(dn, load, slope), expected, rtol=1e-14, atol=1e-14)


def test_triangle_frames_are_the_unit_normal_the_dual_edge_basis_and_the_altitudes():
    rng = np.random.default_rng(8)
    a, b, c = (rng.normal(size=(3, 25)) for _ in range(3))
    normal, grad, altitudes = triangle_frames(a, b, c)
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


def test_near_pairs_keeps_exactly_the_pairs_the_definitions_keep():
    rng = np.random.default_rng(5)
    triangles = rng.normal(size=(40, 3, 3))
    points = rng.normal(size=(60, 3)) * 1.5
    num_tri, num_nodes = len(triangles), len(points)
    node = np.repeat(np.arange(num_nodes), num_tri)
    tri = np.tile(np.arange(num_tri), num_nodes)
    # frames from the definitions: unit normal, dual basis of the edges in the plane
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    grads = np.empty((num_tri, 3, 3))
    for t in range(num_tri):
        basis = np.linalg.inv(np.stack([b[t] - a[t], c[t] - a[t], normal[t]], axis=1))
        grads[t, 1], grads[t, 2] = basis[0], basis[1]
        grads[t, 0] = -grads[t, 1] - grads[t, 2]
    altitudes = 1.0 / np.linalg.norm(grads, axis=2)
    node_body = rng.integers(0, 2, num_nodes)
    triangle_body = rng.integers(0, 2, num_tri)
    side_band = rng.uniform(0.1, 0.6, (num_tri, 3))
    excluded = np.full((num_tri, 4), -1, dtype=np.int64)
    excluded[:, 0] = rng.integers(0, num_nodes, num_tri)
    search, reach = 0.8, 0.5
    got = near_pairs(node, tri, np.ascontiguousarray(points.T), np.ascontiguousarray(a.T),
                     np.ascontiguousarray(normal.T), np.ascontiguousarray(grads[:, 1].T),
                     np.ascontiguousarray(grads[:, 2].T), np.ascontiguousarray(altitudes.T),
                     node_body, triangle_body, side_band, 0.1, excluded, search, reach)
    kept = []
    for p, t in zip(node, tri, strict=True):
        r = points[p] - a[t]
        d0 = r @ normal[t]
        lam = np.array([1.0 - grads[t, 1] @ r - grads[t, 2] @ r, grads[t, 1] @ r,
                        grads[t, 2] @ r])
        band = side_band[t] if node_body[p] != triangle_body[t] else np.full(3, 0.1)
        in_band = bool(np.all(lam > -band))
        beyond = np.max(-lam * altitudes[t])
        if (abs(d0) < search and (in_band or (beyond < reach and abs(d0) < reach))
                and p not in excluded[t]):
            kept.append((p, t, d0, lam, beyond, in_band))
    assert 50 < len(kept) < len(node) // 2  # the tests cut: neither all nor none
    assert np.array_equal(got[0], [k[0] for k in kept])
    assert np.array_equal(got[1], [k[1] for k in kept])
    assert np.allclose(got[2], [k[2] for k in kept], rtol=0.0, atol=1e-12)
    assert np.allclose(got[3], [k[3] for k in kept], rtol=0.0, atol=1e-12)
    assert np.allclose(got[4], [k[4] for k in kept], rtol=0.0, atol=1e-12)
    assert np.array_equal(got[5], [k[5] for k in kept])


def test_narrow_rows_are_the_face_rows_then_the_edge_rows_within_reach():
    rng = np.random.default_rng(11)
    num_tri, num_nodes = 30, 50
    x = np.concatenate([rng.normal(size=(num_tri * 3, 3)), rng.normal(size=(num_nodes, 3))])
    triangles = np.arange(num_tri * 3).reshape(num_tri, 3)
    node = np.repeat(np.arange(num_tri * 3, len(x)), num_tri)
    tri = np.tile(np.arange(num_tri), num_nodes)
    a, b, c = (x[triangles[tri, j]] for j in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    r = x[node] - a
    d0 = np.einsum("ij,ij->i", r, normal)
    lam = np.empty((len(node), 3))
    for k in range(len(node)):
        basis = np.stack([b[k] - a[k], c[k] - a[k], normal[k]], axis=1)
        lam[k, 1:] = np.linalg.solve(basis, r[k])[:2]
    lam[:, 0] = 1.0 - lam[:, 1] - lam[:, 2]
    in_band = np.all(lam > -0.1, axis=1)
    beyond = np.zeros(len(node))  # a lower bound of the in-plane distance: the weakest one
    reach, tolerance = 0.5, 1e-10
    normal_by_axis = np.zeros((3, num_tri))
    normal_by_axis[:, tri[:num_tri]] = normal[:num_tri].T
    got = narrow_rows(node, tri, d0, lam, beyond, in_band, np.ascontiguousarray(x.T),
                      triangles, normal_by_axis, reach, reach + 1e-6, tolerance)
    face = np.flatnonzero(in_band)
    outside = np.flatnonzero((lam.min(axis=1) < -tolerance) & (np.abs(d0) < reach + 1e-6))
    q = reference_closest(x[node[outside]], a[outside], b[outside], c[outside])
    gap = np.linalg.norm(x[node[outside]] - q, axis=1)
    edge, gaps, closest = outside[gap < reach], gap[gap < reach], q[gap < reach]
    assert 20 < len(edge) and 20 < len(face)  # both kinds, and pairs of both kinds left out
    assert len(face) + len(edge) < len(node) // 2
    rows = np.concatenate([face, edge])
    assert np.array_equal(got[0], node[rows]) and np.array_equal(got[1], tri[rows])
    assert np.array_equal(got[2], d0[rows])
    assert np.isnan(got[3][:len(face)]).all()
    assert np.allclose(got[3][len(face):], gaps, rtol=0.0, atol=1e-12)
    # face rows: the projection's coordinates and the offset along the normal
    assert np.array_equal(got[4][:len(face)], lam[face])
    assert np.allclose(got[5][:len(face)], d0[face, None] * normal[face], rtol=0.0,
                       atol=1e-15)
    # edge rows: the closest point's coordinates (they sum to 1 and give the point) and the
    # offset from it
    weights = got[4][len(face):]
    assert np.allclose(weights.sum(axis=1), 1.0, atol=1e-14) and (weights >= 0.0).all()
    corners = np.stack([a[edge], b[edge], c[edge]], axis=1)
    assert np.allclose(np.einsum("kj,kjx->kx", weights, corners), closest, atol=1e-12)
    assert np.allclose(got[5][len(face):], x[node[edge]] - closest, atol=1e-12)
    assert np.array_equal(got[6], lam[rows])


@pytest.mark.parametrize("seed", range(5))
def test_nearest_inside_is_the_inside_flag_of_each_groups_nearest_pair(seed):
    rng = np.random.default_rng(seed)
    count = 400
    group = rng.integers(0, 60, count)
    # few distinct distances (ties), some unreachable (inf) and a few NaN
    distance = rng.choice([0.1, 0.2, 0.3, np.inf, np.nan], count, p=[0.3, 0.3, 0.2, 0.15, 0.05])
    inside = rng.random(count) < 0.5
    got = nearest_inside(group, distance, inside)
    # the definition: per group the smallest distance (NaN last), inside first among
    # equals, then the first pair
    for g in np.unique(group):
        members = np.flatnonzero(group == g)
        key = [(np.isnan(distance[i]), np.nan_to_num(distance[i], nan=0.0), not inside[i], i)
               for i in members]
        nearest = members[min(range(len(members)), key=key.__getitem__)]
        assert (got[members] == inside[nearest]).all()
    # and what the sort of the pairs gives
    order = np.lexsort((~inside, distance, group))
    first = order[np.unique(group[order], return_index=True)[1]]
    assert np.array_equal(got, np.isin(group, group[first[inside[first]]]))
