"""The contact Jacobian's block sums (valve_dolfinx.contact.blocks) against plain loops
written from their definitions.

The blocks themselves are checked against finite differences with the contact models
(test_contact_model.py); here: that each block reaches its node pair and the sums run in
the documented order."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx.contact.blocks import NodeBlocks, group_blocks, row_block_sums, sum_blocks


def _summed_in_order(rows, cols, blocks):
    """{(row, col): sum of its blocks, left to right}, the all-zero sums left out."""
    expected = {}
    for r, c, b in zip(rows, cols, blocks, strict=True):  # left to right, as documented
        expected[(r, c)] = expected.get((r, c), 0.0) + b
    return {key: value for key, value in expected.items() if np.any(value != 0.0)}


def test_block_sums_per_pair_in_input_order_sorted_and_without_zero_sums():
    rng = np.random.default_rng(3)
    n = 7
    rows, cols = rng.integers(0, n, 400), rng.integers(0, n, 400)
    blocks = rng.normal(size=(400, 3, 3)) * 10.0 ** rng.integers(-8, 8, (400, 1, 1))
    # a pair whose two blocks cancel exactly gives no block
    rows = np.append(rows, [n + 1, n + 1])
    cols = np.append(cols, [2, 2])
    blocks = np.concatenate([blocks, [np.eye(3), -np.eye(3)]])
    out_rows, out_cols, summed = sum_blocks(rows, cols, blocks, n + 2)
    expected = _summed_in_order(rows, cols, blocks)
    assert (n + 1, 2) not in expected
    assert list(zip(out_rows, out_cols, strict=True)) == sorted(expected)
    for r, c, s in zip(out_rows, out_cols, summed, strict=True):
        assert np.array_equal(s, expected[(r, c)])  # bit for bit


@pytest.mark.parametrize("geometric", [True, False])
def test_row_block_sums_are_the_row_blocks_from_their_formula_summed_in_order(geometric):
    rng = np.random.default_rng(11)
    count, m, n = 60, 4, 15
    ids = np.stack([rng.choice(n, m, replace=False) for _ in range(count)])
    B = np.concatenate([np.ones((count, 1)), -rng.uniform(0, 1, (count, m - 1))], axis=1)
    normal = rng.normal(size=(count, 3))
    own = rng.normal(size=(count, m, 3))
    magnitude = rng.uniform(0, 2, count)
    dn, dlam = rng.normal(size=(count, m, 3, 3)), rng.normal(size=(count, m - 1, m, 3))
    live = np.flatnonzero(rng.uniform(size=count) < 0.8)
    extra_rows, extra_cols = rng.integers(0, n, 50), rng.integers(0, n, 50)
    extra = rng.normal(size=(50, 3, 3))
    rows, cols, blocks = row_block_sums(live, ids, B, normal, own, magnitude, geometric, dn,
                                        dlam, NodeBlocks(extra_rows, extra_cols, extra), n)
    # the blocks one by one from the documented formula, then the extra ones
    ref_rows, ref_cols, ref_blocks = [], [], []
    for i in live:
        for r in range(m):
            for c in range(m):
                if geometric:
                    T = B[i, r] * own[i, c] - (magnitude[i] * dlam[i, r - 1, c] if r else 0.0)
                    block = np.outer(normal[i], T) + (B[i, r] * magnitude[i]) * dn[i, c]
                else:
                    block = np.outer(B[i, r] * normal[i], own[i, c])
                ref_rows.append(ids[i, r])
                ref_cols.append(ids[i, c])
                ref_blocks.append(block)
    expected = _summed_in_order([*ref_rows, *extra_rows], [*ref_cols, *extra_cols],
                                [*ref_blocks, *extra])
    assert list(zip(rows, cols, strict=True)) == sorted(expected)
    for r, c, s in zip(rows, cols, blocks, strict=True):
        assert np.allclose(s, expected[(r, c)], rtol=1e-14, atol=1e-13)


def test_group_blocks_are_the_pairwise_group_sums():
    rng = np.random.default_rng(2)
    count, m, n = 40, 4, 12
    group = rng.integers(0, 6, count)
    ids = np.stack([rng.choice(n, m, replace=False) for _ in range(count)])
    Bn, U, V = (rng.normal(size=(count, m, 3)) for _ in range(3))
    alpha, beta = rng.normal(size=count), rng.normal(size=count)
    alpha[:3] = beta[:3] = 0.0  # rows that push nothing
    rows, cols, blocks = group_blocks(group, ids, Bn, alpha, beta, U, V, n)
    expected = {}
    for i in range(count):
        for k in range(count):
            if group[i] != group[k]:
                continue
            for r in range(m):
                for c in range(m):
                    key = (group[i], ids[i, r], ids[k, c])
                    block = np.outer(alpha[i] * Bn[i, r], U[k, c]) \
                        + np.outer(beta[i] * Bn[i, r], V[k, c])
                    expected[key] = expected.get(key, 0.0) + block
    got = {}  # the blocks come per group: sum them per node pair
    for r, c, b in zip(rows, cols, blocks, strict=True):
        got[(r, c)] = got.get((r, c), 0.0) + b
    summed = {}
    for (_, r, c), b in expected.items():
        summed[(r, c)] = summed.get((r, c), 0.0) + b
    assert set(got) <= set(summed)
    for key, value in summed.items():
        assert np.allclose(got.get(key, 0.0), value, rtol=1e-12, atol=1e-12)
