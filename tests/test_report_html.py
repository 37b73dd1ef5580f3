"""``report.html`` (``ipr_shapes.report_html``): a self-contained page with the frames and pushes, the
segmentation with the result's ids, a 3-D view, hypotheses, timings and settings; the result's
own ids and labels; and, slow, the page rendered by headless Chromium."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from ipr_shapes.cli import EXIT_INPUT_ERROR, main
from ipr_shapes.errors import ResultError
from ipr_shapes.perception.output import label_png, palette
from ipr_shapes.report_html import REPORT_FILE, result_labels, write_report
from ipr_shapes.result import load_occupancy, load_result, write_result
from ipr_shapes.scene import frames_digest, load_scene

BOX = ((-0.03, -0.03, 0.0), (0.03, 0.03, 0.03))  # the conftest scene's bump, metres


def _box(low, high):
    low, high = np.asarray(low, float), np.asarray(high, float)
    mesh = trimesh.creation.box(extents=high - low)
    mesh.apply_translation((low + high) / 2)
    return mesh


def _bump_labels(scene, object_id: int) -> dict[str, bytes]:
    """labels/ of every frame: ``object_id`` on the pixels of the bump's top."""
    files = {}
    for frame in scene.frames:
        points = frame.points_world()
        top = (np.abs(points[..., 0]) < 0.028) & (np.abs(points[..., 1]) < 0.028)
        top &= (points[..., 2] > 0.02) & (frame.depth_m > 0)
        files[f"labels/{frame.index:06d}.png"] = label_png(np.where(top, object_id, 0))
    return files


def _sorted(points: np.ndarray) -> np.ndarray:
    return points[np.lexsort(points.T[::-1])]


def _seen(scene_dir: Path) -> np.ndarray:
    """The scene's own world points (N, 3) of frame 0's labelled pixels (the bump's top)."""
    frame = load_scene(scene_dir).frames[0]
    labels = np.asarray(Image.open(io.BytesIO(_bump_labels(load_scene(scene_dir), 5)[
        "labels/000000.png"])))  # fmt: skip
    return _sorted(frame.points_world()[labels == 5].astype(np.float32))


def _result(
    scene_dir: Path, out: Path, shift=(0.0, 0.0, 0.0), labels=True, recorded: dict | None = None
) -> Path:
    """A result of the conftest scene: object 5 (the bump, two hypotheses), written in a world
    frame moved by ``shift`` (m) from the scene's; ``recorded`` adds provenance keys."""
    scene = load_scene(scene_dir)
    moved = np.eye(4)
    moved[:3, 3] = shift
    best = _box(*BOX).apply_translation(shift)
    taller = _box(BOX[0], (0.03, 0.03, 0.05)).apply_translation(shift)
    return write_result(
        out,
        "collision-checker",
        {frame.index: moved @ frame.world_from_camera for frame in scene.frames},
        [(best, [(best, 0.7), (taller, 0.3)], 0.7)],
        {"segmentation": 1.5, "total": 2.0},
        {
            "provenance": {"scene": str(scene_dir), "config_file": "config.toml", "seed": 3}
            | (recorded or {}),
            "objects_summary": [{"object_id": 5, "inference": "exact", "carved": False}],
        },
        extra_files={"config.toml": b"[inference]\nbudget_per_object_s = 1.75\n"}
        | (_bump_labels(scene, 5) if labels else {}),
        ids=[5],
    )


def _page_data(path: Path) -> dict:
    text = path.read_text(encoding="utf-8")
    found = re.search(r'<script type="application/json" id="ipr-data">(.*?)</script>', text, re.S)
    assert found, "the page's data block is missing"
    return json.loads(found.group(1))


def _picture(url: str) -> np.ndarray:
    assert url.startswith("data:image/jpeg;base64,")
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))))


def _decode(text: str, dtype) -> np.ndarray:
    return np.frombuffer(base64.b64decode(text), dtype=dtype)


def test_result_labels_give_every_frame_the_result_ids() -> None:
    """Label values under a result object's frame-0 pixels take its id in every frame (a joined
    piece, 2, takes its object's id, 1); objects not in the result become 0."""
    frame0 = np.array([[1, 1, 2, 0], [3, 3, 0, 0]])
    frame1 = np.array([[0, 2, 2, 1], [0, 3, 3, 4]])

    class Piece:
        def __init__(self, object_id, pixels):
            self.id, self.pixels = object_id, np.array(pixels)

    objects = [Piece(1, [0, 1, 2]), Piece(3, [4, 5])]
    mapped = result_labels([frame0, frame1], objects, ids=[1])
    assert mapped[0].tolist() == [[1, 1, 1, 0], [0, 0, 0, 0]]
    assert mapped[1].tolist() == [[0, 1, 1, 1], [0, 0, 0, 0]]
    both = result_labels([frame0, frame1], objects, ids=[1, 3])
    assert both[1].tolist() == [[0, 1, 1, 1], [0, 3, 3, 0]]


def test_results_keep_the_ids_they_are_given_and_finish_inside_the_atomic_step(tmp_path):
    box = _box(*BOX)
    seen = []

    def finish(staging: Path) -> None:
        seen.append(sorted(p.name for p in staging.iterdir()))
        (staging / "extra.txt").write_text("made from the written result")

    out = write_result(tmp_path / "r", "m", np.eye(4), [(box, []), (box, [])], ids=[4, 9],
                       finish=finish)  # fmt: skip
    assert [obj.id for obj in load_result(out).objects] == [4, 9]
    assert (out / "objects/9/best.ply").is_file() and (out / "extra.txt").is_file()
    assert sorted(load_occupancy(out).objects) == [4, 9]
    assert "result.json" in seen[0] and "occupancy.npz" in seen[0]
    with pytest.raises(ValueError, match="distinct"):
        write_result(tmp_path / "dup", "m", np.eye(4), [(box, []), (box, [])], ids=[4, 4])

    def broken(staging: Path) -> None:
        raise RuntimeError("report failed")

    with pytest.raises(RuntimeError):
        write_result(tmp_path / "failed", "m", np.eye(4), [(box, [])], finish=broken)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r"]  # nothing half-written


def test_report_is_one_self_contained_page_of_the_result(scene_dir: Path, tmp_path: Path):
    result = _result(scene_dir, tmp_path / "result")
    page = write_report(result)
    assert page == result / REPORT_FILE
    text = page.read_text(encoding="utf-8")
    # Nothing to fetch at view time: no external scripts, styles, images or links.
    assert not re.search(r"<script[^>]+src=|<link\b|url\(|https?://", text)
    assert all(src.startswith("data:image/") for src in re.findall(r'src="([^"]*)"', text))
    data = _page_data(page)
    (obj,) = data["objects"]
    assert obj["id"] == 5 and obj["colour"] == "#" + palette([5])[0].tobytes().hex()
    assert obj["probability"] == pytest.approx(0.7) and obj["inference"] == "exact"
    assert [h["probability"] for h in obj["hypotheses"]] == pytest.approx([0.7, 0.3])
    assert [h["volume_m3"] for h in obj["hypotheses"]] == pytest.approx([1.08e-4, 1.8e-4])
    assert data["timing_s"] == {"segmentation": 1.5, "total": 2.0}
    assert data["provenance"]["seed"] == 3 and "budget_per_object_s" in data["config_toml"]
    # 3-D view: the inferred surface spans the box; the observed points lie on its top face.
    vertices = _decode(obj["vertices"], np.float32).reshape(-1, 3)
    assert np.allclose(vertices.min(axis=0), BOX[0], atol=3e-3)
    assert np.allclose(vertices.max(axis=0), BOX[1], atol=3e-3)
    assert _decode(obj["faces"], np.uint32).max() < len(vertices)
    points = _decode(obj["points"], np.float32).reshape(-1, 3)
    assert obj["points_count"] == len(points) == len(_seen(scene_dir))
    assert np.allclose(_sorted(points), _seen(scene_dir), atol=1e-6)
    # Frames: each with its segmentation (the result's ids); the push drawn on frame 0 only.
    assert [f["frame"] for f in data["frames"]] == [0, 1]
    assert all(f["ids"] == [5] and f["segmentation"] for f in data["frames"])
    assert [f["pushes_drawn"] for f in data["frames"]] == [1, 0]
    (push,) = data["pushes"]
    scene = load_scene(scene_dir)
    frame = scene.frames[0]
    middle = (np.asarray(push["start"]) + np.asarray(push["end"])) / 2
    camera = np.linalg.inv(frame.world_from_camera) @ np.append(middle, 1.0)
    u, v = (frame.K @ camera[:3])[:2] / camera[2]
    row, col = round(v), round(u)
    patch = [_picture(f["input"])[row - 1 : row + 2, col - 1 : col + 2] for f in data["frames"]]
    assert patch[0].min() > 190  # the white arrow over frame 0's noise
    assert patch[1].mean() < 190  # frame 1 has no push after it


def test_pushes_and_points_follow_the_results_world_frame(scene_dir: Path, tmp_path: Path):
    """A result written in another world frame (its world_from_camera is authoritative): the
    pushes and observed points move with it, so they line up with its shapes."""
    shift = (1.0, -0.5, 0.2)
    data = _page_data(write_report(_result(scene_dir, tmp_path / "moved", shift=shift)))
    scene = load_scene(scene_dir)
    assert data["pushes"][0]["start"] == pytest.approx(scene.pushes[0].start_m + shift)
    points = _decode(data["objects"][0]["points"], np.float32).reshape(-1, 3)
    assert np.allclose(_sorted(points), _seen(scene_dir) + shift, atol=1e-6)


def test_report_command_remakes_the_page_and_refuses_bad_input(
    scene_dir: Path, tmp_path: Path, capsys
):
    result = _result(scene_dir, tmp_path / "result")
    listing = sorted(p.name for p in result.iterdir())
    elsewhere = tmp_path / "pages" / "page.html"
    assert main(["report", str(result), "-o", str(elsewhere)]) == 0
    assert elsewhere.is_file() and sorted(p.name for p in result.iterdir()) == listing
    assert main(["report", str(result), "-o", str(elsewhere)]) == EXIT_INPUT_ERROR
    assert "already exists" in capsys.readouterr().err
    # The scene moved away: one line naming the fix, nothing written.
    moved = tmp_path / "moved-scene"
    shutil.move(scene_dir, moved)
    assert main(["report", str(result)]) == EXIT_INPUT_ERROR
    error = capsys.readouterr().err.strip()
    assert "--scene" in error and len(error.splitlines()) == 1
    assert not (result / REPORT_FILE).exists()
    assert main(["report", str(result), "--scene", str(moved)]) == 0
    assert (result / REPORT_FILE).is_file()
    # A label image that does not fit the scene's frames.
    (result / "labels" / "000001.png").write_bytes(label_png(np.zeros((5, 5), np.int64)))
    with pytest.raises(ResultError, match="5x5"):
        write_report(result, tmp_path / "x.html", scene=moved)
    assert not (tmp_path / "x.html").exists()


def test_a_result_without_labels_still_gets_a_page(scene_dir: Path, tmp_path: Path):
    data = _page_data(write_report(_result(scene_dir, tmp_path / "old", labels=False)))
    assert not data["has_labels"] and "segmentation" not in data["frames"][0]
    assert data["objects"][0]["points_count"] == 0 and data["objects"][0]["vertices"]


def test_a_result_of_another_writer_needs_its_scene_named(scene_dir: Path, tmp_path: Path, capsys):
    """No provenance (or one of another shape): ``ipr-shapes report`` asks for --scene in one line;
    further keys of unexpected shapes are left out of the page, not a crash."""
    box = _box(*BOX)
    odd = {"provenance": "by hand", "objects_summary": [{"object_id": "x"}], "inference": [1]}
    frames = {frame.index: frame.world_from_camera for frame in load_scene(scene_dir).frames}
    result = write_result(tmp_path / "other", "by-hand", frames, [(box, [])], extra=odd)
    assert main(["report", str(result)]) == EXIT_INPUT_ERROR
    error = capsys.readouterr().err.strip()
    assert "names no scene" in error and "--scene" in error and len(error.splitlines()) == 1
    assert main(["report", str(result), "--scene", str(scene_dir)]) == 0
    data = _page_data(result / REPORT_FILE)
    assert data["provenance"] == {} and data["inference"] == {} and data["config_toml"] is None
    assert data["objects"][0]["id"] == 0 and data["objects"][0]["inference"] is None


def test_report_finds_the_scene_its_result_records_and_refuses_another(
    scene_dir: Path, tmp_path: Path, capsys
):
    """result.json records its scene's folder, frames and their digest (as ``ipr-shapes infer``
    does, tests/test_provenance.py): ``ipr-shapes report RESULT`` uses that folder when it
    holds those frames, ``--scene`` names a copy elsewhere, and a folder holding other
    captures or lacking the frames is refused in one line naming the fix, nothing written."""
    frames = load_scene(scene_dir).frames
    recorded = {"frames": [0, 1], "frames_digest": frames_digest(frames)}
    result = _result(scene_dir, tmp_path / "result", recorded=recorded)
    copy = shutil.copytree(scene_dir, tmp_path / "copy")
    assert main(["report", str(result)]) == 0  # the recorded folder
    assert (result / REPORT_FILE).is_file()
    assert main(["report", str(result), "--scene", str(copy), "-o", str(tmp_path / "a.html")]) == 0
    # Another capture in the recorded folder: frame 1's depth changed.
    depth = scene_dir / "depth" / "000001.png"
    image = np.array(Image.open(depth))
    image[image > 0] += 7
    Image.fromarray(image).save(depth)
    for scene in ([], ["--scene", str(scene_dir)]):
        assert main(["report", str(result), *scene, "-o", str(tmp_path / "b.html")]) == 2
        error = capsys.readouterr().err.strip()
        assert "is not the scene" in error and "--scene" in error and len(error.splitlines()) == 1
        assert not (tmp_path / "b.html").exists()
    # A folder without the recorded frame 1.
    shutil.rmtree(scene_dir)
    cameras = json.loads((copy / "scene_camera.json").read_text())
    lacking = shutil.copytree(copy, tmp_path / "lacking")
    (lacking / "scene_camera.json").write_text(json.dumps({"0": cameras["0"]}))
    for name in ("rgb", "depth"):
        next((lacking / name).glob("000001.*")).unlink()
    assert main(["report", str(result), "--scene", str(lacking)]) == 2
    error = capsys.readouterr().err.strip()
    assert "lacks frames [0, 1]" in error and "--scene" in error
    # The recorded folder is gone: the error says to name where it is now.
    assert main(["report", str(result)]) == 2
    assert "is not there" in capsys.readouterr().err
    assert main(["report", str(result), "--scene", str(copy), "-o", str(tmp_path / "c.html")]) == 0


# --------------------------------------------------------------------------------------------
# In a browser (slow)

#: The 3-D view's background (the page's clear colour), RGB.
BACKGROUND = np.array([244, 245, 247])


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    pytest.skip("chromium is not installed (Debian: apt-get install chromium; .ci/run does)")


def _browse(browser: str, page: Path, *args: str) -> subprocess.CompletedProcess:
    command = [
        browser, "--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader", "--hide-scrollbars", "--window-size=1280,2400",
        "--virtual-time-budget=10000", "--enable-logging=stderr", "--v=0", *args,
        page.resolve().as_uri(),
    ]  # fmt: skip
    return subprocess.run(command, capture_output=True, text=True, timeout=180, check=True)


@pytest.mark.slow
def test_report_of_a_real_run_renders_in_headless_chromium(tmp_path: Path):
    """``ipr-shapes infer`` on a pushed scene, then Chromium: the page's script ran to its end with no
    error or console message, and the 3-D view shows the objects (their colours fill part of
    the canvas). The result's ids are ``ipr-shapes segment``'s."""
    from ipr_shapes.synth import SynthConfig, generate_scene

    browser = _chromium()
    scene = generate_scene(
        tmp_path / "scenes",
        kind="dynamic",
        seed=4,
        arrangement="table",
        config=SynthConfig(width=320, height=240),
    )
    out = tmp_path / "result"
    assert main(["infer", str(scene), "-o", str(out), "--samples", "2", "--workers", "1"]) == 0
    result = load_result(out)
    page = out / REPORT_FILE
    assert page.is_file() and page.stat().st_size < 3_000_000
    # The result's ids and labels are the segmentation's (occluded pieces joined to theirs).
    assert main(["segment", str(scene), "-o", str(tmp_path / "seg")]) == 0
    segment = np.asarray(Image.open(tmp_path / "seg" / "labels" / "000000.png"))
    mine = np.asarray(Image.open(out / "labels" / "000000.png"))
    ids = {obj.id for obj in result.objects}
    assert ids and ids <= set(np.unique(segment).tolist())
    assert set(np.unique(mine).tolist()) - {0} == ids
    for object_id in ids:
        assert np.all(mine[segment == object_id] == object_id)

    dom = _browse(browser, page, "--dump-dom")
    assert 'data-ipr-status="ok"' in dom.stdout, dom.stdout[:2000]
    assert "data-ipr-errors" not in dom.stdout
    canvas = re.search(r'<canvas id="view"[^>]*data-rect="([^"]+)"', dom.stdout)
    assert canvas, "the 3-D view did not record where it was drawn"
    left, top, width, height = (
        round(v) for v in json.loads(canvas.group(1).replace("&quot;", '"'))
    )
    shot = tmp_path / "report.png"
    run = _browse(browser, page, f"--screenshot={shot}")
    console = [
        line
        for line in (dom.stderr + run.stderr).splitlines()
        if ":CONSOLE" in line and "GL Driver Message" not in line
    ]
    assert not console, console
    view = np.asarray(Image.open(shot).convert("RGB"))[top + 4 : top + height - 4,
                                                        left + 4 : left + width - 4]  # fmt: skip
    assert view.shape[0] > 400 and view.shape[1] > 800
    drawn = np.abs(view.astype(int) - BACKGROUND).max(axis=2) > 12
    coloured = np.ptp(view.astype(int), axis=2) > 60  # the objects' colours, not grid or lines
    assert drawn.mean() > 0.05, drawn.mean()
    assert coloured.mean() > 0.01, coloured.mean()
    for object_id in ids:  # every object's colour is somewhere in the view
        colour = palette([object_id])[0].astype(int)
        near = np.abs(view.astype(int) - colour).max(axis=2) < 40
        shaded = np.abs(view.astype(int) - (0.8 * colour).astype(int)).max(axis=2) < 40
        assert (near | shaded).sum() > 20, object_id
    # Without WebGL the page says so instead of failing silently; the rest is still shown.
    bare = _browse(browser, page, "--dump-dom", "--disable-webgl").stdout
    assert 'data-ipr-status="no-webgl"' in bare and "offers no WebGL" in bare
    assert bare.count("<figure") == len(result.world_from_camera)
