"""The auction's columns by team label (`tracks.columns`)."""

from __future__ import annotations

import numpy as np

from uavtrack.tracks import columns


def test_label_column_is_the_column_holding_each_label():
    """A label's column is where it stands among its trial's labels (each row
    increasing, then -1), -1 for a label absent or -1: the sorted search against the
    definition, on random trials and query shapes."""
    rng = np.random.default_rng(0)
    for _ in range(300):
        B, L = int(rng.integers(1, 4)), int(rng.integers(1, 8))
        labels = np.full((B, L), -1)
        for b in range(B):
            n = int(rng.integers(0, L + 1))
            labels[b, :n] = np.sort(rng.choice(30, n, replace=False))
        shape = (B, *rng.integers(1, 4, size=int(rng.integers(0, 3))).tolist())
        label = rng.integers(-1, 30, size=shape)
        expected = np.full(shape, -1)
        for index in np.ndindex(*shape):
            hits = np.flatnonzero(labels[index[0]] == label[index]) if label[index] >= 0 else []
            expected[index] = hits[0] if len(hits) else -1
        np.testing.assert_array_equal(columns.label_column(label, labels), expected)


def test_columns_of_a_batch_and_the_bids_laid_out_by_them():
    label = np.array([[[5, 2, -1], [2, 9, 7]]])
    confirmed = np.array([[[True, True, False], [True, False, True]]])
    cols = columns.of(label, confirmed)
    assert cols.labels.tolist() == [[2, 5, 7]]
    assert cols.column.tolist() == [[[1, 0, -1], [0, -1, 2]]]
    assert columns.holds(cols).tolist() == [[[True, True, False], [True, False, True]]]
    bids = columns.bids(np.array([[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]]), cols)
    assert bids.tolist() == [[[2.0, 1.0, 0.0], [4.0, 0.0, 6.0]]]
