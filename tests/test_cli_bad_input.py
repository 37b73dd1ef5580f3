"""Bad input through the ``ipr`` command (issue 31): each finding fails clearly, with exit 2, one
line on stderr, no traceback and no output, in bounded time."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from ipr_shapes.cli import EXIT_INPUT_ERROR, main


def _edit(path: Path, change) -> None:
    document = json.loads(path.read_text())
    change(document)
    path.write_text(json.dumps(document))


def _refused(capsys, args: list[str], *parts: str) -> str:
    assert main(args) == EXIT_INPUT_ERROR
    captured = capsys.readouterr()
    error = captured.err.strip()
    assert len(error.splitlines()) == 1 and "Traceback" not in error, error
    for part in parts:
        assert part in error, error
    return error


def _run(args: list[str], timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "ipr_shapes", *args], capture_output=True, text=True, timeout=timeout
    )


def _set_push(key, value):
    return lambda actions: actions["pushes"][0].update({key: value})


@pytest.mark.parametrize(
    ("change", "parts"),
    [
        (_set_push("speed_m_s", 1e-9), ["speed_m_s 1e-09 m/s is implausible", "0.001-1 m/s"]),
        (_set_push("distance_m", 50.0), ["distance_m 50 m is implausible"]),
        (_set_push("distance_m", "0.08"), ["distance_m' must be a number"]),
        (_set_push("start_m", [True, 0, 0.1]), ["start_m' must be a list of 3 numbers"]),
        (_set_push("after_frame", 7), ["after_frame 7 names a frame that does not exist"]),
    ],
)
def test_implausible_pushes_are_refused_by_check(scene_dir: Path, capsys, change, parts):
    _edit(scene_dir / "actions.json", change)
    _refused(capsys, ["check", str(scene_dir)], "actions.json", *parts)


def test_a_slow_push_replays_in_bounded_time():
    """A push at the slowest plausible speed is simulated for at most push_max_s."""
    from ipr_shapes.physics import PhysicsConfig, build_world
    from ipr_shapes.scene import Push, Pusher

    from .box_scene import box_mesh

    config = PhysicsConfig()
    world = build_world([], (), config, pusher=Pusher())
    push = Push(0, 1, np.array([0.0, 0.0, 0.1]), np.array([1.0, 0, 0]), 1.0, 1e-3)
    started = time.perf_counter()
    assert world.push(push) == pytest.approx(1.0)
    assert world.data.time <= config.push_max_s + config.settle_max_s + 0.1
    assert time.perf_counter() - started < 5
    assert box_mesh  # the helper module imports (used by other tests)


@pytest.mark.parametrize(
    ("change", "parts"),
    [
        (lambda c: c["0"].update(cam_K=[150, 0, 1e7, 0, 150, 59.5, 0, 0, 1]), ["principal point"]),
        (lambda c: c["0"].update(cam_K=[1e6, 0, 79.5, 0, 1e6, 59.5, 0, 0, 1]), ["fx = 1e+06"]),
        (lambda c: c["0"].update(cam_K=["150", 0, 79.5, 0, 150, 59.5, 0, 0, 1]), ["9 numbers"]),
        (lambda c: c["0"].update(depth_scale=True), ["depth_scale' must be a number"]),
        (lambda c: c["0"].update(depth_scale=1e-300), ["depth_scale 1e-300", "implausible"]),
        (lambda c: c["0"].update(cam_R_w2c=np.eye(3).ravel().tolist()), ["world z does not"]),
        (lambda c: c["0"].update(cam_t_w2c=[0, 0, 1e12]), ["from the world origin"]),
        (lambda c: c.update({"00": c["0"]}), ['keys "0" and "00" both name frame 0']),
        (lambda c: c.update({"-1": c["0"]}), ["key '-1' is not a frame id"]),
    ],
)
def test_implausible_cameras_are_refused_by_check(scene_dir: Path, capsys, change, parts):
    _edit(scene_dir / "scene_camera.json", change)
    _refused(capsys, ["check", str(scene_dir)], "scene_camera.json", *parts)


def test_a_huge_png_is_refused_from_its_header(scene_dir: Path, capsys):
    """A PNG header claiming 100000 x 100000 pixels (one tiny compressed row): refused before
    decoding, in well under a second."""
    path = scene_dir / "depth" / "000000.png"

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return len(data).to_bytes(4, "big") + body + zlib.crc32(body).to_bytes(4, "big")

    header = (100_000).to_bytes(4, "big") * 2 + bytes([16, 0, 0, 0, 0])
    # (and 9000 x 9000: below PIL's own decompression-bomb limit, above ours)
    data = chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * 10)) + chunk(b"IEND", b"")
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + data)
    started = time.perf_counter()
    _refused(capsys, ["check", str(scene_dir)], "000000.png", "at most 8192 pixels a side")
    header = (9000).to_bytes(4, "big") * 2 + bytes([16, 0, 0, 0, 0])
    data = chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * 10)) + chunk(b"IEND", b"")
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + data)
    _refused(capsys, ["check", str(scene_dir)], "000000.png", "is 9000x9000 pixels")
    assert time.perf_counter() - started < 5


def test_a_fifo_or_folder_in_place_of_a_file_is_named(scene_dir: Path):
    frame = scene_dir / "rgb" / "000001.png"
    frame.unlink()
    os.mkfifo(frame)
    completed = _run(["check", str(scene_dir)], timeout=60)  # used to block forever
    assert completed.returncode == EXIT_INPUT_ERROR
    assert "is a named pipe (FIFO), not a regular file" in completed.stderr
    frame.unlink()
    frame.mkdir()
    camera = scene_dir / "scene_camera.json"
    camera.rename(scene_dir / "cam.json")
    camera.mkdir()
    completed = _run(["check", str(scene_dir)])
    assert completed.returncode == EXIT_INPUT_ERROR
    assert "scene_camera.json is a folder, not a regular file" in completed.stderr
    assert "Traceback" not in completed.stderr


def test_deeply_nested_json_is_refused_without_traceback(scene_dir: Path):
    (scene_dir / "actions.json").write_text("[" * 100_000 + "]" * 100_000)
    completed = _run(["check", str(scene_dir)])
    assert completed.returncode == EXIT_INPUT_ERROR
    assert "nested too deeply" in completed.stderr and "Traceback" not in completed.stderr


@pytest.mark.parametrize("seed", ["-1", "1.5", str(2**64)])
def test_a_bad_seed_is_refused(scene_dir: Path, tmp_path: Path, capsys, seed: str):
    with pytest.raises(SystemExit) as exit_info:
        main(["infer", str(scene_dir), "-o", str(tmp_path / "r"), "--seed", seed])
    assert exit_info.value.code == 2
    assert "--seed" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_output_in_the_current_folder_or_a_full_disk_is_refused(
    scene_dir: Path, tmp_path: Path, capsys, monkeypatch
):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    for out in (".", ".."):
        _refused(capsys, ["segment", str(scene_dir), "-o", out, "--overwrite"], "current folder")
    import shutil

    from ipr_shapes import atomic

    real = shutil.disk_usage
    monkeypatch.setattr(
        atomic.shutil, "disk_usage", lambda p: real(p)._replace(free=atomic.MIN_FREE_BYTES - 1)
    )
    _refused(capsys, ["segment", str(scene_dir), "-o", str(tmp_path / "seg")], "MiB free")
    assert not (tmp_path / "seg").exists()


def test_stale_staging_of_a_killed_run_is_cleaned_and_a_live_ones_kept(tmp_path: Path):
    from ipr_shapes.atomic import STAGING_TAG, _owner_tag, staged_directory

    target = tmp_path / "result"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = _owner_tag().rsplit(".", 1)[0]
    stale = tmp_path / f".result.{STAGING_TAG}.{host}.{dead.pid}.abc123"
    live = tmp_path / f".result.{STAGING_TAG}.{host}.{os.getppid()}.def456"
    other_host = tmp_path / f".result.{STAGING_TAG}.elsewhere.{dead.pid}.0"
    unrelated = tmp_path / ".result.user-notes"
    for folder in (stale, live, other_host, unrelated):
        folder.mkdir()
    with staged_directory(target) as staging:
        (staging / "x").write_text("x")
    assert not stale.exists()
    assert live.exists() and other_host.exists() and unrelated.exists()
    assert (target / "x").read_text() == "x"


@pytest.mark.slow
def test_a_killed_runs_staging_folder_is_cleaned_by_the_next_run(scene_dir: Path, tmp_path):
    """A run killed while writing leaves its staging folder; the next run into the same
    target removes it. The killed run is a process that stages the target the way every
    command writes its output (``staged_directory``) and is killed (SIGKILL) mid-write: racing
    a real ``segment`` run's kill against its short write stage was flaky (a small scene's
    write can start and finish between two polls)."""
    out = tmp_path / "seg"
    killed = subprocess.run(
        [
            sys.executable,
            "-c",
            "import os, signal, sys; from pathlib import Path; "
            "from ipr_shapes.atomic import staged_directory\n"
            "with staged_directory(Path(sys.argv[1])) as staging:\n"
            "    (staging / 'labels_000000.png').write_bytes(b'half')\n"
            "    os.kill(os.getpid(), signal.SIGKILL)",
            str(out),
        ],
        capture_output=True,
        timeout=120,
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert [p for p in tmp_path.iterdir() if "ipr-staging" in p.name]
    assert not out.exists()
    assert main(["segment", str(scene_dir), "-o", str(out)]) == 0
    assert not [p for p in tmp_path.iterdir() if "ipr-staging" in p.name]
    assert out.is_dir()


@pytest.mark.slow
def test_warnings_go_to_stderr_not_stdout(tmp_path: Path):
    from ipr_shapes.camera import look_at
    from ipr_shapes.scene import Frame, write_scene

    K = np.array([[150.0, 0, 79.5], [0, 150.0, 59.5], [0, 0, 1]])
    world_from_camera = look_at(np.array([0.0, -0.45, 0.45]), np.zeros(3))
    u, v = np.meshgrid(np.arange(160), np.arange(120))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((120, 160))], -1)
    depth = (-world_from_camera[2, 3] / (rays @ world_from_camera[:3, :3].T)[..., 2]).astype(
        np.float32
    )
    scene = write_scene(
        tmp_path / "empty",
        [Frame(0, np.full((120, 160, 3), 120, np.uint8), depth, K, world_from_camera)],
    )
    completed = _run(["infer", str(scene), "-o", str(tmp_path / "r"), "--workers", "1"], 300)
    assert completed.returncode == 0, completed.stderr
    assert "no object found in frame 0" in completed.stderr
    assert "no object found" not in completed.stdout
    assert completed.stdout.startswith(str(tmp_path / "r"))


def test_nothing_segmented_where_much_lies_off_the_planes_is_an_error(tmp_path: Path):
    """With the support lost (a wrong support choice), an empty first frame whose points lie
    off every plane is refused, naming the frame and the fixes; an empty table passes."""
    import dataclasses

    from ipr_shapes.errors import SceneError
    from ipr_shapes.perception import check_objects_found, perceive_scene
    from ipr_shapes.scene import load_scene, write_scene

    from .conftest import make_frames

    frame = make_frames(1)[0]
    flat = dataclasses.replace(frame, depth_m=frame.depth_m.copy())
    scene = load_scene(write_scene(tmp_path / "s", [flat], write_poses=False))
    perception = perceive_scene(scene)
    empty = dataclasses.replace(perception, objects=[()], planes=[perception.planes[0]])
    check_objects_found(scene, empty)  # everything on the support: an empty table
    lost = dataclasses.replace(empty, planes=[()])
    with pytest.raises(SceneError, match="frame 0: no object found although") as error:
        check_objects_found(scene, lost)
    assert "--up X Y Z" in str(error.value)


def test_frames_option_chooses_frames_and_refuses_a_push_half_chosen(scene_dir: Path, capsys):
    for folder in ("rgb", "depth"):
        (scene_dir / folder / "000001.png").rename(scene_dir / folder / "000005.png")
    _edit(scene_dir / "scene_camera.json", lambda c: c.update({"5": c.pop("1")}))
    _edit(scene_dir / "actions.json", _set_push("after_frame", 5))
    assert main(["check", str(scene_dir)]) == 0
    output = capsys.readouterr().out
    assert "frames: 2 (ids 0, 5;" in output and "frame 0->5" in output
    assert main(["check", str(scene_dir), "--frames", "0"]) == 0
    assert "pushes: 0" in capsys.readouterr().out
    assert main(["check", str(scene_dir), "--frames", "5"]) == 0  # the push came before
    capsys.readouterr()
    import shutil

    for folder in ("rgb", "depth"):
        shutil.copy(scene_dir / folder / "000005.png", scene_dir / folder / "000007.png")
    _edit(scene_dir / "scene_camera.json", lambda c: c.update({"7": c["5"]}))
    _refused(capsys, ["check", str(scene_dir), "--frames", "0,7"], "frame 5 is not chosen")
    _refused(capsys, ["check", str(scene_dir), "--frames", "0-4"], "frames [1, 2, 3, 4] are not")
    with pytest.raises(SystemExit):
        main(["check", str(scene_dir), "--frames", "5-0"])
    assert "empty range" in capsys.readouterr().err


@pytest.mark.slow
def test_eval_refuses_implausible_ground_truth_and_results(tmp_path: Path, capsys):
    from ipr_shapes.synth import SynthConfig, generate_scene

    scene = generate_scene(tmp_path / "scenes", kind="static", seed=3,
                           config=SynthConfig(width=160, height=120))  # fmt: skip
    result = tmp_path / "gt"
    assert main(["ground-truth", str(scene), "-o", str(result)]) == 0
    capsys.readouterr()
    gt, info = scene / "scene_gt.json", scene / "scene_gt_info.json"
    original_gt, original_info = gt.read_text(), info.read_text()
    for path, change, part in (
        (gt, lambda g: g["0"][0].update(obj_id="abc"), "obj_id 'abc' is not an object id"),
        (gt, lambda g: g["0"][0].update(obj_id=True), "obj_id True"),
        (gt, lambda g: g["0"][0].update(cam_t_m2c=[0, 0, 1e12]), "1e+09 m from the camera"),
        (info, lambda g: g["0"][0].update(px_count_visib=1e308), "px_count_visib"),
    ):
        _edit(path, change)
        _refused(capsys, ["eval", str(scene), str(result)], path.name, part)
        gt.write_text(original_gt)
        info.write_text(original_info)
    import trimesh

    mesh_path = next((result / "objects").rglob("best.ply"))
    mesh = trimesh.load(mesh_path, process=False)
    mesh.apply_translation([1e6, 0, 0])
    mesh.export(mesh_path)
    _refused(capsys, ["eval", str(scene), str(result)], "1e+06 m from the world origin")
