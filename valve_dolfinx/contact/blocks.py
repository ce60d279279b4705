r"""The contact Jacobian's 3×3 node blocks, summed per (row node, column node) pair.

A contact row's force acts on its node and on its triangle's vertices and depends on the
positions of the same nodes: its Jacobian is a block per ordered pair of them
(:func:`row_block_sums`), and the rows blended into one contact add blocks coupling each
other's nodes (:func:`group_blocks`).  One contact evaluation of the closed valve at the
default mesh makes some 60 000 blocks, each a few dozen flops, that sum to some 7 000
distinct node pairs; as NumPy expressions over all of them the work would go into
temporaries the size of the result.  These loops, compiled by Numba, sum each block into
its node pair as they compute it (:func:`pair_slots` numbers the pairs); :func:`sum_blocks`
sums given blocks the same way (the solvers'
:meth:`~valve_dolfinx.solvers.nodal.NodalCoupling.merge_blocks`).  Every sum runs in the
order written, so a result is the same to the last bit from run to run.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

__all__ = ["NodeBlocks", "group_blocks", "pair_slots", "row_block_sums", "sum_blocks",
           "summed_already"]


class NodeBlocks(NamedTuple):
    """3×3 blocks ``(K, 3, 3)`` at the (row node, column node) pairs ``rows``, ``cols``
    ``(K,)``."""

    rows: np.ndarray
    cols: np.ndarray
    blocks: np.ndarray

    @classmethod
    def empty(cls) -> NodeBlocks:
        """No blocks."""
        return cls(np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64),
                   np.empty((0, 3, 3)))


@numba.njit(cache=True)
def row_block_sums(live, ids, B, normal, own, magnitude, geometric, dn, dlam, extra,
                   num_nodes):  # pragma: no cover
    r"""The blocks of the rows ``live`` over their own nodes and the ``extra`` blocks
    (:class:`NodeBlocks`), summed per (row node, column node) pair: :func:`sum_blocks` of
    the row blocks followed by the extra ones, without writing the row blocks out one by
    one.  Returns the :class:`NodeBlocks` of the sums, sorted by row then column node, no
    all-zero sum among them.

    Row ``i`` acts on the nodes ``ids[i]`` ``(A, m)`` with the factors ``B[i]`` ``(A, m)``
    (``[1, -λ]``) along ``normal[i]``; its block ``(r, m)`` is
    ``n ⊗ T_rm + B_r φ ∂n/∂x_m`` with ``T_rm = B_r own_m - [r ≥ 1] φ ∂λ_{r-1}/∂x_m``
    (``φ`` the row's force ``magnitude``, ``own`` ``(A, m, 3)`` from
    :func:`~valve_dolfinx.contact.linearisation.row_gradients`, ``dn`` ``(A, m, 3, 3)``,
    ``dlam`` ``(A, m-1, m, 3)``); without the geometric terms (``geometric`` False, ``dn``
    and ``dlam`` unused) ``(B_r n) ⊗ own_m``.  The blocks enter the sums row by row, then
    row node, then column node, then the extra blocks in their order.  The valve's rows
    repeat each node pair six to eight times (a node's blended triangles share their
    corners): summing as they are computed reads and writes a tenth of the memory of
    building all blocks and summing them after.
    """
    extra_rows, extra_cols, extra_blocks = extra.rows, extra.cols, extra.blocks
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
    ``alpha``, ``beta`` ``(A,)``.  Returns the :class:`NodeBlocks`, by group, then row
    node, then column node.
    """
    entry, entry_key = _group_entries(group, ids, num_nodes)
    P, P2, Q, Q2 = _entry_sums(entry, len(entry_key), alpha, beta, Bn, U, V)
    first, last = _group_spans(entry_key, num_nodes)
    entries = len(entry_key)
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
    return NodeBlocks(rows, cols, blocks)


@numba.njit(cache=True)
def _group_entries(group, ids, num_nodes):  # pragma: no cover
    """The distinct (group, node) pairs of :func:`group_blocks`' rows: ``entry`` ``(A·m,)``
    numbers each row node's pair, ``entry_key`` ``(E,)`` holds each pair's key
    ``group·num_nodes + node``, in increasing order (so a group's pairs are contiguous)."""
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
    entry = np.empty(flat, dtype=np.int64)
    entry_key = np.empty(flat, dtype=np.int64)
    entries = 0
    for j in range(flat):
        k = key[order[j]]
        if entries == 0 or entry_key[entries - 1] != k:
            entry_key[entries] = k
            entries += 1
        entry[order[j]] = entries - 1
    return entry, entry_key[:entries].copy()


@numba.njit(cache=True)
def _entry_sums(entry, entries, alpha, beta, Bn, U, V):  # pragma: no cover
    """The factors of :func:`group_blocks` per (group, node) pair ``entry``: ``P`` (``α Bn``),
    ``P2`` (``β Bn``), ``Q`` (``U``) and ``Q2`` (``V``), each ``(entries, 3)``, summed in
    row order."""
    count, m = Bn.shape[0], Bn.shape[1]
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
    return P, P2, Q, Q2


@numba.njit(cache=True)
def _group_spans(entry_key, num_nodes):  # pragma: no cover
    """For each (group, node) pair of ``entry_key`` (sorted), the pairs of its group:
    ``[first[e], last[e])``."""
    entries = len(entry_key)
    first = np.empty(entries, dtype=np.int64)
    last = np.empty(entries, dtype=np.int64)
    start = 0
    for e in range(entries + 1):
        if e == entries or entry_key[e] // num_nodes != entry_key[start] // num_nodes:
            for g in range(start, e):
                first[g], last[g] = start, e
            start = e
    return first, last


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
    return NodeBlocks(rows[:kept], cols[:kept], blocks[:kept])


@numba.njit(cache=True)
def sum_blocks(rows, cols, blocks, num_nodes):  # pragma: no cover
    """The :class:`NodeBlocks` of the blocks ``(K, 3, 3)`` at ``(rows, cols)`` summed per
    (row, column) pair, sorted by row then column, zero sums left out.

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
