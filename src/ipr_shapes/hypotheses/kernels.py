"""Compiled inner loops (numba) of hypothesis generation.

Algorithm 1 casts a few thousand rays per object through the frame's free-space map
(``generate._ray_limits``); in numpy each ray's every sample is placed, indexed and looked up
even though the ray ends at its first free voxel, a few samples in. The loop here stops there.
It does the same IEEE arithmetic as the numpy expression it replaces, operation by operation
(no fastmath), so the results are the same bits; ``tests/test_hypothesis_kernels.py`` pins it
against that expression. Compiled on first use and cached on disk, as
``ipr_shapes.perception.kernels`` (its module doc has the details; ``NUMBA_DISABLE_JIT=1``
runs the loop as plain Python).
"""

from __future__ import annotations

import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True)


@_jit
def first_state_samples(
    origins: np.ndarray,
    direction: np.ndarray,
    t: np.ndarray,
    grid_origin: np.ndarray,
    voxel_m: float,
    state: np.ndarray,
    value: int,
) -> np.ndarray:
    """Per ray, the index (R,) int64 of its first sample whose voxel holds ``value``, or
    ``len(t)`` when none does. Ray r's sample s is ``origins[r] + t[s] * direction`` (world,
    m); its voxel ``floor((sample - grid_origin) / voxel_m)`` in the (nx, ny, nz) ``state``
    grid (outside the grid: no value). The numpy expression it replaces::

        samples = (origins[:, None, :] + t[None, :, None] * direction).reshape(-1, 3)
        hits = (space.state_at(samples) == value).reshape(len(origins), len(t))
        first = np.where(hits.any(axis=1), np.argmax(hits, axis=1), len(t))
    """
    nx, ny, nz = state.shape
    count, samples = origins.shape[0], t.shape[0]
    first = np.full(count, samples, dtype=np.int64)
    for r in range(count):
        for s in range(samples):
            i = np.int64(np.floor((origins[r, 0] + t[s] * direction[0] - grid_origin[0]) / voxel_m))
            if i < 0 or i >= nx:
                continue
            j = np.int64(np.floor((origins[r, 1] + t[s] * direction[1] - grid_origin[1]) / voxel_m))
            if j < 0 or j >= ny:
                continue
            k = np.int64(np.floor((origins[r, 2] + t[s] * direction[2] - grid_origin[2]) / voxel_m))
            if k < 0 or k >= nz:
                continue
            if state[i, j, k] == value:
                first[r] = s
                break
    return first
