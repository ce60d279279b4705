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

import numpy as np

from valve_dolfinx.contact_parameters import ContactParameters

__all__ = [
    "ContactParameters", "contact_force", "DEFAULT_PARAMETERS", "contact_force_slope_in_F",
    "crossing_barrier", "law_force", "driving_force", "law_force_from_load",
]

log = logging.getLogger(__name__)

#: The contact of the closing valve (frozen, so safe as a default argument).
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

    :math:`F = \\max(-f_{ext}\\cdot n, 0)`, the part of the pressure force pushing the node
    into the surface, floored at ``params.min_driving_force``.

    Parameters
    ----------
    f_ext, normal
        ``(K, 3)`` external nodal forces (mN) and unit normals pointing to the
        side the node comes from.
    """
    F = -np.einsum("ij,ij->i", f_ext, normal)
    return np.maximum(F, params.min_driving_force)


def law_force_from_load(d: np.ndarray, f_ext: np.ndarray, normal: np.ndarray,
                        params: ContactParameters,
                        thickness: np.ndarray | float | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`law_force` and its slope in ``d`` with ``F`` the :func:`driving_force` of the
    external nodal forces ``f_ext`` ``(K, 3)`` against the sided normals ``normal``."""
    F = driving_force(f_ext, normal, params)
    return law_force(d, F, params, thickness)
