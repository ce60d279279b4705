"""Compiled loops of the contact Jacobian: its 3×3 blocks, and their sum per node pair.

The blocks of one contact evaluation are many small outer products (some 60 000 on the
closed valve at the default mesh), which NumPy can only build through temporaries of
the size of the result.  These loops, compiled by Numba (cached on disk after the first
call), write each block once.  Every floating-point operation is the one the NumPy
expressions in :meth:`~valve_dolfinx.contact.results.ContactRows.result` would do, in
the same order, so the blocks and their sums are the same to the last bit.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["near_pairs", "outer_blocks", "row_blocks", "sum_blocks"]


@numba.njit(cache=True)
def row_blocks(ids, B, normal, own, magnitude, geometric, dn, dlam, rows, cols,
               blocks):  # pragma: no cover
    r"""Blocks of each row over its own nodes: ``(r, m) = n ⊗ T_rm + B_r φ ∂n/∂x_m``.

    ``T_rm = B_r own_m - [r ≥ 1] φ ∂λ_{r-1}/∂x_m`` (``φ`` the row's force magnitude,
    ``dn`` ``(A, m, 3, 3)``, ``dlam`` ``(A, m-1, m, 3)``); without the geometric
    terms (``geometric`` False, ``dn`` and ``dlam`` unused) ``(B_r n) ⊗ own_m``.
    Writes ``rows``, ``cols`` ``(A·m·m,)`` and ``blocks`` ``(A·m·m, 3, 3)``, row by
    row, then row node, then column node.
    """
    count, m = ids.shape
    k = 0
    for i in range(count):
        phi = magnitude[i]
        for r in range(m):
            Br = B[i, r]
            Bphi = Br * phi
            for c in range(m):
                rows[k] = ids[i, r]
                cols[k] = ids[i, c]
                if not geometric:
                    for a in range(3):
                        for b in range(3):
                            blocks[k, a, b] = (Br * normal[i, a]) * own[i, c, b]
                    k += 1
                    continue
                for b in range(3):
                    t = Br * own[i, c, b]
                    if r >= 1:
                        t = t - phi * dlam[i, r - 1, c, b]
                    for a in range(3):
                        blocks[k, a, b] = normal[i, a] * t + Bphi * dn[i, c, a, b]
                k += 1


@numba.njit(cache=True)
def outer_blocks(P, Q, P2, Q2, a, b, blocks):  # pragma: no cover
    """``blocks[k] = P[a_k] ⊗ Q[b_k] + P2[a_k] ⊗ Q2[b_k]`` (the coupling of a group's rows)."""
    for k in range(len(a)):
        i, j = a[k], b[k]
        for s in range(3):
            for t in range(3):
                blocks[k, s, t] = P[i, s] * Q[j, t] + P2[i, s] * Q2[j, t]


@numba.njit(cache=True)
def sum_blocks(rows, cols, blocks, num_nodes):  # pragma: no cover
    """The blocks summed per (row, column) pair, sorted by row then column, zero sums left out.

    Each pair's sum runs over its blocks in their order in the input.  Linear in the
    number of blocks: a counting sort by row, then a slot per column node within a row.
    """
    count = len(rows)
    start = np.zeros(num_nodes + 1, dtype=np.int64)
    for k in range(count):
        start[rows[k] + 1] += 1
    for n in range(num_nodes):
        start[n + 1] += start[n]
    order = np.empty(count, dtype=np.int64)
    fill = start[:-1].copy()
    for k in range(count):
        order[fill[rows[k]]] = k
        fill[rows[k]] += 1
    slot = np.full(num_nodes, -1, dtype=np.int64)
    out_rows = np.empty(count, dtype=np.int64)
    out_cols = np.empty(count, dtype=np.int64)
    summed = np.empty((count, 3, 3))
    total = 0
    for row in range(num_nodes):
        first = total
        for j in range(start[row], start[row + 1]):
            k = order[j]
            col = cols[k]
            s = slot[col]
            if s < 0:
                s = total
                slot[col] = s
                out_cols[s] = col
                summed[s] = 0.0
                total += 1
            for p in range(3):
                for q in range(3):
                    summed[s, p, q] += blocks[k, p, q]
        for s in range(first, total):
            slot[out_cols[s]] = -1
            out_rows[s] = row
        # columns in increasing order within the row (insertion sort: a row has few)
        for s in range(first + 1, total):
            col = out_cols[s]
            block = summed[s].copy()
            j = s - 1
            while j >= first and out_cols[j] > col:
                out_cols[j + 1] = out_cols[j]
                summed[j + 1] = summed[j]
                j -= 1
            out_cols[j + 1] = col
            summed[j + 1] = block
    # leave out the all-zero sums, in place
    kept = 0
    for s in range(total):
        nonzero = False
        for p in range(3):
            for q in range(3):
                nonzero = nonzero or summed[s, p, q] != 0.0
        if nonzero:
            out_rows[kept], out_cols[kept] = out_rows[s], out_cols[s]
            summed[kept] = summed[s]
            kept += 1
    return out_rows[:kept], out_cols[:kept], summed[:kept]


@numba.njit(cache=True)
def _nan_max(a, b):  # pragma: no cover
    """``np.maximum`` of two scalars: NaN if either is (a degenerate triangle's bound)."""
    if a != a or b != b:
        return np.nan
    return a if a > b else b


@numba.njit(cache=True)
def near_pairs(node, tri, xt, origin, normal, grad1, grad2, altitudes, node_body,
               triangle_body, side_band, face_band, excluded, search_distance,
               reach):  # pragma: no cover
    """The cheap narrow-phase tests of (node, triangle) pairs from the broad phase.

    Keeps a pair when the node lies within ``search_distance`` of the triangle's plane,
    its projection falls in the triangle or its fade band (``side_band`` beyond the
    sides of another body's triangle, ``face_band`` otherwise) or possibly within
    ``reach`` of it, and it is not in the triangle's neighbourhood (``excluded``, ``-1``
    padded rows).  Returns ``node, tri``, the plane distance ``d0``, the barycentric
    coordinates ``lam (K, 3)`` of the projection, ``beyond`` (a lower bound on its
    in-plane distance from the triangle) and ``in_band``, in the order of the input.
    """
    count = len(node)
    out_node = np.empty(count, dtype=np.int64)
    out_tri = np.empty(count, dtype=np.int64)
    out_d0 = np.empty(count)
    out_lam = np.empty((count, 3))
    out_beyond = np.empty(count)
    out_in_band = np.empty(count, dtype=np.bool_)
    kept = 0
    for k in range(count):
        p, t = node[k], tri[k]
        r0 = xt[0, p] - origin[0, t]
        r1 = xt[1, p] - origin[1, t]
        r2 = xt[2, p] - origin[2, t]
        d0 = r0 * normal[0, t] + r1 * normal[1, t] + r2 * normal[2, t]
        if not abs(d0) < search_distance:
            continue
        lam1 = r0 * grad1[0, t] + r1 * grad1[1, t] + r2 * grad1[2, t]
        lam2 = r0 * grad2[0, t] + r1 * grad2[1, t] + r2 * grad2[2, t]
        lam0 = 1.0 - lam1 - lam2
        beyond = _nan_max(_nan_max(-lam0 * altitudes[0, t], -lam1 * altitudes[1, t]),
                          -lam2 * altitudes[2, t])
        other = node_body[p] != triangle_body[t]
        b0 = side_band[t, 0] if other else face_band
        b1 = side_band[t, 1] if other else face_band
        b2 = side_band[t, 2] if other else face_band
        in_band = lam0 > -b0 and lam1 > -b1 and lam2 > -b2
        if not (in_band or (beyond < reach and abs(d0) < reach)):
            continue
        neighbour = False
        for e in excluded[t]:
            neighbour = neighbour or e == p
        if neighbour:
            continue
        out_node[kept], out_tri[kept], out_d0[kept] = p, t, d0
        out_lam[kept, 0], out_lam[kept, 1], out_lam[kept, 2] = lam0, lam1, lam2
        out_beyond[kept], out_in_band[kept] = beyond, in_band
        kept += 1
    return (out_node[:kept], out_tri[:kept], out_d0[:kept], out_lam[:kept],
            out_beyond[:kept], out_in_band[:kept])
