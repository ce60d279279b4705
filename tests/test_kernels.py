"""Compiled contact loops against plain reference computations.

The Jacobian blocks they build are checked against finite differences with the contact
models (test_contact_model.py); here: the block sums and the narrow-phase tests on their
own, against loops written from the definitions."""

from __future__ import annotations

import numpy as np

from valve_dolfinx.contact.kernels import near_pairs, sum_blocks


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
