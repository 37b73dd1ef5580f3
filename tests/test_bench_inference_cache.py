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
    assert skipped == {
        "scene": "s", "seed": 0, "status": "skipped", "reason": "5 objects", "objects": 0
    }  # fmt: skip


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


def _seeded(scene, seed, exact, chosen, status="ok"):
    """A scored comparison row of ``scene`` at sampler seed ``seed``: the sampler puts all
    its probability on ``chosen`` (a hypothesis index per object)."""
    sampler = [[float(i == c) for i in range(len(p))] for p, c in zip(exact, chosen, strict=True)]
    record = {
        "scene": f"/x/{scene}",
        "seed": seed,
        "status": status,
        "exhaustive": _posteriors(exact, None),
        "sampler": _posteriors(sampler, 40) if status == "ok" else None,
    }
    return score_comparison(record)


#: Exact posteriors: scene a has two objects with a clear favourite (hypothesis 0, then 1),
#: scene b one (hypothesis 0).
SEEDED_EXACT = {"a": [[0.8, 0.1, 0.1], [0.2, 0.5, 0.3]], "b": [[0.6, 0.4]]}


def seeded_rows():
    """Seed 0: 2 of 3 clear objects agree; seed 1: 3 of 3; seed 2: 1 of 2 (scene b's
    sampler run failed)."""
    a, b = SEEDED_EXACT["a"], SEEDED_EXACT["b"]
    return [
        _seeded("a", 0, a, [0, 1]),
        _seeded("b", 0, b, [1]),
        _seeded("a", 1, a, [0, 1]),
        _seeded("b", 1, b, [0]),
        _seeded("a", 2, a, [0, 2]),
        _seeded("b", 2, b, [0], status="failed"),
    ]


def test_the_agreement_over_seeds_pools_every_seed_and_object():
    """Issue 29's judged agreement is pooled over the sampler's seeds and the objects (6 of
    8 object-seeds), not seed 0's (2 of 3) nor the mean of the seeds' shares (0.722), and a
    scene's objects are counted once per seed but once as objects."""
    from benchmarks.inference_score import seeded_agreement

    rows = seeded_rows()
    assert rows[0]["seed"] == 0 and rows[-1]["seed"] == 2
    agreement = seeded_agreement(rows)
    pooled = agreement["pooled"]
    assert (pooled["same"], pooled["objects"]) == (6, 8)
    assert pooled["share"] == pytest.approx(0.75)
    assert (pooled["scenes"], pooled["distinct"]) == (2, 3)
    per_seed = {s: (c["same"], c["objects"]) for s, c in agreement["seeds"].items()}
    assert per_seed == {0: (2, 3), 1: (3, 3), 2: (1, 2)}
    assert agreement["ratio"] == pytest.approx(0.18)
    # A record without a seed is seed 0's (the comparison's own run).
    assert score_comparison({"scene": "/x/s", "status": "skipped"})["seed"] == 0


def test_the_seeded_sampler_gets_a_count_budget_from_exhaustives_joint_models():
    """The budget is a count (18 % of exhaustive's joint models, rounded up), not a share of
    its seconds: the same record gives the same budget however long exhaustive took."""
    from benchmarks.inference_run import COMPARISON_COMPUTE_SHARE
    from benchmarks.inference_seeds import sampler_samples

    record = {
        "status": "ok",
        "exhaustive": {**_posteriors(SEEDED_EXACT["a"], None), "samples": 324},
    }
    assert COMPARISON_COMPUTE_SHARE == 0.18
    assert sampler_samples(record) == 59  # 58.32 rounded up
    slower = {**record["exhaustive"], "timing_s": {"inference_sampling": 99.0}}
    assert sampler_samples({**record, "exhaustive": slower}) == 59
    assert sampler_samples({**record, "exhaustive": {**record["exhaustive"], "samples": 100}}) == 18
    assert sampler_samples({**record, "exhaustive": {**record["exhaustive"], "samples": 2}}) == 1
    assert sampler_samples({**record, "status": "skipped"}) is None
    assert sampler_samples({"status": "failed"}) is None


def test_every_seed_runs_the_sampler_with_the_count_budget_and_no_deadline(
    runs_root, tmp_path, monkeypatch
):
    """Seed 0 included (its comparison record's wall-budget sampler is not read), each seed's
    sampler is a run of its own with ``samples`` set, kept and reused; the pipeline is asked
    for exactly that many samples, one worker, seed 0's hypotheses and no time budget."""
    from benchmarks import inference_seeds

    base = {
        "scene": str(tmp_path / "scene-022"),
        "status": "ok",
        "exhaustive": {**_posteriors(SEEDED_EXACT["a"], None), "samples": 100},
        "sampler": _posteriors([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], 7),  # a wall-budget run
    }
    monkeypatch.setattr(inference_seeds, "run_comparison", lambda *a, **k: dict(base))
    calls = []

    def isolated(function, partial, settings, seed, samples, hypotheses, *, timeout_s):
        calls.append((seed, samples, settings["samples"], settings["budget_per_object_s"]))
        inference_run._write_record(
            partial, {**settings, "status": "ok", "sampler": _posteriors([[0.0, 1.0, 0.0],
                      [1.0, 0.0, 0.0]], samples)},
        )  # fmt: skip

    monkeypatch.setattr(inference_seeds, "isolated", isolated)
    records = inference_seeds.seeded_records("suite", tmp_path / "scene-022", seeds=(0, 1))
    assert calls == [(0, 18, 18, None), (1, 18, 18, None)]
    assert [r["seed"] for r in records] == [0, 1]
    assert all(r["sampler"]["samples"] == 18 and r["budget_samples"] == 18 for r in records)
    again = inference_seeds.seeded_records("suite", tmp_path / "scene-022", seeds=(0, 1))
    assert len(calls) == 2 and all(r["cached"] for r in again)
    assert score_comparison(again[0])["budget_samples"] == 18

    asked = {}

    def run_pipeline(scene, config, **kwargs):
        asked.update(kwargs, hypotheses=config.hypotheses.count,
                     budget=config.inference.budget_per_object_s)  # fmt: skip
        raise RuntimeError("stop here")

    import ipr_shapes.pipeline as pipeline
    import ipr_shapes.scene as scene_module

    monkeypatch.setattr(pipeline, "run_pipeline", run_pipeline)
    monkeypatch.setattr(scene_module, "load_scene", lambda path: path)
    with pytest.raises(RuntimeError, match="stop here"):
        inference_seeds.sampler_at_seed(tmp_path, 3, 18, 6)
    assert asked["samples"] == 18 and asked["workers"] == 1 and asked["seed"] == 0
    assert asked.get("time_budget_s") is None and asked["hypotheses"] == 6


def test_the_comparison_section_judges_the_agreement_pooled_over_the_sampler_seeds():
    """The target row reads the pooled share (6 of 8 object-seeds: no), each seed's is in
    its own table, the per-scene counts add the seeds up, and the count budget is stated."""
    from benchmarks.inference_render import comparison_section

    page = comparison_section(seeded_rows())
    cells = {line.split("|")[1].strip(): line.split("|")[2:-1] for line in page.splitlines()
             if line.startswith("| ")}  # fmt: skip
    target = next(k for k in cells if k.startswith("same most probable hypothesis, exact"))
    assert cells[target][0].strip().startswith("75.0% (6/8 object-seeds: 3 objects in 2 scenes")
    assert cells[target][1].strip() == "**no**"
    assert [cells[str(s)][0].strip() for s in (0, 1, 2)] == [
        "66.7% (2/3)", "100.0% (3/3)", "50.0% (1/2)",
    ]  # fmt: skip
    assert [c.strip() for c in cells["a"][4:8]] == ["5/6", "2 2 1", "5/6", "2 2 1"]
    # The budget is stated: a count of samples, the same at every seed.
    assert cells["a"][2].strip() == "40"
    assert "18% of the joint models exhaustive scores, rounded up, as its samples" in page
    assert "b seed 2" in page  # the failed run is listed
    right = [_seeded(s, seed, e, [int(max(p) == p[1]) for p in e])
             for seed in (0, 1) for s, e in SEEDED_EXACT.items()]  # fmt: skip
    page = comparison_section(right)
    assert "100.0% (6/6 object-seeds" in page and "| **no** |" not in page.split("target")[1]
