"""The SPEC §5 contact force law and its parameters.

Reference values come from the SPEC formula written out below with ``math``,
not from the code under test:

    f = 0                 d >= h
    f = F·exp(-k·d/F)     0 <= d < h
    f = F - k·d           d < 0

with k = 10 mN/mm and h = 0.1 mm.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from valve_dolfinx.contact import ContactParameters, contact_force, driving_force
from valve_dolfinx.contact.law import law_force
from valve_dolfinx.exceptions import ParameterError

K, H = 10.0, 0.1


def spec_force(d: float, F: float) -> float:
    if d >= H:
        return 0.0
    if d >= 0.0:
        return F * math.exp(-K * d / F)
    return F - K * d


def test_defaults_are_the_spec_law_with_the_valve_contact_layer():
    """k and h are SPEC §5's; the layer (0.25 mm) and the penetration window (0.3 mm) pad
    the search."""
    p = ContactParameters()
    assert (p.stiffness, p.cutoff) == (10.0, 0.1)
    assert p.reach == pytest.approx(0.25 + 0.1)
    assert p.search_distance == pytest.approx(0.25 + 0.3)


@pytest.mark.parametrize("F", [0.05, 0.4, 1.0, 3.0])
def test_force_matches_spec_at_sampled_distances(F):
    d = np.linspace(-0.3, 0.15, 181)
    f, _ = contact_force(d, np.full_like(d, F), K, H)
    expected = [spec_force(di, F) for di in d]
    np.testing.assert_allclose(f, expected, rtol=1e-14, atol=0.0)


def test_some_hand_values():
    # F = 1 mN: d = 0.05 → exp(-0.5) = 0.6065306597; d = -0.02 → 1.2 mN
    f, _ = contact_force(np.array([0.05, -0.02, 0.1, 0.2]), np.ones(4), K, H)
    np.testing.assert_allclose(f, [0.6065306597126334, 1.2, 0.0, 0.0], rtol=1e-13)


@pytest.mark.parametrize("F", [0.1, 1.0, 5.0])
def test_both_branches_give_F_at_contact(F):
    f, dfdd = contact_force(np.array([0.0, -1e-300, 1e-300]), np.full(3, F), K, H)
    np.testing.assert_allclose(f, F, rtol=1e-15)
    np.testing.assert_allclose(dfdd, -K, rtol=1e-15)


@pytest.mark.parametrize("F", [0.2, 1.0, 4.0])
def test_slope_is_minus_k_on_both_sides_of_zero(F):
    eps = 1e-7
    for centre in (-2 * eps, 2 * eps):  # one-sided stencils that stay in one branch
        d = np.array([centre - eps, centre + eps])
        f, _ = contact_force(d, np.full(2, F), K, H)
        assert (f[1] - f[0]) / (2 * eps) == pytest.approx(-K, rel=1e-5)


@pytest.mark.parametrize("F", [0.2, 1.0])
def test_derivative_matches_central_differences(F):
    d = np.array([-0.15, -0.01, 0.01, 0.03, 0.07, 0.095])
    _, dfdd = contact_force(d, np.full_like(d, F), K, H)
    eps = 1e-6
    fp, _ = contact_force(d + eps, np.full_like(d, F), K, H)
    fm, _ = contact_force(d - eps, np.full_like(d, F), K, H)
    np.testing.assert_allclose(dfdd, (fp - fm) / (2 * eps), rtol=1e-7)


def test_zero_at_and_beyond_cutoff():
    d = np.array([H, H + 1e-12, 0.2, 5.0])
    f, dfdd = contact_force(d, np.full(4, 2.0), K, H)
    assert np.all(f == 0.0) and np.all(dfdd == 0.0)


def test_documented_jump_at_cutoff():
    F = 1.0
    below = np.nextafter(H, 0.0)
    f, _ = contact_force(np.array([below, H]), np.full(2, F), K, H)
    assert f[0] == pytest.approx(F * math.exp(-K * H / F), rel=1e-12)  # 0.3679 mN
    assert f[1] == 0.0


def test_tiny_driving_force_leaves_a_pure_penalty():
    F = ContactParameters().min_driving_force
    f, _ = contact_force(np.array([0.05, -0.03]), np.full(2, F), K, H)
    assert f[0] == 0.0
    assert f[1] == pytest.approx(F + K * 0.03, rel=1e-12)


def test_driving_force_is_the_push_into_the_surface():
    """F = max(-f_ext·n, floor): the normal part of the pressure force pushing the node into
    the surface; a force away from it leaves the floor."""
    n = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    f_ext = np.array([[0.3, 0.0, -0.4], [0.0, 0.0, 2.0]])   # into / away from the surface
    F = driving_force(f_ext, n, ContactParameters())
    np.testing.assert_allclose(F, [0.4, 1e-9])


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("stiffness", 0.0),
        ("stiffness", -1.0),
        ("cutoff", 0.0),
        ("cutoff", float("nan")),
        ("penetration_depth", -0.1),
        ("min_driving_force", 0.0),
        ("crossing_stiffness", -1.0),
        ("crossing_width", 0.0),
    ],
)
def test_bad_parameters_raise_naming_the_parameter(field, value):
    with pytest.raises(ParameterError, match=field):
        ContactParameters(**{field: value})


def test_taper_removes_the_jump_and_keeps_the_contact_point():
    """With taper τ the force is the SPEC law up to (1-τ)h, then fades C¹ to zero at h."""
    F, tau = 3.0, 0.5
    d = np.array([-0.02, 0.0, 0.03, 0.05])  # up to (1 - τ)h = 0.05: the SPEC law exactly
    f, _ = contact_force(d, np.full_like(d, F), K, H, taper=tau)
    assert f == pytest.approx([spec_force(x, F) for x in d], rel=1e-14)
    # inside the fade: f = s(ξ)·F·exp(-kd/F), s = 1 - 3ξ² + 2ξ³, ξ = (d - h/2)/(h/2)
    d = np.array([0.06, 0.075, 0.09])
    xi = (d - 0.05) / 0.05
    expected = (1 - 3 * xi**2 + 2 * xi**3) * F * np.exp(-K * d / F)
    f, dfdd = contact_force(d, np.full(3, F), K, H, taper=tau)
    assert f == pytest.approx(expected, rel=1e-12)
    # continuous at h (no jump) and the derivative matches finite differences
    f_h, _ = contact_force(np.array([H - 1e-12, H]), np.full(2, F), K, H, taper=tau)
    assert abs(f_h[0]) < 1e-9 and f_h[1] == 0.0
    eps = 1e-7
    fp, _ = contact_force(d + eps, np.full(3, F), K, H, taper=tau)
    fm, _ = contact_force(d - eps, np.full(3, F), K, H, taper=tau)
    assert dfdd == pytest.approx((fp - fm) / (2 * eps), rel=1e-6)
    with pytest.raises(ParameterError, match="taper"):
        ContactParameters(taper=1.5)


# -- the barrier against crossing mid-surfaces (ContactParameters.crossing_stiffness) -------

def barrier_by_hand(d: float, t_c: float, k_x: float, w: float) -> float:
    e = -(d + t_c)
    if e <= 0.0:
        return 0.0
    return k_x * (e * e / (2.0 * w) if e < w else e - w / 2.0)


@pytest.mark.parametrize("t_c", [0.0, 0.25])
def test_crossing_barrier_adds_nothing_until_the_mid_surfaces_cross(t_c):
    params = ContactParameters(thickness=t_c, crossing_stiffness=1000.0, crossing_width=0.02)
    d = np.array([0.05, 0.0, -0.5 * t_c, -t_c, -t_c - 0.01, -t_c - 0.02, -t_c - 0.3])
    F = 2.0
    f, dfdd = law_force(d, F, params)
    spec = np.array([spec_force(v, F) for v in d])
    extra = np.array([barrier_by_hand(v, t_c, 1000.0, 0.02) for v in d])
    np.testing.assert_allclose(f, spec + extra, rtol=1e-12, atol=1e-12)
    assert extra[:4].max() == 0.0 and extra[-1] == pytest.approx(1000.0 * (0.3 - 0.01))
    # C¹: the derivative matches central differences, including at both kinks
    eps = 1e-7
    fd = (law_force(d + eps, F, params)[0] - law_force(d - eps, F, params)[0]) / (2 * eps)
    np.testing.assert_allclose(dfdd, fd, rtol=1e-5, atol=5e-3)  # eps × curvature jump
    # without it the law is the SPEC law alone
    f0, _ = law_force(d, F, ContactParameters(thickness=t_c, crossing_stiffness=0.0))
    np.testing.assert_allclose(f0, spec, rtol=1e-12, atol=1e-12)


def test_crossing_barrier_holds_a_pulled_node_near_the_surface():
    """A node pulled into the surface by 20 mN more than its pressure force (a taut free
    edge): without the barrier the SPEC penalty lets its mid-surface cross by
    20/k − t_c = 1.75 mm; with k_x it stops where k·|d| + k_x·(e − w/2) = 20 mN."""
    t_c, k_x, w, pull, F = 0.25, 1000.0, 0.02, 20.0, 2.0
    params = ContactParameters(thickness=t_c, crossing_stiffness=k_x, crossing_width=w)
    # on the linear branch: K·(t_c + e) + k_x·(e − w/2) = pull
    e = (pull - K * t_c + k_x * w / 2) / (K + k_x)
    d = -(t_c + e)
    f, _ = law_force(np.array([d]), F, params)
    assert e > w and f[0] == pytest.approx(F + pull, rel=1e-12)
    assert e < 0.03  # the mid-surfaces cross by 0.027 mm, not 1.75 mm
