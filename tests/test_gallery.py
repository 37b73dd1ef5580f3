"""The gallery writes one small JPEG overlay per real scene and a page; a scene that fails is
shown as a placeholder naming the error, an absent data set is left out."""

from __future__ import annotations

from pathlib import Path

from benchmarks import gallery
from PIL import Image

from ipr_shapes.scene import write_scene
from tests.conftest import make_frames


def test_gallery_writes_small_jpegs_and_a_page(tmp_path: Path) -> None:
    data = tmp_path / "data"
    write_scene(data / "table_000", make_frames(1))
    broken = data / "zz_broken"
    broken.mkdir(parents=True)
    (broken / "scene_camera.json").write_text("{")  # not JSON: loading fails
    out, page = tmp_path / "gallery", tmp_path / "GALLERY.md"
    messages: list[str] = []
    rows = gallery.run(out, page, sets={"tiny": data, "absent": None}, progress=messages.append)
    assert [row.scene for row in rows] == ["table_000", "zz_broken"]
    good, bad = rows
    assert good.error is None and good.support and good.segments >= 1
    assert 0.5 < good.support_share <= 1.0 and good.gt_visible is None
    assert bad.error is not None and "scene_camera.json" in bad.error
    for row in rows:
        with Image.open(out / row.image) as image:
            assert image.format == "JPEG" and image.width <= gallery.WIDTH
    text = page.read_text()
    assert "## tiny" in text and "](gallery/table_000.jpg)" in text
    assert "| zz_broken | - | failed |" in text
    assert any("absent" in message and "left out" in message for message in messages)


def test_gallery_time_is_the_median_cpu_time_of_the_runs_after_the_first(
    tmp_path: Path, monkeypatch
) -> None:
    """The page's per-frame figure leaves out the run that draws the overlay (on a process's
    first frame it loads the compiled kernels) and is CPU time: the median of the later runs."""
    import time

    import ipr_shapes.perception as perception

    data = tmp_path / "data"
    write_scene(data / "table_000", make_frames(1))
    clock = {"now": 0.0, "calls": 0}
    # CPU seconds of each call: the first (the overlay's) far slower, then an odd spread.
    durations = [5.0, 0.6, 0.1, 0.2]
    real = perception.perceive_scene

    def perceive(*args, **kwargs):
        clock["now"] += durations[clock["calls"]]
        clock["calls"] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(perception, "perceive_scene", perceive)
    monkeypatch.setattr(time, "process_time", lambda: clock["now"])
    out, page = tmp_path / "gallery", tmp_path / "GALLERY.md"
    (row,) = gallery.run(out, page, sets={"tiny": data}, progress=lambda _: None)
    assert clock["calls"] == 1 + gallery.TIMING_RUNS == len(durations)
    assert abs(row.per_frame_ms - 200.0) < 1e-6  # the median of 0.6, 0.1 and 0.2 s
    assert row.first_run_wall_ms > 0
    assert "| CPU ms | 1st run wall ms |" in page.read_text()
