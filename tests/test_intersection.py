"""Crossing of two leaflets' surfaces (analysis/intersection.py) on constructed sheets whose
intersection is known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx.analysis.intersection import leaflet_intersections

CELLS = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
TAGS = np.array([1, 1, 2, 2])


def _sheets(offset_b: float = 0.0, angle_deg: float = 90.0, shift=(0.0, 0.0, 0.0)):
    """Sheet 1: the plane y = 0, x in [-1, 1], z in [0, 2]; sheet 2: the same rotated
    about the z axis by ``angle_deg`` and moved ``offset_b`` along x; both moved by ``shift``."""
    square = np.array([[-1, 0, 0], [1, 0, 0], [1, 0, 2], [-1, 0, 2]], float)
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    rotated = square @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
    return np.vstack([square, rotated + [offset_b, 0, 0]]) + shift


@pytest.mark.parametrize("angle", [90.0, 30.0])
def test_crossing_sheets_cross_along_their_common_line(angle):
    # the two planes meet in the z axis: a line of the sheets' height, 2 mm, at r = 0
    (pair,) = leaflet_intersections(_sheets(angle_deg=angle), CELLS, TAGS, root_radius_mm=10.0)
    assert pair.leaflets == (1, 2)
    assert pair.total_mm == pytest.approx(2.0, abs=1e-9)
    assert pair.inner_mm == pytest.approx(2.0, abs=1e-9)
    assert pair.inner_radius_mm == pytest.approx((0.0, 0.0), abs=1e-9)
    assert 0.0 <= pair.inner_height_mm[0] <= pair.inner_height_mm[1] <= 2.0


def test_a_crossing_at_the_root_wall_is_not_inner():
    # the same crossing moved to 9.5 mm from the axis, within 1 mm of a 10 mm root wall
    (pair,) = leaflet_intersections(_sheets(shift=(9.5, 0.0, 0.0)), CELLS, TAGS,
                                    root_radius_mm=10.0)
    assert pair.total_mm == pytest.approx(2.0, abs=1e-9)
    assert pair.inner_mm == 0.0 and pair.inner_radius_mm is None


def test_separate_sheets_do_not_cross():
    # sheet 2 perpendicular to sheet 1 but 3 mm along x, beyond sheet 1's end at x = 1
    (pair,) = leaflet_intersections(_sheets(offset_b=3.0), CELLS, TAGS, root_radius_mm=10.0)
    assert pair.total_mm == 0.0 and pair.inner_mm == 0.0
