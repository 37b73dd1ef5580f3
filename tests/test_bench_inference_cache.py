"""The inference benchmark's run cache (``benchmarks.inference_run``) and its comparison
scores (``benchmarks.inference_score.score_comparison``, ``clear_agreement``), without
running a method."""

from __future__ import annotations

from pathlib import Path

import pytest
from benchmarks import inference_run
from benchmarks.inference_score import clear_agreement, score_comparison


@pytest.fixture
def runs_root(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("IPR_BENCH_RUNS", str(tmp_path / "runs"))
    return tmp_path / "runs"


def _fake_isolated(calls: list, *, fail: Exception | None = None):
    """Stands in for ``isolated``: records the call, writes the run record as the child would
    (or raises as a timed-out child does)."""

    def isolated(function, partial, settings, *args, timeout_s):
        calls.append(settings)
        if fail is not None:
            raise fail
        inference_run._write_record(partial, {**settings, "error": None, "wall_s": 1.5})

    return isolated


def test_a_run_is_kept_and_reused_and_other_settings_or_code_make_new_runs(
    runs_root, tmp_path, monkeypatch
):
    calls: list = []
    monkeypatch.setattr(inference_run, "isolated", _fake_isolated(calls))
    scene = tmp_path / "scene-000"
    first = inference_run.run_scene("suite", scene, "ipr+uniform", budget=0.5)
    assert not first["cached"] and first["wall_s"] == 1.5
    assert Path(first["directory"]).parent == runs_root / "suite" / "scene-000"
    again = inference_run.run_scene("suite", scene, "ipr+uniform", budget=0.5)
    assert again["cached"] and again["directory"] == first["directory"] and len(calls) == 1
    # Another budget, method or scene is another run; so is the same run on changed code.
    inference_run.run_scene("suite", scene, "ipr+uniform", budget=1.0)
    inference_run.run_scene("suite", scene, "ipr+size", budget=0.5)
    inference_run.run_scene("suite", tmp_path / "scene-001", "ipr+uniform", budget=0.5)
    assert len(calls) == 4
    assert inference_run.stale_runs() == []
    monkeypatch.setattr(inference_run, "_CODE_KEY", "changed-code")
    changed = inference_run.run_scene("suite", scene, "ipr+uniform", budget=0.5)
    assert not changed["cached"] and changed["directory"] != first["directory"]
    assert len(calls) == 5
    assert len(inference_run.stale_runs()) == 4  # the runs of the code before


def test_a_run_killed_after_its_time_limit_is_not_kept(runs_root, tmp_path, monkeypatch):
    calls: list = []
    timeout = inference_run.SceneTimeout("no answer after 900 s; killed")
    monkeypatch.setattr(inference_run, "isolated", _fake_isolated(calls, fail=timeout))
    record = inference_run.run_scene("suite", tmp_path / "scene-000", "collision-checker")
    assert record["error"].startswith("SceneTimeout") and record["directory"] is None
    inference_run.run_scene("suite", tmp_path / "scene-000", "collision-checker")
    assert len(calls) == 2
    assert not any(runs_root.rglob("*.part-*"))


def test_the_code_key_follows_the_package_source(tmp_path, monkeypatch):
    import ipr_shapes

    package = tmp_path / "ipr_shapes"
    package.mkdir()
    (package / "__init__.py").write_text("x = 1\n")
    monkeypatch.setattr(ipr_shapes, "__file__", str(package / "__init__.py"))
    monkeypatch.setattr(inference_run, "_CODE_KEY", None)
    before = inference_run.code_key()
    (package / "__init__.py").write_text("x = 2\n")
    monkeypatch.setattr(inference_run, "_CODE_KEY", None)
    assert inference_run.code_key() != before


def _posteriors(rows, samples):
    return {
        "posteriors": [{"object_id": i, "probabilities": p} for i, p in enumerate(rows)],
        "timing_s": {"inference_sampling": 10.0 if samples is None else 1.8},
        "samples": samples,
        "fallback": None,
    }


def test_the_comparison_counts_agreement_margins_and_exact_shares():
    record = {
        "scene": "/x/scene-003",
        "status": "ok",
        "reason": None,
        "exhaustive": _posteriors([[0.5, 0.3, 0.2], [0.1, 0.9]], None),
        "sampler": _posteriors([[0.2, 0.7, 0.1], [0.0, 1.0]], 40),
    }
    row = score_comparison(record)
    assert row["scene"] == "scene-003" and row["objects"] == 2 and row["same"] == 1
    assert row["margins"] == pytest.approx([0.2, 0.8])
    assert row["agreements"] == [False, True]
    assert row["exact_shares"] == pytest.approx([0.6, 1.0])
    assert (row["exhaustive_s"], row["sampler_s"], row["samples"]) == (10.0, 1.8, 40)
    skipped = score_comparison({"scene": "/x/s", "status": "skipped", "reason": "5 objects"})
    assert skipped == {"scene": "s", "status": "skipped", "reason": "5 objects", "objects": 0}


def test_agreement_is_counted_only_on_objects_whose_exact_posterior_has_a_clear_favourite():
    # Scene a: a clear favourite the sampler found (0.8 over 0.1), a clear one it missed (0.5
    # over 0.3), and a near tie (0.34 over 0.33) it missed, which does not count.
    a = score_comparison(
        {
            "scene": "/x/a",
            "status": "ok",
            "exhaustive": _posteriors([[0.8, 0.1, 0.1], [0.2, 0.5, 0.3], [0.34, 0.33, 0.33]], None),
            "sampler": _posteriors([[0.9, 0.1, 0.0], [0.6, 0.2, 0.2], [0.0, 1.0, 0.0]], 30),
        }
    )
    # Scene b: only near ties (margins 0.08 and 0.02): no measurable object.
    b = score_comparison(
        {
            "scene": "/x/b",
            "status": "ok",
            "exhaustive": _posteriors([[0.54, 0.46], [0.51, 0.49]], None),
            "sampler": _posteriors([[0.0, 1.0], [1.0, 0.0]], 12),
        }
    )
    clear = clear_agreement([a, b])
    assert (clear["objects"], clear["same"], clear["scenes"]) == (2, 1, 1)
    assert clear["share"] == pytest.approx(0.5)
    assert clear_agreement([a, b], min_margin=0.0)["objects"] == 5
    assert clear_agreement([a, b], min_margin=0.0)["same"] == 2
    empty = clear_agreement([b])
    assert empty["objects"] == 0 and empty["share"] != empty["share"]  # nan: nothing to agree on
