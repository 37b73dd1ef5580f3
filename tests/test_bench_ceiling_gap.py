"""The ceiling-gap analysis' exact split of a candidate's 1 - IoU over voxel classes."""

from __future__ import annotations

import numpy as np
import pytest
from benchmarks.ceiling_gap import SPLITS, _split
from benchmarks.hypothesis_ceiling import _iou

from ipr_shapes import voxels
from ipr_shapes.perception.free_space import FREE, OCCUPIED, SpaceMap, VoxelGrid

PITCH = 0.005


def block(lo, hi) -> np.ndarray:
    """Sorted keys of the voxels with indices lo <= (i, j, k) < hi."""
    axes = [np.arange(a, b) for a, b in zip(lo, hi, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.unique(voxels.pack(grid))


def test_the_split_is_exact_and_puts_each_voxel_in_its_class():
    truth = block((0, 0, 0), (10, 10, 10))  # 1000 voxels
    hull = block((0, 0, 0), (10, 10, 12))  # the true hull: two more layers on top
    # Candidate: the truth without its lowest layer (100 missing), with the hull's two
    # layers (200 concave) and two layers beyond x = 10 (200 outside the hull).
    candidate = np.union1d(block((0, 0, 1), (10, 10, 12)), block((10, 0, 0), (12, 10, 10)))
    grid = VoxelGrid(np.zeros(3), PITCH, (20, 20, 20))
    state = np.full(grid.shape, OCCUPIED, dtype=np.uint8)
    state[11, :, :] = FREE  # one of the outside layers is seen free: a leak
    state[:10, :10, 0] = FREE  # the missing layer is seen free: perception's
    split = _split(candidate, truth, hull, SpaceMap(grid, state), PITCH)
    union = 1000 + 200 + 200
    assert split["concave"] == pytest.approx(200 / union)
    assert split["leak"] == pytest.approx(100 / union)
    assert split["extra"] == pytest.approx(100 / union)
    assert split["missing_free"] == pytest.approx(100 / union)
    assert split["missing"] == pytest.approx(0.0)
    assert sum(split[s] for s in SPLITS) == pytest.approx(1 - _iou(candidate, truth))
