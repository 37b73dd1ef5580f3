"""View fusion: a later frame's view of a moved object registered into frame 0 (ipr_shapes.fusion)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from ipr_shapes.camera import backproject
from ipr_shapes.fusion import (
    FusedViews,
    FusionConfig,
    Registration,
    SweptCapsule,
    TrackedFreeSpace,
    _even_subsample,
    _icp_starts,
    _Nearest,
    _pca_normals,
    _rotation_about,
    _small_rotation,
    fuse_views,
    pushed_through,
    register_view,
    tracked_free_spaces,
)
from ipr_shapes.perception.free_space import FREE, UNKNOWN, SpaceMap
from ipr_shapes.scene import Push, Pusher
from tests.box_scene import BOX_HALF, SUPPORT, K, box_mesh, partial_box, render_view

EYE = (0.2, -0.35, 0.3)


def _motion(angle_deg: float, shift) -> np.ndarray:
    """(4, 4) world transform: turn about the vertical through the box's centre, then shift."""
    angle = np.radians(angle_deg)
    turn = np.eye(4)
    turn[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    move = np.eye(4)
    move[:3, 3] = shift
    return move @ turn


def _moved_view(motion: np.ndarray):
    """The box moved by ``motion``, rendered from EYE: a partial object of frame 1 and that
    frame's free-space map."""
    vertices, faces = box_mesh()
    view = render_view(EYE, box=(vertices @ motion[:3, :3].T + motion[:3, 3], faces))
    return partial_box(view, motion=motion, frame=1), view.space()


def _faces(points: np.ndarray) -> np.ndarray:
    """Face (N,) in 0..5 of the box at its frame-0 pose nearest to each world point."""
    local = (points - [0.0, 0.0, BOX_HALF[2]]) / BOX_HALF
    axis = np.argmax(np.abs(local), axis=1)
    return axis * 2 + (local[np.arange(len(local)), axis] > 0)


def _box_surface_distance(points: np.ndarray) -> np.ndarray:
    """Distance (N,) of world points to the surface of the box at its frame-0 pose (m)."""
    local = np.abs(points - [0.0, 0.0, BOX_HALF[2]]) - BOX_HALF
    outside = np.linalg.norm(np.maximum(local, 0.0), axis=1)
    inside = np.minimum(local.max(axis=1), 0.0)
    return outside + np.abs(inside)


@pytest.fixture(scope="module")
def views():
    first = render_view(EYE)
    reference = partial_box(first)
    motion = _motion(70.0, [0.04, 0.03, 0.0])
    later, later_space = _moved_view(motion)
    return reference, first.space(), later, later_space, motion


def test_a_turned_and_shifted_view_registers_onto_the_first(views):
    reference, space, later, later_space, motion = views
    registration = register_view(later.points, reference.points, SUPPORT.normal, space, later_space)
    assert registration is not None
    assert registration.overlap > 0.5 and registration.rmse_m < 0.003
    assert registration.free_share < 0.03 and registration.reverse_free_share < 0.03
    transform = registration.frame0_from_frame
    registered = later.points @ transform[:3, :3].T + transform[:3, 3]
    # On the box's frame-0 surface (a box's half-turn symmetry may be chosen: either is right).
    assert np.median(_box_surface_distance(registered)) < 0.002
    assert np.percentile(_box_surface_distance(registered), 95) < 0.005
    # Unregistered, the later view is centimetres away from it.
    assert np.percentile(_box_surface_distance(later.points), 90) > 0.02


def test_fusion_adds_the_sides_frame_0_did_not_see(views):
    reference, space, later, later_space, _ = views
    views_fused = fuse_views([(reference,), (later,)], [space, later_space], SUPPORT)
    (fused,), used = views_fused.objects, views_fused.fused_frames
    assert used == {1: [1]} and set(views_fused.motions) == {1}
    added = len(fused.points) - len(reference.points)
    assert added >= 30
    assert np.array_equal(fused.points[: len(reference.points)], reference.points)
    assert (fused.pixels[len(reference.points) :] == -1).all()
    assert len(fused.pixels) == len(fused.points) == len(fused.colours)
    assert len(fused.facet_of_point) == len(fused.points)
    new = fused.points[len(reference.points) :]
    assert np.percentile(_box_surface_distance(new), 95) < 0.005
    assert (SUPPORT.signed_distance(new) > 0).all()
    # Frame 0 saw the box from one side: the fused points cover a face it did not see.
    seen, added_faces = _faces(reference.points), _faces(new)
    unseen = [f for f in range(6) if (seen == f).sum() < 5]
    assert any((added_faces == f).sum() >= 30 for f in unseen)
    # A face the later frame shows for the first time joins as a facet, turned into frame 0.
    assert len(fused.facets) > len(reference.facets)
    for facet in fused.facets[len(reference.facets) :]:
        assert abs(np.linalg.norm(facet.normal) - 1.0) < 1e-9
        assert np.median(_box_surface_distance(facet.points)) < 0.003


def test_a_view_that_lands_in_seen_free_space_is_not_fused(views):
    reference, space, later, later_space, _ = views
    everything_free = SpaceMap(space.grid, np.full(space.state.shape, FREE, dtype=np.uint8))
    assert (
        register_view(later.points, reference.points, SUPPORT.normal, everything_free, None) is None
    )
    views_fused = fuse_views([(reference,), (later,)], [everything_free, later_space], SUPPORT)
    (fused,) = views_fused.objects
    assert views_fused.fused_frames == {} and views_fused.motions == {} and fused is reference


def test_another_object_under_the_same_id_is_not_fused(views):
    reference, space, *_ = views
    # A long flat bar seen where the box was (a tracking swap): it cannot lie on the box
    # without leaving its silhouette, through space frame 0 saw to be empty.
    bar = render_view(EYE, box=box_mesh(np.array([0.12, 0.01, 0.01]), np.array([0.0, 0.05, 0.01])))
    mask = (bar.index == 0) & (bar.depth > 0)
    camera = backproject(bar.depth, K)[mask]
    points = camera @ bar.world_from_camera[:3, :3].T + bar.world_from_camera[:3, 3]
    assert len(points) > 100
    assert register_view(points, reference.points, SUPPORT.normal, space, bar.space()) is None


def test_no_later_frame_or_no_object_leaves_frame_0_as_it_is(views):
    reference, space, *_ = views
    alone = fuse_views([(reference,)], [space], SUPPORT)
    assert alone.objects == (reference,) and alone.fused_frames == {} and alone.motions == {}
    for nothing in (fuse_views([], [], None), fuse_views([(), ()], [None, None], SUPPORT)):
        assert (nothing.objects, nothing.fused_frames, nothing.motions) == ((), {}, {})


def test_fusion_settings_are_validated():
    with pytest.raises(ValueError):
        FusionConfig(fine_gate_m=0.1, coarse_gate_m=0.05)
    with pytest.raises(ValueError):
        FusionConfig(min_overlap=1.5)
    with pytest.raises(ValueError):
        FusionConfig(yaw_starts=0)


def _inside_box(points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
    """(N,) True for world points inside the box at its frame-0 pose, shrunk by ``margin_m``."""
    local = np.abs(points - [0.0, 0.0, BOX_HALF[2]])
    return np.all(local < BOX_HALF - margin_m, axis=1)


def test_later_free_space_reaches_frame_0_through_the_registered_motion(views):
    reference, space, later, later_space, _ = views
    fused = fuse_views([(reference,), (later,)], [space, later_space], SUPPORT)
    tracked = tracked_free_spaces(fused, [space, later_space])
    assert set(tracked) == {1}
    seen = tracked[1]
    centres = space.grid.centres().reshape(-1, 3)
    frame0 = space.state_at(centres)
    combined = seen.state_at(centres)
    # What frame 0 saw stands; only its hidden voxels can turn free.
    assert np.array_equal(combined[frame0 != UNKNOWN], frame0[frame0 != UNKNOWN])
    # The box's own hidden inside is (all but 1 %) not free: the box was there in the later
    # frame too.
    inside = _inside_box(centres, margin_m=0.006)
    assert inside.sum() > 200
    assert np.count_nonzero(combined[inside] == FREE) <= 0.01 * inside.sum()
    # Behind the box (hidden in frame 0, outside it) the turned box's view shows empty space.
    near = np.all(np.abs(centres - [0.0, 0.0, 0.03]) < [0.1, 0.1, 0.025], axis=1)
    behind = near & (frame0 == UNKNOWN) & ~_inside_box(centres, margin_m=-0.015)
    assert behind.sum() > 100
    assert np.count_nonzero(combined[behind] == FREE) > 0.2 * behind.sum()


def test_an_object_without_a_registered_later_view_keeps_frame_0s_space(views):
    reference, space, later, later_space, _ = views
    everything_free = SpaceMap(space.grid, np.full(space.state.shape, FREE, dtype=np.uint8))
    fused = fuse_views([(reference,), (later,)], [everything_free, later_space], SUPPORT)
    assert tracked_free_spaces(fused, [everything_free, later_space]) == {}
    assert tracked_free_spaces(FusedViews((), {}, {1: {1: np.eye(4)}}), [None, later_space]) == {}


PUSHER = Pusher(radius_m=0.01, length_m=0.15)


def _push(start, direction, distance_m: float, before: int = 0, after: int = 1) -> Push:
    direction = np.asarray(direction, float)
    return Push(
        before, after, np.asarray(start, float), direction / np.linalg.norm(direction),
        distance_m, 0.05,
    )  # fmt: skip


def test_swept_capsule_distance_agrees_with_a_dense_sampling():
    # A tilted stick pushed obliquely: the swept parallelogram is not a rectangle.
    pusher = Pusher(0.01, 0.15, np.array([0.3, 0.0, 1.0]))
    capsule = SweptCapsule.of(_push([0.0, 0.0, 0.08], [1.0, 0.4, 0.3], 0.1), pusher)
    s, t = np.meshgrid(np.linspace(-1, 1, 301) * capsule.half_length_m, np.linspace(0, 0.1, 301))
    sheet = capsule.start + s[..., None] * capsule.axis + t[..., None] * capsule.direction
    rng = np.random.default_rng(0)
    points = sheet.reshape(-1, 3)[rng.integers(0, sheet.size // 3, 3000)]
    points = points + rng.normal(scale=0.015, size=points.shape)
    brute = cKDTree(sheet.reshape(-1, 3)).query(points)[0]
    assert np.allclose(capsule.distance(points), brute, atol=6e-4)
    clear = np.abs(brute - capsule.radius_m) > 1e-3
    inside = capsule.contains(points)
    assert np.array_equal(inside[clear], brute[clear] <= capsule.radius_m)
    assert 100 < inside.sum() < len(points) - 100
    # Moving the volume moves what it contains.
    shift = np.eye(4)
    shift[:3, 3] = [0.3, -0.2, 0.0]
    assert np.array_equal(capsule.moved(shift).contains(points + shift[:3, 3]), inside)


def test_a_push_that_did_not_move_an_object_frees_what_it_swept(views):
    reference, space, *_ = views
    behind = _push([-0.15, 0.065, 0.04], [1.0, 0.0, 0.0], 0.3)  # 2.5 cm behind the box
    swept = pushed_through(reference.points, {1: np.eye(4)}, [behind], PUSHER)
    assert len(swept) == 1
    centres = space.grid.centres().reshape(-1, 3)
    frame0 = space.state_at(centres)
    combined = TrackedFreeSpace(space, (), swept).state_at(centres)
    in_sweep = swept[0].contains(centres)
    hidden_swept = in_sweep & (frame0 == UNKNOWN)
    assert hidden_swept.sum() > 20
    assert np.all(combined[hidden_swept] == FREE)
    assert np.array_equal(combined[~hidden_swept], frame0[~hidden_swept])
    # Through the entry point: only with a pusher and pushes.
    fused = FusedViews((reference,), {}, {reference.id: {1: np.eye(4)}})
    no_later = FusionConfig(later_free_space=False, pusher_free_space=True)
    assert tracked_free_spaces(fused, [space, space], [behind], PUSHER) != {}  # later views
    off = FusionConfig(later_free_space=False)  # the pusher's volume is off by default
    assert tracked_free_spaces(fused, [space, space], [behind], PUSHER, off) == {}
    tracked = tracked_free_spaces(fused, [space, space], [behind], PUSHER, no_later)
    assert set(tracked) == {reference.id} and len(tracked[reference.id].swept) == 1
    assert tracked_free_spaces(fused, [space, space], [behind], None, no_later) == {}
    assert tracked_free_spaces(fused, [space, space], [], PUSHER, no_later) == {}
    # A push through the object's own observed points contradicts "did not move"; a push to a
    # frame the object did not register in says nothing.
    through = _push([-0.15, 0.0, 0.04], [1.0, 0.0, 0.0], 0.3)
    assert pushed_through(reference.points, {1: np.eye(4)}, [through], PUSHER) == ()
    assert pushed_through(reference.points, {}, [behind], PUSHER) == ()


def test_a_push_that_moved_an_object_frees_only_where_the_pusher_stopped(views):
    reference, *_ = views
    # The box slid 5 cm along +x; the pusher stopped against its -x face (at x = 0 after).
    moved = np.eye(4)
    moved[:3, 3] = [0.05, 0.0, 0.0]
    push = _push([-0.2, 0.0, 0.04], [1.0, 0.0, 0.0], 0.2 - 0.011)
    config = FusionConfig(settle_margin_m=0.003)
    (end,) = pushed_through(reference.points, {1: np.linalg.inv(moved)}, [push], PUSHER, config)
    # In the box's frame-0 pose the pusher's end is 5 cm further back, 3 mm thinner.
    assert end.distance_m == 0 and end.radius_m == pytest.approx(0.007)
    assert np.allclose(end.start, [-0.061, 0.0, 0.04])
    assert end.contains(np.array([[-0.061, 0.0, 0.04], [-0.055, 0.0, 0.04]])).tolist() == [
        True,
        True,
    ]
    assert not end.contains(np.array([[-0.15, 0.0, 0.04], [-0.05, 0.0, 0.02]])).any()


def test_registration_keeps_frame_0s_points_out_of_the_later_frames_free_space():
    # Frame 0 saw a flat 10 x 4 cm patch; the later view a 4 x 4 cm square of it, which fits
    # the patch at any quarter turn equally well. The later frame saw empty space on both
    # sides of the square along x: frame 0's patch can only lie along y there (turned a
    # quarter turn), not along x.
    from ipr_shapes.perception.free_space import VoxelGrid

    long_side, short_side = np.linspace(-0.05, 0.05, 41), np.linspace(-0.02, 0.02, 17)
    reference = np.array([[x, y, 0.05] for x in long_side for y in short_side])
    view = np.array([[x, y, 0.05] for x in short_side for y in short_side])
    grid = VoxelGrid.around(np.array([-0.1, -0.1, 0.0]), np.array([0.1, 0.1, 0.1]), 0.005)
    state = np.full(grid.shape, UNKNOWN, dtype=np.uint8)
    state[np.abs(grid.centres()[..., 0]) > 0.03] = FREE
    registration = register_view(
        view, reference, np.array([0.0, 0.0, 1.0]), None, SpaceMap(grid, state)
    )
    assert registration is not None
    assert registration.overlap == 1.0 and registration.reverse_free_share == 0.0
    rotation = registration.frame0_from_frame[:3, :3]
    assert abs(rotation[0, 0]) < 1e-6 and abs(abs(rotation[0, 1]) - 1.0) < 1e-6


def _reference_icp(source, target, target_normals, tree, rotation, translation, config):
    """One start's point-to-plane ICP as it ran before the starts were batched (one query
    per start and iteration): the pin of ``_icp_starts``. Returns (rotation, translation,
    iterations run)."""
    gates = np.geomspace(config.coarse_gate_m, config.fine_gate_m, config.iterations)
    for iteration, gate in enumerate(gates):
        moved = source @ rotation.T + translation
        distance, index = tree.query(moved, distance_upper_bound=gate)
        paired = np.isfinite(distance)
        if paired.sum() < 6:
            return rotation, translation, iteration
        p, q, n = moved[paired], target[index[paired]], target_normals[index[paired]]
        rows = np.hstack([np.cross(p, n), n])
        rhs = np.einsum("ij,ij->i", q - p, n)
        solution, *_ = np.linalg.lstsq(rows, rhs, rcond=None)
        step = _small_rotation(solution[:3])
        rotation = step @ rotation
        translation = step @ translation + solution[3:]
        if np.linalg.norm(solution) < 1e-6:
            return rotation, translation, iteration + 1
    return rotation, translation, len(gates)


def _reference_register(view, reference, up, reference_space, view_space, config):
    """``register_view``'s best registration (before acceptance) as it was computed start by
    start, each scored on its own."""
    source = _even_subsample(np.asarray(view, float), config.max_points)
    target = _even_subsample(np.asarray(reference, float), config.max_points)
    tree = cKDTree(target)
    normals = _pca_normals(target, tree, config.normal_neighbours)
    up = np.asarray(up, float) / np.linalg.norm(up)
    source_centre, target_centre = source.mean(axis=0), target.mean(axis=0)
    best, best_score = None, -np.inf
    for angle in np.arange(config.yaw_starts) * (2 * np.pi / config.yaw_starts):
        rotation = _rotation_about(up, float(angle))
        translation = target_centre - rotation @ source_centre
        rotation, translation, _ = _reference_icp(
            source, target, normals, tree, rotation, translation, config
        )
        moved = source @ rotation.T + translation
        distance, _ = tree.query(moved, distance_upper_bound=config.fine_gate_m)
        paired = np.isfinite(distance)
        overlap = float(paired.mean())
        free = float(np.mean(reference_space.state_at(moved) == FREE))
        back = (target - translation) @ rotation
        reverse = float(np.mean(view_space.state_at(back) == FREE))
        score = overlap - config.free_weight * (free + reverse)
        if score > best_score:
            rmse = float(np.sqrt(np.mean(distance[paired] ** 2))) if paired.any() else np.inf
            transform = np.eye(4)
            transform[:3, :3], transform[:3, 3] = rotation, translation
            best, best_score = Registration(transform, overlap, free, reverse, rmse), score
    return best


@pytest.mark.parametrize("workers", [1, 2])
def test_batched_icp_starts_are_each_the_start_run_alone(views, workers):
    # The 12 turned starts of a registration, plus one too far away to pair (it stops at
    # once): in lockstep, each must end bit for bit where it ends alone, whichever iteration
    # it stops at and however many threads share the queries.
    reference, _, later, _, _ = views
    config = FusionConfig()
    source = _even_subsample(later.points, config.max_points)
    target = _even_subsample(reference.points, config.max_points)
    tree = cKDTree(target)
    normals = _pca_normals(target, tree, config.normal_neighbours)
    up = SUPPORT.normal
    rotations = [_rotation_about(up, angle) for angle in np.arange(12) * (np.pi / 6)]
    translations = [target.mean(axis=0) - r @ source.mean(axis=0) for r in rotations]
    rotations.insert(5, np.eye(3))
    translations.insert(5, np.array([1.0, 0.0, 0.0]))
    nearest = _Nearest(target, workers)
    got = _icp_starts(source, target, normals, nearest, rotations, translations, config)
    stopped = []
    for start, (rotation, translation) in enumerate(zip(rotations, translations, strict=True)):
        expected = _reference_icp(source, target, normals, tree, rotation, translation, config)
        assert np.array_equal(got[0][start], expected[0]), start
        assert np.array_equal(got[1][start], expected[1]), start
        stopped.append(expected[2])
    # The case covers starts stopping at different iterations, not only all running to the end.
    assert stopped[5] == 0 and len(set(stopped)) > 2


def test_batched_scoring_chooses_the_registration_of_starts_scored_one_by_one(views):
    reference, space, later, later_space, _ = views
    config = FusionConfig(min_overlap=0.0, max_free_share=1.0)  # the best, accepted or not
    for view in (later.points, later.points[::3] + [0.004, -0.002, 0.0]):
        expected = _reference_register(
            view, reference.points, SUPPORT.normal, space, later_space, config
        )
        for workers in (1, 2):
            got = register_view(
                view, reference.points, SUPPORT.normal, space, later_space, config, workers
            )
            assert np.array_equal(got.frame0_from_frame, expected.frame0_from_frame)
            assert (got.overlap, got.free_share, got.reverse_free_share, got.rmse_m) == (
                expected.overlap,
                expected.free_share,
                expected.reverse_free_share,
                expected.rmse_m,
            )


def test_objects_fused_on_threads_are_those_fused_one_by_one(views, monkeypatch):
    # Three frame-0 objects: two that register (one turned the other way, in frame 2) and
    # one whose later view is a flattened copy that does not; fused on threads, each object is what it is fused alone,
    # in the objects' order, and the threads did the registrations.
    import dataclasses
    import threading

    import ipr_shapes.fusion as fusion

    reference, space, later, later_space, _ = views
    other = dataclasses.replace(reference, id=2)
    half_turn = _motion(180.0, [0.0, 0.0, 0.0])
    turned, turned_space = _moved_view(half_turn @ _motion(70.0, [0.04, 0.03, 0.0]))
    bar = dataclasses.replace(reference, id=3)
    bar_view = dataclasses.replace(later, id=3, points=later.points[::3] * [1.0, 0.2, 1.0])
    frames = [(reference, other, bar), (later, bar_view), (dataclasses.replace(turned, id=2),)]
    spaces = [space, later_space, turned_space]
    threads = []
    register = fusion.register_view
    monkeypatch.setattr(
        fusion,
        "register_view",
        lambda *a: threads.append(threading.current_thread().name) or register(*a),
    )
    together = fuse_views(frames, spaces, SUPPORT, workers=2)
    assert all(name.startswith("ipr-fusion") for name in threads) and len(threads) == 3
    alone = [fuse_views([(obj,), *frames[1:]], spaces, SUPPORT) for obj in frames[0]]
    assert [o.id for o in together.objects] == [1, 2, 3]
    assert list(together.motions) == [k for k in (1, 2, 3) if alone[k - 1].motions]
    assert set(together.fused_frames) == {1, 2} and 3 not in together.motions
    for obj, single in zip(together.objects, alone, strict=True):
        (expected,) = single.objects
        assert np.array_equal(obj.points, expected.points)
        assert np.array_equal(obj.pixels, expected.pixels)
        assert len(obj.facets) == len(expected.facets)
        assert together.fused_frames.get(obj.id) == single.fused_frames.get(obj.id)
        mine, theirs = together.motions.get(obj.id, {}), single.motions.get(obj.id, {})
        assert list(mine) == list(theirs)
        assert all(np.array_equal(mine[t], theirs[t]) for t in mine)
