"""Small segments joined to the surface they continue (``ipr_shapes.perception.fragments``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.fragments import continues_surface, join_fragments, lies_on
from ipr_shapes.perception.types import KnownPlane, Supervoxels

K = np.array([[500.0, 0.0, 40.0], [0.0, 500.0, 30.0], [0.0, 0.0, 1.0]])
HEIGHT, WIDTH = 60, 80
RGB = np.full((HEIGHT, WIDTH, 3), 120, dtype=np.uint8)


def _config(area_m2: float = 3e-4, share: float = 0.3) -> PerceptionConfig:
    base = PerceptionConfig()
    return dataclasses.replace(
        base,
        segmentation=dataclasses.replace(
            base.segmentation, fragment_area_m2=area_m2, fragment_contact_share=share
        ),
    )


def _supervoxels(labels: np.ndarray, normals: np.ndarray | None = None) -> Supervoxels:
    """One supervoxel per segment (supervoxel i is segment i + 1; a fourth, unused), facing the
    camera unless ``normals`` (4, 3) says otherwise."""
    normals = np.tile([0.0, 0.0, -1.0], (4, 1)) if normals is None else normals
    return Supervoxels(
        labels - 1, np.zeros((4, 3)), normals, np.zeros((4, 3)), np.ones(4), np.zeros((0, 2))
    )


def _points(depth: np.ndarray) -> np.ndarray:
    """(H, W, 3) camera-frame points of a (H, W) depth image (the world frame here)."""
    rows, cols = np.mgrid[:HEIGHT, :WIDTH]
    x = (cols - K[0, 2]) / K[0, 0] * depth
    y = (rows - K[1, 2]) / K[1, 1] * depth
    return np.stack([x, y, depth], axis=-1)


def _scene(step_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A surface at 0.5 m over the whole frame: segment 1 on the left, a 10 x 10 px segment 2
    (1 cm^2 at 0.5 m) cut out of its right edge, and segment 3, a 16 px wide band on the
    right whose surface is ``step_m`` nearer than segment 1's. Background (0) above and below."""
    labels = np.zeros((HEIGHT, WIDTH), dtype=np.int32)
    labels[10:50, 0:50] = 1
    labels[20:30, 40:50] = 2  # inside segment 1's outline: surrounded by it on three sides
    labels[10:50, 50:66] = 3
    depth = np.full((HEIGHT, WIDTH), 0.5)
    depth[:, 50:66] -= step_m
    depth[labels == 0] = 0.8  # the table below, far behind
    segment_of_supervoxel = np.array([1, 2, 3, 0], dtype=np.int32)
    return labels, depth, segment_of_supervoxel


def test_a_fragment_joins_the_surface_it_continues_and_other_labels_are_kept():
    labels, depth, segments = _scene(step_m=0.05)
    joined, segments_joined = join_fragments(
        labels, segments, _points(depth), depth, K, RGB, _supervoxels(labels), _config()
    )
    # Segment 2 continues segment 1 (no depth step on three of its four sides) and takes its
    # label; segment 3 is 5 cm in front: it stays, under its own label.
    assert np.all(joined[20:30, 40:50] == 1)
    np.testing.assert_array_equal(joined[labels != 2], labels[labels != 2])
    assert segments_joined.tolist() == [1, 1, 3, 0]


def test_a_small_object_in_front_of_another_is_kept():
    labels, depth, segments = _scene(step_m=0.05)
    depth[labels == 2] -= 0.03  # a small box standing 3 cm in front of segment 1
    joined, _ = join_fragments(
        labels, segments, _points(depth), depth, K, RGB, _supervoxels(labels), _config()
    )
    assert len(np.unique(joined[joined > 0])) == 3


def test_a_short_contact_does_not_join():
    labels, depth, segments = _scene(step_m=0.0)
    # Segment 2 (8 x 8 px, small) moved above segment 3, at its depth: they meet along 6 of
    # segment 2's 32 outline pairs, the rest is background far behind.
    labels[labels == 2] = 1
    labels[2:10, 60:68] = 2
    depth[2:10, 60:68] = 0.5
    joined, _ = join_fragments(
        labels, segments, _points(depth), depth, K, RGB, _supervoxels(labels), _config()
    )
    assert len(np.unique(joined[joined > 0])) == 3


def test_large_segments_and_the_switch_off_are_left_alone():
    labels, depth, segments = _scene(step_m=0.05)
    points = _points(depth)
    for config in (_config(area_m2=0.0), _config(area_m2=0.5e-4)):  # off; 2 is 1 cm^2
        joined, segments_out = join_fragments(
            labels, segments, points, depth, K, RGB, _supervoxels(labels), config
        )
        assert joined is labels and segments_out is segments


@pytest.mark.parametrize("share", [0.5, 0.9])
def test_the_contact_share_decides(share):
    labels, depth, segments = _scene(step_m=0.05)
    # Segment 2 meets segment 1 along 30 of its 40 outline pairs (three sides of ten).
    joined, _ = join_fragments(
        labels, segments, _points(depth), depth, K, RGB, _supervoxels(labels), _config(share=share)
    )
    assert (len(np.unique(joined[joined > 0])) == 2) == (share <= 0.75)


def test_a_touching_piece_of_another_colour_is_kept():
    labels, depth, segments = _scene(step_m=0.05)
    rgb = RGB.copy()
    rgb[labels == 2] = (200, 60, 60)  # a red object packed into segment 1's grey one
    joined, _ = join_fragments(
        labels, segments, _points(depth), depth, K, rgb, _supervoxels(labels), _config()
    )
    assert len(np.unique(joined[joined > 0])) == 3


def test_a_piece_meeting_at_a_crease_is_kept():
    labels, depth, segments = _scene(step_m=0.05)
    normals = np.tile([0.0, 0.0, -1.0], (4, 1))
    normals[1] = [-1.0, 0.0, 0.0]  # segment 2 is a face square to segment 1's
    joined, _ = join_fragments(
        labels, segments, _points(depth), depth, K, RGB, _supervoxels(labels, normals), _config()
    )
    assert len(np.unique(joined[joined > 0])) == 3


def _numpy_borders(labels, points, depth, rgb, sv_labels, sv_normals, gap_m, min_cos, touch, n):
    """The numpy expression ``kernels.fragment_borders`` replaces."""
    valid = depth > 0
    area = np.bincount(labels[valid], weights=depth[valid] ** 2 / (K[0, 0] * K[1, 1]), minlength=n)
    colour = np.stack(
        [np.bincount(labels.ravel(), weights=rgb[..., c].ravel(), minlength=n) for c in range(3)],
        axis=1,
    )
    normals = np.append(sv_normals, np.zeros((1, 3)), axis=0)[sv_labels]
    outline = np.zeros((n, n), dtype=np.int64)
    continuous = np.zeros((n, n), dtype=np.int64)
    touching = np.zeros((n, n), dtype=np.int64)
    height, width = labels.shape
    for d_row, d_col in ((0, 1), (1, 0)):
        first = (slice(0, height - d_row), slice(0, width - d_col))
        second = (slice(d_row, height), slice(d_col, width))
        a, b = labels[first], labels[second]
        border = valid[first] & valid[second] & (a != b)
        low, high = np.minimum(a, b)[border], np.maximum(a, b)[border]
        np.add.at(outline, (low, high), 1)
        gap = np.linalg.norm(points[first][border] - points[second][border], axis=1)
        cosine = np.einsum("ij,ij->i", normals[first][border], normals[second][border])
        keep = (low > 0) & (gap < gap_m) & (cosine >= min_cos)
        np.add.at(continuous, (low[keep], high[keep]), 1)
        keep = (low > 0) & (gap < gap_m) & (cosine >= touch)
        np.add.at(touching, (low[keep], high[keep]), 1)
    return area, colour, outline, continuous, touching


def test_the_border_kernel_matches_its_numpy_expression():
    rng = np.random.default_rng(3)
    labels = rng.integers(0, 6, size=(HEIGHT, WIDTH)).astype(np.int32)
    labels[:, :40] = np.repeat(rng.integers(0, 6, size=(HEIGHT, 1)), 40, axis=1)  # long runs
    depth = 0.5 + 0.004 * rng.standard_normal((HEIGHT, WIDTH))
    depth[rng.random((HEIGHT, WIDTH)) < 0.1] = 0.0
    rgb = rng.integers(0, 256, size=(HEIGHT, WIDTH, 3)).astype(np.uint8)
    sv_labels = rng.integers(-1, 9, size=(HEIGHT, WIDTH)).astype(np.int32)
    sv_normals = rng.standard_normal((9, 3))
    sv_normals /= np.linalg.norm(sv_normals, axis=1, keepdims=True)
    points = _points(depth)
    # touch 0.0: pixels of no supervoxel (cosine exactly 0) lie on the bound.
    for gap_m, min_cos, touch in ((0.01, 0.5, -1.0), (0.003, -1.0, 0.5), (0.02, 0.9, 0.0)):
        got = kernels.fragment_borders(
            labels,
            points,
            depth,
            rgb,
            sv_labels,
            sv_normals,
            gap_m,
            min_cos,
            touch,
            1.0 / (K[0, 0] * K[1, 1]),
            6,
        )
        want = _numpy_borders(
            labels, points, depth, rgb, sv_labels, sv_normals, gap_m, min_cos, touch, 6
        )
        for g, w in zip(got, want, strict=True):
            np.testing.assert_allclose(g, w, rtol=1e-12)
        assert got[3].sum() > 0 and got[3].sum() < got[2].sum()
        assert got[4].sum() > 0 and got[4].sum() != got[3].sum()


def test_merged_counts_are_those_of_the_joined_labels():
    # Pair counts of 4 labels; joining label 3 into 1 must give the counts the relabelled
    # image would have: rows and columns added, pairs within the joined segment dropped.
    from ipr_shapes.perception.fragments import merge_counts

    counts = np.array([[0, 4, 1, 2], [4, 0, 3, 5], [1, 3, 0, 7], [2, 5, 7, 0]])
    merge_counts(counts, 3, 1)
    expected = np.array([[0, 6, 1, 0], [6, 0, 10, 0], [1, 10, 0, 0], [0, 0, 0, 0]])
    np.testing.assert_array_equal(counts, expected)
    np.testing.assert_array_equal(counts, counts.T)


#: The support for the tests below: world up is the camera's -y (image rows grow downwards).
SUPPORT = KnownPlane("support", np.array([0.0, -1.0, 0.0]), 0.0, np.zeros((0, 3)))


def _tilted_scene(piece_rows: slice) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``_scene`` without the band, on a surface tilted away from the camera (depth grows by
    2 mm a row, so footprints on the support have an extent), with segment 2 red: a cap or a
    printed band of another colour than its grey body, at ``piece_rows`` of the body's right
    edge. Returns (labels, depth, segments, rgb)."""
    labels, _, _ = _scene(step_m=0.0)
    segments = np.array([1, 2, 0, 0], dtype=np.int32)
    labels[labels == 2] = 1
    labels[labels == 3] = 0
    labels[piece_rows, 40:50] = 2
    depth = 0.5 + 0.002 * np.arange(HEIGHT)[:, None] * np.ones((1, WIDTH))
    depth[labels == 0] = 0.8
    rgb = RGB.copy()
    rgb[labels == 2] = (200, 60, 60)
    return labels, depth, segments, rgb


def _on_body_config(on_body: bool = True) -> PerceptionConfig:
    config = _config()
    return dataclasses.replace(
        config,
        segmentation=dataclasses.replace(config.segmentation, fragment_on_body=on_body),
    )


def test_a_piece_of_another_colour_on_its_body_joins():
    # The red piece lies within the grey body's footprint, in its upper half (a cap, a lid, a
    # band on a shoulder): the colours do not keep it apart.
    labels, depth, segments, rgb = _tilted_scene(slice(12, 22))
    points = _points(depth)
    sv = _supervoxels(labels)
    joined, _ = join_fragments(
        labels, segments, points, depth, K, rgb, sv, _on_body_config(), support=SUPPORT
    )
    assert np.all(joined[12:22, 40:50] == 1)
    # The rule's switch, and no support to measure heights on: the colour gate refuses it.
    for config, support in ((_on_body_config(False), SUPPORT), (_on_body_config(), None)):
        kept, _ = join_fragments(
            labels, segments, points, depth, K, rgb, sv, config, support=support
        )
        assert len(np.unique(kept[kept > 0])) == 2


def test_a_piece_of_another_colour_under_its_neighbour_is_kept():
    # The same red piece at the bottom of the grey surface: within its footprint but below it
    # (a ball wedged under a block that rests on it) stays a segment of its own.
    labels, depth, segments, rgb = _tilted_scene(slice(40, 50))
    joined, _ = join_fragments(
        labels,
        segments,
        _points(depth),
        depth,
        K,
        rgb,
        _supervoxels(labels),
        _on_body_config(),
        support=SUPPORT,
    )
    assert len(np.unique(joined[joined > 0])) == 2


def test_a_piece_lies_on_its_body_only_within_its_footprint_and_not_below_it():
    # A body: a 10 cm square box's top at 10 cm above the support (world up is -y here) and
    # its front face below it; pieces of 2 x 2 cm at 12 cm high on the box (a cap), 5 cm beside
    # its footprint at that height, and within its footprint but at 4 cm (under an overhang).
    grid = np.linspace(0.0, 0.1, 21)
    top = np.array([[x, -0.10, z] for x in grid for z in grid])
    front = np.array([[x, -h, 0.0] for x in grid for h in np.linspace(0.0, 0.1, 21)])
    body = np.concatenate([top, front])
    square = np.array(
        [[x, 0.0, z] for x in np.linspace(0, 0.02, 5) for z in np.linspace(0, 0.02, 5)]
    )
    cases = {
        "cap": (square + [0.04, -0.12, 0.04], True),
        "beside": (square + [0.15, -0.12, 0.04], False),
        "under": (square + [0.04, -0.04, 0.04], False),
    }
    for name, (piece, on) in cases.items():
        points = np.concatenate([body, piece]).reshape(1, -1, 3)
        labels = np.concatenate([np.full(len(body), 1), np.full(len(piece), 2)]).reshape(1, -1)
        depth = np.ones(labels.shape)
        got = lies_on(labels, 2, 1, points, depth, SUPPORT, PerceptionConfig())
        assert got == on, name


def _surface_scene(
    piece: str, body_noise_m: float = 3e-4, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, KnownPlane]:
    """A grey body curved as a cylinder of 10 cm radius about a vertical axis (depth 0.5 m at
    its middle column, 1 mm per pixel), with a red 2 x 2 cm segment 2 at its right edge (the
    body around it on three sides): ``"band"`` on the body's surface (a printed band),
    ``"ball"`` bending towards the camera away from it from the contact at its left side (a
    ball of 2 cm radius touching the body tangentially). White noise of ``body_noise_m`` on
    both; a support whose inliers scatter by 2 mm about it (the sensor's error). Returns
    (labels, depth, segments, rgb, support)."""
    rng = np.random.default_rng(seed)
    labels = np.zeros((HEIGHT, WIDTH), dtype=np.int32)
    labels[10:50, 0:60] = 1
    labels[20:40, 40:60] = 2
    x_m = (np.arange(WIDTH) - K[0, 2]) * 1e-3
    depth = np.tile(0.5 + 0.1 - np.sqrt(0.1**2 - np.minimum(x_m, 0.09) ** 2), (HEIGHT, 1))
    if piece == "ball":
        away = np.clip(x_m - x_m[40], 0.0, None)
        depth[labels == 2] -= np.tile(away**2 / (2 * 0.02), (HEIGHT, 1))[labels == 2]
    depth += rng.normal(0.0, body_noise_m, depth.shape)
    depth[labels == 0] = 0.8
    rgb = RGB.copy()
    rgb[labels == 2] = (200, 60, 60)
    plane = rng.uniform(-0.2, 0.2, (400, 3))
    plane[:, 1] = rng.normal(0.0, 0.002, 400)
    support = KnownPlane("support", np.array([0.0, -1.0, 0.0]), 0.0, plane)
    return labels, depth, np.array([1, 2, 0, 0], dtype=np.int32), rgb, support


def _surface_config(surface: bool = True) -> PerceptionConfig:
    config = _config(area_m2=16e-4)
    return dataclasses.replace(
        config,
        segmentation=dataclasses.replace(config.segmentation, fragment_surface=surface),
    )


def _segments_after(labels, depth, segments, rgb, support, config) -> int:
    joined, _ = join_fragments(
        labels,
        segments,
        _points(depth),
        depth,
        K,
        rgb,
        _supervoxels(labels),
        config,
        support=support,
    )
    return len(np.unique(joined[joined > 0]))


@pytest.mark.parametrize("seed", [0, 1])
def test_a_piece_of_another_colour_on_its_body_s_smooth_surface_joins(seed):
    # A printed band on a curved body: the colours differ, the surface runs on.
    scene = _surface_scene("band", seed=seed)
    assert _segments_after(*scene, _surface_config()) == 1
    assert continues_surface(scene[0], 2, 1, _points(scene[1]), scene[1], scene[4])
    # The switch off, or no support to read the sensor's error from: the colour gate holds.
    assert _segments_after(*scene, _surface_config(False)) == 2
    assert _segments_after(*scene[:4], None, _surface_config()) == 2


@pytest.mark.parametrize("seed", [0, 1])
def test_a_piece_bending_away_from_its_neighbour_is_kept(seed):
    # A ball touching the body tangentially: continuous at the contact, normals alike there,
    # but its surface leaves the body's by d^2 / 2R.
    scene = _surface_scene("ball", seed=seed)
    assert _segments_after(*scene, _surface_config()) == 2
    assert not continues_surface(scene[0], 2, 1, _points(scene[1]), scene[1], scene[4])


def test_a_piece_on_a_body_rougher_than_the_sensor_is_kept():
    # The body scatters about its quadric by more than the support about its plane (3 mm
    # against 2 mm): no single smooth surface around the piece to continue.
    scene = _surface_scene("band", body_noise_m=0.003)
    assert _segments_after(*scene, _surface_config()) == 2


EYE = np.zeros(3)


def _specks_config(specks: bool = True) -> PerceptionConfig:
    config = _config(area_m2=16e-4)  # the default: a speck is a fragment too
    return dataclasses.replace(
        config, segmentation=dataclasses.replace(config.segmentation, fragment_specks=specks)
    )


def _speck_scene(
    speck_normal: tuple[float, float, float] = (-1.0, 0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, Supervoxels]:
    """A grey segment 1 (rows 10-50, columns 0-40) facing the camera (at the origin) and a
    red 4 x 6 px speck 2 (0.1 cm^2 at 0.5 m) on its right edge, at rows 20-24, reaching 6 px
    into the background: mixed pixels at a silhouette, whose supervoxel is seen edge-on
    (normal ``speck_normal``, square to the ray) and whose colour differs. Along its outline
    with segments it touches segment 1 only. Returns (labels, depth, segments, rgb, points,
    supervoxels)."""
    labels = np.zeros((HEIGHT, WIDTH), dtype=np.int32)
    labels[10:50, 0:40] = 1
    labels[20:24, 40:46] = 2
    depth = np.full((HEIGHT, WIDTH), 0.5)
    depth[labels == 0] = 0.8
    rgb = RGB.copy()
    rgb[labels == 2] = (200, 60, 60)
    points = _points(depth)
    sv = _speck_supervoxels(labels, points, speck_normal)
    return labels, depth, np.array([1, 2, 0, 0], dtype=np.int32), rgb, points, sv


def _speck_supervoxels(
    labels: np.ndarray, points: np.ndarray, speck_normal: tuple[float, float, float]
) -> Supervoxels:
    """One supervoxel per segment (label - 1): segment 1 facing the camera, the speck (2)
    with ``speck_normal``."""
    normals = np.tile([0.0, 0.0, -1.0], (4, 1))
    normals[1] = speck_normal
    centres = np.zeros((4, 3))
    for segment in (1, 2):
        centres[segment - 1] = points[labels == segment].mean(axis=0)
    return Supervoxels(labels - 1, centres, normals, np.zeros((4, 3)), np.ones(4), np.zeros((0, 2)))


def _segments_after_specks(labels, segments, depth, rgb, sv, config=None, viewpoint=EYE) -> int:
    """How many segments are left after the fragment and speck joins (camera at the origin)."""
    joined, _ = join_fragments(
        labels, segments, _points(depth), depth, K, rgb, sv, config or _specks_config(),
        viewpoint=viewpoint,
    )  # fmt: skip
    return len(np.unique(joined[joined > 0]))


def test_a_speck_seen_edge_on_joins_the_segment_it_touches():
    labels, depth, segments, rgb, points, sv = _speck_scene()
    eye = np.zeros(3)
    joined, _ = join_fragments(
        labels, segments, points, depth, K, rgb, sv, _specks_config(), viewpoint=eye
    )
    assert np.all(joined[20:24, 40:46] == 1)
    # Off (or no camera to judge edge-on by), the fragment rules refuse it: it meets segment
    # 1 at a crease and in another colour.
    for config, viewpoint in ((_specks_config(False), eye), (_specks_config(), None)):
        kept, _ = join_fragments(
            labels, segments, points, depth, K, rgb, sv, config, viewpoint=viewpoint
        )
        assert len(np.unique(kept[kept > 0])) == 2


def test_a_speck_facing_the_camera_is_kept():
    # The same speck facing the camera: a surface (a small object's visible part, as in the
    # generated scenes, where objects peek out between others), not mixed pixels.
    labels, depth, segments, rgb, _, sv = _speck_scene(speck_normal=(0.0, 0.0, -1.0))
    # It meets segment 1 with its own normal: the fragment rule's colours refuse it.
    assert _segments_after_specks(labels, segments, depth, rgb, sv) == 2


def test_a_speck_seen_behind_the_background_is_kept():
    # What lies around the speck (label 0) is nearer than it: a wall or a drawer's rim in
    # front, the speck an object's part seen past it, not mixed pixels in front of it.
    labels, depth, segments, rgb, _, sv = _speck_scene()
    depth[labels == 0] = 0.3
    assert _segments_after_specks(labels, segments, depth, rgb, sv) == 2


def test_a_speck_between_two_segments_is_kept():
    # A third segment below the speck, 5 cm in front of it (not touching it): the speck is
    # between two objects, a small object's part as well as mixed pixels.
    labels, depth, segments, rgb, points, sv = _speck_scene()
    labels[24:30, 40:46] = 3
    depth[24:30, 40:46] = 0.45
    segments = np.array([1, 2, 3, 0], dtype=np.int32)
    assert _segments_after_specks(labels, segments, depth, rgb, sv) == 3


def test_a_segment_of_a_seed_square_is_no_speck():
    # The speck grown to 6 x 11 px at 1.2 m (3.8 cm^2 by the footprint; the seed's square is
    # 4 cm^2 when the seed is 2 cm): at seed 1.9 cm it is no speck and stays.
    labels, depth, segments, rgb, _, _ = _speck_scene()
    labels[labels == 2] = 0
    labels[18:24, 40:51] = 2
    depth[labels > 0] = 1.2
    depth[labels == 0] = 1.6
    points = _points(depth)
    sv = _speck_supervoxels(labels, points, (-1.0, 0.0, 0.0))
    config = _specks_config()
    joined, _ = join_fragments(labels, segments, points, depth, K, rgb, sv, config, viewpoint=EYE)
    assert np.all(joined[18:24, 40:51] == 1)
    smaller_seed = dataclasses.replace(
        config, supervoxels=dataclasses.replace(config.supervoxels, seed_size_m=0.019)
    )
    assert _segments_after_specks(labels, segments, depth, rgb, sv, smaller_seed) == 2
