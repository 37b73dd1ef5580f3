"""The partial-sort order statistics (``geometry.order``) against ``np.percentile`` and
``np.median``: the same bits on random, tied, tiny and NaN-holding arrays."""

import numpy as np
import pytest

from ipr_shapes.geometry import order


def _arrays():
    rng = np.random.default_rng(7)
    yield np.array([0.3])
    yield np.array([0.3, -1.0])
    yield np.array([2.0, 2.0, 2.0])
    for size in (3, 4, 10, 11, 57, 100, 1001, 5000):
        yield rng.normal(0.1, 0.05, size)
        yield np.round(rng.uniform(-1, 1, size), 2)  # ties
        yield rng.uniform(0, 1, size) * 1e-3 + 0.7  # close values, rounding matters


@pytest.mark.parametrize("q", [0, 0.5, 2, 5, 25, 50, 90, 95, 98, 99.5, 100])
def test_percentile_matches_numpy_bit_for_bit(q):
    for values in _arrays():
        kept = values.copy()
        got = order.percentile(values, q)
        assert got == float(np.percentile(values, q))
        assert np.array_equal(values, kept)  # not modified


def test_percentiles_match_numpy_for_several_at_once():
    for values in _arrays():
        got = order.percentiles(values, (2, 98))
        assert got == tuple(float(v) for v in np.percentile(values, [2, 98]))


def test_median_matches_numpy_bit_for_bit():
    for values in _arrays():
        kept = values.copy()
        assert order.median(values) == float(np.median(values))
        assert np.array_equal(values, kept)


def test_nan_gives_nan_like_numpy():
    values = np.array([0.1, np.nan, 0.3, 0.2])
    assert np.isnan(order.median(values)) and np.isnan(np.median(values))
    assert np.isnan(order.percentile(values, 2)) and np.isnan(np.percentile(values, 2))


def test_other_dtypes_go_to_numpy():
    single = np.array([0.1, 0.7, 0.3, 0.25], dtype=np.float32)
    assert order.median(single) == float(np.median(single))
    assert order.percentile(single, 98) == float(np.percentile(single, 98))
    whole = np.array([3, 1, 2, 8])
    assert order.percentiles(whole, (2, 98)) == tuple(
        float(v) for v in np.percentile(whole, [2, 98])
    )
