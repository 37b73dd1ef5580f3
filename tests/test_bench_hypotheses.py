"""The hypothesis-ceiling section's figures from fixed per-object rows."""

from __future__ import annotations

from collections import Counter

import pytest
from benchmarks.hypothesis_ceiling import render, summarise


def scene(rows, objects, cpu_s, generated):
    return {"scene": "s", "rows": rows, "objects": objects, "cpu_s": cpu_s, "wall_s": 2 * cpu_s,
            "generated": Counter(generated)}  # fmt: skip


def test_ceiling_per_generator_and_unmatched_objects_count_zero():
    rows = [
        {"checker": 0.6, "oracle": 0.9, "oracle_carved": 0.95,
         "generators": {"algorithm1": 0.7, "revolution": 0.9},
         "best": "revolution", "spread": 2.0, "kept": 10},
        {"checker": 0.5, "oracle": 0.8, "oracle_carved": 0.85,
         "generators": {"algorithm1": 0.8, "box": 0.6},
         "best": "algorithm1", "spread": 4.0, "kept": 12},
        {"checker": 0.0, "oracle": 0.0, "oracle_carved": 0.0, "generators": {},
         "best": None},  # unmatched
    ]  # fmt: skip
    summary = summarise(
        [scene(rows[:2], 2, 0.5, {"algorithm1": 32, "revolution": 16, "box": 16}),
         scene(rows[2:], 2, 0.3, {"algorithm1": 64})]
    )  # fmt: skip
    assert summary["truths"] == 3
    assert summary["oracle"] == pytest.approx((0.9 + 0.8) / 3)
    assert summary["checker"] == pytest.approx((0.6 + 0.5) / 3)
    assert summary["oracle_carved"] == pytest.approx((0.95 + 0.85) / 3)
    assert summary["generators"]["algorithm1"]["oracle"] == pytest.approx((0.7 + 0.8) / 3)
    assert summary["generators"]["revolution"]["wins"] == 1
    assert summary["generators"]["box"]["wins"] == 0
    assert summary["generators"]["algorithm1"]["per_object"] == pytest.approx(96 / 4)
    assert summary["spread"] == pytest.approx(3.0)
    assert summary["cpu_s_per_object"] == pytest.approx(0.8 / 4)
    page = render({"ycb-dynamic": summary})
    assert "| ycb-dynamic | revolution | 0.300 | 1/3 | 4.0 |" in page
    assert "| ycb-dynamic | 2 | 3 | 0.367 | 0.567 | 0.600 | 3.0 |" in page  # oracle, carved
