"""The replay ladder's statistics and table (``benchmarks.replay``), on fixed rows, and the
motion error on known rigid motions; the replays themselves run in ``make bench``."""

from __future__ import annotations

import numpy as np
import pytest
from benchmarks.replay import RUNGS, jittered, ladder_table, motion_error, rung_figures


def _shift(x: float) -> np.ndarray:
    transform = np.eye(4)
    transform[0, 3] = x
    return transform


def test_the_motion_error_compares_the_two_motions_of_the_same_points():
    points = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    error, motion = motion_error(points, _shift(0.03), _shift(0.05))
    assert error == pytest.approx(0.02) and motion == pytest.approx(0.05)
    # A half turn about z through the origin against no motion: each point's distance from
    # the axis, doubled.
    turn = np.diag([-1.0, -1.0, 1.0, 1.0])
    error, motion = motion_error(points, turn, np.eye(4))
    assert error == pytest.approx(2 * (0.0 + 0.1 + 0.1) / 3) and motion == 0.0


def test_rung_figures_count_only_the_pairs_that_truly_moved():
    # (error, true motion) in metres: three moved (> 5 mm), two still.
    pairs = [(0.010, 0.040), (0.020, 0.030), (0.040, 0.006), (0.500, 0.001), (0.0, 0.0049)]
    figures = rung_figures(pairs)
    assert figures["moved"] == 3
    assert figures["median"] == pytest.approx(20.0)
    assert figures["q25"] == pytest.approx(15.0) and figures["q75"] == pytest.approx(30.0)
    assert figures["motion"] == pytest.approx(30.0)
    assert figures["still"] == pytest.approx(250.0)
    empty = rung_figures([])
    assert empty["moved"] == 0 and np.isnan(empty["median"])


def test_the_ladder_table_has_one_row_per_rung_in_order():
    rows = {key: [(0.001 * (i + 1), 0.05)] for i, key in enumerate(RUNGS)}
    rows.pop("g")  # a rung without pairs shows dashes, not a crash
    lines = ladder_table(rows).splitlines()[2:]
    assert [line.split("|")[1].strip()[:3] for line in lines] == [f"({k})" for k in RUNGS]
    assert "| 1 | 3.0 | 3.0-3.0 | - |" in lines[2]
    empty = [line for line in lines if line.split("|")[1].strip().startswith("(g)")]
    assert len(empty) == 1 and empty[0].endswith("| 0 | - | - | - |")


def test_jitter_moves_and_turns_each_pose_by_the_set_amounts():
    rng = np.random.default_rng(3)
    poses = np.stack([np.eye(4), _shift(0.2)])
    moved = jittered(poses, rng)
    steps = np.linalg.norm(moved[:, :3, 3] - poses[:, :3, 3], axis=1)
    assert steps == pytest.approx([1e-4, 1e-4])
    for before, after in zip(poses, moved, strict=True):
        relative = after[:3, :3] @ before[:3, :3].T
        angle = np.arccos(np.clip((np.trace(relative) - 1) / 2, -1, 1))
        assert angle == pytest.approx(1e-3, rel=1e-3)
        assert np.allclose(after[:3, :3] @ after[:3, :3].T, np.eye(3))
    assert np.array_equal(poses[1], _shift(0.2))  # the input is not modified


@pytest.mark.slow
def test_the_generator_world_is_rebuilt_and_replays_its_pushes_exactly(tmp_path):
    import json

    from benchmarks.replay import generator_rungs, rebuild_generator_scene

    from ipr_shapes.synth import SynthConfig, generate_scene

    # YCB models when present, else the procedural objects (both must replay exactly).
    config = SynthConfig(width=160, height=120, min_visible_px=20, max_objects=4)
    path = generate_scene(tmp_path, kind="dynamic", seed=4, arrangement="table", config=config)
    rows = generator_rungs(rebuild_generator_scene(path))
    exact = rung_figures(rows["a"])
    assert exact["moved"] >= 1 and max(error for error, _ in rows["a"]) < 1e-5
    assert rung_figures(rows["b"])["q75"] > 10 * max(exact["q75"], 1e-3)  # chaos, not zero
    # A scene whose seed does not give its pile is refused, not measured.
    info = json.loads((path / "synth.json").read_text())
    info["seed"] += 1
    (path / "synth.json").write_text(json.dumps(info))
    with pytest.raises(ValueError, match="rebuilt pile"):
        rebuild_generator_scene(path)
