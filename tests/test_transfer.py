"""A loaded valve's shape carried onto another mesh of the valve (geometry.transfer).

The unloaded valve is the test field: every leaflet lies on the wrap cylinder of radius
d/2 = 10 mm, an exact map of its flat coordinates (an isometry).  Carried from a coarse
mesh by linear interpolation, a point lands on a chord of that cylinder: inside by at most
the sagitta c²/(8R) of the longest chord c, and the error falls as the square of the
source's mesh size.
"""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx.exceptions import MeshError
from valve_dolfinx.geometry.symmetry import single_leaflet
from valve_dolfinx.geometry.transfer import native_frame, transfer_positions
from valve_dolfinx.geometry.valve import build_valve

R = 10.0  # the wrap cylinder's radius (mm)


def _longest_edge(valve) -> float:
    p = valve.points[valve.cells]
    return max(np.linalg.norm(p[:, (k + 1) % 3] - p[:, k], axis=1).max() for k in range(3))


def _radius(points: np.ndarray) -> np.ndarray:
    return np.linalg.norm(points[:, :2], axis=1)


def test_a_valve_carried_onto_itself_is_unchanged():
    valve = build_valve(mesh_size=2.0)
    moved = valve.points + np.array([0.3, -0.2, 1.1]) * valve.points[:, 2:3] / 10.0
    assert np.allclose(transfer_positions(valve, moved, valve), moved, atol=1e-12)


def test_coarse_to_fine_lands_on_the_cylinder_within_the_chord_sagitta():
    fine = build_valve(mesh_size=0.8)
    errors = []
    for size in (2.0, 1.0):
        coarse = build_valve(mesh_size=size)
        carried = transfer_positions(coarse, coarse.points, fine)
        sagitta = _longest_edge(coarse) ** 2 / (8 * R)
        error = R - _radius(carried)
        assert error.max() <= sagitta * (1 + 1e-9)
        assert error.min() >= -1e-9  # on or inside the cylinder: chords, never beyond
        # heights are linear in the flat coordinates: exact inside the coarse outline, off
        # by less than the lower edge's own sagitta (y'' <= 2/(d tan 34°)) just outside it
        dz = np.abs(carried[:, 2] - fine.points[:, 2])
        assert np.mean(dz < 1e-9) > 0.9
        assert dz.max() <= _longest_edge(coarse) ** 2 / 8 * 2 / (2 * R * np.tan(np.radians(34)))
        errors.append(error.max())
    # second order: halving the source's mesh size divides the error by about four
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.5)


def test_graft_laid_over_the_native_leaflet_it_replaces():
    normal = build_valve(mesh_size=1.0)
    graft = build_valve(mesh_size=1.0, graft_width_pct=27, graft_height_pct=40)
    carried = transfer_positions(normal, normal.points, graft)
    patch = graft.leaflet("non_coronary")
    native = normal.leaflet("non_coronary")
    # the native frame takes the graft's outline onto the native one
    frame = native_frame(patch)
    assert frame[:, 0].min() == pytest.approx(native.flat[:, 0].min(), abs=1e-9)
    assert frame[:, 1].max() == pytest.approx(native.flat[:, 1].max(), abs=1e-9)
    # on the wrap cylinder as the native leaflet is, and within its angular span
    sagitta = _longest_edge(normal) ** 2 / (8 * R)
    assert np.all(np.abs(_radius(carried[patch.nodes]) - R) <= sagitta)
    centre = 4 * np.pi / 3  # the non-coronary position
    xy = carried[patch.nodes, :2]
    offset = np.arctan2(xy[:, 1] * np.cos(centre) - xy[:, 0] * np.sin(centre),
                        xy[:, 0] * np.cos(centre) + xy[:, 1] * np.sin(centre))
    assert np.abs(offset).max() <= np.pi / 3 + 1e-9
    # the graft's midline free-edge node lands on the native one's
    tip = carried[patch.nodes[patch.midline_free_edge_node]]
    assert np.allclose(tip, normal.points[native.nodes[native.midline_free_edge_node]],
                       atol=1e-9)
    # the native leaflets are the same mesh in both valves: carried exactly
    for name in ("left_coronary", "right_coronary"):
        nodes = graft.leaflet(name).nodes
        assert np.allclose(carried[nodes], graft.points[nodes], atol=1e-12)


def test_valves_with_other_leaflets_are_refused():
    valve = build_valve(mesh_size=2.0)
    with pytest.raises(MeshError, match="leaflets"):
        transfer_positions(valve, valve.points, single_leaflet(valve))
    with pytest.raises(MeshError, match="nodes"):
        transfer_positions(valve, valve.points[:-1], valve)
