r"""Linearisation of the contact forces: how each row's force magnitude, its direction and
its reactions change with the positions.

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

The first term is the magnitude changing: the distance ``d`` (``∂d/∂x_m = B_m n``
exactly), the presence, the blending weights and the driving force
(:func:`row_gradients`; the driving force's turning with ``n`` is :func:`turning_load`).
The other two are geometric (:func:`direction_derivatives`):

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

The blocks are made of these terms and summed per node pair in
:mod:`~valve_dolfinx.contact.blocks`.  All terms are exact first derivatives (checked
against finite differences in ``tests/test_contact_model.py``).  They are loops over the
contacts compiled by Numba: a contact's terms are a few dozen 3-vectors, and as NumPy
expressions over all contacts most of their cost would be temporaries.
The dependence of the external force itself on the positions is not here: the hook
freezes it within a step (see :mod:`valve_dolfinx.solvers.contact_hook`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from valve_dolfinx.contact.geometry import dot3

__all__ = ["direction_derivatives", "row_gradients", "turning_load"]

#: Barycentric coordinates below this count as zero when telling an edge contact
#: (two vertices carry the contact point) from a vertex contact (one does).
_ON_FEATURE = 1e-12


@numba.njit(cache=True)
def _face_terms(x, row, node, support, lam, normal, grad, dn, dlam, dnhat):  # pragma: no cover
    """``∂n/∂x_m`` ``(4, 3, 3)`` and ``∂λ_j/∂x_m`` ``(3, 4, 3)`` of contact ``row``, a face
    contact of node ``p`` with triangle ``tri`` (``grad`` ``(3, 3)``: its barycentric
    gradients ``g_j``), written into ``dn``, ``dlam`` (zero on entry); ``dnhat`` a
    ``(3, 3, 3)`` scratch buffer (``∂n̂/∂x_k``).  The arrays are those of all contacts: the
    row's views are taken here, not passed (passing views costs more than the terms)."""
    p, tri, lam, normal, grad = node[row], support[row], lam[row], normal[row], grad[row]
    dn, dlam = dn[row], dlam[row]
    a, b, c = tri[0], tri[1], tri[2]
    e10, e11, e12 = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
    e20, e21, e22 = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
    r0, r1, r2 = x[p, 0] - x[a, 0], x[p, 1] - x[a, 1], x[p, 2] - x[a, 2]
    N0 = e11 * e22 - e12 * e21
    N1 = e12 * e20 - e10 * e22
    N2 = e10 * e21 - e11 * e20
    length = math.sqrt(N0 * N0 + N1 * N1 + N2 * N2)
    n0, n1, n2 = N0 / length, N1 / length, N2 / length
    side = np.sign(n0 * normal[0] + n1 * normal[1] + n2 * normal[2])
    # ∂n̂/∂x_k = (I - n̂ n̂ᵀ) K_k / |N|, K_a = [e2 - e1]×, K_b = -[e2]×, K_c = [e1]×
    for k in range(3):
        sign = -1.0 if k == 1 else 1.0
        if k == 0:
            v0, v1, v2 = e20 - e10, e21 - e11, e22 - e12
        elif k == 1:
            v0, v1, v2 = e20, e21, e22
        else:
            v0, v1, v2 = e10, e11, e12
        K00, K01, K02 = 0.0, sign * -v2, sign * v1
        K10, K11, K12 = sign * v2, 0.0, sign * -v0
        K20, K21, K22 = sign * -v1, sign * v0, 0.0
        for i in range(3):
            ni = n0 if i == 0 else (n1 if i == 1 else n2)
            P0 = (1.0 if i == 0 else 0.0) - ni * n0
            P1 = (1.0 if i == 1 else 0.0) - ni * n1
            P2 = (1.0 if i == 2 else 0.0) - ni * n2
            t0 = (P0 * K00 + P1 * K10 + P2 * K20) / length
            t1 = (P0 * K01 + P1 * K11 + P2 * K21) / length
            t2 = (P0 * K02 + P1 * K12 + P2 * K22) / length
            dnhat[k, i, 0], dnhat[k, i, 1], dnhat[k, i, 2] = t0, t1, t2
            dn[1 + k, i, 0], dn[1 + k, i, 1], dn[1 + k, i, 2] = side * t0, side * t1, side * t2
    d0 = dot3(n0, n1, n2, r0, r1, r2)
    # dλ_j = g_j·(dx_p - Σ_k λ_k dx_k - d₀ dn̂)
    for j in range(3):
        g0, g1, g2 = grad[j, 0], grad[j, 1], grad[j, 2]
        dlam[j, 0, 0], dlam[j, 0, 1], dlam[j, 0, 2] = g0, g1, g2
        for k in range(3):
            for s in range(3):
                g_dn = g0 * dnhat[k, 0, s] + g1 * dnhat[k, 1, s] + g2 * dnhat[k, 2, s]
                dlam[j, 1 + k, s] = -lam[k] * grad[j, s] - d0 * g_dn


@numba.njit(cache=True)
def _feature_terms(x, row, node, support, lam, normal, dn, dlam):  # pragma: no cover
    """The same for an edge or vertex contact (``dn``, ``dlam`` zero on entry)."""
    p, tri, lam, normal = node[row], support[row], lam[row], normal[row]
    dn, dlam = dn[row], dlam[row]
    q0 = 0.0 + lam[0] * x[tri[0], 0] + lam[1] * x[tri[1], 0] + lam[2] * x[tri[2], 0]
    q1 = 0.0 + lam[0] * x[tri[0], 1] + lam[1] * x[tri[1], 1] + lam[2] * x[tri[2], 1]
    q2 = 0.0 + lam[0] * x[tri[0], 2] + lam[1] * x[tri[1], 2] + lam[2] * x[tri[2], 2]
    o0, o1, o2 = x[p, 0] - q0, x[p, 1] - q1, x[p, 2] - q2
    gap = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    u, v, carrying = -1, -1, 0
    for j in range(3):
        if lam[j] > _ON_FEATURE:
            carrying += 1
            if u < 0:
                u = j
            v = j
    on_edge = carrying == 2
    t0 = t1 = t2 = 0.0
    ell = 1.0
    if on_edge:
        d0 = x[tri[v], 0] - x[tri[u], 0]
        d1 = x[tri[v], 1] - x[tri[u], 1]
        d2 = x[tri[v], 2] - x[tri[u], 2]
        ell = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        t0, t1, t2 = d0 / ell, d1 / ell, d2 / ell
        # the edge turning (dt = P(dx_v - dx_u)/ℓ) drags the foot point along t
        for m in range(4):
            Bm = 1.0 if m == 0 else -lam[m - 1]
            dlam[v, m, 0] = Bm * (t0 / ell)
            dlam[v, m, 1] = Bm * (t1 / ell)
            dlam[v, m, 2] = Bm * (t2 / ell)
        for s in range(3):
            turn = (gap / ell) * normal[s] / ell
            dlam[v, 1 + u, s] -= turn
            dlam[v, 1 + v, s] += turn
        for m in range(4):
            for s in range(3):
                dlam[u, m, s] = -dlam[v, m, s]
    # ∂n/∂x_m = B_m Q/gap, Q the projector normal to n (and, on an edge, to t)
    scale = max(gap, 1e-300)
    for i in range(3):
        ti = t0 if i == 0 else (t1 if i == 1 else t2)
        for j in range(3):
            tj = t0 if j == 0 else (t1 if j == 1 else t2)
            Q = (1.0 if i == j else 0.0) - normal[i] * normal[j]
            if on_edge:
                Q -= ti * tj
            for m in range(4):
                Bm = 1.0 if m == 0 else -lam[m - 1]
                dn[m, i, j] = Bm * (Q / scale)
            if on_edge:
                # ... and turns within the plane of t and n: dn = -t (n·(dx_v - dx_u))/ℓ
                tn = ti * (normal[j] / ell)
                dn[1 + u, i, j] += tn
                dn[1 + v, i, j] -= tn


@numba.njit(cache=True)
def _all_terms(x, node, support, lam, normal, edge, grad, dn, dlam):  # pragma: no cover
    dnhat = np.empty((3, 3, 3))
    for row in range(len(node)):
        if edge[row]:
            _feature_terms(x, row, node, support, lam, normal, dn, dlam)
        else:
            _face_terms(x, row, node, support, lam, normal, grad, dn, dlam, dnhat)


def direction_derivatives(x: np.ndarray, node: np.ndarray, support: np.ndarray,
                          lam: np.ndarray, normal: np.ndarray, edge: np.ndarray,
                          gradients: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    gradients
        ``(A, 3, 3)`` the barycentric gradients ``g_j`` of each row's triangle at ``x``
        (:func:`~valve_dolfinx.contact.geometry.triangle_frames`; used by face rows).
    """
    count = len(node)
    dn = np.zeros((count, 4, 3, 3))
    dlam = np.zeros((count, 3, 4, 3))
    _all_terms(np.ascontiguousarray(x, dtype=np.float64), np.asarray(node, dtype=np.int64),
               np.ascontiguousarray(support, dtype=np.int64),
               np.ascontiguousarray(lam, dtype=np.float64),
               np.ascontiguousarray(normal, dtype=np.float64), np.asarray(edge, dtype=np.bool_),
               np.ascontiguousarray(gradients, dtype=np.float64), dn, dlam)
    return dn, dlam


@numba.njit(cache=True)
def _turning_load(dn, load, slope, out):  # pragma: no cover
    for a in range(dn.shape[0]):
        scale = -slope[a]
        for m in range(dn.shape[1]):
            for j in range(3):
                total = dn[a, m, 0, j] * load[a, 0]
                total = total + dn[a, m, 1, j] * load[a, 1]
                out[a, m, j] = scale * (total + dn[a, m, 2, j] * load[a, 2])


def turning_load(dn: np.ndarray, load: np.ndarray, slope: np.ndarray) -> np.ndarray:
    """``-slope_a (∂n/∂x_m)ᵀ load_a`` ``(A, 4, 3)``: how a force ``f(F)`` of slope
    ``slope = ∂f/∂F`` changes as its driving force ``F = -load·n`` turns with ``n``
    (``dn`` from :func:`direction_derivatives`, ``load`` ``(A, 3)``)."""
    out = np.empty(dn.shape[:2] + (3,))
    _turning_load(np.ascontiguousarray(dn), np.ascontiguousarray(load, dtype=np.float64),
                  np.ascontiguousarray(slope, dtype=np.float64), out)
    return out


@numba.njit(cache=True)
def row_gradients(B, normal, grad_logp, p, dfdd, grad_f, turning, w, G, f, c, blended, depth,
                  scale, multi):  # pragma: no cover
    r"""Per row and node ``m`` of ``[node, support]``, the gradients its blocks are made of
    (:meth:`~valve_dolfinx.contact.results.ContactRows.with_jacobian`), each ``(A, m, 3)``:

    * ``own``: ``w G ∇f + w f c ∇p``, with blending ``+ G f w(1-w) ∇L``, and on a row
      of a group of several (``multi``) ``+ (G f w² ∇L - w f c ∇p)`` (the ``i = k``
      term of the group sum taken out),
    * ``∇d = B ⊗ n``, ``w ∇L`` and ``c ∇p`` (the group coupling's factors),

    with ``∇p = p ∇log p``, ``∇f = f' ∇d`` (``+ grad_f`` if ``turning``) and
    ``∇L = ∇log p (1 + p·depth) - (p/scale) ∇d``.

    The row's force magnitude is ``s = w G f``: ``w`` its blending weight (``blended``:
    rows blended into one contact), ``G`` its group's presence and ``c = ∂G/∂p`` (from the
    row's presence ``p`` and its gradient ``grad_logp`` ``(A, m, 3)``), ``f`` the law's
    force, ``dfdd`` its slope in ``d`` and ``grad_f`` ``(A, m, 3)`` the rest of its gradient
    (the driving force turning, :func:`turning_load`; read if ``turning``);
    ``B = [1, -λ]`` ``(A, m)`` and ``normal`` ``(A, 3)`` give ``∇d``;
    ``depth = (h - d)/scale`` with the blend distance ``scale``.
    """
    count, m = B.shape
    own = np.empty((count, m, 3))
    grad_d = np.empty((count, m, 3))
    U = np.zeros((count, m, 3))
    V = np.empty((count, m, 3))
    for i in range(count):
        wG = w[i] * G[i]
        wfc = (w[i] * f[i]) * c[i]
        Gfw = (G[i] * f[i]) * w[i]
        spread = Gfw * (1.0 - w[i])
        self_term = Gfw * w[i]
        lift = 1.0 + p[i] * depth[i]
        pull = p[i] / scale
        for r in range(m):
            for s in range(3):
                gd = B[i, r] * normal[i, s]
                gl = grad_logp[i, r, s]
                gp = p[i] * gl
                gf = dfdd[i] * gd
                if turning:
                    gf = gf + grad_f[i, r, s]
                value = wG * gf + wfc * gp
                if blended:
                    gL = gl * lift - pull * gd
                    value = value + spread * gL
                    if multi[i]:
                        value = value + (self_term * gL - wfc * gp)
                    U[i, r, s] = w[i] * gL
                own[i, r, s] = value
                grad_d[i, r, s] = gd
                V[i, r, s] = c[i] * gp
    return own, grad_d, U, V
