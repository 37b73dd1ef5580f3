"""The Collision Checker: uniform posterior over jointly feasible models."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from ipr_shapes.collision_checker import CollisionCheckerConfig, collision_checker
from ipr_shapes.factor_graph import exact_marginals, gibbs_marginals
from ipr_shapes.hypotheses import ConstraintConfig, HypothesisConfig
from ipr_shapes.perception.free_space import FREE, SpaceMap
from ipr_shapes.perception.types import Facet, PartialObject
from ipr_shapes.result import load_result, write_posterior_result

from .box_scene import GRID, SUPPORT, partial_box, render_view

CONFIG = CollisionCheckerConfig()
# The candidates this scene was built for. With superquadric slots the other families' variants
# cycle differently and the second object gets a 2 mm thin symmetry candidate, through which
# box candidates pass within the 5 mm penetration tolerance (penetration depth does not see a
# thin shape passed through: a limit of the pairwise constraint, not of the Collision Checker).
HYPOTHESES = HypothesisConfig(count=16, superquadric_count=0)
CONSTRAINTS = ConstraintConfig()
WALL_Y = 0.10  # the second object's seen front face (m)


@pytest.fixture(scope="module")
def scene():
    """The box seen from its height (its depth is hidden) and, behind it, the seen front face
    of a second object at y = 0.10: box hypotheses reaching past it must intersect it."""
    view = render_view((0.0, -0.5, 0.03))
    box = partial_box(view, object_id=1)
    grid = np.stack(
        np.meshgrid(np.linspace(-0.05, 0.05, 21), [WALL_Y], np.linspace(0.0, 0.04, 9)), -1
    ).reshape(-1, 3)
    face = Facet(grid.mean(axis=0), np.array([0.0, -1.0, 0.0]), grid, 0.1 * 0.04)
    behind = PartialObject(
        2, 0, np.arange(len(grid)), grid, np.zeros((len(grid), 3), np.uint8), (face,)
    )
    return view, (box, behind)


def test_hypotheses_that_must_hit_a_neighbour_get_zero_probability(scene):
    view, objects = scene
    posteriors = collision_checker(
        objects, view.space(), (SUPPORT,), CONFIG, np.random.default_rng(0), hypotheses=HYPOTHESES
    )
    assert [p.object_id for p in posteriors] == [1, 2]
    box = posteriors[0]
    assert box.probabilities.sum() == pytest.approx(1.0)
    assert len(box.hypotheses) == 16
    reach = np.array([h.vertices[:, 1].max() for h in box.hypotheses])
    through = reach > WALL_Y + CONSTRAINTS.overlap_tolerance_m + 1e-3
    assert through.any() and (~through).any()  # the test means something
    assert np.all(box.probabilities[through] == 0)
    assert np.all(box.probabilities[~through] > 0)
    assert box.probabilities[box.best] > 0
    assert box.inference == "exact"
    # The second object fits behind the short box hypotheses: none of its own is excluded.
    assert posteriors[1].probabilities.sum() == pytest.approx(1.0)
    assert np.all(posteriors[1].probabilities > 0)


def test_result_directory(scene, tmp_path):
    view, objects = scene
    posteriors = collision_checker(
        objects, None, (SUPPORT,), CONFIG, np.random.default_rng(1), hypotheses=HYPOTHESES
    )
    path = write_posterior_result(
        tmp_path / "result",
        posteriors,
        {0: view.world_from_camera},
        {"total": 1.0},
        method="collision-checker",
    )
    result = load_result(path)
    assert result.method == "collision-checker"
    assert len(result.objects) == 2
    for obj, posterior in zip(result.objects, posteriors, strict=True):
        assert sum(h.probability for h in obj.hypotheses) == pytest.approx(1.0, abs=1e-6)
        assert len(obj.hypotheses) == np.count_nonzero(posterior.probabilities)
        assert obj.probability == pytest.approx(posterior.probabilities.max(), abs=1e-6)
    # result.json names the generator of every written hypothesis, in their order.
    for entry, posterior in zip(result.extra["objects_summary"], posteriors, strict=True):
        kept = [
            h for h, p in zip(posterior.hypotheses, posterior.probabilities, strict=True) if p > 0
        ]
        assert entry["hypothesis_generators"] == [h.generator for h in kept]
        assert entry["best_generator"] == posterior.best_hypothesis.generator
        assert set(entry["hypothesis_generators"]) <= {
            "algorithm1", "symmetry", "revolution", "box", "cylinder", "sphere", "superquadric",
            "minimum"
        }  # fmt: skip


def test_minimum_shape_when_no_hypothesis_is_feasible(scene):
    _, objects = scene
    everything_free = SpaceMap(GRID, np.full(GRID.shape, FREE, dtype=np.uint8))
    (posterior,) = collision_checker(
        objects[:1], everything_free, (SUPPORT,), CONFIG, hypotheses=HYPOTHESES
    )
    assert posterior.inference == "minimum"
    assert posterior.hypotheses == (posterior.minimum,)
    assert posterior.probabilities.tolist() == [1.0]


def brute_force(sizes, edges):
    counts = {i: np.zeros(n) for i, n in sizes.items()}
    nodes = sorted(sizes)
    for values in itertools.product(*(range(sizes[i]) for i in nodes)):
        state = dict(zip(nodes, values, strict=True))
        if all(m[state[a], state[b]] for (a, b), m in edges.items()):
            for i in nodes:
                counts[i][state[i]] += 1
    return {i: c / c.sum() for i, c in counts.items()}


def test_exact_and_sampled_marginals_match_enumeration():
    rng = np.random.default_rng(3)
    sizes = {1: 5, 2: 4, 3: 6, 4: 3}
    edges = {pair: rng.random((sizes[pair[0]], sizes[pair[1]])) > 0.35 for pair in
             [(1, 2), (2, 3), (3, 4), (1, 3)]}  # fmt: skip
    truth = brute_force(sizes, edges)
    exact = exact_marginals(sorted(sizes), edges, sizes)
    sampled = gibbs_marginals(
        sorted(sizes), edges, sizes, rng, np.inf, chains=4, sweeps=1500, burn_in=20
    )
    for i in sizes:
        assert np.allclose(exact[i], truth[i], atol=1e-12)
        assert np.abs(sampled[i] - truth[i]).max() < 0.06
    impossible = {(1, 2): np.zeros((5, 4), dtype=bool)}
    assert exact_marginals([1, 2], impossible, sizes) is None


def test_tiny_time_budget_still_gives_valid_posteriors(scene):
    _, objects = scene
    posteriors = collision_checker(
        objects, None, (SUPPORT,), CONFIG, np.random.default_rng(2), time_budget_s=0.01,
        hypotheses=HYPOTHESES,
    )  # fmt: skip
    for posterior in posteriors:
        assert posterior.probabilities.sum() == pytest.approx(1.0)
        assert posterior.probabilities[posterior.best] > 0


def test_the_sampler_reaches_feasible_assignments_that_random_draws_would_not():
    # A chain of six objects whose neighbours must agree: 6 of the 6^6 = 46656 assignments are
    # feasible. Min-conflicts moves reach one at once; uniform draws would almost never.
    sizes = {i: 6 for i in range(6)}
    edges = {(i, i + 1): np.eye(6, dtype=bool) for i in range(5)}
    rng = np.random.default_rng(0)
    sampled = gibbs_marginals(
        sorted(sizes), edges, sizes, rng, np.inf, chains=2, sweeps=100, burn_in=10
    )
    assert sampled is not None
    for i in sizes:  # every counted state is feasible: all objects agree
        assert sampled[i] == pytest.approx(sampled[0])
