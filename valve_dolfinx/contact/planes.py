"""Penalty contact of the nodes of a surface with rigid planes (SPEC §5, SPEC §4's symmetry
planes)."""

from __future__ import annotations

import numpy as np

from valve_dolfinx.contact.law import DEFAULT_PARAMETERS, ContactParameters, law_force_from_load
from valve_dolfinx.contact.results import ContactResult, ContactRows, check_nodes, check_positions
from valve_dolfinx.exceptions import ParameterError

__all__ = ["PlaneContact"]


class PlaneContact:
    """Penalty contact of nodes with rigid planes (half-spaces).

    Plane ``i`` passes through ``points[i]``; ``normals[i]`` points to the side
    where the nodes live, so :math:`d = (x - p_i)\\cdot n_i`.  Same law as
    :class:`~valve_dolfinx.contact.surface.SurfaceContact` with ``F`` from
    :math:`f_{ext}\\cdot n_i`; the planes take no reaction.  A node is in contact
    whenever ``d < h`` — there is no ``penetration_depth`` window, because a
    half-space has no far side a node could legitimately be on.  The Jacobian
    block ``(df/dd) n⊗n`` on the node's diagonal is exact up to ``∂F/∂x`` (``F``
    depends on ``f_ext`` only).

    Parameters
    ----------
    points, normals
        ``(P, 3)`` a point on each plane (mm) and its normal (normalised here).
    params
        Contact law parameters.
    mirror
        ``False``: a rigid wall, ``d = δ − t_c/2`` (δ the distance to the plane,
        the sheet's half of the contact layer).  ``True``: a symmetry plane
        whose far side holds the sheet's mirror image (SPEC §4's one-leaflet
        reference): the law sees the distance to that image, ``d = 2δ − t_c``,
        exactly as a neighbouring sheet's node would, so the symmetric
        reference and the full valve share one contact law.  Every node of a
        sheet is tested against its neighbour's triangles and the other way
        round, so the image's nodes would also push back on the sheet's
        triangles; for a mirror image those reactions equal the sheet's own
        contact forces, so the force is doubled (the sheets rest where each
        pass carries half the load, as between leaflets).
    """

    def __init__(self, points: np.ndarray, normals: np.ndarray,
                 params: ContactParameters = DEFAULT_PARAMETERS, *,
                 mirror: bool = False) -> None:
        points = np.atleast_2d(np.asarray(points, dtype=float))
        normals = np.atleast_2d(np.asarray(normals, dtype=float))
        if points.shape != normals.shape or points.shape[1:] != (3,):
            raise ParameterError(f"plane points {points.shape} and normals {normals.shape} "
                                 "must both be (P, 3)")
        length = np.linalg.norm(normals, axis=1)
        if np.any(~np.isfinite(length) | (length <= 0.0)):
            raise ParameterError("plane normals must be finite and non-zero")
        self.points = points
        self.normals = normals / length[:, None]
        self.params = params
        self.mirror = bool(mirror)

    def evaluate(self, x: np.ndarray, f_ext: np.ndarray, nodes: np.ndarray | None = None,
                 jacobian: bool = True) -> ContactResult:
        """Contact forces of ``nodes`` (default: all) against the planes, with their Jacobian
        blocks (``jacobian=True``).

        Arguments as in :meth:`~valve_dolfinx.contact.surface.SurfaceContact.evaluate`.
        """
        num_nodes = len(np.asarray(x))
        x = check_positions(x, num_nodes, "x")
        f_ext = check_positions(f_ext, num_nodes, "f_ext")
        nodes = check_nodes(nodes, num_nodes)
        d = (x[nodes] @ self.normals.T) - np.einsum("ij,ij->i", self.points, self.normals)
        # d(x) = scale·δ(x) − offset: the image is at 2δ, the wall at δ
        scale = 2.0 if self.mirror else 1.0
        offset = scale * 0.5 * self.params.thickness
        passes = 2.0 if self.mirror else 1.0
        d = scale * d - offset
        k, i = np.nonzero(d < self.params.cutoff)                 # (node, plane) candidates
        node, normal = nodes[k], self.normals[i]
        f, dfdd = law_force_from_load(d[k, i], f_ext[node], normal, self.params)
        f, dfdd = passes * f, passes * dfdd
        a = f > 0.0
        empty = np.empty((int(a.sum()), 0))
        # dfdd enters the Jacobian as f'(d)·∂d/∂x with ∂d/∂x = n: carry the scale in it
        contacts = ContactRows(node=node[a], support=empty.astype(np.int64), weights=empty,
                             normal=normal[a], d=d[k, i][a], f=f[a], dfdd=scale * dfdd[a],
                             partner=-1 - i[a], surface_offset=offset)
        return contacts.result(num_nodes, jacobian=jacobian)

