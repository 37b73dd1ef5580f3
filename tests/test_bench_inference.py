"""The inference benchmark's scores and tables (``benchmarks.inference_score``, ``_render``)."""

from __future__ import annotations

from pathlib import Path

import pytest
from benchmarks.inference_score import best_hypothesis_iou

from ipr_shapes.ground_truth import write_ground_truth_result
from ipr_shapes.metrics import evaluate
from ipr_shapes.result import load_result, write_result


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    from ipr_shapes.synth import SynthConfig, generate_scenes

    folder = tmp_path_factory.mktemp("scenes")
    config = SynthConfig(width=320, height=240, write_preview=False)
    (path,) = generate_scenes(folder, kind="static", seed=5, count=1, config=config)
    return Path(path)


@pytest.mark.slow  # several seconds: keeps `make test` under 3 minutes on 2 cores
def test_the_best_hypothesis_ceiling_finds_the_true_shape_among_the_hypotheses(scene, tmp_path):
    truth = load_result(write_ground_truth_result(scene, tmp_path / "truth"))
    assert len(truth.objects) >= 2
    shrunk, with_truth = [], []
    for obj in truth.objects:
        true_mesh = obj.load_mesh()
        small = true_mesh.copy()
        centre = small.centroid
        small.apply_translation(-centre)
        small.apply_scale(0.7)
        small.apply_translation(centre)
        shrunk.append((small, [(small, 1.0)], 1.0))
        # The chosen shape is the shrunken one; the true shape is a less probable hypothesis.
        with_truth.append((small, [(small, 0.6), (true_mesh, 0.4)], 0.6))
    frames = {0: truth.world_from_camera[0]}
    for name, objects in (("shrunk", shrunk), ("with-truth", with_truth)):
        write_result(tmp_path / name, "test", frames, objects, {"total": 0.0})
    only_shrunk = load_result(tmp_path / "shrunk")
    evaluation = evaluate(scene, only_shrunk)
    assert 0.2 < evaluation.object_space.iou < 0.5
    # With only the shrunken hypotheses the ceiling is what was chosen.
    assert best_hypothesis_iou(scene, only_shrunk, evaluation) == pytest.approx(
        evaluation.object_space.iou
    )
    # The true shape among the hypotheses: choosing it would have scored 1.
    mixed = load_result(tmp_path / "with-truth")
    mixed_evaluation = evaluate(scene, mixed)
    assert mixed_evaluation.object_space.iou == pytest.approx(evaluation.object_space.iou)
    assert best_hypothesis_iou(scene, mixed, mixed_evaluation) > 0.99


def _row(scene: str, method: str, iou: float, samples: int | None) -> dict:
    from benchmarks.inference_score import SCORE_KEYS

    return {
        "scene": scene, "method": method, "error": None, **dict.fromkeys(SCORE_KEYS, iou),
        "objects": 3, "hypotheses_s_per_object": 0.2, "method_s_per_object": 0.3,
        "inference_s_per_object": 1.0, "total_s_per_object": 1.5, "samples": samples,
        "fallback": None, "volume_spreads": [2.0], "best_hypothesis_iou": iou + 0.1,
    }  # fmt: skip


def test_every_inference_table_has_as_many_cells_per_row_as_columns(tmp_path):
    from benchmarks.common import markdown_table
    from benchmarks.inference_render import BUDGETS_S, budget_section, method_table

    with pytest.raises(ValueError, match="cells"):
        markdown_table(["a", "b"], [[1, 2, 3]])

    class Rows:  # the budget section's view of the benchmark runs, with fixed rows
        suites = {"ycb-dynamic": ["s0", "s1"]}

        def rows(self, suite, method, budget=None, limit=None):
            samples = None if method == "collision-checker" else int(10 * (budget or 1))
            return [_row(f"s{i}", method, 0.5 + 0.01 * i, samples) for i in range(2)]

    runs = Rows()
    page = method_table(
        {m: runs.rows("ycb-dynamic", m) for m in ("collision-checker", "ipr+uniform")},
        "ycb-dynamic",
    )
    page += "\n" + budget_section(runs, image=tmp_path / "budget.png")
    tables = [line for line in page.splitlines() if line.startswith("|")]
    assert len(tables) == 2 + 2 + 2 + 1 + len(BUDGETS_S)
    widths = {line.count("|") for line in tables}
    assert len(widths) == 2  # the two tables, each with one width
    assert (tmp_path / "budget.png").is_file()


def test_the_dynamic_section_judges_the_physics_gains_against_the_collision_checker():
    """Issue 29's targets on the page: gravity +0.03, pushes +0.06 and 60 % of the gap to the
    Collision Checker's ceiling; a gain just under a target is "no", just over it "yes"."""
    from benchmarks.inference_render import DYNAMIC_METHODS, dynamic_section

    iou = {"collision-checker": 0.60, "ipr+uniform": 0.64, "ipr+action+uniform": 0.655}

    class Rows:
        suites = {"ycb-dynamic": ["s0"]}
        default_budget = 0.8

        def rows(self, suite, method, budget=None, limit=None):
            samples = None if method.startswith("collision") else 60
            return [_row("s0", method, iou.get(method, 0.5), samples)]

    assert "ipr+uniform" in DYNAMIC_METHODS
    verdicts = {
        line.split("|")[1].strip(): line.split("|")[3].strip()
        for line in dynamic_section(Rows()).splitlines()
        if line.startswith("| ") and line.count("|") == 4
    }
    assert verdicts["ipr+uniform >= collision-checker + 0.03 (object IoU)"] == "yes"
    assert verdicts["ipr+action+uniform >= collision-checker + 0.06 (object IoU)"] == "**no**"
    # ceiling 0.70 (the test rows' best hypothesis is 0.1 above their IoU): 0.055 of 0.100
    gap = next(k for k in verdicts if k.startswith("ipr+action+uniform closes"))
    assert verdicts[gap] == "**no**"
    assert verdicts["ipr+action+uniform (the default) samples/scene >= 50 (median)"] == "yes"
    assert verdicts["ipr+action+uniform (the default) wall time <= 1.5 s/object (median)"] == "yes"
    iou["ipr+action+uniform"] = 0.665
    verdicts = {
        line.split("|")[1].strip(): line.split("|")[3].strip()
        for line in dynamic_section(Rows()).splitlines()
        if line.startswith("| ") and line.count("|") == 4
    }
    assert verdicts["ipr+action+uniform >= collision-checker + 0.06 (object IoU)"] == "yes"
    assert verdicts[gap] == "yes"  # 0.065 of 0.100
