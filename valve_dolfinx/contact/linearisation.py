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
``tests/test_contact_model.py``).
The dependence of the driving force on the positions is not here: the hook
freezes it within a step (see :mod:`valve_dolfinx.solvers.contact_hook`).
"""

from __future__ import annotations

import numpy as np

from valve_dolfinx.contact.geometry import barycentric_gradients

__all__ = ["direction_derivatives"]

#: Barycentric coordinates below this count as zero when telling an edge contact
#: (two vertices carry the contact point) from a vertex contact (one does).
_ON_FEATURE = 1e-12


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices ``[v]×`` of ``(K, 3)`` vectors, ``(K, 3, 3)``: ``[v]×·u = v × u``."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _face_terms(x, node, support, lam, normal):
    """``∂n/∂x_m`` ``(F, 4, 3, 3)`` and ``∂λ_j/∂x_m`` ``(F, 3, 4, 3)`` of face contacts."""
    X = x[support]
    e1, e2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    N = np.cross(e1, e2)
    length = np.linalg.norm(N, axis=1)
    nhat = N / length[:, None]
    side = np.sign(np.einsum("ij,ij->i", nhat, normal))
    P = np.eye(3) - nhat[:, :, None] * nhat[:, None, :]
    K = np.stack([_skew(e2 - e1), -_skew(e2), _skew(e1)], axis=1)          # (F, 3k, 3, 3)
    dnhat = np.einsum("fij,fkjl->fkil", P, K) / length[:, None, None, None]
    dn = np.zeros((len(node), 4, 3, 3))
    dn[:, 1:] = side[:, None, None, None] * dnhat
    _, grad = barycentric_gradients(X[:, 0], X[:, 1], X[:, 2])          # (F, 3j, 3)
    d0 = np.einsum("ij,ij->i", nhat, x[node] - X[:, 0])
    g_dn = np.einsum("fji,fkil->fjkl", grad, dnhat)                       # g_jᵀ ∂n̂/∂x_k
    dlam = np.zeros((len(node), 3, 4, 3))
    dlam[:, :, 0] = grad
    dlam[:, :, 1:] = (-lam[:, None, :, None] * grad[:, :, None, :]
                      - d0[:, None, None, None] * g_dn)
    return dn, dlam


def _feature_terms(x, node, support, lam, normal):
    """``∂n/∂x_m`` and ``∂λ_j/∂x_m`` of edge and vertex contacts (shapes as above)."""
    B = np.concatenate([np.ones((len(node), 1)), -lam], axis=1)
    q = np.einsum("ij,ijk->ik", lam, x[support])
    gap = np.linalg.norm(x[node] - q, axis=1)
    carrying = lam > _ON_FEATURE
    on_edge = carrying.sum(axis=1) == 2
    Q = np.eye(3) - normal[:, :, None] * normal[:, None, :]
    dlam = np.zeros((len(node), 3, 4, 3))
    if on_edge.any():
        rows = np.flatnonzero(on_edge)
        # the two carrying vertices, u before v
        u = np.argmax(carrying[rows], axis=1)
        v = 2 - np.argmax(carrying[rows][:, ::-1], axis=1)
        xu, xv = x[support[rows, u]], x[support[rows, v]]
        edge_length = np.linalg.norm(xv - xu, axis=1)
        t = (xv - xu) / edge_length[:, None]
        Q[rows] -= t[:, :, None] * t[:, None, :]
        # the edge turning (dt = P(dx_v - dx_u)/ℓ) drags the foot point along t
        n, ell = normal[rows], edge_length[:, None]
        slide = B[rows][:, :, None] * (t / ell)[:, None, :]                      # (E, 4, 3)
        turn = (gap[rows, None] / ell) * n / ell
        slide[np.arange(len(rows)), 1 + u] -= turn
        slide[np.arange(len(rows)), 1 + v] += turn
        dlam[rows, v] = slide
        dlam[rows, u] = -slide
    dn = B[:, :, None, None] * (Q / np.maximum(gap, 1e-300)[:, None, None])[:, None]
    if on_edge.any():
        # ... and turns the direction within the plane of t and n: dn = -t (n·(dx_v - dx_u))/ℓ
        tn = t[:, :, None] * (n / ell)[:, None, :]
        dn[rows, 1 + u] += tn
        dn[rows, 1 + v] -= tn
    return dn, dlam


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
    for mask, terms in ((~edge, _face_terms), (edge, _feature_terms)):
        if mask.any():
            dn[mask], dlam[mask] = terms(x, node[mask], support[mask], lam[mask], normal[mask])
    return dn, dlam
