"""The contact rows' group index (valve_dolfinx.contact.results) against the distinct
labels counted by hand."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx.contact.results import group_index


@pytest.mark.parametrize("count, largest", [(0, 0), (1, 0), (500, 40), (300, 10_000)])
def test_group_index_is_the_rank_among_the_distinct_labels_and_their_counts(count, largest):
    labels = np.random.default_rng(count).integers(0, largest + 1, count)
    inverse, counts = group_index(labels)
    distinct = sorted(set(labels.tolist()))
    assert inverse.tolist() == [distinct.index(g) for g in labels]
    assert counts.tolist() == [int(np.sum(labels == g)) for g in distinct]
