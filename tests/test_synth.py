"""Benchmark scene generator: contract, ground truth, sensor model, pushes, determinism."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from ipr_shapes.camera import apply_transform, project
from ipr_shapes.data import ycb_models_dir
from ipr_shapes.scene import load_ground_truth, load_model, load_scene
from ipr_shapes.synth import (
    ARRANGEMENTS,
    GenerationError,
    SynthConfig,
    generate_scene,
    generate_scenes,
    scene_seed,
)
from ipr_shapes.synth.catalogue import (
    PROCEDURAL_FIRST_ID,
    load_ycb_catalogue,
    procedural_catalogue,
    write_bop_models,
    ycb_pool,
)
from ipr_shapes.synth.sensor import depth_sigma, noisy_depth

YCB = ycb_models_dir()
needs_ycb = pytest.mark.skipif(YCB is None, reason="shared YCB models not found (../shared/data)")
SMALL = SynthConfig(width=160, height=120, min_visible_px=20)
FULL = SynthConfig(write_clean_depth=True)


def _json(path: Path):
    return json.loads(path.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def suite(tmp_path_factory) -> dict[str, Path]:
    """A full-size dynamic scene (with clean depth) and a small static drawer scene."""
    out = tmp_path_factory.mktemp("synth")
    dynamic = generate_scene(out, kind="dynamic", seed=3, arrangement="table", config=FULL)
    static = generate_scene(
        out,
        kind="static",
        seed=5,
        arrangement="drawer",
        config=replace(SMALL, static_frames=2),
    )
    return {"dynamic": dynamic, "static": static, "out": out}


# --------------------------------------------------------------------------------------------
# Scene contract


@pytest.mark.slow  # the full-size scene fixture (12 s): .ci/run's slow stage
def test_scenes_load_with_the_right_frames_and_pushes(suite):
    dynamic = load_scene(suite["dynamic"])
    assert dynamic.world_frame_source == "camera_poses"
    assert 1 <= len(dynamic.pushes) <= 3
    assert len(dynamic.frames) == len(dynamic.pushes) + 1
    assert [(p.before_frame, p.after_frame) for p in dynamic.pushes] == [
        (k, k + 1) for k in range(len(dynamic.pushes))
    ]
    assert dynamic.frames[0].rgb.shape == (480, 640, 3)
    assert dynamic.pusher.radius_m == pytest.approx(0.01)
    assert dynamic.pusher.length_m == pytest.approx(0.15)
    assert np.allclose(dynamic.pusher.axis, [0, 0, 1])
    for push in dynamic.pushes:
        assert push.start_m[2] - 0.075 == pytest.approx(0.005, abs=1e-9)  # tip 5 mm up (table)
        assert abs(push.direction[2]) < 1e-12
        assert 0.01 < push.distance_m <= 0.12 + 1e-9
        assert 0.04 <= push.speed_m_s <= 0.06

    static = load_scene(suite["static"])
    assert not static.is_dynamic and static.pusher is None
    assert not (suite["static"] / "actions.json").exists()
    assert len(static.frames) == 2
    assert static.frames[0].depth_m.shape == (120, 160)
    assert (suite["static"] / "preview.png").is_file()
    assert _json(suite["static"] / "synth.json")["arrangement"] == "drawer"


@pytest.mark.slow  # the full-size scene fixture (12 s): .ci/run's slow stage
def test_ground_truth_ids_and_info_are_consistent(suite):
    for path in (suite["dynamic"], suite["static"]):
        cameras = _json(path / "scene_camera.json")
        gt = _json(path / "scene_gt.json")
        info = _json(path / "scene_gt_info.json")
        meta = _json(path / "synth.json")
        ids = [item["obj_id"] for item in meta["objects"]]
        assert 3 <= len(ids) <= 8
        assert set(gt) == set(info) == set(cameras)
        for frame in gt:
            assert [item["obj_id"] for item in gt[frame]] == ids  # every object, every frame
            assert len(info[frame]) == len(ids)
            for entry in info[frame]:
                assert set(entry) >= {
                    "bbox_obj",
                    "bbox_visib",
                    "px_count_all",
                    "px_count_visib",
                    "visib_fract",
                }
                assert 0 <= entry["px_count_visib"] <= entry["px_count_all"]
                assert 0.0 <= entry["visib_fract"] <= 1.0
        visible = [e["px_count_visib"] >= 20 for e in info["0"]]
        assert sum(visible) >= 3


@needs_ycb
@pytest.mark.slow  # the full-size scene fixture (12 s): .ci/run's slow stage
def test_models_are_written_in_millimetres(suite):
    models = suite["out"] / "models"
    info = _json(models / "models_info.json")
    meta = _json(suite["dynamic"] / "synth.json")
    import trimesh

    for item in meta["objects"][:2]:
        entry = info[str(item["obj_id"])]
        assert entry["name"] == item["name"]
        source = trimesh.load(YCB / "models" / f"{item['name']}.ply", process=False)
        written = trimesh.load(models / f"obj_{item['obj_id']:06d}.ply", process=False)
        assert np.allclose(written.extents, source.extents * 1000.0, atol=1e-3)
        assert np.allclose(
            [entry["size_x"], entry["size_y"], entry["size_z"]], source.extents * 1000.0, atol=1e-3
        )
        assert entry["min_x"] == pytest.approx(source.bounds[0, 0] * 1000.0, abs=1e-3)
        assert entry["diameter"] >= np.linalg.norm(source.extents) * 1000.0 * 0.5
        assert np.array_equal(
            np.asarray(written.visual.vertex_colors)[:, :3],
            np.asarray(source.visual.vertex_colors)[:, :3],
        )
        metres = load_model(models, item["obj_id"])  # the contract's loader: mm -> m
        assert np.allclose(metres.extents, source.extents, atol=1e-6)


@pytest.mark.slow  # the full-size scene fixture (12 s): .ci/run's slow stage
def test_camera_distance_elevation_and_intrinsics_in_range(suite):
    scene = load_scene(suite["dynamic"])
    target = np.array(_json(suite["dynamic"] / "synth.json")["camera"]["target_m"])
    for frame in scene.frames:
        centre = frame.world_from_camera[:3, 3]
        axis = frame.world_from_camera[:3, 2]  # optical axis in the world
        assert 0.5 <= np.linalg.norm(centre - target) <= 0.9
        elevation = np.degrees(np.arcsin(-axis[2]))
        assert 35.0 <= elevation <= 65.0
        assert np.allclose(np.cross(axis, target - centre), 0.0, atol=1e-9)  # looks at target
        assert 600.0 <= frame.K[0, 0] <= 620.0
        assert abs(frame.K[1, 1] / frame.K[0, 0] - 1.0) < 0.01
        assert abs(frame.K[0, 2] - 319.5) <= 4.0 and abs(frame.K[1, 2] - 239.5) <= 4.0
    assert all(
        np.array_equal(f.world_from_camera, scene.frames[0].world_from_camera) for f in scene.frames
    )


# --------------------------------------------------------------------------------------------
# Ground truth agrees with the images


@pytest.mark.slow  # the full-size scene fixture (12 s): .ci/run's slow stage
def test_ground_truth_poses_project_onto_matching_depth(suite):
    """Front-facing model vertices, posed by scene_gt and projected with K, land on pixels whose
    depth matches theirs: poses, camera and depth agree."""
    path = suite["dynamic"]
    scene = load_scene(path)
    gt = load_ground_truth(path)
    info = _json(path / "scene_gt_info.json")["0"]
    frame = scene.frames[0]
    height, width = frame.depth_m.shape
    fractions = []
    for pose, entry in zip(gt[0], info, strict=True):
        if entry["visib_fract"] < 0.8 or entry["px_count_visib"] < 500:
            continue
        model = load_model(path.parent / "models", pose.obj_id)
        points = apply_transform(pose.camera_from_model, np.asarray(model.vertices))
        normals = np.asarray(model.vertex_normals) @ pose.camera_from_model[:3, :3].T
        facing = (normals * -points).sum(axis=1) / np.linalg.norm(points, axis=1) > 0.3
        pixels = np.round(project(points[facing], frame.K)).astype(int)
        inside = ((pixels >= 0) & (pixels < [width, height])).all(axis=1)
        depth = frame.depth_m[pixels[inside, 1], pixels[inside, 0]]
        valid = depth > 0
        error = np.abs(depth[valid] - points[facing][inside][valid, 2])
        fractions.append(float((error < 0.01).mean()))
    assert fractions, "no well-visible object in frame 0"
    assert max(fractions) > 0.9
    assert np.median(fractions) > 0.7


@pytest.mark.slow  # the full-size scene fixture (12 s): .ci/run's slow stage
def test_pushes_move_an_object_and_start_outside_all_objects(suite):
    path = suite["dynamic"]
    scene = load_scene(path)
    gt = load_ground_truth(path)
    world_from_camera = scene.frames[0].world_from_camera
    models = {p.obj_id: load_model(path.parent / "models", p.obj_id) for p in gt[0]}
    for push in scene.pushes:
        before = [world_from_camera @ p.camera_from_model for p in gt[push.before_frame]]
        after = [world_from_camera @ p.camera_from_model for p in gt[push.after_frame]]
        moved = [np.linalg.norm(a[:3, 3] - b[:3, 3]) for a, b in zip(after, before, strict=True)]
        assert max(moved) >= 0.01
        # The capsule (axis segment + radius) at the start is clear of every object's vertices.
        low = push.start_m - [0, 0, 0.075 - 0.01]
        high = push.start_m + [0, 0, 0.075 - 0.01]
        for object_pose, pose in zip(gt[push.before_frame], before, strict=True):
            vertices = apply_transform(pose, np.asarray(models[object_pose.obj_id].vertices))
            along = np.clip((vertices[:, 2] - low[2]) / (high[2] - low[2]), 0.0, 1.0)
            nearest = low + along[:, None] * (high - low)
            assert np.linalg.norm(vertices - nearest, axis=1).min() > 0.01


# --------------------------------------------------------------------------------------------
# Sensor model


@pytest.mark.slow  # the full-size scene fixture (12 s): .ci/run's slow stage
def test_depth_is_noisy_quantised_and_has_holes(suite):
    path = suite["dynamic"]
    written = np.asarray(Image.open(path / "depth" / "000000.png")).astype(np.float64)
    clean = np.asarray(Image.open(path / "depth_clean" / "000000.png")).astype(np.float64)
    in_range = (clean >= 200) & (clean <= 3000)
    valid = in_range & (written > 0)
    difference = written[valid] - clean[valid]
    assert (difference != 0).mean() > 0.5  # noise present
    assert 0.5 < np.median(np.abs(difference)) < 5.0  # a few millimetres at 0.5-1 m
    assert abs(np.median(difference)) <= 1.0  # unbiased
    holes = in_range & (written == 0)
    assert 50 < holes.sum() < 0.2 * in_range.sum()  # holes present, most pixels read
    frame = load_scene(path).frames[0]
    millimetres = frame.depth_m.astype(np.float64) * 1000.0
    assert np.allclose(millimetres, np.round(millimetres), atol=1e-3)  # whole millimetres
    rgb = np.asarray(Image.open(path / "rgb" / "000000.png"))
    assert rgb.dtype == np.uint8 and rgb.std() > 10


def test_noise_model_statistics():
    config = SynthConfig()
    rng = np.random.default_rng(0)
    clean = np.full((480, 640), 0.8, dtype=np.float32)
    clean[:, 320:] = 1.2  # a 40 cm step: a depth discontinuity down the middle
    noisy = noisy_depth(clean, rng, config)
    assert noisy.dtype == np.float32
    millimetres = noisy.astype(np.float64) * 1000.0
    assert np.allclose(millimetres, np.round(millimetres), atol=1e-3)  # 1 mm quantisation
    assert len(np.unique(millimetres[:, :300].round())) > 5
    left = noisy[:, 20:300][noisy[:, 20:300] > 0] - 0.8
    expected = float(depth_sigma(np.array(0.8), config))
    assert abs(left.mean()) < 2e-4  # unbiased
    assert 0.9 * expected < left.std() < 1.3 * expected  # sigma(z), plus quantisation
    far = noisy[:, 340:620][noisy[:, 340:620] > 0] - 1.2
    assert far.std() > left.std() * 1.2  # noise grows with depth
    edge = noisy[:, 318:322]
    assert (edge == 0).mean() > 0.3  # dropout at the discontinuity
    flat = np.concatenate([noisy[:, :310], noisy[:, 330:]], axis=1)
    assert 0 < (flat == 0).mean() < 0.05  # a few random holes away from it
    assert np.array_equal(noisy, noisy_depth(clean, np.random.default_rng(0), config))
    outside = noisy_depth(np.full((60, 80), 5.0, dtype=np.float32), rng, config)
    assert not outside.any()  # beyond the sensor's range: no reading


# --------------------------------------------------------------------------------------------
# Determinism, fallback, arguments


@pytest.mark.slow
def test_same_seed_gives_identical_files_and_another_seed_differs(suite, tmp_path):
    config = replace(SMALL, static_frames=2)
    again = generate_scene(tmp_path, kind="static", seed=5, arrangement="drawer", config=config)
    original = suite["static"]
    files = sorted(p.relative_to(original) for p in original.rglob("*") if p.is_file())
    assert Path("rgb/000000.png") in files and Path("depth/000001.png") in files
    for relative in files:
        assert (original / relative).read_bytes() == (again / relative).read_bytes(), relative
    other = generate_scene(tmp_path, kind="static", seed=6, arrangement="drawer", config=config)
    for name in ("rgb/000000.png", "depth/000000.png", "scene_gt.json"):
        assert (other / name).read_bytes() != (original / name).read_bytes()


@pytest.mark.slow
def test_procedural_fallback_when_ycb_folder_is_missing(tmp_path):
    with pytest.warns(UserWarning, match="procedural"):
        path = generate_scene(
            tmp_path,
            kind="dynamic",
            seed=11,
            arrangement="container",
            models_dir=tmp_path / "no_such_folder",
            config=SMALL,
        )
    scene = load_scene(path)
    assert len(scene.frames) == len(scene.pushes) + 1 >= 2
    meta = _json(path / "synth.json")
    assert meta["object_source"] == "procedural"
    ids = [item["obj_id"] for item in meta["objects"]]
    assert all(obj_id >= PROCEDURAL_FIRST_ID for obj_id in ids)
    info = _json(tmp_path / "models" / "models_info.json")
    shapes = {item.obj_id: item for item in procedural_catalogue(SMALL.procedural_density_kg_m3)}
    for obj_id in ids:
        assert info[str(obj_id)]["size_z"] == pytest.approx(shapes[obj_id].extents[2] * 1000, 1e-4)
    forced = generate_scene(
        tmp_path,
        kind="static",
        seed=11,
        arrangement="table",
        config=replace(SMALL, object_source="procedural"),
    )
    assert _json(forced / "synth.json")["object_source"] == "procedural"


@pytest.mark.slow
def test_generate_scenes_seeds_arrangements_and_progress(tmp_path):
    calls = []
    paths = generate_scenes(
        tmp_path,
        kind="static",
        seed=42,
        count=2,
        config=SMALL,
        progress=lambda done, total: calls.append((done, total)),
    )
    assert calls == [(1, 2), (2, 2)]
    assert [p.name for p in paths] == ["static_000000", "static_000001"]
    metas = [_json(p / "synth.json") for p in paths]
    assert [m["arrangement"] for m in metas] == list(ARRANGEMENTS[:2])
    assert [m["seed"] for m in metas] == [scene_seed(42, 0), scene_seed(42, 1)]
    assert scene_seed(42, 0) != scene_seed(42, 1) != scene_seed(43, 1)
    for path in paths:
        load_scene(path)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"kind": "moving"}, "kind"),
        ({"seed": -1}, "seed"),
        ({"seed": 1.5}, "seed"),
        ({"arrangement": "shelf"}, "arrangement"),
        ({"name": "a/b"}, "name"),
        ({"config": {"width": 0}}, "width"),
        ({"config": {"height": 100.5}}, "height"),
        ({"config": {"min_objects": 5, "max_objects": 4}}, "min_objects"),
        ({"config": {"camera_distance_m": (0.9, 0.5)}}, "camera_distance_m"),
        ({"config": {"friction": (float("nan"), 1.0)}}, "friction"),
        ({"config": {"object_source": "lego"}}, "object_source"),
        ({"config": {"pushes": (0, 2)}}, "pushes"),
    ],
)
def test_bad_arguments_raise_value_error(tmp_path, kwargs, message):
    arguments = {"kind": "static", "seed": 0, **kwargs}
    with pytest.raises(ValueError, match=message):
        if "config" in arguments:
            arguments["config"] = SynthConfig(**arguments["config"])
        generate_scene(tmp_path, **arguments)
    assert not any(tmp_path.iterdir())  # nothing written


def test_bad_suite_arguments_and_exhausted_attempts(tmp_path):
    with pytest.raises(ValueError, match="count"):
        generate_scenes(tmp_path, kind="static", seed=0, count=0)
    with pytest.raises(ValueError, match="kind"):
        generate_scenes(tmp_path, kind="", seed=0, count=1)
    impossible = replace(SMALL, min_visible_px=10**6, max_attempts=1, object_source="procedural")
    with pytest.raises(GenerationError, match="attempts"):
        generate_scene(tmp_path, kind="static", seed=0, arrangement="table", config=impossible)


# --------------------------------------------------------------------------------------------
# Object sources


@needs_ycb
def test_ycb_pool_rule_keeps_convex_objects_and_drops_thin_or_hollow_ones():
    names = {item.name for item in ycb_pool(load_ycb_catalogue(str(YCB)), SynthConfig())}
    assert {"003_cracker_box", "005_tomato_soup_can", "013_apple", "061_foam_brick"} <= names
    dropped = {
        "024_bowl",
        "025_mug",
        "030_fork",
        "032_knife",
        "065-a_cups",
        "011_banana",
        "063-b_marbles",
        "070-a_colored_wood_blocks",
    }
    assert not names & dropped
    catalogue = load_ycb_catalogue(str(YCB))
    files = sorted(p.stem for p in (YCB / "models").glob("*.ply"))
    assert [item.name for item in catalogue] == files  # id = 1-based index in sorted files
    assert [item.obj_id for item in catalogue] == list(range(1, len(files) + 1))


@needs_ycb
def test_extra_objects_join_the_pool_and_unknown_names_are_refused():
    catalogue = load_ycb_catalogue(str(YCB))
    plain = ycb_pool(catalogue, SynthConfig())
    extra = ycb_pool(catalogue, SynthConfig(extra_objects=("025_mug", "024_bowl", "025_mug")))
    assert [item.name for item in extra] == [
        *(item.name for item in plain),
        "025_mug",
        "024_bowl",
        "025_mug",
    ]
    with pytest.raises(ValueError, match="999_teapot"):
        ycb_pool(catalogue, SynthConfig(extra_objects=("999_teapot",)))


def test_extra_objects_must_be_a_tuple_of_names():
    with pytest.raises(ValueError, match="extra_objects"):
        SynthConfig(extra_objects="025_mug")
    with pytest.raises(ValueError, match="extra_objects"):
        SynthConfig(extra_objects=(25,))


def test_models_folder_is_reused_and_conflicts_are_refused(tmp_path):
    shapes = list(procedural_catalogue(SynthConfig().procedural_density_kg_m3))[:3]
    write_bop_models(tmp_path, shapes)
    path = tmp_path / f"obj_{shapes[0].obj_id:06d}.ply"
    stamp = path.stat().st_mtime_ns
    write_bop_models(tmp_path, shapes)
    assert path.stat().st_mtime_ns == stamp  # identical model: not rewritten
    info = _json(tmp_path / "models_info.json")
    assert sorted(info) == sorted(str(s.obj_id) for s in shapes)
    impostor = replace(shapes[1], name="not_the_same")
    with pytest.raises(ValueError, match="already holds"):
        write_bop_models(tmp_path, [impostor])
