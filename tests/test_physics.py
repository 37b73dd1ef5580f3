"""The physics world: gravity, pushes, stability candidates, rendering at reduced resolution."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from ipr_shapes.camera import look_at
from ipr_shapes.perception.types import KnownPlane
from ipr_shapes.physics import (
    STIFF_PUSHER,
    Body,
    PhysicsConfig,
    _mesh_asset,
    build_world,
    decimated_camera,
    decimated_pixels,
)
from ipr_shapes.rendering import Renderer, render_depth_and_ids
from ipr_shapes.scene import Push, Pusher
from tests.box_scene import SUPPORT, box_mesh

STANDING = box_mesh(np.array([0.05, 0.03, 0.02]), np.array([0.0, 0.0, 0.02]))


def test_a_supported_box_stays_and_an_unsupported_one_falls_by_its_gap():
    floating = box_mesh(np.array([0.03, 0.03, 0.02]), np.array([0.2, 0.0, 0.07]))  # 5 cm gap
    world = build_world([Body(*STANDING), Body(*floating)], [SUPPORT])
    assert world.settle()
    moved = world.displacements()
    assert moved[0] < 0.002
    assert moved[1] == pytest.approx(0.05, abs=0.004)
    # Its pose says where it went: straight down.
    assert world.poses()[1][:3, 3] == pytest.approx([0.0, 0.0, -0.05], abs=0.004)


def test_gravity_follows_a_tilted_support_normal():
    normal = np.array([0.0, np.sin(0.3), np.cos(0.3)])
    tilted = KnownPlane("support", normal, 0.0, SUPPORT.points)
    world = build_world([], [tilted])
    assert np.asarray(world.model.opt.gravity) == pytest.approx(-9.81 * normal)


def test_candidates_ignore_each_other_but_rest_on_static_context():
    # Two overlapping candidates on a static box: alone, each would be stable.
    low = box_mesh(np.array([0.02, 0.02, 0.01]), np.array([0.0, 0.0, 0.05]))
    high = box_mesh(np.array([0.02, 0.02, 0.015]), np.array([0.005, 0.0, 0.055]))
    bodies = [
        Body(*STANDING, dynamic=False),
        Body(*low, candidate=True),
        Body(*high, candidate=True),
    ]
    world = build_world(bodies, [SUPPORT])
    world.settle(0.3)
    moved = world.displacements()
    assert moved[0] == 0.0 and moved[1] < 0.002 and moved[2] < 0.002
    # As ordinary bodies the same two shapes overlap and shove each other apart.
    shoved = build_world([Body(*STANDING, dynamic=False), Body(*low), Body(*high)], [SUPPORT])
    shoved.settle(0.3)
    assert shoved.displacements()[1:].max() > 0.003


def test_a_push_moves_the_box_along_its_direction_and_a_miss_moves_nothing():
    push = Push(0, 1, np.array([-0.15, 0.0, 0.03]), np.array([1.0, 0.0, 0.0]), 0.12, 0.05)
    world = build_world([Body(*STANDING)], [SUPPORT], pusher=Pusher())
    world.settle()
    assert world.push(push) == pytest.approx(0.12)
    # The capsule (r = 1 cm) meets the box face at x = -0.05 after 9 cm: 3 cm of push.
    shift = world.poses()[0][:3, 3]
    assert shift[0] == pytest.approx(0.03, abs=0.006) and abs(shift[1]) < 0.005
    miss = Push(0, 1, np.array([-0.15, 0.2, 0.03]), np.array([1.0, 0.0, 0.0]), 0.12, 0.05)
    world = build_world([Body(*STANDING)], [SUPPORT], pusher=Pusher())
    world.settle()
    world.push(miss)
    assert world.displacements()[0] < 0.001 and not world.exploded


def test_walls_hold_objects_back():
    wall_points = np.array([[0.08, y, z] for y in (-0.2, 0.2) for z in (0.0, 0.2)])
    wall = KnownPlane("wall", np.array([-1.0, 0.0, 0.0]), 0.08, wall_points, 0.02)
    push = Push(0, 1, np.array([-0.15, 0.0, 0.03]), np.array([1.0, 0.0, 0.0]), 0.2, 0.05)
    free = build_world([Body(*STANDING)], [SUPPORT], pusher=Pusher())
    free.push(push)
    walled = build_world([Body(*STANDING)], [SUPPORT, wall], pusher=Pusher())
    walled.push(push)
    # Without the wall the box travels ~11 cm; the wall at x = 0.08 stops its face there.
    assert free.poses()[0][0, 3] > 0.08
    assert walled.poses()[0][0, 3] < 0.035


def test_flung_objects_are_flagged():
    world = build_world([Body(*STANDING)], [SUPPORT], PhysicsConfig(flung_m=0.3))
    world.data.qpos[:3] += [0.0, 0.0, 1.0]  # teleported a metre up
    import mujoco

    mujoco.mj_forward(world.model, world.data)
    assert world.flung()[0] and np.isinf(world.displacements()[0])


def test_decimated_rendering_samples_the_full_image():
    K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
    pose = look_at(np.array([0.1, -0.4, 0.35]), np.array([0.0, 0.0, 0.02]))
    full, full_index = render_depth_and_ids([STANDING], [None], K, 320, 240, pose)
    camera = decimated_camera(K, 320, 240, pose, 4)
    world = build_world([Body(*STANDING)], [SUPPORT], cameras=[camera])
    with Renderer(camera.width, camera.height) as renderer:
        depth, index = world.render(renderer, world.cameras[0])
    assert depth.shape == (60, 80)
    sampled = decimated_pixels(full, 4)
    sampled_index = decimated_pixels(full_index, 4)
    agree = (index >= 0) == (sampled_index >= 0)
    assert agree.mean() > 0.995 and (index >= 0).sum() > 100
    both = (index >= 0) & (sampled_index >= 0)
    assert np.abs(depth[both] - sampled[both]).max() < 1e-3


def test_config_rejects_nonsense():
    with pytest.raises(ValueError, match="timestep_s"):
        PhysicsConfig(timestep_s=0.0)
    with pytest.raises(ValueError, match="friction"):
        PhysicsConfig(friction=-1.0)


def test_drop_measures_falls_but_not_the_shove_that_resolves_an_overlap():
    floating = box_mesh(np.array([0.03, 0.03, 0.02]), np.array([0.2, 0.0, 0.07]))  # 5 cm gap
    # Overlaps the static box by 4 mm sideways, resting on the table.
    overlapping = box_mesh(np.array([0.03, 0.03, 0.02]), np.array([0.076, 0.0, 0.02]))
    bodies = [
        Body(*STANDING, dynamic=False),
        Body(*floating, candidate=True),
        Body(*overlapping, candidate=True),
    ]
    world = build_world(bodies, [SUPPORT])
    world.settle(0.3)
    drops, moved = world.drops(), world.displacements()
    assert drops[1] == pytest.approx(0.05, abs=0.004)
    assert moved[2] > 0.002 and drops[2] < 0.001


def test_a_static_shape_switched_off_is_absent_and_a_held_body_stays_put():
    # A box resting on a static box: with the static box on it stays, switched off it falls
    # onto the support; held, it stays in mid-air. One compiled world serves all three.
    top = box_mesh(np.array([0.02, 0.02, 0.01]), np.array([0.0, 0.0, 0.05]))
    world = build_world(
        [Body(*STANDING, dynamic=False), Body(*top, candidate=True, switchable=True)], [SUPPORT]
    )
    world.settle(0.5)
    assert world.drops()[1] < 0.001
    world.set_colliding(0, False)
    world.reset()
    world.settle(0.5)
    assert world.drops()[1] == pytest.approx(0.04, abs=0.003)
    world.hold(1)
    world.reset()
    world.settle(0.5)
    assert world.drops()[1] == 0.0
    with pytest.raises(ValueError, match="switchable"):
        world.hold(0)


def test_settle_each_holds_each_shape_once_at_rest_and_measures_as_settle_does():
    standing = box_mesh(np.array([0.02, 0.02, 0.02]), np.array([0.0, 0.1, 0.02]))
    falling = box_mesh(np.array([0.02, 0.02, 0.02]), np.array([0.0, -0.1, 0.08]))  # 6 cm gap
    bodies = [Body(*standing, switchable=True), Body(*falling, switchable=True)]
    reference = build_world([Body(*standing), Body(*falling)], [SUPPORT])
    reference.settle(0.3)
    world = build_world(bodies, [SUPPORT])
    rested = world.settle_each([0, 1], 0.3)
    assert rested.tolist() == [True, True]
    # The standing box was held at the first check; the other fell its gap and stood.
    assert world.model.body_gravcomp[world.body_ids].tolist() == [1.0, 1.0]
    assert world.drops() == pytest.approx(reference.drops(), abs=5e-4)
    assert world.drops()[1] == pytest.approx(0.06, abs=0.003)
    # Too short a test: the falling box is still moving and is not held.
    world.reset()
    world.hold(0, False)
    world.hold(1, False)
    assert world.settle_each([0, 1], 0.05).tolist() == [True, False]


def test_settle_each_sweeps_each_shape_from_its_start_to_where_it_rested():
    # The swept box covers every step's pose: the standing box's is its own box, the falling
    # box's spans its 6 cm fall down to the support; the same steps as without sweeping.
    standing = box_mesh(np.array([0.02, 0.02, 0.02]), np.array([0.0, 0.1, 0.02]))
    falling = box_mesh(np.array([0.02, 0.02, 0.02]), np.array([0.0, -0.1, 0.08]))
    bodies = [Body(*standing, switchable=True), Body(*falling, switchable=True)]
    plain, swept_world = build_world(bodies, [SUPPORT]), build_world(bodies, [SUPPORT])
    plain.settle_each([0, 1], 0.3)
    swept = np.zeros((2, 2, 3))
    swept_world.settle_each([0, 1], 0.3, swept)
    assert swept_world.drops().tolist() == plain.drops().tolist()
    for k, (vertices, _) in enumerate((standing, falling)):
        start = np.stack([vertices.min(axis=0), vertices.max(axis=0)])
        end = swept_world.shape_boxes([k])[0]
        assert np.all(swept[k, 0] <= np.minimum(start[0], end[0]) + 1e-9)
        assert np.all(swept[k, 1] >= np.maximum(start[1], end[1]) - 1e-9)
    # (the standing box sinks 0.6 mm into the soft support)
    assert swept[0] == pytest.approx(np.stack([standing[0].min(0), standing[0].max(0)]), abs=1e-3)
    # Down to the support (the box enters it 6 mm on landing), up to where it started.
    assert -0.01 < swept[1, 0, 2] <= swept_world.shape_boxes([1])[0, 0, 2]
    assert swept[1, 1, 2] == pytest.approx(0.10, abs=1e-9)  # from its start
    # A box turned by 45 degrees about z: its box grows by sqrt(2) (the box of the turned box).
    c = np.cos(np.pi / 4)
    turn = np.array([c, -c, 0.0, c, c, 0.0, 0.0, 0.0, 1.0])
    swept_world.data.xmat[swept_world.body_ids[0]] = turn
    box = swept_world.shape_boxes([0])[0]
    assert box[1, 0] - box[0, 0] == pytest.approx(0.04 * np.sqrt(2))
    assert box[1, 2] - box[0, 2] == pytest.approx(0.04)


def test_resting_drop_settles_only_the_clear_cases_and_agrees_with_the_simulation():
    from ipr_shapes.physics import convex_centroid, resting_drop

    def screened(mesh, obstacles=()):
        vertices = mesh[0]
        return resting_drop(
            vertices, convex_centroid(vertices), SUPPORT, list(obstacles),
            gap_m=0.002, margin_m=0.005,
        )  # fmt: skip

    hovering = box_mesh(np.array([0.03, 0.02, 0.02]), np.array([0.0, 0.0, 0.0215]))
    assert screened(STANDING) == pytest.approx(0.0, abs=1e-9)
    drop = screened(hovering)
    assert drop == pytest.approx(0.0015)
    world = build_world([Body(*hovering)], [SUPPORT])
    world.settle(0.3)
    assert world.drops()[0] == pytest.approx(drop, abs=5e-4)
    # Not clear: too high above the support, near another shape, or on an edge.
    assert screened(box_mesh(np.array([0.03, 0.02, 0.02]), np.array([0.0, 0.0, 0.03]))) is None
    near = np.array([[0.032, -0.02, 0.0], [0.05, 0.02, 0.04]])
    assert screened(STANDING, [near]) is None
    assert screened(STANDING, [near + [0.03, 0.0, 0.0]]) == pytest.approx(0.0, abs=1e-9)
    angle = np.pi / 4  # a cube standing on one edge: it tips, whichever way
    rotation = np.array(
        [[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]]
    )
    cube = box_mesh(np.array([0.02, 0.02, 0.02]), np.zeros(3))
    on_edge = (cube[0] @ rotation.T + [0.0, 0.0, 0.02 * np.sqrt(2)], cube[1])
    assert screened(on_edge) is None


#: The settings before 2026-11-26: 4 ms steps, every push at its own speed (the tests that
#: count steps or compare pushers were written for them).
AT_4_MS = {"timestep_s": 0.004, "push_timestep_s": 0.004, "push_max_s": 20.0}


def test_a_push_into_a_world_at_rest_skips_the_steps_before_the_pusher_arrives():
    push = Push(0, 1, np.array([-0.15, 0.0, 0.03]), np.array([1.0, 0.0, 0.0]), 0.12, 0.05)
    # 600 steps of 0.2 mm at 4 ms and the push's own speed; the capsule (r = 1 cm) meets the
    # box face after 9 cm (450 steps).
    config = PhysicsConfig(**AT_4_MS)
    settled = build_world([Body(*STANDING)], [SUPPORT], config, pusher=Pusher())
    assert settled.settle() and settled.at_rest
    before = settled.data.time
    settled.push(push)
    skipped = 600 - round((settled.data.time - before) / 0.004)
    moving = build_world([Body(*STANDING)], [SUPPORT], config, pusher=Pusher())
    moving.step(0.2)  # the same world, not known to be at rest: every step simulated
    assert not moving.at_rest
    start = moving.data.time
    moving.push(push)
    assert round((moving.data.time - start) / 0.004) >= 600  # every push step, then settling
    # Most of the 450 steps before contact skipped, the pusher stopping 5 mm short; the box
    # ends where it did with every step.
    assert 400 < skipped < 450
    shift = settled.poses()[0][:3, 3]
    assert shift == pytest.approx(moving.poses()[0][:3, 3], abs=0.002)
    # A push that touches nothing takes no step at all.
    miss = Push(0, 1, np.array([-0.15, 0.2, 0.03]), np.array([1.0, 0.0, 0.0]), 0.12, 0.05)
    before = settled.data.time
    settled.push(miss)
    assert round((settled.data.time - before) / 0.004) <= 12  # one settle check


def test_the_stiff_pusher_moves_a_box_as_far_as_it_travels_past_the_contact():
    # The capsule (r = 1 cm) meets the box face after 9 cm of a 12 cm push at 5 cm/s: a
    # position-controlled robot moves the box 3 cm. A force limit of 0.7 mm of intrusion
    # stops a pusher that yields: MuJoCo's default sinks about 2.5 mm into the box, the stiff
    # contact at a 4 ms step (its time constant raised to 8 ms) 0.9 mm, at its 2 ms push step
    # 0.5 mm.
    push = Push(0, 1, np.array([-0.15, 0.0, 0.03]), np.array([1.0, 0.0, 0.0]), 0.12, 0.05)
    variants = {
        "stiff": STIFF_PUSHER,
        "stiff at 4 ms": {**STIFF_PUSHER, "push_timestep_s": 0.004},
        "soft": {},
    }
    shifts = {}
    for name, settings in variants.items():
        for limit in (0.0007, 0.01):
            config = PhysicsConfig(push_stop_intrusion_m=limit, **{**AT_4_MS, **settings})
            world = build_world([Body(*STANDING)], [SUPPORT], config, pusher=Pusher())
            world.settle()
            world.step(0.004)  # not known to be at rest: every push step simulated
            before = world.data.time
            travelled = world.push(push)
            shifts[name, limit] = (travelled, world.poses()[0][0, 3])
            # The pusher moves at its speed whatever the step; settling returns to its own.
            pushing = world.data.time - before - travelled / push.speed_m_s
            assert -1e-6 < pushing < config.settle_max_s + 0.05
            assert world.model.opt.timestep == config.timestep_s
    assert shifts["stiff", 0.0007][0] == pytest.approx(0.12)
    assert shifts["stiff at 4 ms", 0.0007][0] < 0.11  # stopped by its own intrusion
    assert shifts["soft", 0.0007][0] < 0.11
    # Without the limit all travel the whole way; the stiff pusher's box ends within 0.5 mm
    # of 3 cm, the soft one's over 1 mm short (the pusher sank into it).
    assert shifts["stiff", 0.01][1] == pytest.approx(0.03, abs=0.0005)
    assert shifts["soft", 0.01][1] < 0.029


def test_pusher_contact_settings_reach_mujoco_and_are_checked():
    config = PhysicsConfig(pusher_timeconst_s=0.006, pusher_dampratio=0.8)
    world = build_world([Body(*STANDING)], [SUPPORT], config, pusher=Pusher())
    geom = world.pusher_geom
    assert world.model.geom_solref[geom] == pytest.approx([0.006, 0.8])
    assert world.model.geom_solimp[geom][:3] == pytest.approx([0.9, 0.95, 0.001])
    # Its contacts take the pusher's settings, not a mix with the object's.
    assert world.model.geom_priority[geom] > world.model.geom_priority[world.shape_geoms[0]]
    with pytest.raises(ValueError, match="pusher_impedance"):
        PhysicsConfig(pusher_impedance=(0.99, 0.9))
    with pytest.raises(ValueError, match="push_timestep_s"):
        PhysicsConfig(push_timestep_s=0.0)


def test_the_default_step_and_push_speed_move_a_box_as_the_push_at_its_own_speed_does():
    # A 12 cm push at 5 cm/s meets the box after 9 cm and carries it about 3 cm. At the
    # defaults (8 ms steps, a push lasting at most push_max_s = 1 s: 12 cm/s) the box ends
    # within 2.5 mm of where 4 ms steps at the push's own speed leave it (the soft pusher
    # sinks about 2 mm deeper at 12 cm/s), in less than half the simulated pushing time; a
    # push faster than that floor keeps its own speed.
    push = Push(0, 1, np.array([-0.15, 0.0, 0.03]), np.array([1.0, 0.0, 0.0]), 0.12, 0.05)
    fast = Push(0, 1, np.array([-0.15, 0.0, 0.03]), np.array([1.0, 0.0, 0.0]), 0.12, 0.3)
    ends, pushing = {}, {}
    for name, settings in {"4 ms, own speed": AT_4_MS, "default": {}}.items():
        config = PhysicsConfig(**settings)
        for each in (push, fast):
            world = build_world([Body(*STANDING)], [SUPPORT], config, pusher=Pusher())
            world.settle()
            world.step(config.timestep_s)  # not known to be at rest: every push step simulated
            before = world.data.time
            travelled = world.push(each)
            ends[name, each.speed_m_s] = world.poses()[0][:3, 3]
            pushing[name, each.speed_m_s] = seconds = travelled / max(
                each.speed_m_s, each.distance_m / config.push_max_s
            )
            after = world.data.time - before - seconds  # the settling after the push
            assert -1e-6 < after < config.settle_max_s + 0.05
    assert pushing["default", 0.05] == pytest.approx(1.0)
    assert pushing["4 ms, own speed", 0.05] == pytest.approx(2.4)
    assert pushing["default", 0.3] == pytest.approx(0.4)
    assert ends["default", 0.05][0] > 0.025  # carried, not left behind
    assert ends["default", 0.05] == pytest.approx(ends["4 ms, own speed", 0.05], abs=0.0025)


def test_the_default_8_ms_step_settles_and_tests_stability_as_4_ms_steps_do():
    # Candidates on a static box: one resting on it, one overhanging its edge by more than
    # half (it tips off), one 6 cm above it (it falls); and a two-box stack settling as one
    # world. Drops and settled poses agree with 4 ms steps within 1 mm.
    base = box_mesh(np.array([0.04, 0.04, 0.02]), np.array([0.0, 0.0, 0.02]))
    on_top = box_mesh(np.array([0.02, 0.02, 0.02]), np.array([0.0, 0.0, 0.06]))
    overhanging = box_mesh(np.array([0.03, 0.01, 0.01]), np.array([0.06, 0.0, 0.05]))
    above = box_mesh(np.array([0.02, 0.02, 0.02]), np.array([0.0, 0.0, 0.12]))
    drops, poses = {}, {}
    for name, settings in {"4 ms": AT_4_MS, "default": {}}.items():
        config = PhysicsConfig(**settings)
        bodies = [Body(*base, dynamic=False)] + [
            Body(*shape, candidate=True, switchable=True) for shape in (on_top, overhanging, above)
        ]
        world = build_world(bodies, [SUPPORT], config)
        world.settle_each([1, 2, 3], config.stability_s)
        drops[name] = world.drops()[1:]
        stack = build_world([Body(*base), Body(*on_top)], [SUPPORT], config)
        assert stack.settle()
        poses[name] = stack.poses()
    assert drops["default"] == pytest.approx(drops["4 ms"], abs=0.001)
    assert drops["default"][0] < 0.001 and drops["default"][1] > 0.02
    assert drops["default"][2] > 0.055
    assert poses["default"] == pytest.approx(poses["4 ms"], abs=0.001)


def _model_arrays(model) -> dict[str, np.ndarray]:
    """Every numeric array of a compiled model but its names and file paths."""
    skipped = {"names", "paths", "names_map", "mesh_pathadr"}
    arrays = {}
    for name in dir(model):
        if name.startswith("_") or name in skipped:
            continue
        value = getattr(model, name)
        if isinstance(value, np.ndarray):
            arrays[name] = value
    return arrays


def test_meshes_given_as_cached_assets_compile_to_the_same_model():
    # Shapes as named mesh files (MuJoCo's asset cache) and as vertex lists: the same
    # compiled model, array for array, also when a shape was processed before (a cache hit)
    # and for two shapes with equal vertices but other faces (no name clash).
    rng = np.random.default_rng(4)
    shapes = []
    for k in range(5):
        points = rng.normal(size=(60, 3)) * [0.03, 0.02, 0.015] + [0.1 * k, 0.0, 0.04]
        shapes.append((points, ConvexHull(points).simplices))
    box_vertices, box_faces = STANDING
    shapes.append((box_vertices, box_faces))
    shapes.append((box_vertices + [0.0, 0.2, 0.0], box_faces[::-1].copy()))
    bodies = [Body(v, f, dynamic=k % 2 == 0) for k, (v, f) in enumerate(shapes)]
    vertices_only = build_world(bodies, [SUPPORT], cached_meshes=False).model
    for _ in range(2):  # the second time every shape is a cache hit
        cached = build_world(bodies, [SUPPORT]).model
        expected, got = _model_arrays(vertices_only), _model_arrays(cached)
        assert expected.keys() == got.keys() and len(got) > 100
        for name, value in expected.items():
            assert np.array_equal(value, got[name], equal_nan=True), name
    names = {_mesh_asset(v - v.mean(axis=0), f)[0] for v, f in shapes}
    assert len(names) == len(shapes)


def test_contact_and_solver_settings_reach_mujoco_and_are_checked():
    # Every contact and solver setting of ``PhysicsConfig`` is in the compiled model; the
    # defaults are the elliptic cones, Newton and condim 6 the physics was measured with.
    rng = np.random.default_rng(2)
    directions = rng.normal(size=(120, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = directions * [0.03, 0.02, 0.015] + [0.0, 0.0, 0.05]  # all on its hull
    ball = Body(points, ConvexHull(points).simplices)
    default = build_world([ball], [SUPPORT], pusher=Pusher()).model
    assert default.opt.cone == 1 and default.opt.solver == 2  # elliptic, Newton
    assert set(default.geom_condim) == {6}
    assert default.opt.disableflags == 0  # multi-point and native convex collision on
    whole = default.mesh_graph[default.mesh_graphadr[-1]]  # vertices of the collision hull
    assert whole == len(ConvexHull(points).vertices) > 32
    config = PhysicsConfig(
        condim=3, cone="pyramidal", solver="cg", solver_iterations=7, solver_tolerance=1e-5,
        ls_iterations=4, max_hull_vertices=16, multiccd=False, nativeccd=False,
    )  # fmt: skip
    model = build_world([ball], [SUPPORT], config, pusher=Pusher()).model
    assert set(model.geom_condim) == {3}
    assert model.opt.cone == 0 and model.opt.solver == 1  # pyramidal, CG
    assert (model.opt.iterations, model.opt.ls_iterations) == (7, 4)
    assert model.opt.tolerance == pytest.approx(1e-5)
    assert model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_MULTICCD)
    assert model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)
    assert 4 <= model.mesh_graph[model.mesh_graphadr[-1]] <= 16
    # The bounded hull is MuJoCo's processing of the same mesh file: it has its own name in
    # MuJoCo's asset cache, and a shape compiled with the whole hull first keeps it.
    assert _mesh_asset(points, ball.faces)[0] != _mesh_asset(points, ball.faces, 16)[0]
    again = build_world([ball], [SUPPORT]).model
    assert again.mesh_graph[again.mesh_graphadr[-1]] == whole
    for field, value in [
        ("condim", 5), ("cone", "round"), ("solver", "newton2"), ("solver_iterations", 0),
        ("ls_iterations", 0), ("max_hull_vertices", 3), ("multiccd", 1),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match=field):
            PhysicsConfig(**{field: value})


def test_rolling_friction_stops_a_rolled_cylinder_and_condim_4_has_none():
    # A 32-sided cylinder lying on the support, set rolling at 30 cm/s: the default contacts
    # (condim 6, rolling friction 2 mm) stop it within 8 cm, as pushed round objects stop in
    # the data; without rolling friction (condim 4) it rolls past 15 cm, which is why
    # condim 4's cheaper steps replayed the pushes further from the data
    # (docs/experiments/2026-11-27-cheaper-steps.md).
    angles = np.linspace(0.0, 2 * np.pi, 33)[:-1]
    ring = np.stack([np.zeros_like(angles), np.cos(angles), np.sin(angles) + 1.0], 1) * 0.03
    points = np.vstack([ring - [0.05, 0.0, 0.0], ring + [0.05, 0.0, 0.0]])
    cylinder = Body(points, ConvexHull(points).simplices)
    travelled = {}
    for condim in (6, 4):
        world = build_world([cylinder], [SUPPORT], PhysicsConfig(condim=condim))
        assert world.settle()
        world.data.qvel[[1, 3]] = 0.3, -0.3 / 0.03  # rolling along +y without slipping
        assert world.settle(3.0)
        pose = world.poses()[0]
        centre = points.mean(axis=0)
        travelled[condim] = np.linalg.norm(pose[:3, :3] @ centre + pose[:3, 3] - centre)
    assert 0.02 < travelled[6] < 0.08
    assert travelled[4] > 0.15
