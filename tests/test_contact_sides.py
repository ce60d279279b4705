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

from valve_dolfinx.config import VALVE_CONTACT as VALVE
from valve_dolfinx.contact import SurfaceContact

#: a 4 mm square of body 0 (normals +z), and a node of body 1
SQUARE = 4.0 * np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
TRIANGLES = np.array([[0, 1, 2], [0, 2, 3]])
BODY = np.array([0, 0])
XY = (2.6, 1.0)  # inside one triangle, 1.1 mm from the other (no blending)
PUSH = 0.8  # mN
#: the valve's contact settings with the literal SPEC law (no taper of the cut-off)
VALVE_CONTACT = replace(VALVE, taper=0.0)


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
