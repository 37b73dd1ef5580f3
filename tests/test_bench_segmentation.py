"""The segmentation section scores a scene against its BOP mask_visib/ masks, reports the
suites real first with their targets, and its command runs on named suites."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from benchmarks import segmentation
from PIL import Image

from tests.conftest import make_frames


def _scene_with_masks(root: Path) -> tuple[Path, np.ndarray]:
    """A one-frame scene (the conftest table with its bump) whose ground truth is one object
    given only as a mask_visib/ file (no model: rendering it would fail)."""
    from ipr_shapes.scene import write_scene

    frame = make_frames(1)[0]
    scene = write_scene(root / "masked", [frame])
    pose = {"obj_id": 1, "cam_R_m2c": np.eye(3).ravel().tolist(), "cam_t_m2c": [0, 0, 500]}
    (scene / "scene_gt.json").write_text(json.dumps({"0": [pose]}))
    mask = np.zeros(frame.shape, dtype=bool)
    mask[40:80, 60:100] = True
    (scene / "mask_visib").mkdir()
    Image.fromarray(mask.astype(np.uint8) * 255).save(scene / "mask_visib" / "000000_000000.png")
    return scene, mask


def test_section_scores_mask_files_and_lists_suites_real_first(tmp_path: Path) -> None:
    scene, mask = _scene_with_masks(tmp_path)

    def perceive(loaded):
        return [mask.astype(np.int32) * 7], [0.1]

    text = segmentation.run({"ycb-static": [], "bins-real": [scene]}, perceive)
    rows = [line for line in text.splitlines() if line.startswith("| bins-real")]
    assert rows[0].split(" | ")[9] == "100.0 %"  # F>=0.75 pooled
    assert "| bins-real | F>=0.75 pooled >= 80% | 100.0 % | yes |" in text
    assert text.index("| bins-real |") < text.index("| ycb-static |")
    assert "ycbv-real >= 95%, bins-real >= 80%, ycb-static >= 95%, ycb-dynamic >= 95%" in text
    assert "keeps >= 97% of ids" in text


def test_suites_are_ordered_real_first() -> None:
    suites = {"other": [], "ycb-dynamic": [], "ycb-static": [], "bins-real": [], "ycbv-real": []}
    assert list(segmentation.ordered(suites)) == [
        "ycbv-real",
        "bins-real",
        "ycb-static",
        "ycb-dynamic",
        "other",
    ]
