"""The contact force law of SPEC §5 and its parameters.

For a node that meets a surface at signed distance ``d`` (positive on the side
the node comes from), pushed towards it by a driving force ``F``, the contact
force acts along the surface normal with magnitude

.. math::

    f(d, F) = \\begin{cases}
        0                      & d \\ge h \\\\
        F\\, e^{-k d / F}       & 0 \\le d < h \\\\
        F - k d                & d < 0
    \\end{cases}

with penalty stiffness ``k`` (mN/mm) and cut-off distance ``h`` (mm).  Units
throughout: mm, kPa, mN.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from valve_dolfinx.exceptions import ParameterError, check_range

__all__ = [
    "ContactParameters", "DRIVING_FORCE_MODES", "PAIRINGS", "contact_force",
    "DEFAULT_PARAMETERS", "contact_force_slope_in_F", "crossing_barrier", "law_force",
    "driving_force", "law_force_from_load",
]

log = logging.getLogger(__name__)

#: Accepted values of :attr:`ContactParameters.driving_force`.
DRIVING_FORCE_MODES = ("normal", "magnitude")
#: Accepted values of :attr:`ContactParameters.pairing`.
PAIRINGS = ("one_pass", "two_pass")


@dataclass(frozen=True, slots=True)
class ContactParameters:
    """Parameters of the penalty contact (SPEC §5).

    Attributes
    ----------
    stiffness
        Penalty stiffness ``k`` in mN/mm (SPEC: 10 N/m = 10 mN/mm).
    cutoff
        Distance ``h`` in mm beyond which a surface exerts no force (SPEC: 0.1 mm).
    penetration_depth
        How far behind a triangle (mm) a node is still treated as penetrating
        it.  Nodes further behind are taken to belong to the other side of the
        (thin) sheet and are ignored.  Must exceed the largest penetration the
        solver can produce in one step.
    driving_force
        How the driving force ``F`` of a node is taken from its external
        (pressure) force ``f_ext``: ``"normal"`` uses
        :math:`F = \\max(-f_{ext}\\cdot n, 0)`, the part of the pressure force
        pushing the node into the surface whose sided normal is ``n``;
        ``"magnitude"`` uses :math:`F = |f_{ext}|`, the literal SPEC wording.
    min_driving_force
        Floor on ``F`` in mN, so that :math:`e^{-kd/F}` stays defined when no
        pressure acts; with the floor the law reduces to a pure penalty
        :math:`-k d` behind the surface and (numerically) zero in front of it.
    taper
        Fraction of the cut-off band ``[0, h)`` over whose outer part the
        exponential branch is faded smoothly to zero (a C¹ smoothstep on
        ``[(1 - taper)·h, h]``).  ``0`` is the literal SPEC law, whose force jumps
        from ``F·e^{-kh/F}`` to 0 at ``d = h``; with nodal pressure forces of a
        few mN that jump is several mN, and an implicit solver sees a
        discontinuous residual there: Newton fails repeatedly and the adaptive
        time step collapses.  The default 0.5 leaves the law untouched for
        ``d ≤ h/2`` -- in particular ``f(0) = F`` and the slope ``-k`` at
        contact, which set the equilibrium -- and removes the jump.
    thickness
        Contact thickness ``t_c`` (mm): the law acts on ``d = distance − t_c``,
        so two sheets rest about ``t_c`` apart (a plane, which stands for a
        mirror-image neighbour, at ``t_c/2``).  0 is the SPEC's zero-thickness
        law.  A positive value gives the membranes the volume real leaflets
        have: a third leaflet cannot slide into the (force-free) seam between
        two coapting ones at the valve centre without pushing them apart, which
        zero-thickness sheets do freely.
    blend_distance
        ε (mm) of the smooth minimum over the triangles a node meets on one
        body: ``w ∝ exp(-(d - min d)/ε)``, so that a node in a crease does
        not jump between the two faces' normals (see
        ``SurfaceContact._blend_weights``).
    pairing
        ``"two_pass"`` (default): every node is tested against every other
        body's triangles (and its own body's, for folds) at full weight.  When
        two pressure-loaded sheets press on each other, each feels its own
        nodes' forces *and* the reactions of the other's nodes, so each pass
        carries half the pressure: the sheets rest where ``f(d) = F/2``, a small
        gap (inside the taper band, about 0.075 mm with the defaults) --
        never a penetration, and no node can slip through a surface unseen.
        A node pressing on a surface whose own nodes do not see it back (a free
        edge on a belly) rests at ``d = 0``.  ``"one_pass"``: a node of body A
        is tested against body B only if A < B (own body at half weight):
        contact exactly at ``d = 0`` on both sides, but the second body's nodes
        are not checked against the first body's triangles and can pass
        through it where the surfaces are curved (seen at the valve centre).
    crossing_stiffness
        Stiffness ``k_x`` (mN/mm) of a barrier against the *mid-surfaces*
        crossing (``d < -thickness``), added to the law: SPEC §5 asks for no
        interpenetration, but its penalty ``k`` = 10 mN/mm only answers a node
        pushed by its own pressure force.  A node pulled through a neighbour by
        membrane tension (the taut free edge of a stiff pericardial graft near
        a commissure: ~7 mN) would sink ~0.5 mm before ``k`` balanced it.  The
        barrier :func:`crossing_barrier` leaves the SPEC law untouched wherever
        the mid-surfaces have not crossed -- every equilibrium of the normal
        valve -- and is C¹ (quadratic onset over ``crossing_width``).  0 (the
        default, also the closure's setting) is the SPEC law alone.
    crossing_width
        Width (mm) of the barrier's quadratic onset.
    """

    stiffness: float = 10.0
    cutoff: float = 0.1
    penetration_depth: float = 0.2
    driving_force: str = "normal"
    min_driving_force: float = 1e-9
    taper: float = 0.5
    pairing: str = "two_pass"
    blend_distance: float = 0.01
    thickness: float = 0.0
    crossing_stiffness: float = 0.0
    crossing_width: float = 0.02

    def __post_init__(self) -> None:
        check_range("crossing_stiffness", self.crossing_stiffness, 0.0, 1e6, unit="mN/mm",
                    hint="0 is the SPEC law alone")
        check_range("crossing_width", self.crossing_width, 0.0, 1.0, low_open=True, unit="mm")
        check_range("blend_distance", self.blend_distance, 0.0, 1.0, low_open=True, unit="mm")
        check_range("thickness", self.thickness, 0.0, 2.0, unit="mm")
        check_range("taper", self.taper, 0.0, 1.0,
                    hint="0 keeps the force jump at d = h, 1 fades it over the whole band")
        if self.pairing not in PAIRINGS:
            raise ParameterError(f"pairing = {self.pairing!r} is not one of {PAIRINGS}")
        check_range("stiffness", self.stiffness, 0.0, low_open=True, unit="mN/mm")
        check_range("cutoff", self.cutoff, 0.0, low_open=True, unit="mm")
        check_range("penetration_depth", self.penetration_depth, 0.0, low_open=True, unit="mm",
                    hint="it is the depth behind a triangle that still counts as penetration")
        check_range("min_driving_force", self.min_driving_force, 0.0, low_open=True, unit="mN",
                    hint="a tiny positive floor such as 1e-9 mN keeps exp(-k d / F) defined")
        if self.driving_force not in DRIVING_FORCE_MODES:
            raise ParameterError(
                f"driving_force = {self.driving_force!r} is not one of {DRIVING_FORCE_MODES}"
            )

    @property
    def search_distance(self) -> float:
        """Padding (mm) of the bounding boxes: ``thickness + max(cutoff, penetration_depth)``."""
        return self.thickness + max(self.cutoff, self.penetration_depth)

    @property
    def reach(self) -> float:
        """Largest raw distance (mm) at which a surface pushes: ``thickness + cutoff``."""
        return self.thickness + self.cutoff


#: The SPEC §5 parameters (frozen, so safe as a default argument).
DEFAULT_PARAMETERS = ContactParameters()


def contact_force(d: np.ndarray, F: np.ndarray, k: float, h: float, taper: float = 0.0
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Magnitude ``f(d, F)`` of the SPEC §5 contact force and its derivative ``df/dd``.

    .. math::

        f = \\begin{cases} 0 & d \\ge h \\\\ F e^{-kd/F} & 0 \\le d < h \\\\
            F - k d & d < 0 \\end{cases}
        \\qquad
        \\frac{\\partial f}{\\partial d} = \\begin{cases} 0 & d \\ge h \\\\
            -k e^{-kd/F} & 0 \\le d < h \\\\ -k & d < 0 \\end{cases}

    Both branches give ``f = F`` and slope ``-k`` at ``d = 0``, so ``f`` is
    continuously differentiable there.  At ``d = h`` the law as stated jumps:
    ``f(h⁻) = F e^{-kh/F}`` (0.37 mN for F = 1 mN, k = 10 mN/mm, h = 0.1 mm) but
    ``f(h) = 0``; the jump is kept, as SPEC §5 states it, and it vanishes
    quickly as ``F`` drops below ``k h``.

    Parameters
    ----------
    d
        Signed distances (mm), positive on the side the node comes from.
    F
        Driving forces (mN), strictly positive (see
        :attr:`ContactParameters.min_driving_force`); broadcast against ``d``.
    k, h
        Penalty stiffness (mN/mm) and cut-off distance (mm).
    taper
        Fade the exponential branch to zero over ``[(1 - taper)·h, h]`` with
        the smoothstep ``s = 1 - 3ξ² + 2ξ³`` (``f → s·f``); 0 = the law as stated.

    Returns
    -------
    f, dfdd
        Force magnitudes (mN) and their derivatives with respect to ``d`` (mN/mm).
    """
    d, F = np.broadcast_arrays(np.asarray(d, dtype=float), np.asarray(F, dtype=float))
    f = np.zeros(d.shape)
    dfdd = np.zeros(d.shape)
    behind = d < 0.0
    f[behind] = F[behind] - k * d[behind]
    dfdd[behind] = -k
    near = (d >= 0.0) & (d < h)
    decay = np.exp(-k * d[near] / F[near])
    f[near] = F[near] * decay
    dfdd[near] = -k * decay
    if taper > 0.0:
        start = (1.0 - taper) * h
        fade = near & (d > start)
        xi = (d[fade] - start) / (taper * h)
        s = 1.0 - xi * xi * (3.0 - 2.0 * xi)
        ds = -6.0 * xi * (1.0 - xi) / (taper * h)
        dfdd[fade] = s * dfdd[fade] + ds * f[fade]
        f[fade] = s * f[fade]
    return f, dfdd


def contact_force_slope_in_F(d: np.ndarray, F: np.ndarray, k: float, h: float,
                             taper: float = 0.0) -> np.ndarray:
    """``∂f/∂F`` of :func:`contact_force`: ``e^{-kd/F}(1 + kd/F)`` in front, 1 behind, 0 beyond h.

    The taper's smoothstep multiplies it like it multiplies ``f``.
    """
    d, F = np.broadcast_arrays(np.asarray(d, dtype=float), np.asarray(F, dtype=float))
    out = np.zeros(d.shape)
    out[d < 0.0] = 1.0
    near = (d >= 0.0) & (d < h)
    ratio = k * d[near] / F[near]
    out[near] = np.exp(-ratio) * (1.0 + ratio)
    if taper > 0.0:
        start = (1.0 - taper) * h
        fade = near & (d > start)
        xi = (d[fade] - start) / (taper * h)
        out[fade] *= 1.0 - xi * xi * (3.0 - 2.0 * xi)
    return out


def crossing_barrier(d: np.ndarray, params: ContactParameters,
                     thickness: np.ndarray | float | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Barrier force against crossing mid-surfaces and its derivative ``df/dd``.

    With the crossing depth ``e = -(d + t_c)`` (``t_c`` the contact thickness, the
    parameters' unless ``thickness`` gives it, per distance; ``d`` the law's distance) and
    ``w`` the onset width:

    .. math::

        f_x = k_x \\begin{cases} 0 & e \\le 0 \\\\ e^2/(2w) & 0 < e < w \\\\
              e - w/2 & e \\ge w \\end{cases}

    continuous with its slope, zero wherever the mid-surfaces have not crossed.
    """
    d = np.asarray(d, dtype=float)
    k, w = params.crossing_stiffness, params.crossing_width
    e = -(d + (params.thickness if thickness is None else thickness))
    f = k * np.where(e < w, 0.5 * np.clip(e, 0.0, None) ** 2 / w, e - 0.5 * w)
    dfdd = -k * np.clip(e / w, 0.0, 1.0)
    return f, dfdd


def law_force(d: np.ndarray, F: np.ndarray, params: ContactParameters,
              thickness: np.ndarray | float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`contact_force` with the parameters' ``k``, ``h``, taper, plus the crossing barrier
    (:func:`crossing_barrier`, with the contact ``thickness`` of each distance if given)."""
    f, dfdd = contact_force(d, F, params.stiffness, params.cutoff, params.taper)
    if params.crossing_stiffness > 0.0:
        fb, dfb = crossing_barrier(d, params, thickness)
        f, dfdd = f + fb, dfdd + dfb
    return f, dfdd


def driving_force(f_ext: np.ndarray, normal: np.ndarray, params: ContactParameters
                  ) -> np.ndarray:
    """Driving force ``F`` (mN) of nodes with external forces ``f_ext`` against sided normals.

    ``"normal"``: :math:`F = \\max(-f_{ext}\\cdot n, 0)`; ``"magnitude"``:
    :math:`F = |f_{ext}|`; both floored at ``params.min_driving_force``.

    Parameters
    ----------
    f_ext, normal
        ``(K, 3)`` external nodal forces (mN) and unit normals pointing to the
        side the node comes from.
    """
    if params.driving_force == "normal":
        F = -np.einsum("ij,ij->i", f_ext, normal)
    else:
        F = np.linalg.norm(f_ext, axis=1)
    return np.maximum(F, params.min_driving_force)


def law_force_from_load(d: np.ndarray, f_ext: np.ndarray, normal: np.ndarray,
                        params: ContactParameters,
                        thickness: np.ndarray | float | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`law_force` and its slope in ``d`` with ``F`` the :func:`driving_force` of the
    external nodal forces ``f_ext`` ``(K, 3)`` against the sided normals ``normal``."""
    F = driving_force(f_ext, normal, params)
    return law_force(d, F, params, thickness)
