"""ipr_shapes.from_arrays: frames in memory make the same Scene as their folder, by the same rules; and
ipr_shapes.infer runs on it as on the folder."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import ipr_shapes
from ipr_shapes.errors import ArrayInputError
from ipr_shapes.scene import Push, Pusher, Scene, load_scene, write_scene
from tests.conftest import make_frames

ROOT = Path(__file__).resolve().parents[1]


def _depth_units(scene_dir: Path, scene: Scene) -> np.ndarray:
    return np.stack(
        [np.asarray(Image.open(scene_dir / "depth" / f"{f.index:06d}.png")) for f in scene.frames]
    ).astype(np.uint16)


def assert_same_scene(a: Scene, b: Scene) -> None:
    """Every field of two scenes equal (paths aside), arrays exactly."""
    assert len(a.frames) == len(b.frames)
    for fa, fb in zip(a.frames, b.frames, strict=True):
        assert fa.index == fb.index
        for name in ("rgb", "depth_m", "K", "world_from_camera"):
            x, y = getattr(fa, name), getattr(fb, name)
            assert x.dtype == y.dtype and np.array_equal(x, y), name
        assert (fa.robot_mask is None) == (fb.robot_mask is None)
        if fa.robot_mask is not None:
            assert np.array_equal(fa.robot_mask, fb.robot_mask)
    assert a.world_frame_source == b.world_frame_source and a.support_note == b.support_note
    assert (a.pusher is None) == (b.pusher is None)
    if a.pusher is not None:
        assert (a.pusher.radius_m, a.pusher.length_m) == (b.pusher.radius_m, b.pusher.length_m)
        assert np.allclose(a.pusher.axis, b.pusher.axis, atol=1e-12)
    assert len(a.pushes) == len(b.pushes)
    for pa, pb in zip(a.pushes, b.pushes, strict=True):
        assert (pa.before_frame, pa.after_frame) == (pb.before_frame, pb.after_frame)
        assert (pa.distance_m, pa.speed_m_s) == (pb.distance_m, pb.speed_m_s)
        assert np.allclose(pa.start_m, pb.start_m, atol=1e-12)
        assert np.allclose(pa.direction, pb.direction, atol=1e-12)


def test_arrays_of_a_folder_make_the_scene_load_scene_reads(scene_dir: Path):
    folder = load_scene(scene_dir)
    scale = json.loads((scene_dir / "scene_camera.json").read_text())["0"]["depth_scale"]
    common = dict(pushes=folder.pushes, pusher=folder.pusher, name=scene_dir)
    rgb = np.stack([f.rgb for f in folder.frames])
    poses = np.stack([f.world_from_camera for f in folder.frames])
    # uint16 units with the file's scale, one K per frame.
    units = _depth_units(scene_dir, folder)
    K = np.stack([f.K for f in folder.frames])
    made = ipr_shapes.from_arrays(
        rgb, units, K, depth_scale=scale, world_from_camera=poses, **common
    )
    assert_same_scene(made, folder)
    assert made.path == scene_dir
    # float metres, lists, a shared K and (R, t) poses.
    made = ipr_shapes.from_arrays(
        [f.rgb for f in folder.frames],
        [f.depth_m for f in folder.frames],
        folder.frames[0].K,
        world_from_camera=[(p[:3, :3], p[:3, 3]) for p in poses],
        **common,
    )
    assert_same_scene(made, folder)
    assert made.is_dynamic and made.world_frame_source == "camera_poses"


def test_without_poses_the_world_frame_comes_from_the_support_as_for_a_folder(tmp_path: Path):
    scene_dir = write_scene(tmp_path / "static", make_frames(2), write_poses=False)
    folder = load_scene(scene_dir)
    frames = folder.frames  # depth as the folder holds it (whole millimetres)
    made = ipr_shapes.from_arrays([f.rgb for f in frames], [f.depth_m for f in frames], frames[0].K)
    assert_same_scene(made, folder)
    assert made.world_frame_source == "support_plane" and made.path == Path("<arrays>")
    # Pushes given in frame 0's camera coordinates land in that world frame.
    camera = np.linalg.inv(made.frames[0].world_from_camera)
    start_world = np.array([-0.1, 0.0, 0.05])
    start_camera = camera[:3, :3] @ start_world + camera[:3, 3]
    push = Push(0, 1, start_camera, camera[:3, :3] @ np.array([1.0, 0, 0]), 0.05, 0.05)
    pushed = ipr_shapes.from_arrays(
        [f.rgb for f in frames],
        [f.depth_m for f in frames],
        frames[0].K,
        pushes=[push],
        actions_frame="camera:0",
    )
    assert np.allclose(pushed.pushes[0].start_m, start_world, atol=1e-9)
    assert np.allclose(pushed.pushes[0].direction, [1, 0, 0], atol=1e-9)
    assert np.allclose(pushed.pusher.axis, camera[:3, :3].T @ Pusher().axis)


def _good():
    frames = make_frames(2)
    return (
        np.stack([f.rgb for f in frames]),
        np.stack([f.depth_m for f in frames]),
        frames[0].K.copy(),
        frames[0].world_from_camera.copy(),
    )


def _nan_K(rgb, depth, K, pose):
    K[0, 2] = np.nan
    return (rgb, depth, K), {"world_from_camera": pose}


def _scaled_pose(rgb, depth, K, pose):
    pose[:3, :3] *= 1.1
    return (rgb, depth, K), {"world_from_camera": pose}


@pytest.mark.parametrize(
    "change, where, words",
    [
        (lambda r, d, K, p: ((r.astype(np.float32) / 255, d, K), {}), "rgb[0]", "not uint8"),
        (lambda r, d, K, p: ((r[..., :2].copy(), d, K), {}), "rgb[0]", "not (H, W, 3)"),
        (lambda r, d, K, p: ((r, d[:, :, :-1], K), {}), "depth[0]", "depth is 159x120"),
        (lambda r, d, K, p: ((r, d[:1], K), {}), "depth", "1 depth maps for 2 rgb"),
        (lambda r, d, K, p: ((r, (d * 1000).astype(np.int32), K), {}), "depth[0]", "dtype"),
        (lambda r, d, K, p: ((r, (d * 1000).astype(np.uint16), K), {}), "depth[0]", "depth_scale"),
        (lambda r, d, K, p: ((r, d * 1000, K), {}), "depth[0]", "unit error"),
        (lambda r, d, K, p: ((r, d * 0, K), {}), "depth[0]", "no valid reading"),
        (_nan_K, "K", "NaN"),
        (lambda r, d, K, p: ((r, d, K[:2]), {}), "K", "(3, 3)"),
        (_scaled_pose, "world_from_camera", "not a rotation matrix"),
        (
            lambda r, d, K, p: ((r, d, K), {"world_from_camera": np.stack([p, p, p])}),
            "world_from_camera",
            "for 2 frames",
        ),
        (
            lambda r, d, K, p: (
                (r, d, K),
                {"pushes": [Push(0, 1, np.zeros(3), np.array([1.0, 0, 0]), 0.05, 0.05)]},
            ),
            "pushes",
            "no camera pose",
        ),
        (
            lambda r, d, K, p: (
                (r, d, K),
                {
                    "world_from_camera": p,
                    "pushes": [Push(0, 2, np.zeros(3), np.array([1.0, 0, 0]), 0.05, 0.05)],
                },
            ),
            "pushes[0]",
            "after_frame 2 names a frame that does not exist",
        ),
        (
            lambda r, d, K, p: (
                (r, d, K),
                {
                    "world_from_camera": p,
                    "pushes": [Push(0, 1, np.zeros(3), np.array([2.0, 0, 0]), 0.05, 0.05)],
                },
            ),
            "pushes[0]",
            "not a unit vector",
        ),
        (
            lambda r, d, K, p: ((r, d, K), {"world_from_camera": p, "up_camera": (0, -1, 0)}),
            "up_camera",
            "camera poses fix gravity",
        ),
    ],
)
def test_bad_arrays_are_refused_naming_the_argument_and_the_fix(change, where, words):
    args, kwargs = change(*_good())
    with pytest.raises(ArrayInputError) as caught:
        ipr_shapes.from_arrays(*args, **kwargs)
    error = caught.value
    assert isinstance(error, ValueError)
    message = str(error)
    assert message.startswith(f"ipr_shapes.from_arrays: {where}: ") and words in message, message
    assert "\n" not in message


def test_gravity_that_the_arrays_cannot_tell_names_the_array_fix():
    rgb, depth, K, _ = _good()
    rng = np.random.default_rng(0)
    noise = rng.uniform(0.3, 2.0, size=depth.shape).astype(np.float32)  # no plane anywhere
    with pytest.raises(ArrayInputError, match=r"depth\[0\].*up_camera="):
        ipr_shapes.from_arrays(rgb, noise, K)


def test_importing_ipr_stays_light_and_the_api_loads_on_first_use():
    code = (
        "import sys, ipr_shapes\n"
        "heavy = [m for m in ('numpy', 'mujoco', 'ipr_shapes.scene', 'ipr_shapes.pipeline') if m in sys.modules]\n"
        "assert not heavy, heavy\n"
        "assert callable(ipr_shapes.from_arrays) and 'from_arrays' in dir(ipr_shapes) and 'infer' in dir(ipr_shapes)\n"
        "assert 'ipr_shapes.arrays' in sys.modules and 'ipr_shapes.pipeline' not in sys.modules\n"
        "try:\n    ipr_shapes.no_such_name\nexcept AttributeError:\n    print('ok')\n"
    )
    completed = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(ROOT / "src"), "PATH": "/usr/bin:/bin"},
        timeout=120,
    )
    assert completed.returncode == 0 and completed.stdout.strip() == "ok", completed.stderr
    from ipr_shapes import pipeline

    assert (
        ipr_shapes.infer is pipeline.infer_scene and ipr_shapes.save_result is pipeline.save_result
    )


@pytest.mark.slow
def test_infer_on_arrays_gives_the_result_of_the_folder(scene_dir: Path, tmp_path: Path):
    from ipr_shapes.pipeline import infer
    from ipr_shapes.result import load_result

    folder = load_scene(scene_dir)
    made = ipr_shapes.from_arrays(
        [f.rgb for f in folder.frames],
        [f.depth_m for f in folder.frames],
        folder.frames[0].K,
        world_from_camera=folder.frames[0].world_from_camera,
        pushes=folder.pushes,
        pusher=folder.pusher,
    )
    options = dict(seed=3, samples=2, workers=1)
    from_folder = infer(scene_dir, tmp_path / "folder", **options)
    result = ipr_shapes.infer(made, tmp_path / "arrays", **options)
    assert result.posteriors and result.run.scene is made
    written = [load_result(from_folder), load_result(tmp_path / "arrays")]
    assert [len(r.objects) for r in written] == [len(result.posteriors)] * 2
    for a, b in zip(written[0].objects, written[1].objects, strict=True):
        assert a.probability == b.probability
        assert [h.probability for h in a.hypotheses] == [h.probability for h in b.hypotheses]
        assert np.array_equal(a.load_mesh().vertices, b.load_mesh().vertices)
    provenance = json.loads((tmp_path / "arrays" / "result.json").read_text())["provenance"]
    assert provenance["scene"] == "<arrays>" and provenance["seed"] == 3
    # The result in memory writes the same folder again.
    again = ipr_shapes.save_result(result, tmp_path / "again")
    assert load_result(again).objects[0].probability == written[1].objects[0].probability
