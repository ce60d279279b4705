"""Node-to-surface and node-to-plane penalty contact (SPEC §5).

Expected numbers are worked out by hand from the SPEC law (k = 10 mN/mm,
h = 0.1 mm) or come from a brute-force all-pairs reference written here with
plain loops, never from the code under test.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from valve_dolfinx.contact import (
    ContactParameters,
    ContactResult,
    PlaneContact,
    SurfaceContact,
    vertex_adjacency,
)
from valve_dolfinx.contact.narrowphase import TriangleFrames
from valve_dolfinx.contact.results import StepClock
from valve_dolfinx.contact.surface import FACE_BAND
from valve_dolfinx.exceptions import DegenerateGeometryError, MeshError, ParameterError

K, H = 10.0, 0.1
SQUARE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
SQUARE_TRIANGLES = np.array([[0, 1, 2], [0, 2, 3]])      # normals +z

#: The SPEC §5 law on zero-thickness sheets: no contact layer, no barrier against crossing
#: mid-surfaces (the valve's, ContactParameters' defaults, add both), a 0.2 mm penetration
#: window and a 0.01 mm blending width.
SPEC_LAW = ContactParameters(thickness=0.0, crossing_stiffness=0.0, penetration_depth=0.2,
                             blend_distance=0.01)
#: The law exactly as SPEC §5 states it (no taper, next to no blending): the semantics these
#: unit tests check.  The taper is tested at the end of this file and in test_contact_law.py.
LITERAL = replace(SPEC_LAW, taper=0.0, blend_distance=1e-6)


def spec_force(d: float, F: float, taper: float = 0.0) -> float:
    if d >= H:
        return 0.0
    if d < 0.0:
        return F - K * d
    f = F * math.exp(-K * d / F)
    start = (1.0 - taper) * H
    if taper > 0.0 and d > start:  # smoothstep fade over the outer part of [0, h)
        xi = (d - start) / (taper * H)
        f *= 1.0 - 3.0 * xi**2 + 2.0 * xi**3
    return f


def node_over_square(z: float, push: float = -0.8, xy=(0.4, 0.1)):
    """A free node (id 4) above the unit square; its external force is ``push`` along z."""
    x = np.vstack([SQUARE, [xy[0], xy[1], z]])
    f_ext = np.zeros_like(x)
    f_ext[4, 2] = push
    return x, f_ext


def dense_jacobian(result: ContactResult, num_nodes: int) -> np.ndarray:
    J = np.zeros((num_nodes, 3, num_nodes, 3))
    for r, c, block in zip(result.jac_rows, result.jac_cols, result.jac_blocks, strict=True):
        J[r, :, c, :] += block
    return J.reshape(3 * num_nodes, 3 * num_nodes)


def grid_sheet(n: int, m: int, spacing: float):
    u, v = np.arange(n + 1) * spacing, np.arange(m + 1) * spacing
    X, Y = np.meshgrid(u, v, indexing="ij")
    x = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    q = (np.arange(n)[:, None] * (m + 1) + np.arange(m)[None, :]).ravel()
    quads = np.stack([q, q + m + 1, q + m + 2, q + 1], axis=1)
    return x, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def stacked_sheets(cells: int = 10, spacing: float = 0.3, gap: float = 0.06, seed: int = 0):
    """Three jittered wavy sheets (bodies 0, 1, 2) ``gap`` apart, pushed together."""
    rng = np.random.default_rng(seed)
    base, tri = grid_sheet(cells, cells, spacing)
    length = cells * spacing
    interior = np.all((base[:, :2] > 0) & (base[:, :2] < length), axis=1)
    xs, tris, body, fext = [], [], [], []
    for k in range(3):
        x = base.copy()
        x[:, :2] += 0.2 * spacing * rng.uniform(-1, 1, (len(x), 2)) * interior[:, None]
        x[:, 2] = 0.3 * np.sin(2.0 * x[:, 0]) * np.cos(1.5 * x[:, 1]) + (k - 1) * gap
        xs.append(x)
        tris.append(tri + k * len(base))
        body.append(np.full(len(tri), k))
        f = np.zeros_like(x)
        f[:, 2] = (1.0 - k) * 0.5 if k != 1 else -0.3
        fext.append(f)
    return np.concatenate(xs), np.concatenate(tris), np.concatenate(body), np.concatenate(fext)


# -- (a) a single node above a flat triangle pair ----------------------------------------


@pytest.mark.parametrize("z", [0.05, 0.0, 0.099, -0.05])
def test_single_node_force_and_reactions(z):
    x, f_ext = node_over_square(z)
    contact = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL)
    contact.update_history(node_over_square(0.05)[0])      # the node came from above
    res = contact.evaluate(x, f_ext)
    f = spec_force(z, 0.8)
    assert res.n_active == 1
    # (0.4, 0.1) lies in triangle 0, and 0.3 (barycentric) beyond triangle 1's band
    assert res.pairs.tolist() == [[4, 0]]
    np.testing.assert_allclose(res.forces[4], [0.0, 0.0, f], rtol=1e-13, atol=1e-15)
    # projection (0.4, 0.1) = 0.6·(0,0) + 0.3·(1,0) + 0.1·(1,1)
    np.testing.assert_allclose(res.forces[:3, 2], [-0.6 * f, -0.3 * f, -0.1 * f], rtol=1e-12)
    assert np.all(res.forces[:4, :2] == 0.0) and res.forces[3, 2] == 0.0
    np.testing.assert_allclose(res.forces.sum(axis=0), 0.0, atol=1e-14)            # Newton III
    np.testing.assert_allclose(np.cross(x, res.forces).sum(axis=0), 0.0, atol=1e-14)  # moments
    assert res.total_force == pytest.approx(f, rel=1e-13)
    assert res.max_penetration == pytest.approx(max(-z, 0.0), abs=1e-15)


def test_node_beyond_cutoff_or_off_the_triangles_is_free():
    contact = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL)
    for x, f_ext in (node_over_square(0.1), node_over_square(0.05, xy=(1.2, 0.5))):
        res = contact.evaluate(x, f_ext)
        assert res.n_active == 0 and not res.forces.any() and res.jac_blocks.shape == (0, 3, 3)
        assert res.max_penetration == 0.0 and res.total_force == 0.0


def test_driving_force_is_the_normal_part_of_the_external_force():
    x, f_ext = node_over_square(0.05)
    f_ext[4] = [0.3, 0.0, -0.4]                              # |f_ext| = 0.5, normal part 0.4
    normal = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL).evaluate(x, f_ext)
    assert normal.forces[4, 2] == pytest.approx(spec_force(0.05, 0.4), rel=1e-13)


def test_node_above_shared_edge_contacts_its_body_once():
    x, f_ext = node_over_square(0.04, xy=(0.5, 0.5))        # on the diagonal 0–2
    res = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL).evaluate(x, f_ext)
    assert res.n_active == 1
    assert res.forces[4, 2] == pytest.approx(spec_force(0.04, 0.8), rel=1e-12)
    np.testing.assert_allclose(res.forces.sum(axis=0), 0.0, atol=1e-14)


def test_node_between_two_bodies_touches_both():
    """Square of body 7 at z = 0 (normal +z), of body 3 at z = 0.03 (normal -z); the node,
    last accepted at z = 0.02 between them, is at z = 0.04: pushed down onto body 7 by
    0.5 mN, and 0.01 mm through body 3 from below, which its pressure force does not push
    it into (F at the floor): the penalty alone pushes it back."""
    top = SQUARE + [0.0, 0.0, 0.03]
    x = np.vstack([SQUARE, top, [[0.4, 0.1, 0.04]]])
    triangles = np.vstack([SQUARE_TRIANGLES, SQUARE_TRIANGLES[:, ::-1] + 4])
    f_ext = np.zeros_like(x)
    f_ext[8] = [0.0, 0.0, -0.5]
    contact = SurfaceContact(triangles, 9, LITERAL, triangle_body=np.array([7, 7, 3, 3]))
    contact.update_history(x - [0.0, 0.0, 0.02] * (np.arange(9) == 8)[:, None])
    res = contact.evaluate(x, f_ext)
    assert res.n_active == 2
    assert sorted(res.pairs[:, 1].tolist()) == [0, 2]       # triangles over (0.4, 0.1)
    up, down = spec_force(0.04, 0.5), spec_force(-0.01, LITERAL.min_driving_force)
    assert res.forces[8, 2] == pytest.approx(up - down, rel=1e-12)
    assert res.forces[:4, 2].sum() == pytest.approx(-up, rel=1e-12)
    assert res.forces[4:8, 2].sum() == pytest.approx(down, rel=1e-12)


# -- (b) disjoint node sets sum to the whole -----------------------------------------------


def test_disjoint_node_sets_sum_to_the_all_nodes_result():
    x, triangles, body, f_ext = stacked_sheets()
    contact = SurfaceContact(triangles, len(x), LITERAL, triangle_body=body)
    contact.update_history(x)
    whole = contact.evaluate(x, f_ext)
    assert whole.n_active > 100
    rng = np.random.default_rng(7)
    mine = rng.random(len(x)) < 0.5
    parts = [contact.evaluate(x, f_ext, np.flatnonzero(mine)),
             contact.evaluate(x, f_ext, np.flatnonzero(~mine))]
    scale = np.abs(whole.forces).max()
    np.testing.assert_allclose(parts[0].forces + parts[1].forces, whole.forces, rtol=0,
                               atol=1e-12 * scale)
    assert parts[0].n_active + parts[1].n_active == whole.n_active
    assert parts[0].total_force + parts[1].total_force == pytest.approx(whole.total_force,
                                                                        rel=1e-12)
    assert max(parts[0].max_penetration, parts[1].max_penetration) == whole.max_penetration
    pairs = np.concatenate([parts[0].pairs, parts[1].pairs])
    assert sorted(map(tuple, pairs.tolist())) == sorted(map(tuple, whole.pairs.tolist()))

    def assembled(res):
        rows = (3 * res.jac_rows[:, None, None] + np.arange(3)[None, :, None]).repeat(3, 2)
        cols = (3 * res.jac_cols[:, None, None] + np.arange(3)[None, None, :]).repeat(3, 1)
        n = 3 * len(x)
        return sp.coo_matrix((res.jac_blocks.ravel(), (rows.ravel(), cols.ravel())),
                             shape=(n, n)).tocsr()

    diff = assembled(parts[0]) + assembled(parts[1]) - assembled(whole)
    # the sums differ in order only: each entry cancels terms up to ~2000 times larger
    # than the largest entry (1.9e5 against 103 mN/mm here), so its round-off is ~1e-12
    # of the largest entry
    assert abs(diff).max() <= 1e-11 * abs(assembled(whole)).max()


def test_jacobian_after_a_forces_only_call_equals_a_fresh_one():
    """A solver evaluates its residual (forces only), then its Jacobian at the same state:
    the second call reuses the first's rows; its blocks are those of a one-shot call, and
    a new accepted state (history) or new positions are not answered from the kept rows."""
    x, triangles, body, f_ext = stacked_sheets()
    x_prev = x.copy()  # sides from a state with the three sheets in the opposite order
    per_sheet = len(x) // 3
    for k in range(3):
        x_prev[k * per_sheet:(k + 1) * per_sheet, 2] -= 2 * (k - 1) * 0.06
    fresh = SurfaceContact(triangles, len(x), LITERAL, triangle_body=body)
    fresh.update_history(x_prev)
    reference = fresh.evaluate(x, f_ext)
    assert reference.n_active > 100
    contact = SurfaceContact(triangles, len(x), LITERAL, triangle_body=body)
    contact.update_history(x_prev)
    forces_only = contact.evaluate(x, f_ext, jacobian=False)
    assert len(forces_only.jac_blocks) == 0
    np.testing.assert_array_equal(forces_only.forces, reference.forces)
    second = contact.evaluate(x, f_ext)
    np.testing.assert_array_equal(second.forces, reference.forces)
    for field in ("jac_rows", "jac_cols", "jac_blocks"):
        np.testing.assert_array_equal(getattr(second, field), getattr(reference, field))
    # moved positions: evaluated afresh, not from the kept rows
    moved = x.copy()
    moved[:, 2] *= 0.5
    contact.evaluate(x, f_ext, jacobian=False)
    np.testing.assert_array_equal(contact.evaluate(moved, f_ext).jac_blocks,
                                  fresh.evaluate(moved, f_ext).jac_blocks)
    # sides forgotten and recorded afresh flip (the forces change): the kept rows of the old
    # ones are dropped
    contact.evaluate(x, f_ext, jacobian=False)
    for model in (contact, fresh):
        model.clear_history()
        model.update_history(x)
    flipped = fresh.evaluate(x, f_ext)
    assert np.abs(flipped.forces - reference.forces).max() > 1.0
    np.testing.assert_array_equal(contact.evaluate(x, f_ext).forces, flipped.forces)


# -- (c) Jacobian blocks against finite differences (n, λ, F frozen) -----------------------


@pytest.mark.parametrize("z", [-0.05, 0.03, 0.07])
def test_jacobian_matches_finite_differences(z):
    x, f_ext = node_over_square(z)
    contact = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL)
    contact.update_history(node_over_square(0.05)[0])
    J = dense_jacobian(contact.evaluate(x, f_ext), 5)
    np.testing.assert_allclose(J, J.T, atol=1e-14)          # B_p B_q symmetric
    eps = 1e-7
    n = np.array([0.0, 0.0, 1.0])
    # moving the node along n leaves n, λ and F unchanged
    step = np.zeros((5, 3))
    step[4] = eps * n
    fd = (contact.evaluate(x + step, f_ext).forces - contact.evaluate(x - step, f_ext).forces)
    np.testing.assert_allclose(J @ step.ravel(), (fd / 2).ravel(), rtol=1e-6, atol=1e-12)
    # so does translating the square along n (d changes by -eps)
    step = np.zeros((5, 3))
    step[:4] = eps * n
    fd = (contact.evaluate(x + step, f_ext).forces - contact.evaluate(x - step, f_ext).forces)
    np.testing.assert_allclose(J @ step.ravel(), (fd / 2).ravel(), rtol=1e-6, atol=1e-12)
    # and the hand value of the node's own block: (df/dd) n⊗n
    dfdd = -K if z < 0 else -K * math.exp(-K * z / 0.8)
    assert J[14, 14] == pytest.approx(dfdd, rel=1e-12)


# -- (d) own and neighbouring triangles are excluded ---------------------------------------


def test_flat_sheet_alone_has_no_contacts():
    rng = np.random.default_rng(8)
    x, triangles = grid_sheet(12, 9, 0.25)
    interior = np.all((x[:, :2] > 0) & (x[:, :2] < [3.0, 2.25]), axis=1)
    x[:, :2] += 0.1 * rng.uniform(-1, 1, (len(x), 2)) * interior[:, None]
    f_ext = np.zeros_like(x)
    f_ext[:, 2] = rng.choice([-1.0, 1.0], len(x))
    res = SurfaceContact(triangles, len(x), LITERAL).evaluate(x, f_ext)
    assert res.n_active == 0


def test_curved_sheet_alone_has_no_contacts():
    # a cylinder patch of radius 0.6 mm meshed at 0.2 mm: neighbouring triangles bend away
    x, triangles = grid_sheet(12, 8, 0.2)
    angle = x[:, 0] / 0.6
    x = np.stack([0.6 * np.sin(angle), x[:, 1], 0.6 * (1 - np.cos(angle))], axis=1)
    f_ext = np.tile([0.0, 0.0, -1.0], (len(x), 1))
    assert SurfaceContact(triangles, len(x), LITERAL).evaluate(x, f_ext).n_active == 0


def test_commissure_nodes_shared_by_two_bodies_are_excluded_from_both():
    # two sheets (bodies 0 and 1) sharing the edge x = 0 and opening as a narrow V
    a, ta = grid_sheet(6, 4, 0.25)
    b = a.copy()
    a[:, 2] = 0.06 * a[:, 0]                                 # tilted up
    b[:, 2] = -0.06 * b[:, 0]                                # tilted down, shares x = 0
    shared = np.flatnonzero(a[:, 0] == 0.0)
    ids_b = np.arange(len(b)) + len(a)
    ids_b[shared] = shared                                   # reuse the commissure nodes
    keep_b = np.setdiff1d(np.arange(len(b)), shared)
    x = np.vstack([a, b[keep_b]])
    remap = np.empty(len(b), dtype=int)
    remap[shared] = shared
    remap[keep_b] = len(a) + np.arange(len(keep_b))
    triangles = np.vstack([ta, remap[ta[:, ::-1]]])
    body = np.repeat([0, 1], len(ta))
    f_ext = np.zeros_like(x)
    f_ext[: len(a), 2] = -1.0
    f_ext[len(a):, 2] = 1.0
    contact = SurfaceContact(triangles, len(x), LITERAL, triangle_body=body)
    res = contact.evaluate(x, f_ext)
    assert not np.isin(res.pairs[:, 0], shared).any()
    # gap 0.12·x·cos θ < h for x < 0.835.  The row x = 0.25 projects onto the other
    # sheet's triangles at the commissure, which hold its neighbours (excluded), but it is
    # 0.03 mm from the edge x = 0.25 of the next triangle, whose closest point it meets
    active_x = set(x[res.pairs[:, 0], 0].tolist())
    assert active_x == {0.25, 0.5, 0.75}
    np.testing.assert_allclose(res.forces.sum(axis=0), 0.0, atol=1e-13)


def test_vertex_adjacency_table():
    table = vertex_adjacency(SQUARE_TRIANGLES, 5)
    assert table[0].tolist() == [0, 1, 2, 3]
    assert table[1].tolist() == [1, 0, 2, -1]
    assert table[4].tolist() == [4, -1, -1, -1]


# -- (e) self-contact of a folded sheet ----------------------------------------------------


def folded_sheet(gap: float = 0.05, spacing: float = 0.2, n: int = 10, m: int = 5):
    """One body folded at x = L: lower half z = 0 (normal +z), upper half z = gap (normal -z)."""
    x, triangles = grid_sheet(2 * n + 1, m, spacing)
    column = np.arange(len(x)) // (m + 1)
    length = n * spacing
    lower = column <= n
    x[lower, 0] = column[lower] * spacing
    x[~lower, 0] = length - (column[~lower] - n - 1) * spacing
    x[~lower, 2] = gap
    return x, triangles, lower


def test_folded_sheet_is_pushed_apart():
    x, triangles, lower = folded_sheet()
    f_ext = np.zeros_like(x)
    f_ext[:, 2] = np.where(lower, 0.4, -0.4)                 # pressure folds it shut
    contact = SurfaceContact(triangles, len(x), LITERAL)
    res = contact.evaluate(x, f_ext)
    assert res.n_active > 50
    assert res.max_penetration == 0.0
    assert res.forces[~lower, 2].sum() > 0 and res.forces[lower, 2].sum() < 0
    np.testing.assert_allclose(res.forces.sum(axis=0), 0.0, atol=1e-12)
    # away from the fold, every upper node is pushed up by at least its own contact
    far = ~lower & (x[:, 0] < 1.5)
    assert np.all(res.forces[far, 2] >= spec_force(0.05, 0.4) - 1e-12)


def test_folded_sheet_penetrating_itself_is_pushed_back():
    x_before, triangles, lower = folded_sheet(gap=0.05)
    x, _, _ = folded_sheet(gap=-0.03)                        # the upper half went through
    f_ext = np.zeros_like(x)
    f_ext[:, 2] = np.where(lower, 0.4, -0.4)
    contact = SurfaceContact(triangles, len(x), LITERAL)
    contact.update_history(x_before)
    res = contact.evaluate(x, f_ext)
    assert res.max_penetration == pytest.approx(0.03, rel=1e-12)
    far = ~lower & (x[:, 0] < 1.5)
    assert np.all(res.forces[far, 2] >= spec_force(-0.03, 0.4) - 1e-12)   # 0.7 mN up


# -- (f) the side a node comes from is taken from the recorded state ------------------------


def test_sidedness_from_history_pushes_a_crossed_node_back():
    before, _ = node_over_square(0.05)
    x, f_ext = node_over_square(-0.1, push=0.0)             # crossed by 0.1 < 0.2, no load
    contact = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL)
    contact.update_history(before)
    res = contact.evaluate(x, f_ext)
    floor = LITERAL.min_driving_force
    assert res.forces[4, 2] == pytest.approx(floor + K * 0.1, rel=1e-12)   # back up, 1 mN
    assert res.max_penetration == pytest.approx(0.1)
    # without the history the node is taken to be on the side it is now: d = +0.1 >= h
    contact.clear_history()
    assert contact.evaluate(x, f_ext).n_active == 0


def test_sidedness_without_history_follows_the_pressure():
    x, f_ext = node_over_square(-0.05, push=-0.8)           # pushed down: came from above
    res = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL).evaluate(x, f_ext)
    assert res.forces[4, 2] == pytest.approx(0.8 + K * 0.05, rel=1e-12)
    x, f_ext = node_over_square(-0.05, push=0.8)            # pushed up: came from below
    res = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL).evaluate(x, f_ext)
    assert res.forces[4, 2] == pytest.approx(-spec_force(0.05, 0.8), rel=1e-12)


def test_node_further_behind_than_penetration_depth_is_ignored():
    x, f_ext = node_over_square(-0.25)
    contact = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL)
    contact.update_history(node_over_square(0.05)[0])
    assert contact.evaluate(x, f_ext).n_active == 0


# -- a brute-force reference on a multi-body configuration ---------------------------------


def closest_on_segment(p, a, b):
    t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
    return a + t * (b - a), t


def smoothstep(x: float, width: float) -> float:
    xi = min(max(x / width, 0.0), 1.0)
    return xi * xi * (3 - 2 * xi)


def brute_force_forces(x, f_ext, triangles, body, x_prev, params):
    """All pairs, plain loops over the survivors: the contact rules written out directly.

    The side of every pair is the side of the triangle's plane the node was on in
    ``x_prev`` (the one recorded state: every pair here is close in it).
    Face rows where the node projects inside the triangle or within FACE_BAND
    (barycentric) outside it, with presence ``Π_j smoothstep(λ_j + band)``;
    edge/vertex rows (closest point on the boundary, found segment by segment)
    where it projects outside, within the cut-off, with presence
    ``smoothstep(s·d0/ε)·smoothstep(ρ/ε)``, ρ = √(gap² − d0²) the in-plane distance
    of the projection from the triangle (only nodes on their own side).  The rows of one
    (node, body) are blended with weights ``p e^{p(h-d)/ε}`` (normalised) and the
    group's force is scaled by ``G = 1 - Π(1 - p)``.
    """
    N, M = len(x), len(triangles)
    eps = params.blend_distance
    adjacent = np.eye(N, dtype=bool)
    for t in triangles:
        for i in range(3):
            adjacent[t[i], t[(i + 1) % 3]] = adjacent[t[(i + 1) % 3], t[i]] = True
    found: dict[tuple[int, int], list] = {}
    for node in range(N):
        for tri in range(M):
            tv = triangles[tri]
            if adjacent[node, tv].any():
                continue
            a, b, c = x[tv]
            n = np.cross(b - a, c - a)
            n /= np.linalg.norm(n)
            d0 = np.dot(x[node] - a, n)
            if abs(d0) >= params.search_distance:
                continue
            pv = x_prev[tv]
            n_prev = np.cross(pv[1] - pv[0], pv[2] - pv[0])
            s = np.sign(np.dot(x_prev[node] - pv[0], n_prev / np.linalg.norm(n_prev)))
            q = x[node] - d0 * n
            # barycentric coordinates of the projection, by areas
            area = np.dot(np.cross(b - a, c - a), n)
            lam = np.array([np.dot(np.cross(c - b, q - b), n), np.dot(np.cross(a - c, q - c), n),
                            np.dot(np.cross(b - a, q - a), n)]) / area
            rows = []
            if lam.min() > -FACE_BAND:
                fade = np.prod([smoothstep(v + FACE_BAND, FACE_BAND) for v in lam])
                rows.append((s * d0, s * n, lam, fade))
            if lam.min() < 0.0 and s * d0 > 0.0:
                cands = []
                for i, j in ((0, 1), (1, 2), (2, 0)):
                    point, t = closest_on_segment(x[node], x[tv[i]], x[tv[j]])
                    ww = np.zeros(3)
                    ww[i], ww[j] = 1 - t, t
                    cands.append((np.linalg.norm(x[node] - point), point, ww))
                gap, point, ww = min(cands, key=lambda c: c[0])
                if gap < params.cutoff:
                    in_plane = np.sqrt(max(gap * gap - d0 * d0, 0.0))
                    rows.append((gap, (x[node] - point) / gap, ww,
                                 smoothstep(s * d0, eps) * smoothstep(in_plane, eps)))
            for d, normal, w, presence in rows:
                if not -params.penetration_depth < d < params.cutoff or presence == 0.0:
                    continue
                if params.taper > 0:  # every row fades out over the last ε before the cut-off
                    presence *= smoothstep(params.cutoff - d, eps)
                found.setdefault((node, int(body[tri])), []).append(
                    (d, tri, normal, w, presence))
    forces = np.zeros_like(x)
    for (node, _), cands in found.items():
        # a row of presence p blends at the distance h - p (h - d)
        h = params.cutoff
        dmin = min(h - c[4] * (h - c[0]) for c in cands)
        blend = np.array([c[4] * math.exp(-(h - c[4] * (h - c[0]) - dmin) / eps)
                          for c in cands])
        blend /= blend.sum()
        group = 1.0 - np.prod([1.0 - c[4] for c in cands])
        for b, (d, tri, normal, w, _) in zip(blend, cands, strict=True):
            F = max(max(-np.dot(f_ext[node], normal), 0.0), params.min_driving_force)
            f = b * group * spec_force(d, F, params.taper)
            forces[node] += f * normal
            for j in range(3):
                forces[triangles[tri, j]] -= w[j] * f * normal
    return forces, len(found)


@pytest.mark.parametrize("taper", [0.0, 0.5])
def test_matches_brute_force_reference_on_three_sheets(taper):
    x, triangles, body, f_ext = stacked_sheets(cells=6, spacing=0.3, seed=3)
    x_prev = x.copy()
    x = x + np.random.default_rng(4).normal(scale=0.02, size=x.shape)
    params = replace(SPEC_LAW, taper=taper)
    contact = SurfaceContact(triangles, len(x), params, triangle_body=body)
    contact.update_history(x_prev)
    res = contact.evaluate(x, f_ext)
    expected, n_pairs = brute_force_forces(x, f_ext, triangles, body, x_prev, params)
    assert res.n_active > 30
    assert res.n_active <= n_pairs
    np.testing.assert_allclose(res.forces, expected, rtol=0, atol=1e-12)


# -- (g) rigid planes ----------------------------------------------------------------------


def test_plane_contact_law_and_jacobian():
    x = np.array([[0.0, 0.0, 0.05], [1.0, 0.0, -0.3], [2.0, 0.0, 0.05], [3.0, 0.0, 0.5]])
    f_ext = np.array([[0.0, 0.0, -0.6], [0.0, 0.0, -0.6], [0.0, 0.0, 0.6], [0.0, 0.0, -0.6]])
    plane = PlaneContact([[0.0, 0.0, 0.0]], [[0.0, 0.0, 2.0]], SPEC_LAW)   # normalised to +z
    res = plane.evaluate(x, f_ext)
    f0 = 0.6 * math.exp(-K * 0.05 / 0.6)
    assert res.forces[0, 2] == pytest.approx(f0, rel=1e-13)
    assert res.forces[1, 2] == pytest.approx(0.6 + K * 0.3, rel=1e-13)    # deep: still pushed
    assert res.forces[2, 2] == 0.0 and res.forces[3, 2] == 0.0        # pulled away / far
    assert res.n_active == 2 and res.pairs.tolist() == [[0, -1], [1, -1]]
    assert res.max_penetration == pytest.approx(0.3)
    J = dense_jacobian(res, 4)
    assert J[2, 2] == pytest.approx(-K * math.exp(-K * 0.05 / 0.6), rel=1e-13)
    assert J[5, 5] == pytest.approx(-K)
    assert np.count_nonzero(J) == 2


def test_plane_contact_node_subsets_and_two_planes():
    x = np.array([[0.05, 0.5, 0.05]])                          # in a corner of two walls
    f_ext = np.array([[-1.0, 0.0, -1.0]])
    planes = PlaneContact([[0, 0, 0], [0, 0, 0]], [[0, 0, 1], [1, 0, 0]], SPEC_LAW)
    res = planes.evaluate(x, f_ext)
    np.testing.assert_allclose(res.forces[0], [spec_force(0.05, 1.0), 0, spec_force(0.05, 1.0)],
                               rtol=1e-13)
    assert planes.evaluate(x, f_ext, np.array([], dtype=int)).n_active == 0


def test_symmetry_plane_acts_like_the_mirror_image_sheet():
    """A node δ from a symmetry plane feels the law at d = 2δ − t_c: the distance to its
    mirror image, as from a neighbouring sheet (SPEC §4 reference), twice: its own row and
    the image's reaction, as every pair of sheets is tested both ways; Jacobian by FD."""
    params = replace(SPEC_LAW, thickness=0.25, taper=0.0)
    x = np.array([[0.3, 0.0, 0.16], [1.0, 0.0, 0.05]])   # 2δ − t = 0.07 and −0.15
    f_ext = np.array([[0.0, 0.0, -2.0], [0.0, 0.0, -2.0]])
    plane = PlaneContact([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], params, mirror=True)
    res = plane.evaluate(x, f_ext)
    assert res.forces[0, 2] == pytest.approx(2 * spec_force(2 * 0.16 - 0.25, 2.0), rel=1e-12)
    assert res.forces[1, 2] == pytest.approx(2 * spec_force(2 * 0.05 - 0.25, 2.0), rel=1e-12)
    assert res.max_crossing == 0.0   # mid-surfaces 0.1 mm apart: not crossed
    J = dense_jacobian(res, 2)
    step = 1e-7
    for node in range(2):
        shifted = x.copy()
        shifted[node, 2] += step
        fd = (plane.evaluate(shifted, f_ext).forces - res.forces).ravel() / step
        np.testing.assert_allclose(J[:, 3 * node + 2], fd, rtol=1e-5, atol=1e-6)
    wall = PlaneContact([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], params)
    assert wall.evaluate(x, f_ext).forces[0, 2] == pytest.approx(
        spec_force(0.16 - 0.125, 2.0), rel=1e-12)


# -- input checks --------------------------------------------------------------------------


def test_bad_inputs_raise_named_errors():
    with pytest.raises(MeshError, match="triangle node ids"):
        SurfaceContact(np.array([[0, 1, 7]]), 5)
    with pytest.raises(MeshError, match="triangle_body"):
        SurfaceContact(SQUARE_TRIANGLES, 5, triangle_body=np.zeros(3))
    contact = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL)
    with pytest.raises(MeshError, match=r"\(5, 3\)"):
        contact.evaluate(np.zeros((4, 3)), np.zeros((5, 3)))
    with pytest.raises(MeshError, match="contact nodes"):
        contact.evaluate(np.zeros((5, 3)), np.zeros((5, 3)), np.array([5]))
    with pytest.raises(ParameterError, match="normals"):
        PlaneContact([[0, 0, 0]], [[0, 0, 0]])


def test_a_collapsed_triangle_is_named_not_divided_by():
    """Positions at which a triangle has collapsed (a vertex moved onto another) are outside
    the contact's domain: the evaluation and the history raise the named error, naming the
    triangle, its nodes and its body."""
    contact = SurfaceContact(SQUARE_TRIANGLES, 4, LITERAL, triangle_body=np.array([1, 2]),
                             body_names={2: "leaflet right_coronary"})
    x = SQUARE.copy()
    x[1] = x[0]
    with pytest.raises(DegenerateGeometryError,
                       match=r"^1 collapsed .*: triangle 0 \(nodes 0, 1, 2\) of body 1$"):
        contact.evaluate(x, np.zeros((4, 3)))
    x = SQUARE.copy()
    x[3] = x[2]
    with pytest.raises(DegenerateGeometryError,
                       match=r"triangle 1 \(nodes 0, 2, 3\) of leaflet right_coronary$"):
        contact.update_history(x)
    contact.update_history(SQUARE)  # the square itself is fine


def test_two_pressed_sheets_count_their_pair_twice():
    """Two sheets touching (d = 0), each pushed onto the other by its pressure force F.

    Every node is tested against the other body's triangles: A's nodes on B and B's nodes
    under A each push with F, so A is pushed back by 2ΣF (its own nodes' forces and the
    reactions of B's) and the sheets rest where each pass carries half the load.
    """
    xa, ta = grid_sheet(6, 6, 0.25)
    xb, tb = grid_sheet(8, 8, 0.25)
    xb = xb - [0.5, 0.5, 0.0]  # B covers A's nodes with a margin, coincident plane z = 0
    x = np.vstack([xa, xb])
    triangles = np.vstack([ta, tb + len(xa)])
    body = np.r_[np.ones(len(ta), int), np.full(len(tb), 2)]
    F = 0.3
    f_ext = np.zeros_like(x)
    f_ext[: len(xa), 2] = -F  # A is pushed down onto B ...
    f_ext[len(xa):, 2] = +F   # ... and B up onto A (A's nodes come from above B: n = +z)
    contact = SurfaceContact(triangles, len(x), SPEC_LAW, triangle_body=body)
    contact.update_history(x + np.r_[np.zeros((len(xa), 3)) + [0, 0, 0.01],
                                     np.zeros((len(xb), 3))])  # A was above B
    res = contact.evaluate(x, f_ext)
    on_b = res.forces[len(xa):, 2].sum()
    on_a = res.forces[: len(xa), 2].sum()
    # A's 49 nodes sit exactly on B, and B's nodes under A sit on A
    assert on_a == pytest.approx(2 * F * len(xa), rel=1e-12)
    assert on_a + on_b == pytest.approx(0.0, abs=1e-9)  # action = reaction


def rest_gap_of_pressed_sheets(spacing: float, shift: float) -> tuple[float, float]:
    """Two flat 8 mm sheets of ``spacing`` squares under the valve's contact (0.25 mm
    thickness, taper), the upper one shifted by ``shift`` squares, each pushed onto the other
    by 80 mmHg on its nodal areas (``F = p·spacing²``): the gap at which the contact carries
    the pressure of the middle nodes, and the nodal force F."""
    from scipy.optimize import brentq

    params = ContactParameters()
    x, cells = grid_sheet(round(8.0 / spacing), round(8.0 / spacing), spacing)
    upper = x + [shift * spacing, shift * spacing, 0.0]
    triangles = np.vstack([cells, cells + len(x)])
    body = np.r_[np.ones(len(cells), int), np.full(len(cells), 2)]
    force = 80.0 * 0.133322 * spacing**2
    f_ext = np.zeros((2 * len(x), 3))
    f_ext[: len(x), 2], f_ext[len(x):, 2] = force, -force
    middle = np.flatnonzero(np.all(np.abs(x[:, :2] - 4.0) < 2.0, axis=1))

    def carried(gap: float) -> float:  # the lower sheet's middle nodes, pushed back down
        y = np.vstack([x, upper + [0.0, 0.0, gap]])
        contact = SurfaceContact(triangles, len(y), params, triangle_body=body)
        contact.update_history(y)
        return -contact.evaluate(y, f_ext, jacobian=False).forces[middle, 2].mean()

    t = params.thickness
    return brentq(lambda gap: carried(gap) - force, t, t + 0.999 * params.cutoff), force


@pytest.mark.parametrize("spacing", [0.8, 0.4, 0.2])
@pytest.mark.parametrize("shift", [0.0, 0.5])
def test_pressed_flat_sheets_rest_at_the_gap_the_law_predicts(spacing, shift):
    """Each node meets the other sheet and is met by it, so at rest each of the two passes
    carries half the pressure: ``f(d, F) = F/2`` (the tapered SPEC §5 law), a gap of
    ``thickness + d`` that grows with the nodal force, i.e. with the element size: 0.323 mm
    at 0.8 mm elements, 0.317 at 0.4, 0.280 at 0.2.  Where neighbouring triangles' edge rows
    join the blend (fine elements, nodes above edges) they carry less than a face row at
    the same gap, so the sheets rest closer, never beyond the prediction nor inside the
    thickness."""
    from scipy.optimize import brentq

    gap, force = rest_gap_of_pressed_sheets(spacing, shift)
    d = brentq(lambda d: spec_force(d, force, taper=0.5) - 0.5 * force, 0.0, H)
    predicted = ContactParameters().thickness + d
    if spacing >= 0.4:
        assert gap == pytest.approx(predicted, rel=0.02)
    else:
        assert ContactParameters().thickness <= gap <= predicted * 1.001


@pytest.mark.parametrize("thickness", [0.0, 0.05])
def test_full_jacobian_matches_finite_differences_on_curved_sheets(thickness):
    """Blended face/edge/vertex contacts at angles, fading rows, turning driving forces.

    The Jacobian includes the turning of the contact direction, the sliding of
    the contact point, the blending weights, the presence fades and the driving
    force turning with the normal: it must match central differences of the
    forces (with the external forces frozen, as the solver freezes them).
    """
    x, triangles, body, f_ext = stacked_sheets(cells=6, spacing=0.3, seed=5)
    rng = np.random.default_rng(6)
    f_ext = f_ext + rng.normal(scale=0.2, size=f_ext.shape)
    x_prev = x.copy()
    x = x + rng.normal(scale=0.02, size=x.shape)
    params = replace(SPEC_LAW, blend_distance=0.02, thickness=thickness)
    contact = SurfaceContact(triangles, len(x), params, triangle_body=body)
    contact.update_history(x_prev)
    res = contact.evaluate(x, f_ext)
    assert res.n_active > 30
    J = dense_jacobian(res, len(x))
    for eps in (1e-6, 1e-7):
        step = rng.normal(size=x.shape) * eps
        fd = (contact.evaluate(x + step, f_ext).forces
              - contact.evaluate(x - step, f_ext).forces) / 2
        np.testing.assert_allclose(J @ step.ravel(), fd.ravel(), rtol=0,
                                   atol=1e-5 * np.abs(fd).max())


def test_forces_only_evaluation_gives_the_same_forces_and_diagnostics():
    """``jacobian=False`` (forces for output and diagnostics) skips the blocks, nothing else."""
    x, triangles, body, f_ext = stacked_sheets(cells=6, spacing=0.3, seed=3)
    x_prev = x.copy()
    x = x + np.random.default_rng(4).normal(scale=0.02, size=x.shape)
    contact = SurfaceContact(triangles, len(x), replace(SPEC_LAW, thickness=0.1),
                             triangle_body=body)
    contact.update_history(x_prev)
    full = contact.evaluate(x, f_ext)
    light = contact.evaluate(x, f_ext, jacobian=False)
    assert full.n_active > 30 and len(full.jac_blocks) > 0 and len(light.jac_blocks) == 0
    np.testing.assert_array_equal(light.forces, full.forces)
    for name in ("n_active", "max_penetration", "total_force", "max_crossing"):
        assert getattr(light, name) == getattr(full, name)
    np.testing.assert_array_equal(light.pairs, full.pairs)


def test_a_deep_row_fading_out_hands_over_smoothly():
    """A node 0.05 above sheet T1 and 0.55 behind the plane of T2 (same body), sliding off T2.

    Beyond T2's edge its face row fades out across the band (presence 1 -> 0 over
    1 mm here).  Over T2 the deep row dominates the blend: the node is pushed with
    ``F + k·0.55`` = 6.5 mN.  Past the band only T1's row is left:
    ``F e^{-k·0.05/F}`` = 0.607 mN.  The handover must be gradual.  With the plain
    softmin ``p e^{-d/ε}`` the deep row kept its whole weight until its presence
    was ~1e-6 and the force fell by 5 mN within 3e-3 mm (a slope of ~2700 mN/mm
    at this sampling; at the valve's triple point, 6 mN within 1e-5 mm).
    """
    x = np.array([[-5, -5, 0], [5, -5, 0], [0, 5, 0],             # T1, normal +z
                  [0, -5, 0.6], [10, 0, 0.6], [0, 5, 0.6],         # T2, normal +z, edge x = 0
                  [0, 0, 0.05]], dtype=float)                       # the node
    triangles = np.array([[0, 1, 2], [3, 4, 5]])
    f_ext = np.zeros_like(x)
    f_ext[6, 2] = -1.0                                              # F = 1 mN into both
    contact = SurfaceContact(triangles, len(x), replace(SPEC_LAW, penetration_depth=1.0,
                                                        blend_distance=0.05))
    beyond = np.concatenate([np.geomspace(1e-9, 1e-3, 60), np.linspace(1e-3, 1.0, 400)[1:]])
    positions = -1.0 + beyond                                       # the band is x in (-1, 0)
    force = []
    for px in positions:
        y = x.copy()
        y[6, 0] = px
        force.append(contact.evaluate(y, f_ext, np.array([6])).forces[6])
    force = np.array(force)
    np.testing.assert_allclose(force[0], [0, 0, math.exp(-0.5)], atol=1e-9)     # T1 only
    np.testing.assert_allclose(force[-1], [0, 0, 6.5], atol=1e-3)               # T2 dominates
    slope = np.linalg.norm(np.diff(force, axis=0), axis=1) / np.diff(positions)
    assert slope.max() < 200.0                                      # measured 33 mN/mm


def test_face_band_beyond_a_free_edge_fades_smoothly_with_exact_jacobian():
    """A node 0.15 beyond the square's free edge x = 1, 0.05 above its plane.

    Default bands: out of reach (distance to the edge 0.158 > h).  With
    ``boundary_band = 1`` the face row of triangle (0, 1, 2) reaches it (the
    search boxes are 0.2 wide) with presence smoothstep((λ0 + 1)/1),
    λ0 = 1 - x = -0.15: 0.85²(3 - 1.7) = 0.93925.
    """
    x, f_ext = node_over_square(0.05, xy=(1.15, 0.5))
    assert not np.any(SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL).evaluate(x, f_ext).forces)
    contact = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL, boundary_band=1.0)
    contact.update_history(x)
    result = contact.evaluate(x, f_ext)
    assert result.forces[4] == pytest.approx([0.0, 0.0, 0.93925 * spec_force(0.05, 0.8)], rel=1e-9)
    np.testing.assert_allclose(result.forces.sum(axis=0), 0.0, atol=1e-12)
    J = dense_jacobian(result, 5)
    rng = np.random.default_rng(3)
    eps = 1e-7
    for _ in range(3):
        step = eps * rng.normal(size=(5, 3))
        fd = contact.evaluate(x + step, f_ext).forces - contact.evaluate(x - step, f_ext).forces
        np.testing.assert_allclose(J @ step.ravel(), (fd / 2).ravel(), rtol=1e-5, atol=1e-11)


@pytest.mark.parametrize(("x_node", "counted"), [(1.05, True), (1.19, False)])
def test_penetration_is_measured_only_over_the_surface(x_node, counted):
    """A node 0.05 below the square's plane, beyond its free edge x = 1, face band 0.3.

    Presence smoothstep((λ0 + 0.3)/0.3) with λ0 = 1 - x: 0.926 at x = 1.05 (over the
    band: a penetration of 0.05 mm), 0.305 at x = 1.19 (the node has slid past the
    edge: it is still pushed, faintly, but it has not crossed the sheet).
    """
    x, f_ext = node_over_square(-0.05, xy=(x_node, 0.5))
    contact = SurfaceContact(SQUARE_TRIANGLES, 5, LITERAL, boundary_band=0.3)
    contact.update_history(node_over_square(0.05, xy=(x_node, 0.5))[0])
    result = contact.evaluate(x, f_ext)
    assert result.forces[4, 2] > 0.0
    assert result.max_penetration == pytest.approx(0.05 if counted else 0.0, abs=1e-12)


def test_edge_row_fades_in_as_the_projection_leaves_the_triangle():
    """A node crossing the square's boundary edge x = 1 in its plane's projection.

    Inside, only the face row acts; just outside, the face row (fading over the
    band) and the edge row (closest point on the edge, same distance) both exist.
    At d = 0.08 mm both are faded by the cut-off taper (presence 0.35), so the
    group's presence 1 − Π(1 − p) would jump from 0.35 to 0.58 if the edge row
    appeared at once.  Its presence grows from 0 with the in-plane distance ρ of the
    projection (smoothstep(ρ/ε)), so the force is continuous across the edge (a jump
    makes Newton cycle on a graft node near a free edge) and the Jacobian, fade
    included, matches central differences on a tilted square.
    """
    params = replace(SPEC_LAW, blend_distance=0.05)
    contact = SurfaceContact(SQUARE_TRIANGLES, 5, params)
    delta = 1e-7
    inside, f_ext = node_over_square(0.08, xy=(1.0 - delta, 0.5))
    outside, _ = node_over_square(0.08, xy=(1.0 + delta, 0.5))
    contact.update_history(node_over_square(0.06, xy=(1.0, 0.5))[0])
    jump = contact.evaluate(outside, f_ext).forces - contact.evaluate(inside, f_ext).forces
    assert np.max(np.abs(jump)) < 1e-4
    rng = np.random.default_rng(7)
    x, f_ext = node_over_square(0.08, xy=(1.02, 0.45))   # ρ = 0.02 < ε: inside the fade
    x[:4, 2] += 0.01 * rng.normal(size=4)                # tilt and warp the square a little
    contact.update_history(x + np.array([0.0, 0.0, 0.02]))
    result = contact.evaluate(x, f_ext)
    assert result.forces[4, 2] > 0.0
    J = dense_jacobian(result, 5)
    eps = 1e-7
    for _ in range(4):
        step = eps * rng.normal(size=(5, 3))
        fd = contact.evaluate(x + step, f_ext).forces - contact.evaluate(x - step, f_ext).forces
        np.testing.assert_allclose(J @ step.ravel(), (fd / 2).ravel(), rtol=1e-5, atol=1e-10)


def test_search_finds_every_pair_of_the_fade_bands_corners_and_all():
    """The box test may pass extra pairs but must lose none that the narrow phase keeps.

    A face row whose projection lies in its fade band ``{λ_j > -b_j}`` beyond a corner of
    its triangle (two coordinates negative) has a finite presence: a box that cut it off
    would make it appear with a jump in the force.  The band of a lone flat obtuse triangle
    (every side a free edge, band 1) reaches its corner ``3X_0 - X_1 - X_2 = (-1.5, -0.15)``,
    five times the triangle's largest altitude from vertex 0; a grid of free nodes 0.1 above
    and below its plane, every (node, triangle) pair through the narrow phase's tests, and
    all of them must be among the searched ones."""
    u, v = np.meshgrid(np.linspace(-2.0, 3.0, 51), np.linspace(-1.0, 1.2, 23), indexing="ij")
    grid = np.stack([u.ravel(), v.ravel(), np.full(u.size, 0.1)], axis=1)
    x = np.concatenate([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.15, 0.0]], grid,
                        grid * [1.0, 1.0, -1.0]])
    triangles = np.array([[0, 1, 2]])
    contact = SurfaceContact(triangles, len(x), SPEC_LAW, boundary_band=1.0)
    xt = np.ascontiguousarray(x.T)
    frames = TriangleFrames.at(xt, triangles)
    nodes = np.arange(3, len(x))
    found = contact._narrow(xt, frames, contact._search(xt, frames, nodes, StepClock()))
    every = contact._narrow(xt, frames, contact._near(
        xt, frames, nodes, np.zeros(len(nodes), dtype=np.int64), contact.search_distance))
    face_corner = np.isnan(every[3]) & (np.sum(every[6] < 0.0, axis=1) == 2)
    assert face_corner.sum() > 50                   # face rows beyond a corner are in the test
    np.testing.assert_array_equal(np.sort(found[0]), np.sort(every[0]))
