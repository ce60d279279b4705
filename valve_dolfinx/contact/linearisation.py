r"""Geometric part of the contact Jacobian: the turning contact direction and sliding reactions.

A node ``p`` in contact with triangle ``(a, b, c)`` receives ``φ n`` and the
triangle's vertex ``j`` the reaction ``-λ_j φ n`` (``φ`` the force magnitude
with its blending weight, ``n`` the unit contact direction, ``λ`` the
barycentric coordinates of the contact point).  With ``B = [1, -λ_a, -λ_b,
-λ_c]`` over ``[p, a, b, c]`` the force on row ``r`` is ``B_r φ n`` and

.. math::

    \frac{\partial (B_r φ n)}{\partial x_m}
      = B_r\, n \otimes \frac{\partial φ}{\partial x_m}
      + B_r\, φ\, \frac{\partial n}{\partial x_m}
      + φ\, n \otimes \frac{\partial B_r}{\partial x_m}.

The first term (the distance ``d`` changing, ``∂d/∂x_m = B_m n`` exactly) is
built in :meth:`valve_dolfinx.contact.results.ContactRows.result`.  This module
adds the other two:

* **the direction turns.**  Face contact: ``n = s N/|N|``, ``N = e₁ × e₂``
  (``e₁ = b - a``, ``e₂ = c - a``), so ``∂n/∂x_k = s (I - n nᵀ) K_k / |N|``
  with ``K_a = [e₂ - e₁]×``, ``K_b = -[e₂]×``, ``K_c = [e₁]×``.  Edge or
  vertex contact: ``n = (x_p - q)/|x_p - q|``, ``q = Σ λ_j x_j``, turns as the
  offset does across the feature: ``∂n/∂x_m = B_m Q/|x_p - q|``, ``Q`` the
  projector normal to ``n`` (and, on an edge, to the edge direction ``t``).
  On an edge ``(u, v)`` of length ``ℓ`` and direction ``t`` the edge's own
  turning adds ``-t (n·(dx_v - dx_u))/ℓ``;
* **the contact point slides.**  Face: ``dλ_j = g_j·(dx_p - Σ_k λ_k dx_k -
  d₀ dn̂)``, ``g_j`` the in-plane gradients of the barycentric coordinates and
  ``d₀`` the (unsided) plane distance.  Edge:
  ``dλ_v = -dλ_u = [t·(dx_p - λ_u dx_u - λ_v dx_v) + (gap/ℓ) n·(dx_v - dx_u)]/ℓ``.
  Vertex: no sliding.

All terms are exact first derivatives (checked against finite differences in
``tests/test_contact_model.py``).  They are written as loops over the contacts, compiled
by Numba (:mod:`~valve_dolfinx.contact.kernels`): a contact's terms are a few dozen
3-vectors, and as NumPy expressions over all contacts they cost ten times as much in
temporaries as in arithmetic.
The dependence of the driving force on the positions is not here: the hook
freezes it within a step (see :mod:`valve_dolfinx.solvers.contact_hook`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["direction_derivatives"]

#: Barycentric coordinates below this count as zero when telling an edge contact
#: (two vertices carry the contact point) from a vertex contact (one does).
_ON_FEATURE = 1e-12


@numba.njit(cache=True)
def _dot(a, b):  # pragma: no cover
    """``a·b`` of 3-vectors summed as ``(a₀b₀ + a₂b₂) + a₁b₁``, the order of NumPy's
    ``einsum("ij,ij->i")`` in :func:`~valve_dolfinx.contact.geometry.barycentric_gradients`
    and the narrow phase, so that the same triangle gets the same bits here and there."""
    return (a[0] * b[0] + a[2] * b[2]) + a[1] * b[1]


@numba.njit(cache=True)
def _face_terms(x, p, tri, lam, normal, dn, dlam):  # pragma: no cover
    """``∂n/∂x_m`` ``(4, 3, 3)`` and ``∂λ_j/∂x_m`` ``(3, 4, 3)`` of a face contact of node
    ``p`` with triangle ``tri``, written into ``dn``, ``dlam`` (zero on entry)."""
    a, b, c = tri[0], tri[1], tri[2]
    e1 = x[b] - x[a]
    e2 = x[c] - x[a]
    N = np.empty(3)
    N[0] = e1[1] * e2[2] - e1[2] * e2[1]
    N[1] = e1[2] * e2[0] - e1[0] * e2[2]
    N[2] = e1[0] * e2[1] - e1[1] * e2[0]
    length = math.sqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2])
    nhat = N / length
    side = np.sign(nhat[0] * normal[0] + nhat[1] * normal[1] + nhat[2] * normal[2])
    # K_a = [e2 - e1]×, K_b = -[e2]×, K_c = [e1]×
    K = np.zeros((3, 3, 3))
    for k in range(3):
        v = e2 - e1 if k == 0 else (e2 if k == 1 else e1)
        sign = -1.0 if k == 1 else 1.0
        K[k, 0, 1], K[k, 0, 2] = sign * -v[2], sign * v[1]
        K[k, 1, 0], K[k, 1, 2] = sign * v[2], sign * -v[0]
        K[k, 2, 0], K[k, 2, 1] = sign * -v[1], sign * v[0]
    # ∂n̂/∂x_k = (I - n̂ n̂ᵀ) K_k / |N|
    P = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            P[i, j] = (1.0 if i == j else 0.0) - nhat[i] * nhat[j]
    dnhat = np.empty((3, 3, 3))
    for k in range(3):
        for i in range(3):
            for s in range(3):
                total = P[i, 0] * K[k, 0, s] + P[i, 1] * K[k, 1, s] + P[i, 2] * K[k, 2, s]
                dnhat[k, i, s] = total / length
                dn[1 + k, i, s] = side * dnhat[k, i, s]
    # in-plane gradients g_j of the barycentric coordinates (geometry.barycentric_gradients)
    g11, g12, g22 = _dot(e1, e1), _dot(e1, e2), _dot(e2, e2)
    det = g11 * g22 - g12 * g12
    grad = np.empty((3, 3))
    for i in range(3):
        grad[1, i] = (g22 * e1[i] - g12 * e2[i]) / det
        grad[2, i] = (g11 * e2[i] - g12 * e1[i]) / det
        grad[0, i] = -grad[1, i] - grad[2, i]
    d0 = _dot(nhat, x[p] - x[a])
    # dλ_j = g_j·(dx_p - Σ_k λ_k dx_k - d₀ dn̂)
    for j in range(3):
        for s in range(3):
            dlam[j, 0, s] = grad[j, s]
        for k in range(3):
            for s in range(3):
                g_dn = (grad[j, 0] * dnhat[k, 0, s] + grad[j, 1] * dnhat[k, 1, s]
                        + grad[j, 2] * dnhat[k, 2, s])
                dlam[j, 1 + k, s] = -lam[k] * grad[j, s] - d0 * g_dn


@numba.njit(cache=True)
def _feature_terms(x, p, tri, lam, normal, dn, dlam):  # pragma: no cover
    """The same for an edge or vertex contact (``dn``, ``dlam`` zero on entry)."""
    B = np.empty(4)
    B[0] = 1.0
    for j in range(3):
        B[1 + j] = -lam[j]
    q = np.zeros(3)
    for j in range(3):
        q += lam[j] * x[tri[j]]
    offset = x[p] - q
    gap = math.sqrt(offset[0] * offset[0] + offset[1] * offset[1] + offset[2] * offset[2])
    # the projector normal to n (and, on an edge, to its direction t)
    Q = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            Q[i, j] = (1.0 if i == j else 0.0) - normal[i] * normal[j]
    u, v, carrying = -1, -1, 0
    for j in range(3):
        if lam[j] > _ON_FEATURE:
            carrying += 1
            if u < 0:
                u = j
            v = j
    on_edge = carrying == 2
    t = np.zeros(3)
    ell = 1.0
    if on_edge:
        edge = x[tri[v]] - x[tri[u]]
        ell = math.sqrt(edge[0] * edge[0] + edge[1] * edge[1] + edge[2] * edge[2])
        t = edge / ell
        for i in range(3):
            for j in range(3):
                Q[i, j] -= t[i] * t[j]
        # the edge turning (dt = P(dx_v - dx_u)/ℓ) drags the foot point along t
        for m in range(4):
            for s in range(3):
                dlam[v, m, s] = B[m] * (t[s] / ell)
        for s in range(3):
            turn = (gap / ell) * normal[s] / ell
            dlam[v, 1 + u, s] -= turn
            dlam[v, 1 + v, s] += turn
        for m in range(4):
            for s in range(3):
                dlam[u, m, s] = -dlam[v, m, s]
    scale = max(gap, 1e-300)
    for m in range(4):
        for i in range(3):
            for j in range(3):
                dn[m, i, j] = B[m] * (Q[i, j] / scale)
    if on_edge:
        # ... and turns the direction within the plane of t and n: dn = -t (n·(dx_v - dx_u))/ℓ
        for i in range(3):
            for j in range(3):
                tn = t[i] * (normal[j] / ell)
                dn[1 + u, i, j] += tn
                dn[1 + v, i, j] -= tn


@numba.njit(cache=True)
def _all_terms(x, node, support, lam, normal, edge, dn, dlam):  # pragma: no cover
    for i in range(len(node)):
        if edge[i]:
            _feature_terms(x, node[i], support[i], lam[i], normal[i], dn[i], dlam[i])
        else:
            _face_terms(x, node[i], support[i], lam[i], normal[i], dn[i], dlam[i])


def direction_derivatives(x: np.ndarray, node: np.ndarray, support: np.ndarray,
                          lam: np.ndarray, normal: np.ndarray, edge: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """``∂n/∂x_m`` ``(A, 4, 3, 3)`` and ``∂λ_j/∂x_m`` ``(A, 3, 4, 3)``, ``m`` over ``[p, a, b, c]``.

    Parameters
    ----------
    x
        ``(N, 3)`` node positions (mm).
    node, support, lam, normal
        Per contact: the node, the triangle's vertices ``(A, 3)``, the
        barycentric coordinates of the contact point ``(A, 3)`` and the unit
        direction of the force on the node ``(A, 3)``.
    edge
        ``(A,)`` True for edge or vertex contacts (closest point on the boundary).
    """
    count = len(node)
    dn = np.zeros((count, 4, 3, 3))
    dlam = np.zeros((count, 3, 4, 3))
    _all_terms(np.ascontiguousarray(x, dtype=np.float64), np.asarray(node, dtype=np.int64),
               np.ascontiguousarray(support, dtype=np.int64),
               np.ascontiguousarray(lam, dtype=np.float64),
               np.ascontiguousarray(normal, dtype=np.float64), np.asarray(edge, dtype=np.bool_),
               dn, dlam)
    return dn, dlam
