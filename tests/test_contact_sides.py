"""Contact sides (SPEC §5): the side of a node-triangle pair is the side the node comes
from, on whichever face of the triangle that is, between leaflets as within one.

Expected behaviour from the SPEC alone: a node pushed onto a triangle by a force F comes to
rest where the law's force equals F, i.e. at d = 0 (f(0) = |f_ext|), one contact thickness
from the mid-surface, on either face; the reactions on the triangle's vertices balance F;
and no force ever pulls a node towards a triangle it has not passed through.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import brentq

from valve_dolfinx.contact import ContactParameters, SurfaceContact
from valve_dolfinx.contact.exclusions import adjacent_triangles
from valve_dolfinx.contact.sides import SideMemory, nearest_inside

#: a 4 mm square of body 0 (normals +z), and a node of body 1
SQUARE = 4.0 * np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
TRIANGLES = np.array([[0, 1, 2], [0, 2, 3]])
BODY = np.array([0, 0])
XY = (2.6, 1.0)  # inside one triangle, 1.1 mm from the other (no blending)
PUSH = 0.8  # mN
#: the valve's contact settings with the literal SPEC law (no taper of the cut-off)
VALVE_CONTACT = ContactParameters(taper=0.0)


def contact(flipped: bool) -> SurfaceContact:
    """The valve's contact settings; ``flipped`` reverses the triangles (normals -z), so the
    face the node meets is the other one of the triangle's two faces."""
    triangles = TRIANGLES[:, ::-1] if flipped else TRIANGLES
    # the node is a one-node body of its own (label 1): contact between bodies
    return SurfaceContact(np.concatenate([triangles, [[4, 4, 4]]])[:2], 5, VALVE_CONTACT,
                          triangle_body=BODY)


def state(z: float, side: float) -> tuple[np.ndarray, np.ndarray]:
    """Node at height z, pushed towards the square from the side ``side`` (±1 along z)."""
    x = np.vstack([SQUARE, [XY[0], XY[1], z]])
    f_ext = np.zeros_like(x)
    f_ext[4, 2] = -side * PUSH
    return x, f_ext


def force_from_side(model: SurfaceContact, z: float, side: float) -> tuple[float, object]:
    """z-force on the node at z, its last accepted state (the history the solver records
    after every pseudo-time step) on the side ``side`` of the square, just outside reach."""
    reach = VALVE_CONTACT.thickness + VALVE_CONTACT.cutoff
    model.update_history(state(side * (reach + 0.05), side)[0])
    result = model.evaluate(*state(z, side))
    return float(result.forces[4, 2]), result


@pytest.mark.parametrize("flipped", [False, True])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_no_force_pulls_a_node_towards_a_triangle_it_has_not_passed(flipped, side):
    """Scan the node across the whole contact window on both sides of the triangle, for both
    faces: while the node is on the side it came from, its force points away from the
    triangle (or is zero); once it has passed through, within the penetration window, the
    force pushes it back."""
    model = contact(flipped)
    reach = VALVE_CONTACT.thickness + VALVE_CONTACT.cutoff
    depth = VALVE_CONTACT.penetration_depth - VALVE_CONTACT.thickness  # past the mid-surface
    for z in np.linspace(side * (reach + 0.2), -side * (depth + 0.2), 121):
        fz, _ = force_from_side(model, z, side)
        outward = side * fz  # component along the direction the node came from
        assert outward >= 0.0, (z, fz)
        if side * z < reach - 0.01 and side * z > -depth + 0.01:
            assert outward > 0.0, (z, fz)   # inside the window: always repelled


@pytest.mark.parametrize("flipped", [False, True])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_pressed_node_rests_one_thickness_off_either_face_and_reactions_balance(flipped, side):
    model = contact(flipped)

    def imbalance(z: float) -> float:
        fz, _ = force_from_side(model, side * z, side)
        return side * fz - PUSH  # contact force against the push

    height = brentq(imbalance, 0.05, VALVE_CONTACT.thickness + 0.09, xtol=1e-12)
    # f(d) = F exp(-k d / F) equals F at d = 0: one contact thickness off the mid-surface
    assert height == pytest.approx(VALVE_CONTACT.thickness, abs=1e-6)
    _, result = force_from_side(model, side * height, side)
    total = result.forces.sum(axis=0)
    assert np.abs(total).max() < 1e-10                           # action = reaction
    assert result.forces[:4, 2].sum() == pytest.approx(-side * PUSH, rel=1e-6)


# --- the side is remembered while the pair stays close (contact/sides.py) -------------------
#: the literal SPEC law without blending: forces worked out by hand from f = F − k·d
LITERAL = replace(VALVE_CONTACT, thickness=0.0, penetration_depth=0.2, blend_distance=1e-6,
                  crossing_stiffness=0.0)
#: a 4 × 1 strip of 1 mm squares (body 0, normals +z) and a free node of body 1 (id 10)
STRIP_X, STRIP_TRIANGLES = (lambda n: (
    np.array([[i, j, 0.0] for i in range(n + 1) for j in (0, 1)], dtype=float),
    np.array([t for i in range(n) for t in ([2 * i, 2 * i + 2, 2 * i + 3],
                                            [2 * i, 2 * i + 3, 2 * i + 1])])))(4)


def strip_state(x: float, z: float) -> tuple[np.ndarray, np.ndarray]:
    """The strip and its free node at (x, 0.5, z), no external force (F = the floor)."""
    points = np.vstack([STRIP_X, [x, 0.5, z]])
    return points, np.zeros_like(points)


def strip_contact() -> SurfaceContact:
    return SurfaceContact(STRIP_TRIANGLES, 11, LITERAL)


def test_a_node_recorded_past_the_mid_surface_keeps_the_side_it_came_from():
    """A node that came from above and is pulled 0.1 mm through the sheet (inside the
    penetration window) is pushed back up, f = k·0.1 = 1 mN, even after a state with it
    behind the sheet has been accepted: its side is remembered, not read off that state."""
    model = strip_contact()
    model.update_history(strip_state(0.4, 0.05)[0])
    for _ in range(2):
        model.update_history(strip_state(0.4, -0.1)[0])  # accepted behind the sheet, twice
        fz = model.evaluate(*strip_state(0.4, -0.1)).forces[10, 2]
        assert fz == pytest.approx(LITERAL.min_driving_force + 10.0 * 0.1, rel=1e-9)


def test_a_node_sliding_onto_the_next_triangle_keeps_its_side():
    """A pair seen for the first time takes the side its node has on an adjacent triangle of
    the same body: the node recorded over the first square (the second square more than the
    tracking distance away) and then found 0.05 mm behind the second square is pushed back
    up (k·0.05 = 0.5 mN); a node that meets that square afresh is on the side it is on."""
    model = strip_contact()
    model.update_history(strip_state(0.3, 0.05)[0])
    x, f_ext = strip_state(1.5, -0.05)
    assert model.evaluate(x, f_ext).forces[10, 2] == pytest.approx(
        LITERAL.min_driving_force + 10.0 * 0.05, rel=1e-9)
    afresh = strip_contact()
    afresh.update_history(strip_state(1.5, -1.0)[0])   # far below: not close to any triangle
    assert afresh.evaluate(x, f_ext).forces[10, 2] <= 0.0


def test_a_node_that_separated_meets_the_sheet_afresh_on_its_other_face():
    """Once a node has been farther from the sheet than the tracking distance, its side is
    forgotten: having gone round to the back, it is held off the back face (pushed down),
    not pulled through to the front it came from first."""
    model = strip_contact()
    model.update_history(strip_state(2.0, 0.05)[0])
    model.update_history(strip_state(2.0, 1.5)[0])     # away from the sheet
    model.update_history(strip_state(2.0, -1.5)[0])    # round to the back, still away
    x, f_ext = strip_state(2.0, -0.05)
    f_ext[10, 2] = 0.8                                 # pressed up onto the back face
    fz = model.evaluate(x, f_ext).forces[10, 2]
    assert fz == pytest.approx(-0.8 * np.exp(-10.0 * 0.05 / 0.8), rel=1e-9)


def test_a_node_that_goes_round_the_free_edge_meets_the_other_face():
    """A node over the strip, then beyond its edge y = 1 (0.3 mm out, 0.05 mm below the
    plane: over nothing it could have passed through),
    then back under the strip: it takes the side it is on beyond the edge, and pressed up
    onto the back face it is held off it, f = F·e^{−k·d/F} downwards (d = 0.05 mm), not
    pulled up through the strip to the face it first came from."""
    model = strip_contact()
    model.update_history(strip_state(2.0, 0.05)[0])
    beside = np.vstack([STRIP_X, [2.0, 1.3, -0.05]])
    model.update_history(beside)
    model.update_history(strip_state(2.0, -0.05)[0])
    x, f_ext = strip_state(2.0, -0.05)
    f_ext[10, 2] = 0.8
    fz = model.evaluate(x, f_ext).forces[10, 2]
    assert fz == pytest.approx(-0.8 * np.exp(-10.0 * 0.05 / 0.8), rel=1e-9)


def test_adjacent_triangles_are_the_same_body_triangles_sharing_a_vertex():
    rng = np.random.default_rng(3)
    triangles = rng.integers(0, 30, size=(60, 3))
    body = rng.integers(0, 2, size=60)
    table = adjacent_triangles(triangles, body)
    for t in range(len(triangles)):
        expected = [u for u in range(len(triangles)) if u != t and body[u] == body[t]
                    and set(triangles[u]) & set(triangles[t])]
        assert list(table[t][table[t] >= 0]) == expected


def test_side_lookup_is_the_pair_s_side_else_the_first_remembered_adjacent_s_else_zero():
    rng = np.random.default_rng(5)
    num_triangles = 40
    adjacent = np.where(rng.random((num_triangles, 5)) < 0.8,
                        rng.integers(0, num_triangles, (num_triangles, 5)), -1)
    remembered = {(int(p), int(t)): int(s) for p, t, s in zip(
        rng.integers(0, 30, 300), rng.integers(0, num_triangles, 300),
        rng.choice([-1, 1], 300), strict=True)}
    node, tri = np.array(list(remembered)).T
    memory = SideMemory.of(node, tri, np.array(list(remembered.values())), num_triangles)
    queries = rng.integers(0, 30, 500), rng.integers(0, num_triangles, 500)
    expected = []
    for p, t in zip(*queries, strict=True):
        around = [(p, u) for u in adjacent[t] if u >= 0 and (p, u) in remembered]
        key = (p, t) if (p, t) in remembered else (around[0] if around else None)
        expected.append(remembered[key] if key else 0)
    assert 0 < expected.count(0) < len(expected)
    assert memory.lookup(*queries, adjacent).tolist() == expected


# --- next to a seam (a commissure) the contact thickness tapers to zero ----------------------
#: body 1: one triangle sewn to the strip's edge x = 0 (nodes 0 and 1), its free vertex 10
SEWN_TRIANGLES = np.vstack([STRIP_TRIANGLES, [[0, 1, 10]]])
SEWN_BODY = np.r_[np.zeros(len(STRIP_TRIANGLES), dtype=int), 1]


@pytest.mark.parametrize("seam_distance", [1.0, 1.5, 3.0])
def test_contact_thickness_tapers_to_zero_at_the_seam(seam_distance):
    """Node 10 lies ``seam_distance`` from the seam x = 0 in the unloaded state; pressed onto
    the strip far from the seam it rests where f(0) = F, one *tapered* thickness
    t_c·min(δ/L, 1) off the mid-surface (L = 2.5 mm; 0.10, 0.15 and 0.25 mm)."""
    taper = 2.5
    params = replace(VALVE_CONTACT, taper=0.0, crossing_stiffness=0.0)
    unloaded = np.vstack([STRIP_X, [-seam_distance, 0.5, 0.0]])
    model = SurfaceContact(SEWN_TRIANGLES, 11, params, triangle_body=SEWN_BODY,
                           attached_reference=unloaded, seam_taper_length=taper)
    assert model.thickness_scale[10, 0] == pytest.approx(min(seam_distance / taper, 1.0))

    def imbalance(z: float) -> float:
        x = np.vstack([STRIP_X, [2.5, 0.5, z]])
        f_ext = np.zeros_like(x)
        f_ext[10, 2] = -PUSH
        model.update_history(np.vstack([STRIP_X, [2.5, 0.5, 1.0]]))
        return model.evaluate(x, f_ext, nodes=np.array([10])).forces[10, 2] - PUSH

    height = brentq(imbalance, 0.01, params.thickness + 0.09, xtol=1e-12)
    assert height == pytest.approx(params.thickness * min(seam_distance / taper, 1.0),
                                   abs=1e-6)


def test_seam_distances_are_the_distances_to_the_shared_edges():
    from valve_dolfinx.contact.exclusions import seam_distances

    unloaded = np.vstack([STRIP_X, [-1.0, 2.0, 0.0]])     # 1 mm beyond the seam's end (0, 1)
    distances = seam_distances(SEWN_TRIANGLES, SEWN_BODY, unloaded, 2)
    assert distances[10, 0] == pytest.approx(np.sqrt(2.0))
    assert distances[10, 1] == np.inf                       # its own body
    # strip nodes: distance to the segment x = 0, 0 <= y <= 1 (the seam nodes: 0)
    np.testing.assert_allclose(distances[:10, 1], STRIP_X[:, 0])


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

