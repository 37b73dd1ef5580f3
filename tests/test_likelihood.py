"""Eq. 2's depth comparison: which pixels count and how."""

from __future__ import annotations

import numpy as np
import pytest

from ipr_shapes.likelihood import LikelihoodConfig, depth_error_norms, log_likelihood

CONFIG = LikelihoodConfig(error_cap_m=0.1, occlusion_margin_m=0.01)


def _scene():
    """A 20x20 image: object 1 in columns 5-9 at 0.50 m on a 0.60 m background."""
    depth = np.full((20, 20), 0.6, np.float32)
    labels = np.zeros((20, 20), np.int32)
    depth[:, 5:10] = 0.5
    labels[:, 5:10] = 1
    return depth, labels


def test_a_perfect_prediction_has_zero_error():
    depth, labels = _scene()
    predicted = np.where(labels == 1, depth, 0.0)
    norms = depth_error_norms(depth, labels, labels < 0, predicted, labels, [1], CONFIG)
    assert norms == pytest.approx([0.0])


def test_error_grows_with_the_predicted_shift_and_counts_each_pixel_kind():
    depth, labels = _scene()
    ignore = np.zeros_like(labels, bool)
    errors = []
    for shift in (1, 2, 4):
        predicted_ids = np.roll(labels, shift, axis=1)
        predicted = np.where(predicted_ids == 1, 0.5, 0.0).astype(np.float32)
        errors.append(
            depth_error_norms(depth, labels, ignore, predicted, predicted_ids, [1], CONFIG)[0]
        )
    assert errors[0] < errors[1] < errors[2]
    # Shift 1: 20 observed-only pixels at the cap, 20 predicted-only pixels 0.1 m in front of
    # the background (capped at 0.1): sqrt(40 * 0.01).
    assert errors[0] == pytest.approx(np.sqrt(40 * 0.01), rel=1e-5)


def test_predicted_pixels_hidden_by_a_nearer_observed_surface_are_no_evidence():
    depth, labels = _scene()
    occluder = np.zeros_like(labels, bool)
    occluder[:, 10:14] = True
    depth[occluder] = 0.3  # something in front, where the model extends the object
    labels[occluder] = 2
    predicted_ids = labels.copy()
    predicted_ids[occluder] = 1
    predicted = np.where(predicted_ids == 1, 0.5, 0.0).astype(np.float32)
    ignore = np.zeros_like(labels, bool)
    norms = depth_error_norms(depth, labels, ignore, predicted, predicted_ids, [1], CONFIG)
    assert norms[0] == pytest.approx(0.0)
    # Behind the object instead (the camera saw through where the model puts it): evidence.
    depth[occluder] = 0.6
    norms = depth_error_norms(depth, labels, ignore, predicted, predicted_ids, [1], CONFIG)
    assert norms[0] == pytest.approx(np.sqrt(80 * 0.01), rel=1e-5)


def test_missing_depth_and_robot_pixels_are_skipped():
    depth, labels = _scene()
    predicted_ids = np.zeros_like(labels)  # the model lost the object entirely
    predicted = np.zeros_like(depth)
    ignore = np.zeros_like(labels, bool)
    full = depth_error_norms(depth, labels, ignore, predicted, predicted_ids, [1], CONFIG)[0]
    depth[:10] = 0.0  # no readings in the top half
    ignore[15:] = True  # robot in the bottom quarter
    partial = depth_error_norms(depth, labels, ignore, predicted, predicted_ids, [1], CONFIG)[0]
    assert full == pytest.approx(np.sqrt(100 * 0.01))
    assert partial == pytest.approx(np.sqrt(25 * 0.01))


def test_log_likelihood_scales_with_alpha_and_decimation():
    norms = np.array([[0.1, 0.2], [0.3, 0.0]])
    assert log_likelihood(norms, 4, LikelihoodConfig(alpha_per_m=2.0)) == pytest.approx(-4.8)
    with pytest.raises(ValueError, match="decimation"):
        LikelihoodConfig(decimation=0)


def test_pixels_given_to_the_wrong_object_cost_nothing_when_the_geometry_explains_them():
    depth, labels = _scene()
    labels[:, 8:10] = 2  # the segmentation split the object: its right part became object 2
    predicted_ids = np.where(depth == 0.5, 1, 0)  # the model: one object, right depth
    predicted = depth.copy()  # the rendered scene (object and support) matches everywhere
    ignore = np.zeros_like(labels, bool)
    norms = depth_error_norms(depth, labels, ignore, predicted, predicted_ids, [1, 2], CONFIG)
    assert norms == pytest.approx([0.0, 0.0])


def test_the_pushed_frames_count_as_one_trajectory_when_asked():
    from ipr_shapes.likelihood import frame_weights

    frames, pushed = (0, 1, 2, 3), {1, 2, 3}
    each = LikelihoodConfig(pushed_frames="each")
    trajectory = LikelihoodConfig(pushed_frames="trajectory")
    assert frame_weights(frames, pushed, each) == pytest.approx([1, 1, 1, 1])
    # The frames before the first push keep their weight; the pushed ones share one.
    assert frame_weights(frames, pushed, trajectory) == pytest.approx([1, 1 / 3, 1 / 3, 1 / 3])
    assert frame_weights((0, 1, 2), {2}, trajectory) == pytest.approx([1, 1, 1])
    assert frame_weights(frames, set(), trajectory) == pytest.approx([1, 1, 1, 1])
    norms = np.array([[1.0, 2.0], [3.0, 0.0], [0.0, 3.0], [3.0, 3.0]])
    weights = frame_weights(frames, pushed, trajectory)
    assert log_likelihood(norms, 2, trajectory, weights) == pytest.approx(-0.2 * 2 * (3 + 4))
    assert log_likelihood(norms, 2, each) == pytest.approx(-0.2 * 2 * 15)
