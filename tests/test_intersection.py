"""The intersection check (analysis/intersection.py) on surfaces built by hand, whose
intersecting edge–triangle pairs, their places and their distances from the seam are
known in closed form; and the competence it decides (result.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from valve_dolfinx.analysis.intersection import (
    IntersectingPair,
    Intersections,
    commissure_posts,
    find_intersections,
)
from valve_dolfinx.result import CaseResult, competence, competence_text, leaflets_intersect

ipctk = pytest.importorskip("ipctk")


def _library_says(points: np.ndarray, cells: np.ndarray) -> bool:
    """The library's own yes/no over the same surface (its default broad phase)."""
    faces = np.asfortranarray(cells, dtype=np.int32)
    vertices = np.asfortranarray(points, dtype=float)
    mesh = ipctk.CollisionMesh(vertices, np.asfortranarray(ipctk.edges(faces)), faces)
    return ipctk.has_intersections(mesh, vertices)


def _pairs(found: Intersections) -> set[tuple]:
    return {(p.edge, p.triangle, p.leaflets) for p in found.pairs}


def test_two_crossing_triangles_give_the_edge_through_each():
    """Triangle a in z = 0, triangle b in x = 0.5: b's vertical edge pierces a at
    (0.5, 0.5, 0) and a's long side pierces b at (0.5, 1.5, 0), the two ends of the line
    they share; no other edge meets the other triangle."""
    points = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0],          # a
                       [0.5, 0.5, -1], [0.5, 0.5, 1], [0.5, 3, 0]], float)  # b
    cells = np.array([[0, 1, 2], [3, 4, 5]])
    found = find_intersections(points, cells, np.array([1, 2]), {1: "a", 2: "b"})
    assert _pairs(found) == {((3, 4), 0, ("b", "a")), ((1, 2), 1, ("a", "b"))}
    where = {p.edge: p.point for p in found.pairs}
    assert where[(3, 4)] == pytest.approx((0.5, 0.5, 0.0), abs=1e-12)
    assert where[(1, 2)] == pytest.approx((0.5, 1.5, 0.0), abs=1e-12)
    assert found.between() == {"a/b": 2}
    assert found.where() == "no post to measure from (a/b 2)"  # the two share no seam
    assert _library_says(points, cells)


def _book(angle_deg: float, own_spine: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Two pages of two triangles each, 2 mm × 2 mm, bound along the z axis (the spine,
    nodes 0 and 1), page 2 turned ``angle_deg`` from page 1 about the spine; with
    ``own_spine`` page 2 has its own copies of the spine's nodes, at the same places."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    points = np.array([[0, 0, 0], [0, 0, 2], [2, 0, 0], [2, 0, 2],
                       [2 * c, 2 * s, 0], [2 * c, 2 * s, 2], [0, 0, 0], [0, 0, 2]], float)
    spine = (6, 7) if own_spine else (0, 1)
    cells = np.array([[0, 2, 3], [0, 3, 1], [spine[0], 4, 5], [spine[0], 5, spine[1]]])
    return points, cells


@pytest.mark.parametrize("angle", [90.0, 2.0])
@pytest.mark.parametrize("own_spine", [False, True])
def test_sheets_that_share_only_their_seam_do_not_intersect(angle, own_spine):
    """Pages bound along a spine, open wide or nearly closed (2°, 0.07 mm apart at the
    edge): every edge on the spine touches the other page's triangles there, and those
    pairs share a vertex, so none counts; nor when the spine's nodes are copies at the
    same places (a valve drawn as a leaflet and its mirror images)."""
    points, cells = _book(angle, own_spine)
    found = find_intersections(points, cells, np.array([1, 1, 2, 2]))
    assert found.count == 0 and found.where() == "" and found.candidates > 0
    assert not own_spine or _library_says(points, cells)  # the library sees the copies
    assert own_spine or not _library_says(points, cells)


def _folded_strip() -> tuple[np.ndarray, np.ndarray]:
    """A 1 mm wide strip (y in [0, 1]) along the polyline A(0,0,0) B(2,0,0) C(2,0,1)
    D(1,0,-1): its last panel C–D runs down through its first panel A–B along x = 1.5."""
    path = np.array([[0, 0, 0], [2, 0, 0], [2, 0, 1], [1, 0, -1]], float)
    points = np.concatenate([path + [0, y, 0] for y in (0.0, 1.0)])  # node k + 4: y = 1
    cells = np.concatenate([[[k, k + 1, k + 5], [k, k + 5, k + 4]] for k in range(3)])
    return points, cells


def test_a_sheet_folded_through_itself_is_a_self_intersection():
    points, cells = _folded_strip()
    found = find_intersections(points, cells, np.zeros(len(cells), int), {0: "graft"})
    assert found.count > 0
    assert found.between() == {"graft/self": found.count}
    assert all(p.leaflets == ("graft", "graft") for p in found.pairs)
    # every pair lies on the line where the panels meet: x = 1.5, z = 0, y in [0, 1]
    hits = found.points
    assert hits[:, 0] == pytest.approx(1.5, abs=1e-12)
    assert hits[:, 2] == pytest.approx(0.0, abs=1e-12)
    assert np.all((hits[:, 1] >= -1e-12) & (hits[:, 1] <= 1 + 1e-12))
    assert _library_says(points, cells)
    # the panels that meet are the first (cells 0, 1) and the last (cells 4, 5)
    assert {p.triangle for p in found.pairs} <= {0, 1, 4, 5}


def test_the_strip_unfolded_does_not_intersect():
    points, cells = _folded_strip()
    points[[3, 7], 0] = 3.0  # D beyond B: the last panel clears the first
    found = find_intersections(points, cells, np.zeros(len(cells), int))
    assert found.count == 0 and not _library_says(points, cells)


def _post_and_piercing_triangle() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leaflet 1 in the plane y = 0 (x in [0, 2], z in [0, 2]) and leaflet 2 in x = 0 share
    the post from (0,0,0) to (0,0,1); leaflet 3, a triangle in the plane x = 1.5, pierces
    leaflet 1 along x = 1.5, z in [1, 2]."""
    points = np.array([[0, 0, 0], [0, 0, 1], [2, 0, 0], [2, 0, 2], [0, 0, 2],  # 1
                       [0, -2, 0],                                              # 2
                       [1.5, -1, 1], [1.5, 1, 1], [1.5, 0, 3]], float)          # 3
    cells = np.array([[0, 2, 3], [0, 3, 1], [1, 3, 4], [0, 1, 5], [6, 7, 8]])
    return points, cells, np.array([1, 1, 1, 2, 3])


def test_the_post_is_the_seam_two_leaflets_share():
    _, cells, tags = _post_and_piercing_triangle()
    assert commissure_posts(cells, tags).tolist() == [[0, 1]]


def test_distance_from_the_post_is_the_hand_value():
    """Leaflet 3's edge z = 1 pierces leaflet 1 at (1.5, 0, 1), 1.5 mm from the post;
    leaflet 1's edges from (0,0,0), (0,0,1) and (0,0,2) to (2,0,2) pierce leaflet 3 at
    z = 1.5, 1.75 and 2, which are √(1.5² + 0.5²), √(1.5² + 0.75²) and √(1.5² + 1²) mm
    from the post's top end (0, 0, 1)."""
    points, cells, tags = _post_and_piercing_triangle()
    found = find_intersections(points, cells, tags, {1: "left-coronary", 2: "right-coronary",
                                                     3: "graft"})
    distance = {round(p.point[2], 9): p.post_distance_mm for p in found.pairs}
    assert distance == pytest.approx({1.0: 1.5, 1.5: math.hypot(1.5, 0.5),
                                      1.75: math.hypot(1.5, 0.75), 2.0: math.hypot(1.5, 1.0)},
                                     abs=1e-12)
    assert all(p.point[0] == pytest.approx(1.5) and p.point[1] == pytest.approx(0.0)
               for p in found.pairs)
    assert found.between() == {"graft/left-coronary": 4}
    assert found.post_distance_mm() == pytest.approx((1.5, math.hypot(1.5, 1.0)))
    assert found.where() == "1.50–1.80 mm from a post (graft/left-coronary 4)"


def _found(distances: list[float], label=("graft", "left-coronary")) -> Intersections:
    pairs = tuple(IntersectingPair((0, 1), k, label, (float(k), 0.0, 0.0), d)
                  for k, d in enumerate(distances))
    return Intersections(pairs, candidates=100, time_s=0.01)


def test_a_result_with_intersecting_pairs_is_not_competent():
    found = _found([0.21, 1.3, 0.6])
    competent, why = competence(True, 0.0, found.count, found.where())
    assert not competent
    assert why == ("leaflets intersect: 3 edge–triangle pairs, 0.21–1.30 mm from a post "
                   "(graft/left-coronary 3)")
    result = CaseResult(21.0, 27.0, converged=True, regurgitant_orifice_area_mm2=0.0,
                        competent=competent, competence_reason=why,
                        intersecting_pairs=found.count, intersections=found.to_dict())
    assert leaflets_intersect(result)
    assert competence_text(result) == f"not competent ({why})"
    assert competence(True, 0.0, 0) == (True, "")
    assert competence(False, 0.4, 1, "0.50 mm from a post (graft/self 1)") == (
        False, "not converged; leaks 0.40 mm²; leaflets intersect: 1 edge–triangle pair, "
        "0.50 mm from a post (graft/self 1)")


def test_result_json_records_the_pairs_and_reads_back(tmp_path):
    """result.json keeps the count, the pairs per leaflets, the range of distances and at
    most ``listed`` pairs, nearest a post first and spread over the distances (the nearest
    and the farthest kept); it reads back into the same result."""
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.output import write_result

    found = _found([2.0, 0.5, 1.0, 0.2])
    record = found.to_dict(listed=3)
    assert record["between"] == {"graft/left-coronary": 4}
    assert record["post_distance_mm"] == [0.2, 2.0]
    assert [p["post_distance_mm"] for p in record["pairs"]] == [0.2, 1.0, 2.0]  # of 4 sorted
    assert len(found.to_dict(listed=10)["pairs"]) == 4
    assert record["pairs"][0] == {"leaflets": "graft/left-coronary",
                                  "point_mm": [3.0, 0.0, 0.0], "post_distance_mm": 0.2}
    result = CaseResult(21.0, 27.0, converged=True, intersecting_pairs=found.count,
                        intersections=record)
    (tmp_path / "first").mkdir()
    (tmp_path / "again").mkdir()
    written = write_result(tmp_path / "first", result, MPI.COMM_SELF)
    data = json.loads(written.read_text())
    assert data["intersecting_pairs"] == 4 and data["intersections"] == record
    back = CaseResult.from_dict(data)
    assert back.intersecting_pairs == 4 and back.intersections == record
    again = write_result(tmp_path / "again", back, MPI.COMM_SELF)
    assert again.read_text() == written.read_text()
    assert not leaflets_intersect(CaseResult(None, None, converged=True, intersecting_pairs=0))
    assert not leaflets_intersect({"converged": True})  # a result from before the check
