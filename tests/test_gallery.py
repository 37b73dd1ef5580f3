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
