"""The narrow phase's compiled tests (valve_dolfinx.contact.narrowphase) against plain loops
written from their definitions.

The whole search against an all-pairs reference on three sheets is in
test_contact_model.py; here: which pairs each pass keeps, in which order, and what it
returns for them."""

from __future__ import annotations

import numpy as np

# the closest point from the definitions, tests/test_contact_geometry.py
from test_contact_geometry import reference_closest

from valve_dolfinx.contact.narrowphase import NearPairs, TriangleFrames, narrow_rows, near_pairs


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
    by_axis = [np.ascontiguousarray(v.T) for v in (a, normal, grads[:, 1], grads[:, 2], altitudes)]
    frames = TriangleFrames(*by_axis, gradients_by_triangle=grads,
                            collapsed=np.zeros(num_tri, dtype=bool))
    got = near_pairs(node, tri, np.ascontiguousarray(points.T), frames, node_body=node_body,
                     triangle_body=triangle_body, side_band=side_band, face_band=0.1,
                     excluded=excluded, search_distance=search, reach=reach)
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
    near = NearPairs(node=node, tri=tri, d0=d0, lam=lam, beyond=beyond, in_band=in_band)
    got = narrow_rows(near, np.ascontiguousarray(x.T), triangles, normal_by_axis, reach=reach,
                      bound=reach + 1e-6, inside_tolerance=tolerance)
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
