"""Scene contract: reading, writing, world frames, and every validation error with its message."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from ipr_shapes.camera import invert_transform
from ipr_shapes.errors import SceneError
from ipr_shapes.scene import load_scene, write_scene

from .conftest import make_frames

# ---------------------------------------------------------------------------------- round trip


def test_round_trip_preserves_frames_poses_and_pushes(scene_dir: Path):
    scene = load_scene(scene_dir)
    originals = make_frames(2)
    assert len(scene.frames) == 2 and scene.world_frame_source == "camera_poses"
    for frame, original in zip(scene.frames, originals, strict=True):
        assert np.array_equal(frame.rgb, original.rgb)
        # 1 mm quantisation of the depth PNG.
        assert np.abs(frame.depth_m - original.depth_m).max() <= 0.0005 + 1e-6
        assert np.allclose(frame.world_from_camera, original.world_from_camera, atol=1e-9)
        assert np.allclose(frame.K, original.K)
    (push,) = scene.pushes
    assert (push.before_frame, push.after_frame) == (0, 1)
    assert np.allclose(push.start_m, [-0.1, 0, 0.08]) and np.allclose(push.end_m, [-0.02, 0, 0.08])
    assert scene.pusher.radius_m == 0.01 and np.allclose(scene.pusher.axis, [0, 0, 1])
    assert scene.is_dynamic


def test_world_points_of_the_table_lie_on_z0(scene_dir: Path):
    frame = load_scene(scene_dir).frames[0]
    points = frame.points_world()[frame.depth_m > 0]
    table = np.abs(points[:, 0]) > 0.05
    assert np.median(np.abs(points[table, 2])) < 0.002


def test_world_frame_from_support_plane_when_no_poses(tmp_path: Path):
    frames = make_frames(1)
    path = write_scene(tmp_path / "s", frames, write_poses=False)
    scene = load_scene(path)
    assert scene.world_frame_source == "support_plane"
    frame = scene.frames[0]
    points = frame.points_world()[frame.depth_m > 0]
    # Most points are on the table at z = 0; the bump is 3 cm nearer along the optical axis, which
    # is tilted 45 degrees, so it rises 3 cm x cos(45) above the table.
    assert np.median(np.abs(points[:, 2])) < 0.003
    assert np.isclose(np.percentile(points[:, 2], 99.5), 0.03 * np.cos(np.pi / 4), atol=0.002)
    camera_centre = frame.world_from_camera[:3, 3]
    assert camera_centre[2] == pytest.approx(0.45 * np.sqrt(2) * np.sin(np.pi / 4), abs=0.01)
    assert np.allclose(camera_centre[:2], 0, atol=1e-6)  # origin below the camera


def _true_up(frame) -> np.ndarray:
    """World +z in the camera frame of ``frame`` (the up direction a user would give)."""
    return frame.world_from_camera[:3, :3].T @ np.array([0.0, 0.0, 1.0])


def test_a_given_up_direction_finds_the_table(tmp_path: Path):
    frames = make_frames(1)
    path = write_scene(tmp_path / "s", frames, write_poses=False)
    up = _true_up(frames[0])
    # A rough up (20 degrees off, any length) still finds the table, which then sets world z.
    rough = 3.0 * (up + np.tan(np.radians(20.0)) * np.array([1.0, 0.0, 0.0]))
    scene = load_scene(path, up_camera=rough.tolist())
    frame = scene.frames[0]
    assert scene.world_frame_source == "support_plane"
    assert np.degrees(np.arccos(np.clip(_true_up(frame) @ up, -1, 1))) < 1.0
    points = frame.points_world()[frame.depth_m > 0]
    assert np.median(np.abs(points[:, 2])) < 0.003


@pytest.mark.parametrize(
    ("up", "message"),
    [
        ([0.0, 0.0, 0.0], "3 finite numbers"),
        ([1.0, float("nan"), 0.0], "3 finite numbers"),
        ("down", "the camera is below the support"),
        ("sideways", "no plane within 45 degrees"),
    ],
)
def test_a_wrong_up_direction_is_refused_clearly(tmp_path: Path, up, message: str):
    frames = make_frames(1)
    path = write_scene(tmp_path / "s", frames, write_poses=False)
    true_up = _true_up(frames[0])
    if up == "down":
        up = (-true_up).tolist()
    elif up == "sideways":  # along the table: only walls (none here) are perpendicular to it
        up = np.cross(true_up, [0.0, 0.0, 1.0]).tolist()
    error = _expect(path, "depth/000000.png", message, up_camera=up)
    assert "--up" in error.fix


def test_an_up_direction_for_a_scene_with_poses_is_refused(scene_dir: Path):
    with pytest.raises(SceneError, match="camera poses, which fix gravity"):
        load_scene(scene_dir, up_camera=[0.0, -1.0, 0.0])


def test_actions_in_camera_frame_are_converted_to_world(scene_dir: Path):
    scene = load_scene(scene_dir)
    camera_from_world = invert_transform(scene.frames[0].world_from_camera)
    actions = json.loads((scene_dir / "actions.json").read_text())
    push = actions["pushes"][0]
    push["start_m"] = (
        camera_from_world[:3, :3] @ push["start_m"] + camera_from_world[:3, 3]
    ).tolist()
    push["direction"] = (camera_from_world[:3, :3] @ push["direction"]).tolist()
    actions["pusher"]["axis"] = (camera_from_world[:3, :3] @ [0, 0, 1]).tolist()
    actions["frame"] = "camera:0"
    (scene_dir / "actions.json").write_text(json.dumps(actions))
    converted = load_scene(scene_dir)
    assert np.allclose(converted.pushes[0].start_m, scene.pushes[0].start_m, atol=1e-9)
    assert np.allclose(converted.pushes[0].direction, [1, 0, 0], atol=1e-9)
    assert np.allclose(converted.pusher.axis, [0, 0, 1], atol=1e-9)


def test_robot_mask_is_read(scene_dir: Path):
    mask = np.zeros((120, 160), np.uint8)
    mask[10:20, 30:40] = 255
    (scene_dir / "mask_robot").mkdir()
    Image.fromarray(mask).save(scene_dir / "mask_robot" / "000001.png")
    scene = load_scene(scene_dir)
    assert scene.frames[0].robot_mask is None
    assert scene.frames[1].robot_mask.sum() == 100


def test_write_is_atomic_and_refuses_to_overwrite(scene_dir: Path):
    with pytest.raises(SceneError, match="already exists"):
        write_scene(scene_dir, make_frames(1))
    leftovers = [p for p in scene_dir.parent.iterdir() if p.name.startswith(".")]
    assert leftovers == []


def test_real_ycbv_scene_loads(shared_data: Path):
    scene = load_scene(shared_data / "ycbv_real" / "ycbv_0000")
    assert len(scene.frames) == 10 and scene.world_frame_source == "support_plane"
    assert scene.frames[0].shape == (480, 640) and not scene.is_dynamic
    # The camera is above the table plane, looking down at it.
    assert 0.2 < scene.frames[0].world_from_camera[2, 3] < 1.5
    assert scene.frames[0].world_from_camera[2, 2] < 0


# ---------------------------------------------------------------------------------- errors


def _edit_json(path: Path, edit) -> None:
    content = json.loads(path.read_text())
    edit(content)
    path.write_text(json.dumps(content))


def _expect(scene_dir: Path, file_part: str, *message_parts: str, up_camera=None) -> SceneError:
    with pytest.raises(SceneError) as caught:
        load_scene(scene_dir, up_camera=up_camera)
    text = str(caught.value)
    assert file_part in text, text
    for part in message_parts:
        assert part in text, text
    assert "fix:" in text or caught.value.fix == "", text
    return caught.value


def test_missing_scene_directory(tmp_path: Path):
    _expect(tmp_path / "nope", "nope", "not found")


def test_missing_frame_image(scene_dir: Path):
    (scene_dir / "rgb" / "000001.png").unlink()
    _expect(scene_dir, "rgb", "no image of frames [1]")


def test_sparse_frame_ids_keep_their_ids_and_pushes_name_them(scene_dir: Path):
    for folder in ("rgb", "depth"):
        (scene_dir / folder / "000001.png").rename(scene_dir / folder / "000005.png")
    _edit_json(scene_dir / "scene_camera.json", lambda c: c.update({"5": c.pop("1")}))
    # The push still names frame 1, which is gone.
    _expect(scene_dir, "actions.json", "after_frame 1 names a frame that does not exist", "0, 5")
    _edit_json(scene_dir / "actions.json", lambda a: a["pushes"][0].update(after_frame=5))
    scene = load_scene(scene_dir)
    assert [frame.index for frame in scene.frames] == [0, 5]
    assert (scene.pushes[0].before_frame, scene.pushes[0].after_frame) == (0, 5)
    # Choosing frames: one frame only drops the push after it.
    assert load_scene(scene_dir, frames=[0]).pushes == ()
    _expect_chosen = pytest.raises(SceneError, match=r"chosen frames \[3\] are not in the scene")
    with _expect_chosen:
        load_scene(scene_dir, frames=[0, 3])


def test_rgb_depth_size_mismatch(scene_dir: Path):
    Image.fromarray(np.zeros((60, 80), np.uint16)).save(scene_dir / "depth" / "000000.png")
    _expect(scene_dir, "depth/000000.png", "depth is 80x60 but rgb is 160x120")


def test_depth_not_16_bit(scene_dir: Path):
    Image.fromarray(np.full((120, 160), 200, np.uint8)).save(scene_dir / "depth" / "000001.png")
    _expect(scene_dir, "depth/000001.png", "16-bit")


def test_missing_depth_scale(scene_dir: Path):
    _edit_json(scene_dir / "scene_camera.json", lambda c: c["0"].pop("depth_scale"))
    _expect(scene_dir, "scene_camera.json", "'depth_scale' is missing")


@pytest.mark.parametrize("scale", [0.01, 100.0])
def test_implausible_depth_scale_is_flagged_as_unit_error(scene_dir: Path, scale: float):
    _edit_json(scene_dir / "scene_camera.json", lambda c: c["0"].update(depth_scale=scale))
    error = _expect(scene_dir, "depth/000000.png", "likely a unit error")
    assert "depth_scale" in error.fix


def test_non_positive_depth_scale(scene_dir: Path):
    _edit_json(scene_dir / "scene_camera.json", lambda c: c["1"].update(depth_scale=0))
    _expect(scene_dir, "scene_camera.json", "depth_scale' must be positive")


def test_cam_k_not_3x3(scene_dir: Path):
    _edit_json(scene_dir / "scene_camera.json", lambda c: c["0"].update(cam_K=[1, 0, 0, 0, 1, 0]))
    _expect(scene_dir, "scene_camera.json", "cam_K' must hold 9 numbers, got 6")


def test_cam_k_non_positive_focal_length(scene_dir: Path):
    def edit(content):
        content["0"]["cam_K"][0] = -150.0

    _edit_json(scene_dir / "scene_camera.json", edit)
    _expect(scene_dir, "scene_camera.json", "focal lengths must be positive")


def test_malformed_camera_json(scene_dir: Path):
    (scene_dir / "scene_camera.json").write_text('{"0": {"cam_K": [1, 2,, 3]}')
    _expect(scene_dir, "scene_camera.json", "not valid JSON", "line 1")


def test_malformed_actions_json(scene_dir: Path):
    (scene_dir / "actions.json").write_text("{format: nope}")
    _expect(scene_dir, "actions.json", "not valid JSON")


def test_unknown_actions_format(scene_dir: Path):
    _edit_json(scene_dir / "actions.json", lambda c: c.update(format="ipr-actions/9"))
    error = _expect(scene_dir, "actions.json", "unknown format 'ipr-actions/9'")
    assert "ipr-actions/1" in error.fix


def test_push_names_missing_frame(scene_dir: Path):
    _edit_json(scene_dir / "actions.json", lambda c: c["pushes"][0].update(after_frame=5))
    _expect(scene_dir, "actions.json", "after_frame 5 names a frame that does not exist")


def test_push_zero_direction(scene_dir: Path):
    _edit_json(scene_dir / "actions.json", lambda c: c["pushes"][0].update(direction=[0, 0, 0]))
    _expect(scene_dir, "actions.json", "direction' is the zero vector")


def test_push_non_unit_direction(scene_dir: Path):
    _edit_json(scene_dir / "actions.json", lambda c: c["pushes"][0].update(direction=[2, 0, 0]))
    error = _expect(scene_dir, "actions.json", "not a unit vector (length 2.0000)")
    assert "normalise" in error.fix


def test_push_direction_of_unit_length_is_kept_bit_for_bit(scene_dir: Path):
    # (cos a, sin a, 0): unit to float64 rounding, yet dividing it by its norm changes its last
    # bits, which a replayed push amplifies (a generated scene's pushes replay exactly).
    given = [-0.6520162635843662, -0.7582049802141122, 0.0]
    assert not np.array_equal(np.array(given) / np.linalg.norm(given), given)
    _edit_json(scene_dir / "actions.json", lambda c: c["pushes"][0].update(direction=given))
    assert np.array_equal(load_scene(scene_dir).pushes[0].direction, given)


def test_push_direction_within_tolerance_is_normalised(scene_dir: Path):
    _edit_json(
        scene_dir / "actions.json", lambda c: c["pushes"][0].update(direction=[1.0005, 0, 0])
    )
    assert np.array_equal(load_scene(scene_dir).pushes[0].direction, [1.0, 0.0, 0.0])


@pytest.mark.parametrize("key", ["distance_m", "speed_m_s"])
@pytest.mark.parametrize("value", [0, -0.1])
def test_push_non_positive_distance_or_speed(scene_dir: Path, key: str, value: float):
    _edit_json(scene_dir / "actions.json", lambda c: c["pushes"][0].update({key: value}))
    _expect(scene_dir, "actions.json", f"{key}' must be positive")


def test_nan_in_json(scene_dir: Path):
    text = (
        (scene_dir / "actions.json").read_text().replace('"distance_m": 0.08', '"distance_m": NaN')
    )
    (scene_dir / "actions.json").write_text(text)
    _expect(scene_dir, "actions.json", "contains NaN")


def test_infinity_in_json(scene_dir: Path):
    text = json.dumps(json.loads((scene_dir / "scene_camera.json").read_text()))
    text = text.replace('"depth_scale": 1.0', '"depth_scale": Infinity', 1)
    (scene_dir / "scene_camera.json").write_text(text)
    _expect(scene_dir, "scene_camera.json", "contains Infinity")


def test_huge_number_overflowing_to_inf(scene_dir: Path):
    def edit(content):
        content["0"]["cam_t_w2c"][0] = 1e400  # json parses this to inf

    text = (scene_dir / "scene_camera.json").read_text()
    content = json.loads(text)
    edit(content)
    (scene_dir / "scene_camera.json").write_text(json.dumps(content).replace("Infinity", "1e400"))
    _expect(scene_dir, "scene_camera.json", "NaN or inf")


def test_all_zero_depth(scene_dir: Path):
    Image.fromarray(np.zeros((120, 160), np.uint16)).save(scene_dir / "depth" / "000000.png")
    _expect(scene_dir, "depth/000000.png", "no valid reading")


def test_mask_of_wrong_size(scene_dir: Path):
    (scene_dir / "mask_robot").mkdir()
    Image.fromarray(np.zeros((10, 10), np.uint8)).save(scene_dir / "mask_robot" / "000000.png")
    _expect(scene_dir, "mask_robot/000000.png", "mask is 10x10, image is 160x120")


def test_world_actions_without_camera_poses(scene_dir: Path):
    def drop_poses(content):
        for entry in content.values():
            entry.pop("cam_R_w2c")
            entry.pop("cam_t_w2c")

    _edit_json(scene_dir / "scene_camera.json", drop_poses)
    _expect(scene_dir, "actions.json", "no camera poses")


def test_partial_camera_poses(scene_dir: Path):
    _edit_json(
        scene_dir / "scene_camera.json",
        lambda c: (c["1"].pop("cam_R_w2c"), c["1"].pop("cam_t_w2c")),
    )
    _expect(scene_dir, "scene_camera.json", "some frames but not all")


def test_rotation_that_is_not_orthonormal(scene_dir: Path):
    _edit_json(
        scene_dir / "scene_camera.json",
        lambda c: c["0"].update(cam_R_w2c=[1, 0, 0, 0, 2, 0, 0, 0, 1]),
    )
    _expect(scene_dir, "scene_camera.json", "not a rotation matrix")


def test_no_support_plane_without_poses(tmp_path: Path):
    frames = make_frames(1)
    rng = np.random.default_rng(1)
    noisy = [
        type(f)(
            f.index,
            f.rgb,
            rng.uniform(0.3, 2.0, f.depth_m.shape).astype(np.float32),
            f.K,
            f.world_from_camera,
        )
        for f in frames
    ]
    path = write_scene(tmp_path / "s", noisy, write_poses=False)
    error = _expect(path, "depth/000000.png", "frame 0", "cannot determine gravity")
    assert "cam_R_w2c" in error.fix and "--up X Y Z" in error.fix


def test_missing_camera_json(scene_dir: Path):
    (scene_dir / "scene_camera.json").unlink()
    _expect(scene_dir, "scene_camera.json", "is missing")


def test_missing_depth_folder(scene_dir: Path):
    shutil.rmtree(scene_dir / "depth")
    _expect(scene_dir, "depth", "folder is missing")
