"""The offline emulation of the sampler against exhaustive search (``benchmarks.dev_agreement``):
the exact marginals of a hand-made table, the estimate over the models evaluated, the budget."""

from __future__ import annotations

import math

import numpy as np
import pytest
from benchmarks.dev_agreement import Emulation, clear_agreements, models_marginals

from tests.test_inference import _fabricated_problem

#: Two objects of two candidates each; per joint model, (2 frames, 2 objects) depth error norms
#: (m). Model (1, 0) fits best, (0, 0) next; object 0's own term favours candidate 0 when
#: averaged over object 1's candidates, the joint posterior candidate 1.
NORMS = {
    (0, 0): [[0.4, 1.0], [0.4, 1.0]],
    (0, 1): [[0.6, 1.8], [0.6, 1.8]],
    (1, 0): [[0.8, 0.0], [0.8, 0.0]],
    (1, 1): [[2.4, 1.8], [2.4, 1.8]],
}


def _table() -> dict:
    models = list(NORMS)
    return {
        "problem": _fabricated_problem(2),
        "models": models,
        "norms": [np.asarray(NORMS[m], float)[None] for m in models],
        "cpu": [1.0, 1.0, 1.0, 1.0],
    }


def _exact(models) -> list[np.ndarray]:
    """Marginals of P(X) proportional to exp(-alpha * decimation * sum of norms) over
    ``models`` (uniform prior), by hand."""
    problem = _fabricated_problem(2)
    scale = problem.config.likelihood.alpha_per_m * problem.observed.decimation
    out = [np.zeros(2), np.zeros(2)]
    for model in models:
        weight = math.exp(-scale * float(np.sum(NORMS[model])))
        for k, j in enumerate(model):
            out[k][j] += weight
    return [o / o.sum() for o in out]


def test_the_models_estimate_is_the_exact_posterior_over_the_models_evaluated():
    emulation = Emulation(_table())
    for got, want in zip(emulation.exact, _exact(NORMS), strict=True):
        assert got == pytest.approx(want)
    # Drawn repeatedly with unequal proposal probabilities: each model counts once, its
    # proposal does not enter.
    draws = [((1, 0), -3.0), ((0, 0), -0.1), ((0, 0), -0.1), ((0, 1), -2.0), ((0, 0), -0.1)]
    results = [emulation.result(s, m, (q, 0.0), ()) for s, (m, q) in enumerate(draws)]
    estimate = models_marginals(results, emulation.problem)
    for got, want in zip(estimate, _exact([(1, 0), (0, 0), (0, 1)]), strict=True):
        assert got == pytest.approx(want)
    # Every model evaluated: exhaustive's marginals.
    every = [emulation.result(s, m, (-1.0 * s, 0.0), ()) for s, m in enumerate(NORMS)]
    for got, want in zip(models_marginals(every, emulation.problem), emulation.exact, strict=True):
        assert got == pytest.approx(want)


def test_clear_agreements_count_only_objects_with_a_clear_exact_favourite():
    exact = [np.array([0.7, 0.3]), np.array([0.52, 0.48]), np.array([1.0])]
    assert clear_agreements(exact, [np.array([0.4, 0.6]), np.array([0.0, 1.0]), [1.0]], 0.1) == [
        False,
        True,
    ]


@pytest.mark.parametrize("proposal", ["tree", "cover", "uniform"])
def test_a_run_spends_at_most_its_share_and_given_enough_finds_the_exact_favourites(proposal):
    emulation = Emulation(_table())
    results, spent = emulation.run(0, 0.5, proposal)
    # Each new model costs a quarter of exhaustive's CPU: at most one fits in half of it
    # beside the stability tests and draws.
    assert 0 < spent <= 0.5 and len({r.choice for r in results}) <= 2
    results, spent = emulation.run(0, 2.0, proposal, max_samples=200)
    assert {r.choice for r in results} == set(NORMS)
    assert emulation.agreements(results, "models", 0.1) == [True, True]
    # Object 0's exact favourite (candidate 1) is the hypothesis estimator's runner-up: its
    # own term averaged over object 1's candidates favours candidate 0.
    assert emulation.agreements(results, "hypothesis", 0.1)[0] is False


def test_the_emulator_refuses_what_it_cannot_read_before_building_any_table(tmp_path, capsys):
    """A folder that is no scene, a share beyond exhaustive's compute or a malformed set is
    refused with what is wrong, exit 2, and no table is written (an unreadable scene was
    cached as one exhaustive refuses)."""
    from benchmarks.dev_agreement import main

    tables = tmp_path / "tables"
    cases = (
        (["--scene", str(tmp_path), "--sets"], "not a scene folder"),
        (["--share", "2", "--sets"], "--share takes shares"),
        (["--sets", "9100"], "a set is SEED:COUNT"),
        (["--seeds", "0", "--sets"], "--seeds must be at least 1"),
    )
    for argv, message in cases:
        with pytest.raises(SystemExit) as refused:
            main([*argv, "--tables", str(tables)])
        assert refused.value.code == 2
        assert message in capsys.readouterr().err
    assert not tables.exists()
