"""Compiled loops of the contact search and Jacobian: the narrow phase's cheap pair tests,
the gradients the Jacobian's 3×3 blocks are made of, the blocks themselves (per row and per
group of blended rows) and their sums per node pair.

One contact evaluation of the closed valve at the default mesh tests some 20 000
(node, triangle) pairs and makes some 60 000 blocks, each a few dozen flops, that sum to
some 7 000 distinct node pairs; as NumPy expressions over all of them the work would go
into temporaries the size of the result.  These loops, compiled by Numba (cached on disk
after the first call), sum each block into its node pair as they compute it.  Their sums
run in the order written, so a result is the same to the last bit from run to run.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from valve_dolfinx.contact.geometry import closest_point_weights

__all__ = ["group_blocks", "group_index", "narrow_rows", "nearest_inside", "near_pairs",
           "nodal_forces", "pair_slots", "presence_gradients", "row_block_sums",
           "row_gradients", "row_presence", "scalar_rows", "sum_blocks", "summed_already"]


@numba.njit(cache=True)
def _ramp(x, width):  # pragma: no cover
    """C¹ smoothstep: 0 for ``x <= 0``, 1 for ``x >= width``."""
    xi = x / width
    xi = 0.0 if xi < 0.0 else (1.0 if xi > 1.0 else xi)
    return xi * xi * (3.0 - 2.0 * xi)


@numba.njit(cache=True)
def row_presence(side, d0, gap, offset, plane_lam, plane_normal, thickness, band, eps,
                 tapered, cutoff):  # pragma: no cover
    r"""Distance, direction and presence of each candidate row
    (:meth:`~valve_dolfinx.contact.surface.SurfaceContact._find_contacts`).

    A face row (``gap`` NaN) is at its sided plane distance ``s d₀`` along ``s n_t``; an
    edge/vertex row at its distance ``gap`` from the closest point, along the offset from
    it; both less the contact ``thickness``.  The presence fades each row smoothly to 0
    where it appears or vanishes, so that no row enters or leaves the blend with a finite
    weight (a jump in the residual): a face row as the node's projection leaves the
    triangle, :math:`Π_j \operatorname{ramp}(λ_j + b_j, b_j)` over the ``band`` ``b``
    (smooth also near the vertices, where a min would kink); an edge/vertex row as the node
    reaches the triangle's plane (behind it the neighbouring face takes over) and as the
    in-plane distance of its projection from the triangle, :math:`ρ = \sqrt{gap² − d₀²}`,
    falls to 0 (where the projection re-enters the triangle its face row takes over, and a
    row vanishing with a finite weight there would make the blend jump and Newton cycle, a
    graft node at a free edge); every row as ``d`` reaches the cut-off, over ``eps`` if
    ``tapered``, else at once (the literal law jumps there anyway).  Ramps have width
    ``eps`` except the bands'.

    Returns ``edge``, ``d``, the unit directions ``(K, 3)``, ``s d₀``, the smallest
    barycentric coordinate of the projection, ``ρ`` (0 on face rows) and the presence.
    """
    count = len(side)
    edge = np.empty(count, dtype=np.bool_)
    d = np.empty(count)
    normal = np.empty((count, 3))
    side_distance = np.empty(count)
    lam_min = np.empty(count)
    in_plane = np.empty(count)
    presence = np.empty(count)
    for i in range(count):
        edge[i] = not np.isnan(gap[i])
        side_distance[i] = side[i] * d0[i]
        low = plane_lam[i, 0] if plane_lam[i, 0] < plane_lam[i, 1] else plane_lam[i, 1]
        lam_min[i] = low if low < plane_lam[i, 2] else plane_lam[i, 2]
        if edge[i]:
            d[i] = gap[i] - thickness[i]
            scale = max(gap[i], 1e-300)
            for a in range(3):
                normal[i, a] = offset[i, a] / scale
            spread = gap[i] * gap[i] - d0[i] * d0[i]
            in_plane[i] = np.sqrt(spread if spread >= 0.0 else 0.0)
            fade = _ramp(side_distance[i], eps) * _ramp(in_plane[i], eps)
        else:
            d[i] = side_distance[i] - thickness[i]
            for a in range(3):
                normal[i, a] = side[i] * plane_normal[i, a]
            in_plane[i] = 0.0
            fade = _ramp(plane_lam[i, 0] + band[i, 0], band[i, 0])
            fade = fade * _ramp(plane_lam[i, 1] + band[i, 1], band[i, 1])
            fade = fade * _ramp(plane_lam[i, 2] + band[i, 2], band[i, 2])
        if tapered:
            fade = fade * _ramp(cutoff - d[i], eps)
        else:
            fade = fade * (1.0 if d[i] < cutoff else 0.0)
        presence[i] = fade
    return edge, d, normal, side_distance, lam_min, in_plane, presence


@numba.njit(cache=True)
def _log_ramp_slope(x, width):  # pragma: no cover
    """``d log(ramp(x))/dx`` of the C¹ smoothstep ``ramp`` of ``width`` where it is positive
    (0 where it is 1)."""
    xi = min(max(x / width, 1e-300), 1.0)
    return 6.0 * (1.0 - xi) / (xi * (3.0 - 2.0 * xi)) / width


@numba.njit(cache=True)
def presence_gradients(B, normal, d, tapered, cutoff, eps, edge, plane_lam, side, plane_normal,
                       side_distance, in_plane, offset, plane_distance, banded, band, lam,
                       dlam):  # pragma: no cover
    r"""``∂log p/∂x`` ``(A, m, 3)`` over ``[node, support]`` of each row's presence ``p``
    (:meth:`~valve_dolfinx.contact.surface.SurfaceContact._find_contacts`): the taper
    towards the cut-off (``tapered``), with ``∇d = B ⊗ n``; on edge/vertex rows the fade
    in from the plane (``∇(s d₀) = B^{plane} ⊗ s n_t``) and with the in-plane distance
    ``ρ = √(gap² − d₀²)`` (``∇ρ = (B ⊗ (x_p − q) − d₀ B^{plane} ⊗ n_t)/ρ``); on face rows
    fading out beyond their triangle (``banded``) the band ramps of the barycentric
    coordinates, through ``dlam`` ``(A, m-1, m, 3)``."""
    count, m = B.shape
    out = np.zeros((count, m, 3))
    for i in range(count):
        if tapered:
            taper = _log_ramp_slope(cutoff - d[i], eps)
            for r in range(m):
                for s in range(3):
                    out[i, r, s] = out[i, r, s] - taper * (B[i, r] * normal[i, s])
        if edge[i]:
            fade = _log_ramp_slope(side_distance[i], eps)
            rho = in_plane[i]
            spread = _log_ramp_slope(rho, eps) / max(rho, 1e-300)
            for r in range(m):
                plane_B = 1.0 if r == 0 else -plane_lam[i, r - 1]
                for s in range(3):
                    sided = side[i] * plane_normal[i, s]
                    out[i, r, s] = out[i, r, s] + (fade * plane_B) * sided
            for r in range(m):
                plane_B = 1.0 if r == 0 else -plane_lam[i, r - 1]
                for s in range(3):
                    grad_rho = (B[i, r] * offset[i, s]
                                - (plane_distance[i] * plane_B) * plane_normal[i, s])
                    out[i, r, s] = out[i, r, s] + spread * grad_rho
        elif banded[i]:
            s0 = _log_ramp_slope(lam[i, 0] + band[i, 0], band[i, 0])
            s1 = _log_ramp_slope(lam[i, 1] + band[i, 1], band[i, 1])
            s2 = _log_ramp_slope(lam[i, 2] + band[i, 2], band[i, 2])
            for r in range(m):
                for s in range(3):
                    total = s0 * dlam[i, 0, r, s] + s1 * dlam[i, 1, r, s]
                    out[i, r, s] = out[i, r, s] + (total + s2 * dlam[i, 2, r, s])
    return out


@numba.njit(cache=True)
def nodal_forces(node, support, weights, normal, magnitude, num_nodes):  # pragma: no cover
    """``(N, 3)`` nodal forces of the rows: ``φ n`` on the node and ``-λ_j φ n`` on the
    triangle's vertex ``j`` (``φ`` = ``magnitude``), summed per node in the rows' order
    (as ``np.bincount`` sums)."""
    out = np.zeros((num_nodes, 3))
    m = support.shape[1] + 1
    for s in range(3):
        for i in range(len(node)):
            push = magnitude[i] * normal[i, s]
            for r in range(m):
                if r == 0:
                    out[node[i], s] += 1.0 * push
                else:
                    out[support[i, r - 1], s] += -weights[i, r - 1] * push
    return out


@numba.njit(cache=True)
def row_gradients(B, normal, grad_logp, p, dfdd, grad_f, turning, w, G, f, c, blended, depth,
                  scale, multi):  # pragma: no cover
    r"""Per row and node ``m`` of ``[node, support]``, the gradients its blocks are made of
    (:meth:`~valve_dolfinx.contact.results.ContactRows.result`), each ``(A, m, 3)``:

    * ``own``: ``w G ∇f + w f c ∇p``, with blending ``+ G f w(1-w) ∇L``, and on a row
      of a group of several (``multi``) ``+ (G f w² ∇L - w f c ∇p)`` (the ``i = k``
      term of the group sum taken out),
    * ``∇d = B ⊗ n``, ``w ∇L`` and ``c ∇p`` (the group coupling's factors),

    with ``∇p = p ∇log p``, ``∇f = f' ∇d`` (``+ grad_f`` if ``turning``) and
    ``∇L = ∇log p (1 + p·depth) - (p/scale) ∇d``.
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


@numba.njit(cache=True)
def row_block_sums(live, ids, B, normal, own, magnitude, geometric, dn, dlam, extra_rows,
                   extra_cols, extra_blocks, num_nodes):  # pragma: no cover
    r"""The blocks of the rows ``live`` over their own nodes and the ``extra`` blocks,
    summed per (row node, column node) pair: :func:`sum_blocks` of the row blocks
    followed by the extra ones, without writing the row blocks out one by one.

    Row ``i``'s block ``(r, m)`` is ``n ⊗ T_rm + B_r φ ∂n/∂x_m`` with
    ``T_rm = B_r own_m - [r ≥ 1] φ ∂λ_{r-1}/∂x_m`` (``φ`` the row's force magnitude,
    ``dn`` ``(A, m, 3, 3)``, ``dlam`` ``(A, m-1, m, 3)``); without the geometric terms
    (``geometric`` False, ``dn`` and ``dlam`` unused) ``(B_r n) ⊗ own_m``.  The blocks
    enter the sums row by row, then row node, then column node, then the extra blocks
    in their order.  The valve's rows repeat each node pair six to eight times (a
    node's blended triangles share their corners): summing as they are computed reads
    and writes a tenth of the memory of building all blocks and summing them after.
    """
    m = ids.shape[1]
    own_count = len(live) * m * m
    slot, out_rows, out_cols = pair_slots(live, ids, extra_rows, extra_cols, num_nodes)
    summed = np.zeros((len(out_rows), 3, 3))
    k = 0
    for i in live:
        phi = magnitude[i]
        for r in range(m):
            Br = B[i, r]
            Bphi = Br * phi
            for c in range(m):
                s = slot[k]
                if not geometric:
                    for a in range(3):
                        for b in range(3):
                            summed[s, a, b] += (Br * normal[i, a]) * own[i, c, b]
                    k += 1
                    continue
                for b in range(3):
                    t = Br * own[i, c, b]
                    if r >= 1:
                        t = t - phi * dlam[i, r - 1, c, b]
                    for a in range(3):
                        summed[s, a, b] += normal[i, a] * t + Bphi * dn[i, c, a, b]
                k += 1
    for j in range(len(extra_rows)):
        s = slot[own_count + j]
        for a in range(3):
            for b in range(3):
                summed[s, a, b] += extra_blocks[j, a, b]
    return _nonzero_blocks(out_rows, out_cols, summed)


@numba.njit(cache=True)
def group_index(group):  # pragma: no cover
    """``(inverse, counts)`` of non-negative labels, as ``np.unique(group, return_inverse=True,
    return_counts=True)`` gives them: each label's rank among the distinct labels, and how
    often each distinct label occurs.  Linear in the labels and their largest value (a dense
    table; the labels here are ``node · bodies + body``) instead of a sort."""
    size = 0
    for g in group:
        size = max(size, g + 1)
    rank = np.zeros(size, dtype=np.int64)
    for g in group:
        rank[g] = 1
    distinct = 0
    for g in range(size):
        if rank[g]:
            rank[g] = distinct
            distinct += 1
    inverse = np.empty(len(group), dtype=np.int64)
    counts = np.zeros(distinct, dtype=np.int64)
    for i in range(len(group)):
        inverse[i] = rank[group[i]]
        counts[inverse[i]] += 1
    return inverse, counts


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
    # entries in increasing key order: a counting sort by group, then each group's few
    # entries by node (insertion sort)
    num_groups = 0
    for i in range(count):
        num_groups = max(num_groups, group[i] + 1)
    start = np.zeros(num_groups + 1, dtype=np.int64)
    for i in range(count):
        start[group[i] + 1] += m
    for g in range(num_groups):
        start[g + 1] += start[g]
    order = np.empty(flat, dtype=np.int64)
    fill = start[:-1].copy()
    for j in range(flat):
        g = group[j // m]
        order[fill[g]] = j
        fill[g] += 1
    for g in range(num_groups):
        for a in range(start[g] + 1, start[g + 1]):
            moved = order[a]
            b = a - 1
            while b >= start[g] and key[order[b]] > key[moved]:
                order[b + 1] = order[b]
                b -= 1
            order[b + 1] = moved
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
def pair_slots(live, ids, extra_rows, extra_cols, num_nodes):  # pragma: no cover
    """The distinct (row, column) node pairs of the blocks of :func:`row_block_sums` (row
    ``i``'s block ``(r, c)`` at ``(ids[i, r], ids[i, c])`` for ``i`` in ``live``, then the
    extra blocks at ``(extra_rows, extra_cols)``), sorted by row then column, and the slot
    of every block among them: ``(slot (K,), pair rows, pair cols)``.

    Linear in the number of blocks: a counting sort of the row nodes ``(i, r)`` (not of
    every block), then per row node its distinct columns (marked in a table of the nodes),
    put in order (an insertion sort: a row has few), and each block's slot read back from
    the table.
    """
    m = ids.shape[1]
    own_rows = len(live) * m
    own_count = own_rows * m
    count = own_count + len(extra_rows)
    start = np.zeros(num_nodes + 1, dtype=np.int64)
    for li in range(len(live)):
        for r in range(m):
            start[ids[live[li], r] + 1] += 1
    for j in range(len(extra_rows)):
        start[extra_rows[j] + 1] += 1
    for n in range(num_nodes):
        start[n + 1] += start[n]
    order = np.empty(own_rows + len(extra_rows), dtype=np.int64)  # row instances by row node
    fill = start[:-1].copy()
    for li in range(len(live)):
        for r in range(m):
            row = ids[live[li], r]
            order[fill[row]] = li * m + r
            fill[row] += 1
    for j in range(len(extra_rows)):
        order[fill[extra_rows[j]]] = own_rows + j
        fill[extra_rows[j]] += 1
    slot_of = np.full(num_nodes, -1, dtype=np.int64)  # a column's slot in the current row
    slot = np.empty(count, dtype=np.int32)
    out_rows = np.empty(count, dtype=np.int64)
    out_cols = np.empty(count, dtype=np.int64)
    total = 0
    for row in range(num_nodes):
        first = total
        for a in range(start[row], start[row + 1]):  # the row's distinct columns
            instance = order[a]
            own = instance < own_rows
            for c in range(m if own else 1):
                col = ids[live[instance // m], c] if own else extra_cols[instance - own_rows]
                if slot_of[col] < 0:
                    slot_of[col] = 0
                    out_cols[total] = col
                    total += 1
        for s in range(first + 1, total):  # in increasing order
            col = out_cols[s]
            j = s - 1
            while j >= first and out_cols[j] > col:
                out_cols[j + 1] = out_cols[j]
                j -= 1
            out_cols[j + 1] = col
        for s in range(first, total):
            slot_of[out_cols[s]] = s
            out_rows[s] = row
        for a in range(start[row], start[row + 1]):  # every block's slot
            instance = order[a]
            if instance < own_rows:
                i, k0 = live[instance // m], instance * m
                for c in range(m):
                    slot[k0 + c] = slot_of[ids[i, c]]
            else:
                slot[own_count + instance - own_rows] = slot_of[extra_cols[instance - own_rows]]
        for s in range(first, total):
            slot_of[out_cols[s]] = -1
    return slot, out_rows[:total], out_cols[:total]


@numba.njit(cache=True)
def _zero_block(blocks, k):  # pragma: no cover
    """Whether the 3×3 block ``blocks[k]`` is all zero."""
    for p in range(3):
        for q in range(3):
            if blocks[k, p, q] != 0.0:
                return False
    return True


@numba.njit(cache=True)
def _nonzero_blocks(rows, cols, blocks):  # pragma: no cover
    """The (row, col, block) triples whose block is not all zero, in order (in place)."""
    kept = 0
    for s in range(len(rows)):
        if not _zero_block(blocks, s):
            rows[kept], cols[kept] = rows[s], cols[s]
            blocks[kept] = blocks[s]
            kept += 1
    return rows[:kept], cols[:kept], blocks[:kept]


@numba.njit(cache=True)
def sum_blocks(rows, cols, blocks, num_nodes):  # pragma: no cover
    """The blocks summed per (row, column) pair, sorted by row then column, zero sums left out.

    Each pair's sum runs over its blocks in their order in the input
    (:func:`pair_slots`, then one pass over the blocks).
    """
    slot, out_rows, out_cols = pair_slots(np.empty(0, dtype=np.int64),
                                          np.empty((0, 1), dtype=np.int64), rows, cols,
                                          num_nodes)
    summed = np.zeros((len(out_rows), 3, 3))
    for k in range(len(rows)):
        s = slot[k]
        for p in range(3):
            for q in range(3):
                summed[s, p, q] += blocks[k, p, q]
    return _nonzero_blocks(out_rows, out_cols, summed)


@numba.njit(cache=True)
def summed_already(rows, cols, blocks):  # pragma: no cover
    """Whether the blocks are what :func:`sum_blocks` would return for them: sorted by
    row then column, each (row, column) pair once, no all-zero block."""
    for k in range(len(rows)):
        if k > 0 and (rows[k] < rows[k - 1] or (rows[k] == rows[k - 1]
                                                 and cols[k] <= cols[k - 1])):
            return False
        if _zero_block(blocks, k):
            return False
    return True


@numba.njit(cache=True)
def scalar_rows(rows, cols, blocks, scale, row_base, col_base):  # pragma: no cover
    """``scale``·3×3 blocks as matrix rows: ``(indptr, columns, values, rows)`` of a CSR
    with three rows per block row.

    ``rows``/``cols`` are block row/column ids, the blocks of a row consecutive;
    ``row_base[r] + p`` is the matrix row of component ``p`` of block row ``r`` and
    ``col_base[c] + q`` the column of component ``q`` of block column ``c``.  Within a
    matrix row the columns ascend (the blocks of a row put in order of ``col_base``, an
    insertion sort of the row's few blocks), which is the order a compressed-row matrix
    finds them fastest in.  Every entry of every block is written, zeros included.
    """
    n = len(rows)
    runs = 0
    for k in range(n):
        if k == 0 or rows[k] != rows[k - 1]:
            runs += 1
    indptr = np.empty(3 * runs + 1, dtype=np.int64)
    out_rows = np.empty(3 * runs, dtype=np.int64)
    columns = np.empty(9 * n, dtype=np.int64)
    values = np.empty(9 * n)
    order = np.empty(n, dtype=np.int64)
    position, r, start = 0, 0, 0
    while start < n:
        stop = start
        while stop < n and rows[stop] == rows[start]:
            key = col_base[cols[stop]]
            a = stop
            while a > start and col_base[cols[order[a - 1]]] > key:
                order[a] = order[a - 1]
                a -= 1
            order[a] = stop
            stop += 1
        for p in range(3):
            out_rows[r] = row_base[rows[start]] + p
            indptr[r] = position
            for a in range(start, stop):
                m = order[a]
                for q in range(3):
                    columns[position] = col_base[cols[m]] + q
                    values[position] = scale * blocks[m, p, q]
                    position += 1
            r += 1
        start = stop
    indptr[r] = position
    return indptr, columns, values, out_rows


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
    ``reach`` of it, and it is not in the triangle's neighbourhood (``excluded``: per
    triangle the node ids in ascending order, then ``-1`` padding, as
    :mod:`~valve_dolfinx.contact.exclusions` makes them).  Returns ``node, tri``, the
    plane distance ``d0``, the barycentric coordinates ``lam (K, 3)`` of the projection,
    ``beyond`` (a lower bound on its in-plane distance from the triangle) and ``in_band``,
    in the order of the input.
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
        for e in excluded[t]:  # ascending, then -1
            if e < 0 or e > p:
                break
            if e == p:
                neighbour = True
                break
        if neighbour:
            continue
        out_node[kept], out_tri[kept], out_d0[kept] = p, t, d0
        out_lam[kept, 0], out_lam[kept, 1], out_lam[kept, 2] = lam0, lam1, lam2
        out_beyond[kept], out_in_band[kept] = beyond, in_band
        kept += 1
    return (out_node[:kept], out_tri[:kept], out_d0[:kept], out_lam[:kept],
            out_beyond[:kept], out_in_band[:kept])


@numba.njit(cache=True)
def narrow_rows(node, tri, d0, lam, beyond, in_band, xt, triangles, normal, reach, bound,
                inside_tolerance):  # pragma: no cover
    """The rows of the pairs :func:`near_pairs` kept
    (:meth:`~valve_dolfinx.contact.surface.SurfaceContact._narrow`): first the face rows
    (``in_band``), then the edge/vertex rows: the pairs whose projection lies outside the
    triangle (a barycentric coordinate below ``-inside_tolerance``) with the lower bound
    ``√(beyond² + d0²)`` on their distance below ``bound`` and their closest point on the
    triangle within ``reach``, each in the order of the input (a pair whose projection
    lies in the fade band outside the triangle makes one row of each kind).

    Returns ``node, tri``, ``d0``, the distance ``gap`` to the closest point (NaN on face
    rows), the barycentric coordinates ``(K, 3)`` of the closest point (the projection's on
    face rows), the offset ``(K, 3)`` of the node from it (``d0 n`` on face rows) and those
    of the projection.
    """
    count = len(node)
    size = 2 * count  # a pair in a face's fade band, outside the triangle, makes both rows
    out_node = np.empty(size, dtype=np.int64)
    out_tri = np.empty(size, dtype=np.int64)
    out_d0 = np.empty(size)
    out_gap = np.empty(size)
    out_lam = np.empty((size, 3))
    out_offset = np.empty((size, 3))
    out_plane_lam = np.empty((size, 3))
    kept = 0
    for k in range(count):
        if not in_band[k]:
            continue
        t = tri[k]
        out_node[kept], out_tri[kept], out_d0[kept], out_gap[kept] = node[k], t, d0[k], np.nan
        for j in range(3):
            out_lam[kept, j] = lam[k, j]
            out_plane_lam[kept, j] = lam[k, j]
            out_offset[kept, j] = d0[k] * normal[j, t]
        kept += 1
    for k in range(count):
        l0, l1, l2 = lam[k, 0], lam[k, 1], lam[k, 2]
        if l0 != l0 or l1 != l1 or l2 != l2:  # np.min of a degenerate triangle's NaN
            continue
        if not (min(l0, min(l1, l2)) < -inside_tolerance
                and math.hypot(beyond[k], d0[k]) < bound):
            continue
        p, t = node[k], tri[k]
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        u, v, w = closest_point_weights(xt[0, p], xt[1, p], xt[2, p], xt[0, a], xt[1, a],
                                        xt[2, a], xt[0, b], xt[1, b], xt[2, b], xt[0, c],
                                        xt[1, c], xt[2, c])
        o0 = xt[0, p] - (u * xt[0, a] + v * xt[0, b] + w * xt[0, c])
        o1 = xt[1, p] - (u * xt[1, a] + v * xt[1, b] + w * xt[1, c])
        o2 = xt[2, p] - (u * xt[2, a] + v * xt[2, b] + w * xt[2, c])
        gap = math.sqrt((o0 * o0 + o1 * o1) + o2 * o2)  # np.linalg.norm's order
        if not gap < reach:
            continue
        out_node[kept], out_tri[kept], out_d0[kept], out_gap[kept] = p, t, d0[k], gap
        out_lam[kept, 0], out_lam[kept, 1], out_lam[kept, 2] = u, v, w
        out_offset[kept, 0], out_offset[kept, 1], out_offset[kept, 2] = o0, o1, o2
        out_plane_lam[kept, 0], out_plane_lam[kept, 1], out_plane_lam[kept, 2] = l0, l1, l2
        kept += 1
    return (out_node[:kept], out_tri[:kept], out_d0[:kept], out_gap[:kept], out_lam[:kept],
            out_offset[:kept], out_plane_lam[:kept])


@numba.njit(cache=True)
def nearest_inside(group, distance, inside):  # pragma: no cover
    """Per pair, whether the nearest pair of its ``group`` (smallest ``distance``, NaN last;
    of equal distances an ``inside`` one, then the first) is ``inside``: the order of
    ``np.lexsort((~inside, distance, group))``, linear in the pairs and the largest label
    instead of a sort."""
    size = 0
    for g in group:
        size = max(size, g + 1)
    best = np.full(size, -1, dtype=np.int64)
    for i in range(len(group)):
        b = best[group[i]]
        if b < 0:
            best[group[i]] = i
            continue
        d, e = distance[i], distance[b]
        if d != d or e != e:  # NaN: after every number, equal to another NaN
            nearer = e != e and d == d
            tie = d != d and e != e
        else:
            nearer, tie = d < e, d == e
        if nearer or (tie and inside[i] and not inside[b]):
            best[group[i]] = i
    out = np.empty(len(group), dtype=np.bool_)
    for i in range(len(group)):
        out[i] = inside[best[group[i]]]
    return out
