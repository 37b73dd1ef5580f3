"""``ipr-shapes batch``: many scenes, one result each, resumable, failures reported, scores."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ipr_shapes.batch import find_scenes
from ipr_shapes.cli import EXIT_INPUT_ERROR, main
from ipr_shapes.errors import IprError


def test_scenes_are_found_in_folders_of_scenes_and_globs(scene_dir: Path, tmp_path: Path):
    assert find_scenes([scene_dir]) == [scene_dir]
    assert find_scenes([scene_dir.parent]) == [scene_dir]
    assert find_scenes([str(scene_dir.parent / "sc*")]) == [scene_dir]
    assert find_scenes([scene_dir, scene_dir.parent]) == [scene_dir]  # each once
    with pytest.raises(IprError, match="no scene folder"):
        find_scenes([tmp_path / "nothing-here"])
    twin = tmp_path / "elsewhere" / scene_dir.name
    twin.mkdir(parents=True)
    (twin / "scene_camera.json").write_text("{}")
    with pytest.raises(IprError, match="same folder name"):
        find_scenes([scene_dir, twin])


def test_a_batch_output_inside_a_scene_is_refused(scene_dir: Path, capsys):
    before = sorted(p.name for p in scene_dir.iterdir())
    assert main(["batch", str(scene_dir), "-o", str(scene_dir / "out")]) == EXIT_INPUT_ERROR
    assert "would replace the input" in capsys.readouterr().err
    assert sorted(p.name for p in scene_dir.iterdir()) == before


@pytest.mark.slow
@pytest.mark.parametrize("jobs", ["1", "2"])
def test_a_batch_runs_scores_resumes_and_reports_failures(tmp_path: Path, jobs: str, capsys):
    scenes = tmp_path / "scenes"
    synth = ["synth", str(scenes), "--kind", "static", "--seed", "5", "--count", "2"]
    assert main([*synth, "--width", "320", "--height", "240"]) == 0
    broken = scenes / "static_broken"
    broken.mkdir()
    (broken / "scene_camera.json").write_text("{not json")
    out = tmp_path / "out"
    run = ["batch", str(scenes), "-o", str(out), "--method", "collision-checker", "--jobs", jobs]
    assert main(run) == 1  # one scene failed, the others ran
    summary = json.loads((out / "summary.json").read_text())
    status = {Path(o["scene"]).name: o for o in summary["outcomes"]}
    assert [status[f"static_00000{i}"]["status"] for i in (0, 1)] == ["done", "done"]
    for i in (0, 1):
        row = status[f"static_00000{i}"]
        assert row["objects"] >= 1 and 0.0 < row["object_iou"] <= 1.0
        assert (out / f"static_00000{i}" / "result.json").is_file()
    assert status["static_broken"]["status"] == "failed"
    assert "scene_camera.json" in status["static_broken"]["error"]
    assert not (out / "static_broken").exists()  # nothing half-written
    assert "static_broken" in (out / "summary.md").read_text()
    # Rerun: finished results are kept, not recomputed; the fixed scene now runs.
    broken.rename(tmp_path / "set-aside")
    stamp = (out / "static_000000" / "result.json").stat().st_mtime_ns
    assert main(run) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert {o["status"] for o in summary["outcomes"]} == {"kept"}
    assert (out / "static_000000" / "result.json").stat().st_mtime_ns == stamp
    assert "0 run, 2 kept, 0 failed" in capsys.readouterr().out


@pytest.mark.slow
def test_killing_a_batch_ends_its_workers_without_tracebacks(tmp_path: Path):
    """SIGKILL of `ipr-shapes batch --jobs 2` mid-run: its pool workers end with it, silently (no
    BrokenPipe or EOFError traceback on the shared stderr), and leave no process behind."""
    import os
    import signal
    import subprocess
    import sys
    import time

    scenes = tmp_path / "scenes"
    synth = ["synth", str(scenes), "--kind", "static", "--seed", "5", "--count", "2"]
    assert main([*synth, "--width", "320", "--height", "240"]) == 0
    command = [sys.executable, "-m", "ipr_shapes", "batch", str(scenes), "-o", str(tmp_path / "out"),
               "--jobs", "2", "--time-budget", "60"]  # fmt: skip
    errors = tmp_path / "stderr.txt"
    with errors.open("wb") as stderr:
        parent = subprocess.Popen(
            command, stdout=subprocess.DEVNULL, stderr=stderr, start_new_session=True
        )
    deadline = time.monotonic() + 120
    # Wait until both pool workers run (the parent's children started by multiprocessing),
    # give them a moment inside their scenes, then kill the parent.
    while time.monotonic() < deadline and parent.poll() is None:
        if len(_pool_workers(parent.pid)) >= 2:
            time.sleep(3.0)
            break
        time.sleep(0.2)
    assert parent.poll() is None, "the batch ended before it could be killed"
    group = os.getpgid(parent.pid)
    parent.send_signal(signal.SIGKILL)
    parent.wait(timeout=10)
    # Every process of the batch (workers, the resource tracker) ends within seconds.
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            os.killpg(group, 0)
        except ProcessLookupError:
            break
        time.sleep(0.2)
    else:
        os.killpg(group, signal.SIGKILL)
        pytest.fail("processes of the killed batch were still running 30 s later")
    text = errors.read_text(errors="replace")
    assert "Traceback" not in text and "BrokenPipe" not in text, text


def _pool_workers(pid: int) -> list[int]:
    """The pids of the multiprocessing processes (pool workers, a fork server; not the resource
    tracker) among the descendants of process ``pid``."""
    parent_of, command_of = {}, {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            command_of[int(entry.name)] = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        parent_of[int(entry.name)] = int(fields[1])

    def descends(child: int) -> bool:
        while child in parent_of and child > 1:
            child = parent_of[child]
            if child == pid:
                return True
        return False

    return [
        child
        for child, command in command_of.items()
        if (b"spawn_main" in command or b"forkserver" in command) and descends(child)
    ]


@pytest.mark.slow
def test_a_batch_uses_the_chosen_frames_of_every_scene(tmp_path: Path):
    scenes = tmp_path / "scenes"
    synth = ["synth", str(scenes), "--kind", "dynamic", "--seed", "3", "--count", "1"]
    assert main([*synth, "--width", "320", "--height", "240"]) == 0
    out = tmp_path / "out"
    run = ["batch", str(scenes), "-o", str(out), "--method", "collision-checker", "--jobs", "1"]
    assert main([*run, "--frames", "0", "--no-eval"]) == 0
    (result,) = [p for p in out.iterdir() if p.is_dir() and not p.name.startswith(".")]
    provenance = json.loads((result / "result.json").read_text())["provenance"]
    assert provenance["frames"] == [0]
    with pytest.raises(SystemExit) as refused:  # a bad selection is refused before any work
        main([*run, "--frames", "0-x", "--no-eval"])
    assert refused.value.code == EXIT_INPUT_ERROR
