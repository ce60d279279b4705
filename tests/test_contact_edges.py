"""Scissors contact of free-edge segments (valve_dolfinx.contact.edges)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from valve_dolfinx.contact import ContactParameters
from valve_dolfinx.contact.edges import EdgeContact, closest_points_on_lines

K, H = 10.0, 0.1
LITERAL = ContactParameters(taper=0.0, blend_distance=0.01)


def crossing(z: float, push: float = 1.0):
    """Segment 0-1 along x at height z over segment 2-3 along y; node forces push them together."""
    x = np.array([[-1.0, 0.1, z], [1.0, 0.1, z], [0.2, -1.0, 0.0], [0.2, 1.0, 0.0]])
    f_ext = np.array([[0, 0, -push], [0, 0, -push], [0, 0, push], [0, 0, push]], dtype=float)
    return x, np.array([[0, 1], [2, 3]]), f_ext


def dense(result, n):
    J = np.zeros((n, 3, n, 3))
    for r, c, b in zip(result.jac_rows, result.jac_cols, result.jac_blocks, strict=True):
        J[r, :, c, :] += b
    return J.reshape(3 * n, 3 * n)


def test_closest_points_on_lines_against_brute_force():
    rng = np.random.default_rng(0)
    a0, a1, b0, b1 = (rng.normal(size=(50, 3)) for _ in range(4))
    s, t, sin = closest_points_on_lines(a0, a1, b0, b1)
    for i in range(50):
        grid = np.linspace(-3, 4, 1401)
        # minimise over s for the optimal t, then check the returned pair is not beaten
        p = a0[i] + s[i] * (a1[i] - a0[i])
        q = b0[i] + t[i] * (b1[i] - b0[i])
        best = np.linalg.norm(p - q)
        pts_a = a0[i] + grid[:, None] * (a1[i] - a0[i])
        pts_b = b0[i] + grid[:, None] * (b1[i] - b0[i])
        brute = np.min(np.linalg.norm(pts_a[:, None] - pts_b[None], axis=2))
        assert best <= brute + 1e-12
        assert 0.0 < sin[i] <= 1.0


@pytest.mark.parametrize("z", [0.05, -0.03])
def test_scissors_force_law_direction_and_balance(z):
    x, segments, f_ext = crossing(0.5)
    contact = EdgeContact(segments, 4, LITERAL)
    contact.update_history(x)                  # segment a above b: side recorded far apart
    x[:2, 2] = z                               # a lowered to z above (or below) b
    res = contact.evaluate(x, f_ext)
    # closest points: s = 0.6 on a (x = 0.2), t = 0.55 on b (y = 0.1); d = z (signed)
    F = 0.4 * 1.0 + 0.6 * 1.0                  # pressure force at p pushing a down onto b
    expected = F * math.exp(-K * z / F) if z >= 0 else F - K * z
    np.testing.assert_allclose(res.forces[0], [0, 0, 0.4 * expected], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(res.forces[1], [0, 0, 0.6 * expected], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(res.forces[2], [0, 0, -0.45 * expected], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(res.forces.sum(axis=0), 0.0, atol=1e-13)       # Newton III
    # moments balance too: the forces act at one point pair along the common normal
    moment = np.cross(x, res.forces).sum(axis=0)
    np.testing.assert_allclose(moment, 0.0, atol=1e-12)
    assert res.max_penetration == pytest.approx(max(-z, 0.0))


def test_crossed_pair_is_pushed_back_and_far_pair_is_free():
    x, segments, f_ext = crossing(0.5)
    contact = EdgeContact(segments, 4, LITERAL)
    contact.update_history(x)
    x[:2, 2] = 0.5
    assert contact.evaluate(x, f_ext).n_active == 0              # beyond the cut-off
    x[:2, 2] = -0.08                                             # crossed: still pushed up
    res = contact.evaluate(x, f_ext)
    assert res.forces[0, 2] > 0 and res.forces[2, 2] < 0
    # a crossing near a segment end is faded out, not cut off: p at s = 0.9975, half a
    # fade width (0.01 mm) from the end, gets the smoothstep's middle value 1/2
    x2 = x.copy()
    x2[:2, 0] -= 0.795
    weak = contact.evaluate(x2, f_ext)
    assert weak.total_force == pytest.approx(0.5 * res.total_force, rel=1e-9)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_jacobian_matches_finite_differences(seed):
    """The full Jacobian (distance, turning normal, sliding points, driving force, fades)."""
    rng = np.random.default_rng(seed)
    # two zig-zag polylines crossing each other within reach, with random jitter
    u = np.linspace(-1.0, 1.0, 6)
    line_a = np.stack([u, 0.15 * np.sin(3 * u), 0.04 + 0.0 * u], axis=1)
    line_b = np.stack([0.1 * np.cos(2 * u), u, 0.0 * u], axis=1)
    x = np.concatenate([line_a, line_b]) + rng.normal(scale=0.01, size=(12, 3))
    segments = np.array([[i, i + 1] for i in range(5)] + [[6 + i, 7 + i] for i in range(5)])
    f_ext = rng.normal(scale=0.3, size=(12, 3))
    f_ext[:6, 2] -= 1.0
    f_ext[6:, 2] += 1.0
    params = ContactParameters(taper=0.5, blend_distance=0.02)
    contact = EdgeContact(segments, 12, params)
    far = x.copy()
    far[:6, 2] += 1.0
    contact.update_history(far)
    res = contact.evaluate(x, f_ext)
    assert res.n_active >= 1
    J = dense(res, 12)
    for eps in (1e-6,):
        step = rng.normal(size=x.shape) * eps
        fd = (contact.evaluate(x + step, f_ext).forces
              - contact.evaluate(x - step, f_ext).forces) / 2
        np.testing.assert_allclose(J @ step.ravel(), fd.ravel(), rtol=0,
                                   atol=1e-7 * np.abs(fd).max() + 1e-14)


def test_disjoint_node_sets_sum_to_the_whole():
    """Each pair is evaluated by the owner of its first segment's first node, so the results
    of the ranks of a partition (the hook passes each rank's owned nodes) sum to the serial
    result, Jacobian included."""
    rng = np.random.default_rng(4)
    u = np.linspace(-1.0, 1.0, 9)
    x = np.concatenate([np.stack([u, 0.1 * np.sin(3 * u), 0.03 + 0 * u], axis=1),
                        np.stack([0.1 * np.cos(2 * u), u, 0 * u], axis=1),
                        np.stack([u, 0.3 - 0.1 * u, 0.02 + 0 * u], axis=1)])
    x += rng.normal(scale=0.005, size=x.shape)
    segments = np.array([[k * 9 + i, k * 9 + i + 1] for k in range(3) for i in range(8)])
    f_ext = np.zeros_like(x)
    f_ext[:9, 2], f_ext[9:18, 2], f_ext[18:, 2] = -1.0, 1.0, -1.0   # a ↓ onto b, b ↑ onto c
    contact = EdgeContact(segments, len(x), ContactParameters())
    far = x.copy()
    far[:9, 2] += 1.0
    contact.update_history(far)
    whole = contact.evaluate(x, f_ext)
    assert whole.n_active >= 2
    mine = (np.arange(len(x)) < 9) | (rng.random(len(x)) < 0.3)   # a-b pairs: part 0
    parts = [contact.evaluate(x, f_ext, np.flatnonzero(mine)),
             contact.evaluate(x, f_ext, np.flatnonzero(~mine))]
    assert all(p.n_active > 0 for p in parts)
    np.testing.assert_allclose(parts[0].forces + parts[1].forces, whole.forces, rtol=0,
                               atol=1e-14 * np.abs(whole.forces).max())
    J = dense(parts[0], len(x)) + dense(parts[1], len(x))
    np.testing.assert_allclose(J, dense(whole, len(x)), rtol=0, atol=1e-14 * np.abs(J).max())
    assert parts[0].n_active + parts[1].n_active == whole.n_active


def test_reference_exclusion_drops_nearby_segments_of_one_polyline():
    x = np.array([[0, 0, 0], [1, 0, 0], [1.05, 0.3, 0], [0.05, 0.3, 0.0]], dtype=float)
    segments = np.array([[0, 1], [1, 2], [2, 3]])
    assert len(EdgeContact(segments, 4).pairs) == 1                         # 0-1 with 2-3
    assert len(EdgeContact(segments, 4, reference=x, exclusion_radius=0.5).pairs) == 0
