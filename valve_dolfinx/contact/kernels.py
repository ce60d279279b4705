"""Compiled loops of the contact search and Jacobian: the narrow phase's cheap pair tests,
the Jacobian's 3×3 blocks (per row and per group of blended rows) and their sums per node
pair.

One contact evaluation of the closed valve at the default mesh tests some 20 000
(node, triangle) pairs and builds some 60 000 blocks, each a few dozen flops; as NumPy
expressions over all of them the work would go into temporaries the size of the result.
These loops, compiled by Numba (cached on disk after the first call), write each result
once.  Their sums run in the order written, so a result is the same to the last bit
from run to run.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["group_blocks", "near_pairs", "row_blocks", "sum_blocks"]


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
def group_blocks(group, ids, Bn, alpha, beta, U, V, num_nodes):  # pragma: no cover
    r"""Blocks coupling the rows of each group: ``Σ_{i,k} Bn_i[r] ⊗ (α_i U_k[m] + β_i V_k[m])``.

    The sum runs over all ordered pairs of rows ``(i, k)`` with the same ``group``
    label, ``i = k`` included, and puts the block at ``(ids[i, r], ids[k, m])``.  It
    factorises into :math:`P\otimes Q + P'\otimes Q'` over the distinct nodes the
    group's rows touch, with :math:`P_a = Σ_{(i,r): ids[i,r]=a} α_i Bn_i[r]`,
    :math:`Q_b = Σ_{(k,m): ids[k,m]=b} U_k[m]` (and β, V for the primed vectors), so a
    group of ``r`` rows over ``u`` distinct nodes costs ``u²`` blocks instead of the
    ``16 r²`` of the pair-by-pair sum (about 12 times fewer on the meshes of
    ``benchmarks/contact.py``).  A node whose rows carry no force (``α = β = 0``)
    takes no blocks.

    ``group`` ``(A,)``; ``ids`` ``(A, m)``; ``Bn``, ``U``, ``V`` ``(A, m, 3)``;
    ``alpha``, ``beta`` ``(A,)``.  Returns the blocks' row and column nodes and the
    ``(K, 3, 3)`` blocks, by group, then row node, then column node.
    """
    count, m = ids.shape
    flat = count * m
    key = np.empty(flat, dtype=np.int64)
    for i in range(count):
        for r in range(m):
            key[i * m + r] = group[i] * num_nodes + ids[i, r]
    order = np.argsort(key, kind="mergesort")
    # the distinct (group, node) entries, in increasing key order
    entry = np.empty(flat, dtype=np.int64)
    entry_key = np.empty(flat, dtype=np.int64)
    entries = 0
    for j in range(flat):
        k = key[order[j]]
        if entries == 0 or entry_key[entries - 1] != k:
            entry_key[entries] = k
            entries += 1
        entry[order[j]] = entries - 1
    P = np.zeros((entries, 3))
    P2 = np.zeros((entries, 3))
    Q = np.zeros((entries, 3))
    Q2 = np.zeros((entries, 3))
    for i in range(count):
        for r in range(m):
            e = entry[i * m + r]
            for s in range(3):
                P[e, s] += alpha[i] * Bn[i, r, s]
                P2[e, s] += beta[i] * Bn[i, r, s]
                Q[e, s] += U[i, r, s]
                Q2[e, s] += V[i, r, s]
    # the entries of one group are contiguous: [first[e], last[e])
    first = np.empty(entries, dtype=np.int64)
    last = np.empty(entries, dtype=np.int64)
    start = 0
    for e in range(entries + 1):
        if e == entries or entry_key[e] // num_nodes != entry_key[start] // num_nodes:
            for g in range(start, e):
                first[g], last[g] = start, e
            start = e
    pushed = np.empty(entries, dtype=np.bool_)
    total = 0
    for e in range(entries):
        pushed[e] = False
        for s in range(3):
            pushed[e] = pushed[e] or P[e, s] != 0.0 or P2[e, s] != 0.0
        if pushed[e]:
            total += last[e] - first[e]
    rows = np.empty(total, dtype=np.int64)
    cols = np.empty(total, dtype=np.int64)
    blocks = np.empty((total, 3, 3))
    k = 0
    for a in range(entries):
        if not pushed[a]:
            continue
        for b in range(first[a], last[a]):
            rows[k] = entry_key[a] % num_nodes
            cols[k] = entry_key[b] % num_nodes
            for s in range(3):
                for t in range(3):
                    blocks[k, s, t] = P[a, s] * Q[b, t] + P2[a, s] * Q2[b, t]
            k += 1
    return rows, cols, blocks


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
