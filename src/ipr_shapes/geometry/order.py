"""Order statistics of 1-D float64 arrays by a partial sort: ``np.percentile`` and ``np.median``
with the same values, without their per-call set-up.

``np.percentile`` (linear method) and ``np.median`` of a small array cost 30-100 microseconds,
mostly argument handling, and the perception calls them about 90 times per bin frame (the wall
cues, the container rules). Here one ``np.partition`` at the two order statistics and numpy's own
interpolation formulas (``_lerp``: ``a + (b - a) * g``, or ``b - (b - a) * (1 - g)`` for
``g >= 0.5``; the median of an even count ``(a + b) / 2``), so the results are bit for bit those
of numpy (``tests/test_order.py``). A NaN among the values gives NaN, as numpy's does; other
dtypes, shapes and empty arrays are passed to numpy itself.
"""

from __future__ import annotations

import numpy as np


def _interpolated(ordered: np.ndarray, virtual: float) -> float:
    """numpy's linear interpolation at the virtual index ``virtual`` of the partially sorted
    ``ordered`` (its order statistics at floor(virtual) and the next are in place)."""
    count = ordered.size
    lower = int(np.floor(virtual))
    upper = min(lower + 1, count - 1)
    gamma = virtual - lower
    a, b = ordered[lower], ordered[upper]
    difference = b - a
    return float(b - difference * (1 - gamma) if gamma >= 0.5 else a + difference * gamma)


def _positions(count: int, percentiles: tuple[float, ...]) -> tuple[list[float], list[int]]:
    """The virtual indices (numpy's ``(n - 1) * q``) and the order statistics they need."""
    virtual = [(count - 1) * (q / 100.0) for q in percentiles]
    needed = set()
    for v in virtual:
        lower = int(np.floor(v))
        needed.update((lower, min(lower + 1, count - 1)))
    return virtual, sorted(needed)


def percentile(values: np.ndarray, q: float) -> float:
    """``float(np.percentile(values, q))``, ``q`` in [0, 100]; the values are not modified."""
    values = np.asarray(values)
    if values.dtype != np.float64 or values.ndim != 1 or values.size == 0:
        return float(np.percentile(values, q))  # numpy's own rules (a scalar q, as called)
    return percentiles(values, (q,))[0]


def percentiles(values: np.ndarray, qs: tuple[float, ...]) -> tuple[float, ...]:
    """``np.percentile(values, qs)`` as floats: for (N,) float64 ``values`` (N >= 1) one partial
    sort for all of them."""
    values = np.asarray(values)
    if values.dtype != np.float64 or values.ndim != 1 or values.size == 0:
        return tuple(float(v) for v in np.percentile(values, list(qs)))  # numpy's own rules
    if np.isnan(values).any():
        return tuple(float("nan") for _ in qs)
    virtual, needed = _positions(values.size, tuple(qs))
    ordered = np.partition(values, needed)
    return tuple(_interpolated(ordered, v) for v in virtual)


def median(values: np.ndarray) -> float:
    """``float(np.median(values))``: for (N,) float64 ``values`` (N >= 1) a partial sort."""
    values = np.asarray(values)
    if values.dtype != np.float64 or values.ndim != 1 or values.size == 0:
        return float(np.median(values))  # numpy's own rules (and its warnings)
    if np.isnan(values).any():
        return float("nan")
    count = values.size
    half = count // 2
    if count % 2:
        return float(np.partition(values, half)[half])
    ordered = np.partition(values, (half - 1, half))
    return float((ordered[half - 1] + ordered[half]) / 2.0)
