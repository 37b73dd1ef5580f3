"""IPR inference (Algorithm 2): gravity and push evidence, importance weights, anytime and
parallel sampling, exhaustive validation, fallbacks."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from ipr_shapes.camera import look_at
from ipr_shapes.inference import FRICTION_GRID, InferenceConfig, infer_shapes
from ipr_shapes.likelihood import LikelihoodConfig, observed_frames
from ipr_shapes.physics import Body, PhysicsConfig, build_world
from ipr_shapes.products import PreparedHypotheses, ShapeHypothesis
from ipr_shapes.rendering import render_depth_and_ids
from ipr_shapes.scene import Frame, Push, Pusher
from tests.box_scene import BACKDROP, HEIGHT, SUPPORT, TABLE, WIDTH, K, box_mesh

TRUE_HALF = np.array([0.05, 0.03, 0.02])
TRUE_CENTRE = np.array([0.0, 0.0, 0.02])


def _hypothesis(index: int, low: np.ndarray, high: np.ndarray) -> ShapeHypothesis:
    half = (np.asarray(high) - np.asarray(low)) / 2
    vertices, faces = box_mesh(half, (np.asarray(high) + np.asarray(low)) / 2)
    return ShapeHypothesis(
        object_id=1,
        index=index,
        vertices=vertices,
        faces=faces,
        volume_m3=float(np.prod(2 * half)),
        distances_m=np.zeros(1),
        facet_normals=np.array([[0.0, 1.0, 0.0]]),
    )


def _prepared(*hypotheses: ShapeHypothesis) -> PreparedHypotheses:
    return PreparedHypotheses(
        ids=[1],
        generated={1: tuple(hypotheses)},
        minima={1: hypotheses[-1]},
        candidates={1: list(range(len(hypotheses)))},
        seconds={1: 0.0},
        depths={},
        thresholds={},
    )


def _frame(index: int, eye, box_pose: np.ndarray | None = None) -> tuple[Frame, np.ndarray]:
    """A rendered frame of the true box (moved by ``box_pose``) and its label image."""
    pose = look_at(np.asarray(eye, float), TRUE_CENTRE)
    box = box_mesh(TRUE_HALF, TRUE_CENTRE)
    depth, which = render_depth_and_ids(
        [box, TABLE, BACKDROP], [box_pose, None, None], K, WIDTH, HEIGHT, pose
    )
    rgb = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    return Frame(index, rgb, depth, K, pose), (which == 0).astype(np.int32)


TRUE_BOX = _hypothesis(0, TRUE_CENTRE - TRUE_HALF, TRUE_CENTRE + TRUE_HALF)
#: Only the top 1.5 cm of the box: it hangs 2.5 cm above the table.
TOP_SLAB = _hypothesis(1, [-0.05, -0.03, 0.025], [0.05, 0.03, 0.04])
#: The same front and top as the true box, but 6 cm deeper behind it (hidden from a low camera).
DEEP_BOX = _hypothesis(1, [-0.05, -0.03, 0.0], [0.05, 0.09, 0.04])
LOW_EYE = (0.0, -0.45, 0.035)
#: Passes behind the true box (y = 6 cm) but through the deep hypothesis.
BEHIND = Push(0, 1, np.array([-0.16, 0.06, 0.02]), np.array([1.0, 0.0, 0.0]), 0.2, 0.05)


def test_gravity_prefers_the_shape_that_reaches_the_table():
    frame, labels = _frame(0, (0.0, -0.35, 0.3))
    observed = observed_frames([frame], [labels], 4)
    outcome = infer_shapes(
        _prepared(TRUE_BOX, TOP_SLAB),
        (SUPPORT,),
        observed,
        method="ipr+uniform",
        config=InferenceConfig(max_samples=12),
        workers=1,
    )
    probabilities = outcome.posteriors[0].probabilities
    assert outcome.fallback is None and len(outcome.samples) == 12
    # The slab falls in its stability test: rarely or never drawn, and when not drawn its
    # evidence is the sampled box's scaled by its exploration probability over the box's.
    assert probabilities[0] > 0.9 and outcome.posteriors[0].best == 0
    explored = np.mean([s.exploration[0] for s in outcome.samples], axis=0)
    assert explored[1] < 0.1 * explored[0]


def _push_scene():
    before, labels0 = _frame(0, LOW_EYE)
    after, labels1 = _frame(1, LOW_EYE)  # the push passed behind the box: nothing moved
    return observed_frames([before, after], [labels0, labels1], 4)


def test_replaying_the_push_rules_out_a_shape_it_would_have_moved():
    observed = _push_scene()
    common = dict(pusher=Pusher(), pushes=(BEHIND,), workers=1)
    strict = InferenceConfig(max_samples=16, likelihood=LikelihoodConfig(alpha_per_m=8.0))
    with_action = infer_shapes(
        _prepared(TRUE_BOX, DEEP_BOX), (SUPPORT,), observed,
        method="ipr+action+uniform", config=strict, **common,
    )  # fmt: skip
    gravity_only = infer_shapes(
        _prepared(TRUE_BOX, DEEP_BOX), (SUPPORT,), observed,
        method="ipr+uniform", config=strict, **common,
    )  # fmt: skip
    assert with_action.posteriors[0].probabilities[0] > 0.95
    assert with_action.summary.pushes_replayed == 1
    # Without the push the two shapes look alike from the low camera.
    assert gravity_only.summary.pushes_replayed == 0
    assert 0.2 < gravity_only.posteriors[0].probabilities[0] < 0.8
    # The default alpha weighs the same evidence more cautiously, in the same direction.
    default = infer_shapes(
        _prepared(TRUE_BOX, DEEP_BOX), (SUPPORT,), observed,
        config=InferenceConfig(max_samples=16), **common,
    )  # fmt: skip
    assert (
        0.6 < default.posteriors[0].probabilities[0] <= with_action.posteriors[0].probabilities[0]
    )


def test_the_size_prior_favours_the_smaller_shape_when_the_evidence_is_equal():
    observed = _push_scene().only(1)
    outcome = infer_shapes(
        _prepared(TRUE_BOX, DEEP_BOX), (SUPPORT,), observed,
        method="ipr+size", config=InferenceConfig(max_samples=80), workers=1,
    )  # fmt: skip
    # Volumes 240 vs 480 cm^3: prior 2/3 vs 1/3, likelihoods nearly equal.
    assert 0.55 < outcome.posteriors[0].probabilities[0] < 0.8


def test_samples_are_the_same_with_one_or_two_workers():
    observed = _push_scene()
    runs = [
        infer_shapes(
            _prepared(TRUE_BOX, DEEP_BOX),
            (SUPPORT,),
            observed,
            pusher=Pusher(),
            pushes=(BEHIND,),
            config=InferenceConfig(max_samples=6),
            workers=workers,
            seed=3,
        )  # fmt: skip
        for workers in (1, 2)
    ]
    first, second = ([(s.choice, s.log_likelihood) for s in run.samples] for run in runs)
    assert first == second and len(first) == 6
    assert np.array_equal(runs[0].posteriors[0].probabilities, runs[1].posteriors[0].probabilities)


def test_a_larger_budget_keeps_the_smaller_budgets_samples():
    # Common random numbers: sample i is drawn from its own generator (seed, i), so a run that
    # stops later (a larger budget) scores the same joint models first and only adds others;
    # the budget table's differences are then the added samples' alone.
    observed = _push_scene()
    runs = [
        infer_shapes(
            _prepared(TRUE_BOX, DEEP_BOX, TOP_SLAB),
            (SUPPORT,),
            observed,
            pusher=Pusher(),
            pushes=(BEHIND,),
            config=InferenceConfig(max_samples=count),
            workers=2,
            seed=5,
        )  # fmt: skip
        for count in (3, 8)
    ]
    small, large = (
        [(s.index, s.choice, s.log_proposal, s.log_likelihood) for s in run.samples] for run in runs
    )
    assert len(small) == 3 and len(large) == 8
    assert large[:3] == small
    assert len({s[1] for s in large}) > 1  # the added samples are draws of their own


def test_exhaustive_agrees_with_the_sampler():
    observed = _push_scene()
    kwargs = dict(pusher=Pusher(), pushes=(BEHIND,), workers=1)
    # max_samples lifts the time budget (a loaded machine may not score both in 1.75 s).
    exhaustive = infer_shapes(
        _prepared(TRUE_BOX, DEEP_BOX), (SUPPORT,), observed, method="exhaustive",
        config=InferenceConfig(max_samples=2), **kwargs,
    )  # fmt: skip
    assert len(exhaustive.samples) == 2  # every joint model once
    # Exact: the posterior is the normalised likelihood of the two models (each the mean over
    # the frictions searched).
    log_l = np.array([s.log_likelihood for s in exhaustive.samples])
    exact = np.exp(log_l - np.logaddexp.reduce(log_l))
    assert exhaustive.posteriors[0].probabilities == pytest.approx(exact)
    assert exhaustive.posteriors[0].best == 0 and exact[0] > 0.6
    sampled = infer_shapes(
        _prepared(TRUE_BOX, DEEP_BOX), (SUPPORT,), observed,
        config=InferenceConfig(max_samples=12), **kwargs,
    )  # fmt: skip
    assert sampled.posteriors[0].best == exhaustive.posteriors[0].best


def test_a_spent_budget_returns_the_collision_checker_answer_and_says_so():
    frame, labels = _frame(0, (0.0, -0.35, 0.3))
    outcome = infer_shapes(
        _prepared(TRUE_BOX, TOP_SLAB),
        (SUPPORT,),
        observed_frames([frame], [labels], 4),
        deadline=time.perf_counter(),
        workers=1,
    )
    assert outcome.fallback and "budget" in outcome.fallback
    assert outcome.posteriors[0].probabilities == pytest.approx([0.5, 0.5])


def test_a_model_whose_simulation_flings_an_object_is_impossible():
    frame, labels = _frame(0, (0.0, -0.35, 0.3))
    # With flung_m = 1 cm the slab's 2.5 cm fall counts as flung: every sample is impossible.
    config = InferenceConfig(max_samples=3, physics=PhysicsConfig(flung_m=0.01))
    outcome = infer_shapes(
        _prepared(TOP_SLAB), (SUPPORT,), observed_frames([frame], [labels], 4),
        method="ipr+uniform", config=config, workers=1,
    )  # fmt: skip
    assert all(s.log_likelihood == -np.inf for s in outcome.samples)
    assert outcome.fallback and "impossible" in outcome.fallback


def test_stability_of_the_true_box_with_the_default_physics():
    world = build_world([Body(TRUE_BOX.vertices, TRUE_BOX.faces)], [SUPPORT])
    world.settle()
    assert world.displacements()[0] < 0.002


def test_exhaustive_refuses_scenes_it_cannot_enumerate():
    from ipr_shapes.errors import IprError
    from ipr_shapes.inference import InferenceProblem, exhaustive_models

    observed = _push_scene()
    problem = InferenceProblem(
        ids=(1, 2, 3, 4, 5),
        candidates=((TRUE_BOX, DEEP_BOX),) * 5,
        minima=(TRUE_BOX,) * 5,
        compatible={},
        neighbours=((),) * 5,
        log_prior=(np.log([0.5, 0.5]),) * 5,
        planes=(SUPPORT,),
        pusher=None,
        pushes=(),
        observed=observed,
        config=InferenceConfig(),
        seed=0,
    )
    with pytest.raises(IprError, match="at most 4 objects"):
        exhaustive_models(problem)
    small = InferenceConfig(max_exhaustive_objects=5, max_exhaustive_models=10)
    with pytest.raises(IprError, match="32 joint models"):
        exhaustive_models(dataclasses.replace(problem, config=small))


def test_completion_image_shows_the_input_beside_the_completed_objects():
    from ipr_shapes.collision_checker import uniform_posteriors
    from ipr_shapes.report import completion_image

    frame, _ = _frame(0, (0.0, -0.35, 0.3))
    posteriors = uniform_posteriors(_prepared(TRUE_BOX, TOP_SLAB))
    image = completion_image(frame, posteriors)
    assert image.shape == (HEIGHT, 2 * WIDTH, 3)
    assert np.array_equal(image[:, :WIDTH], frame.rgb)
    right = image[:, WIDTH:].astype(int)
    coloured = np.ptp(right, axis=2) > 30  # the object colour, not the grey backdrop
    assert 500 < coloured.sum() < 0.5 * WIDTH * HEIGHT
    assert np.ptp(completion_image(frame, [])[:, WIDTH:].astype(int), axis=2).max() <= 1


def test_completion_shading_around_the_drawn_pixels_is_the_whole_images():
    """The picture shades only the drawn pixels' box grown by one pixel; each drawn pixel's
    shade must be the whole image's, bit for bit (also at the image's edge)."""
    from ipr_shapes.collision_checker import uniform_posteriors
    from ipr_shapes.perception.output import palette
    from ipr_shapes.report import _shading, completion_image

    for eye in ((0.0, -0.35, 0.3), (0.03, -0.1, 0.06)):  # the second cut by the image's edge
        frame, _ = _frame(0, eye)
        posteriors = uniform_posteriors(_prepared(TRUE_BOX, TOP_SLAB))
        depth, index = render_depth_and_ids(
            [p.output_mesh for p in posteriors], [None] * len(posteriors), K, WIDTH, HEIGHT,
            frame.world_from_camera,
        )  # fmt: skip
        drawn = index >= 0
        rgb = np.asarray(frame.rgb, np.uint8)
        grey = rgb.astype(np.float64).mean(axis=2, keepdims=True)
        expected = np.repeat(0.35 * grey + 40.0, 3, axis=2)
        colours = palette(np.array([p.object_id for p in posteriors])).astype(np.float64)
        whole = _shading(depth, np.asarray(K, float))
        expected[drawn] = colours[np.maximum(index, 0)][drawn] * whole[drawn, None]
        image = completion_image(frame, posteriors)[:, WIDTH:]
        assert np.array_equal(image, np.clip(expected, 0, 255).astype(np.uint8))
        # The shade is not flat (so that a window without its margin would show).
        assert np.ptp(whole[drawn]) > 0.1
    assert drawn[:, 0].any() or drawn[:, -1].any() or drawn[0].any() or drawn[-1].any()


def _fabricated_problem(
    count: int, compatible: dict | None = None, weighting="hypothesis", drawn_models="factorised"
):
    """A problem of ``count`` objects with two candidates each, for estimators alone. The
    factorised marginals by default: the tests of the unary factors build samples whose joint
    log likelihood is a placeholder (``_result``); the drawn models' own weights (the default
    ``drawn_models``) are tested with samples scored as the sampler scores them (``_scored``)."""
    from ipr_shapes.inference import InferenceProblem

    return InferenceProblem(
        ids=tuple(range(1, count + 1)),
        candidates=((TRUE_BOX, DEEP_BOX),) * count,
        minima=(TRUE_BOX,) * count,
        compatible=compatible or {},
        neighbours=((),) * count,
        log_prior=(np.log([0.5, 0.5]),) * count,
        planes=(SUPPORT,),
        pusher=None,
        pushes=(),
        observed=_push_scene(),
        config=InferenceConfig(weighting=weighting, drawn_models=drawn_models),
        seed=0,
    )


def _result(index: int, choice, norms, log_q):
    from ipr_shapes.inference import SampleResult

    norms = np.asarray(norms, float)[None, None, :]
    return SampleResult(index, tuple(choice), float(sum(log_q)), -1.0, 0.0, 0.0, 0, norms, log_q)


def test_hypothesis_weighting_scores_each_candidate_by_its_own_evidence_not_its_draws():
    from ipr_shapes.inference import marginals

    # Candidate 0 was drawn nine times, candidate 1 once (exploration 0.9 / 0.1), and
    # candidate 1 fits better by 0.01 of depth error norm.
    results = [_result(s, (0,), [0.05], (np.log(0.9),)) for s in range(9)]
    results.append(_result(9, (1,), [0.04], (np.log(0.1),)))
    problem = _fabricated_problem(1)
    scale = problem.config.likelihood.alpha_per_m * problem.observed.decimation
    estimate = marginals(results, problem)[0]
    assert estimate[1] / estimate[0] == pytest.approx(np.exp(scale * 0.01))
    # Algorithm 2's per-object update reaches the same ratio only through the draw counts.
    per_object = marginals(results, _fabricated_problem(1, weighting="object"))[0]
    assert per_object[1] / per_object[0] == pytest.approx(np.exp(scale * 0.01))
    # A candidate never drawn has no evidence of its own: the prior decides between them.
    assert marginals(results[:9], problem)[0] == pytest.approx([0.5, 0.5])


def test_candidates_no_sample_chose_take_their_objects_mean_evidence():
    from ipr_shapes.inference import marginals

    # Three candidates; the first two drawn, the third never: it takes the mean of the
    # sampled candidates' likelihoods, between theirs, not zero.
    problem = dataclasses.replace(
        _fabricated_problem(1),
        candidates=((TRUE_BOX, DEEP_BOX, DEEP_BOX),),
        log_prior=(np.log(np.full(3, 1 / 3)),),
    )
    results = [_result(0, (0,), [0.01], (0.0,)), _result(1, (1,), [0.05], (0.0,))]
    scale = problem.config.likelihood.alpha_per_m * problem.observed.decimation
    likelihood = np.exp(-scale * np.array([0.01, 0.05]))
    expected = np.append(likelihood, likelihood.mean())
    assert marginals(results, problem)[0] == pytest.approx(expected / expected.sum())
    # With the exploration probabilities the samples were drawn from, the undrawn candidate's
    # mean is scaled by its mean exploration probability over the drawn ones' (0.05 / 0.475).
    explored = (np.array([0.5, 0.45, 0.05]),)
    results = [dataclasses.replace(r, exploration=explored) for r in results]
    expected = np.append(likelihood, likelihood.mean() * 0.05 / 0.475)
    assert marginals(results, problem)[0] == pytest.approx(expected / expected.sum())


def test_samples_without_evidence_give_the_collision_checkers_marginals():
    from ipr_shapes.inference import marginals

    # Equal likelihoods for every sampled joint model: the marginals are the prior restricted
    # to the jointly feasible models, whichever candidates the samples happened to choose.
    compatible = {(0, 1): np.array([[True, False], [True, True]])}
    problem = _fabricated_problem(2, compatible)
    results = [_result(0, (1, 1), [0.02, 0.02], (0.0, 0.0))]
    estimate = marginals(results, problem)
    # Feasible pairs: (0, 0), (1, 0), (1, 1) equally likely.
    assert estimate[0] == pytest.approx([1 / 3, 2 / 3])
    assert estimate[1] == pytest.approx([2 / 3, 1 / 3])


def test_hypothesis_weighting_respects_the_pairwise_constraints():
    from ipr_shapes.inference import marginals

    # Object 0's candidate 0 cannot coexist with object 1's candidate 1.
    compatible = {(0, 1): np.array([[True, False], [True, True]])}
    problem = _fabricated_problem(2, compatible)
    norms = {(0, 0): [0.01, 0.05], (1, 0): [0.03, 0.05], (1, 1): [0.03, 0.02]}
    results = [_result(s, c, n, (0.0, 0.0)) for s, (c, n) in enumerate(norms.items())]
    estimate = marginals(results, problem)
    scale = problem.config.likelihood.alpha_per_m * problem.observed.decimation
    # Exact: unary factors from the mean own terms, summed over the feasible pairs only.
    u0 = np.exp(-scale * np.array([0.01, 0.03]))
    u1 = np.exp(-scale * np.array([0.05, 0.02]))
    feasible = compatible[(0, 1)] * np.outer(u0, u1)
    assert estimate[0] == pytest.approx(feasible.sum(1) / feasible.sum())
    assert estimate[1] == pytest.approx(feasible.sum(0) / feasible.sum())


def _scored(problem, index: int, choice, norms):
    """A sample of ``problem`` whose likelihood and prior are its norms' and candidates' (None
    norms: a failed simulation)."""
    from ipr_shapes.inference import SampleResult
    from ipr_shapes.likelihood import log_likelihood

    log_prior = float(sum(problem.log_prior[k][j] for k, j in enumerate(choice)))
    if norms is None:
        return SampleResult(index, tuple(choice), 0.0, -np.inf, log_prior, 0.0, 0, None)
    norms = np.asarray(norms, float)[None, None, :]
    log_l = log_likelihood(norms[0], problem.observed.decimation, problem.config.likelihood)
    return SampleResult(
        index, tuple(choice), 0.0, log_l, log_prior, 0.0, 0, norms, (0.0,) * len(choice)
    )


def _interacting(drawn_models: str):
    """Two objects of two candidates each, all four pairs feasible, whose own terms interact:
    object 1's candidate 1 makes object 0's rendered depth worse by 2 of norm, which object
    0's candidates share alike; exhaustive's answer is then object 1's candidate 0, the
    factorised one a tie."""
    problem = _fabricated_problem(
        2, {(0, 1): np.ones((2, 2), dtype=bool)}, drawn_models=drawn_models
    )
    norms = {
        (0, 0): [0.01, 0.02], (0, 1): [2.01, 0.02],
        (1, 0): [0.02, 0.02], (1, 1): [0.02, 0.02],
    }  # fmt: skip
    return problem, norms


def test_drawn_models_scored_by_their_own_likelihood_give_exhaustive_searchs_marginals():
    from ipr_shapes.inference import marginals

    assert InferenceConfig().drawn_models == "exact"  # the default
    exact_problem, norms = _interacting("exact")
    results = [_scored(exact_problem, s, c, n) for s, (c, n) in enumerate(norms.items())]
    # Exhaustive search's marginals: the joint posterior summed.
    log_w = np.array([r.log_likelihood + r.log_prior for r in results])
    weights = np.exp(log_w - log_w.max()).reshape(2, 2)
    exhaustive = marginals(results, exact_problem, joint=True)
    assert exhaustive[1] == pytest.approx(weights.sum(0) / weights.sum())
    # Every model drawn (some twice: a model counts once): the drawn models' own likelihoods.
    estimate = marginals([*results, results[1], results[1]], exact_problem)
    for got, want in zip(estimate, exhaustive, strict=True):
        assert got == pytest.approx(want)
    assert estimate[1][0] > 0.6
    # The factorised estimate (the default) cannot see that object 1's candidate 1 costs
    # object 0 its fit: the per-candidate means of its own term tie.
    factorised_problem, _ = _interacting("factorised")
    assert factorised_problem.config == dataclasses.replace(
        exact_problem.config, drawn_models="factorised"
    )
    factorised = marginals(results, factorised_problem)
    assert factorised[1] == pytest.approx([0.5, 0.5])
    # Two models drawn, both with object 0's candidate 0: they tell object 1's candidates
    # apart, the two undrawn models keep their factorised weight.
    partial = marginals(results[:2], exact_problem)
    assert partial[1][0] > 0.55 and factorised_problem.config.drawn_models == "factorised"
    assert marginals(results[:2], factorised_problem)[1] == pytest.approx([0.5, 0.5])


def test_undrawn_models_take_what_the_drawn_ones_said_of_a_candidate_to_its_neighbour():
    from ipr_shapes.inference import marginals

    # Object 1's candidate 1 worsens object 0's depth by 2 of norm with either of object 0's
    # candidates; the model (1, 1) is not drawn. Declared neighbours, its weight is the
    # first-order expansion: object 0's residual in the drawn (0, 1) counts against object
    # 1's candidate 1 there too; without neighbours it would count for nothing.
    norms = {(0, 0): [0.01, 0.02], (0, 1): [2.01, 0.02], (1, 0): [0.02, 0.02]}
    undrawn = [0.02 + 2.0, 0.02]
    base = _fabricated_problem(2, {(0, 1): np.ones((2, 2), dtype=bool)}, drawn_models="exact")
    near = dataclasses.replace(base, neighbours=((1,), (0,)))
    results = [_scored(near, s, c, n) for s, (c, n) in enumerate(norms.items())]
    every = [*results, _scored(near, 3, (1, 1), undrawn)]
    exhaustive = marginals(every, near, joint=True)[1][1]
    first_order = marginals(results, near)[1][1]
    own_only = marginals(results, base)[1][1]
    assert exhaustive < first_order < own_only
    # The output's own-evidence weights do not take the neighbours' residuals ("own").
    from ipr_shapes.inference.estimators import medoid_weights

    for a, b in zip(medoid_weights(results, near), medoid_weights(results, base), strict=True):
        assert a == pytest.approx(b)


def test_a_drawn_model_that_failed_takes_its_share_of_the_marginals_away():
    from ipr_shapes.inference import marginals

    problem, norms = _interacting("exact")
    problem = dataclasses.replace(
        problem, compatible={(0, 1): np.array([[True, True], [True, False]])}
    )
    # Object 1's candidate 1 fits only with object 0's candidate 0, and that model failed:
    # candidate 1 is impossible, whatever its factorised evidence says.
    results = [
        _scored(problem, 0, (0, 0), norms[(0, 0)]),
        _scored(problem, 1, (0, 1), None),
        _scored(problem, 2, (1, 0), norms[(1, 0)]),
    ]
    estimate = marginals(results, problem)
    assert estimate[1] == pytest.approx([1.0, 0.0])
    factorised = marginals(
        results,
        dataclasses.replace(
            problem, config=dataclasses.replace(problem.config, drawn_models="factorised")
        ),
    )
    assert factorised[1][1] > 0.2


def test_the_log_partition_is_the_sum_over_the_feasible_assignments():
    from ipr_shapes.factor_graph import log_partition

    rng = np.random.default_rng(4)
    sizes = {0: 3, 1: 2, 2: 4}
    edges = {(0, 1): rng.random((3, 2)) > 0.3, (1, 2): rng.random((2, 4)) > 0.3}
    unary = {k: rng.random(m) * 5 for k, m in sizes.items()}
    total = sum(
        unary[0][a] * unary[1][b] * unary[2][c] * edges[(0, 1)][a, b] * edges[(1, 2)][b, c]
        for a in range(3) for b in range(2) for c in range(4)
    )  # fmt: skip
    assert log_partition([0, 1, 2], edges, sizes, unary=unary) == pytest.approx(np.log(total))
    none = {(0, 1): np.zeros((3, 2), dtype=bool)}
    assert log_partition([0, 1], none, {0: 3, 1: 2}) == -np.inf


def test_a_joint_model_drawn_again_is_not_simulated_again():
    from ipr_shapes.collision_checker import uniform_posteriors
    from ipr_shapes.inference import Sampler, build_problem
    from ipr_shapes.methods import METHODS

    prepared = _prepared(TRUE_BOX, DEEP_BOX)
    problem, _ = build_problem(
        prepared, uniform_posteriors(prepared), (SUPPORT,), _push_scene(),
        variant=METHODS["ipr+action+uniform"], pusher=Pusher(), pushes=(BEHIND,),
        config=InferenceConfig(), seed=0,
    )  # fmt: skip
    sampler = Sampler(problem)
    try:
        samples = [sampler.sample(index) for index in range(8)]
        assert {s.choice for s in samples} == {(0,), (1,)}
        # Two distinct models, two simulations; the repeats reuse them.
        assert set(sampler.evaluated) == {(0,), (1,)}
        # Reuse is exact because a simulation and its rendering are deterministic.
        for choice in ((0,), (1,)):
            fresh = sampler.depth_norms(choice)
            assert np.array_equal(fresh, sampler.evaluated[choice])
            assert all(np.array_equal(s.norms, fresh) for s in samples if s.choice == choice)
    finally:
        sampler.close()


#: A brisk push into the box's left face: once the pusher is withdrawn the box slides on by
#: about v^2 / (2 mu g), 8 mm at friction 0.25 and 2 mm at 1.0.
FAST = Push(0, 1, np.array([-0.075, 0.0, 0.02]), np.array([1.0, 0.0, 0.0]), 0.05, 0.2)
#: 4 ms steps for the friction tests: there the box ends 5.3 mm further at friction 0.25 than
#: at 1.0, visible at a quarter of the resolution; at the default 8 ms only 2.8 mm, which moves
#: no pixel of the decimated images (docs/experiments/2026-11-26-samples-per-scene.md).
FRICTION_PHYSICS = {"timestep_s": 0.004, "push_timestep_s": 0.004}


def _pushed_scene(friction: float):
    """Frames 0 and 1 of the true box pushed by ``FAST`` in a world of ``friction``."""
    world = build_world(
        [Body(*box_mesh(TRUE_HALF, TRUE_CENTRE))],
        (SUPPORT,),
        PhysicsConfig(friction=friction, **FRICTION_PHYSICS),
        pusher=Pusher(),
    )
    world.settle()
    world.push(FAST)
    moved = world.poses()[0]
    before, labels0 = _frame(0, LOW_EYE)
    after, labels1 = _frame(1, LOW_EYE, moved)
    return observed_frames([before, after], [labels0, labels1], 4), float(moved[0, 3])


@pytest.mark.parametrize("true_friction", [1.0, 0.25])
def test_the_friction_posterior_favours_the_friction_the_push_showed(true_friction):
    observed, _ = _pushed_scene(true_friction)
    # The true shape alone, so the friction is all that differs; a strict alpha, since 5 mm
    # of slide is little evidence at the default one.
    config = InferenceConfig(
        physics=PhysicsConfig(**FRICTION_PHYSICS),
        max_samples=1,
        likelihood=LikelihoodConfig(alpha_per_m=8.0),
        frictions=FRICTION_GRID,
    )
    outcome = infer_shapes(
        _prepared(TRUE_BOX), (SUPPORT,), observed,
        pusher=Pusher(), pushes=(FAST,), config=config, workers=1,
    )  # fmt: skip
    summary = outcome.summary
    frictions = np.array(summary.frictions)
    posterior = np.array(summary.friction_posterior)
    assert list(frictions) == list(FRICTION_GRID)
    assert posterior.sum() == pytest.approx(1.0) and (posterior >= 0).all()
    assert posterior[list(frictions).index(true_friction)] > 0.9
    # The sample's likelihood is the mean over the frictions (their uniform prior).
    log_l = outcome.samples[0].norms.sum(axis=(1, 2)) * -8.0 * 4
    assert outcome.samples[0].log_likelihood == pytest.approx(
        np.logaddexp.reduce(log_l) - np.log(len(frictions))
    )


def test_without_pushes_or_when_off_no_friction_is_searched():
    observed, _ = _pushed_scene(1.0)
    assert InferenceConfig().frictions == ()  # off by default (opt-in)
    for frames, pushes, config in [
        (1, (), InferenceConfig(max_samples=1)),  # nothing to replay
        (2, (FAST,), InferenceConfig(max_samples=1, frictions=())),  # off
    ]:
        outcome = infer_shapes(
            _prepared(TRUE_BOX), (SUPPORT,), observed.only(frames),
            pusher=Pusher(), pushes=pushes, config=config, workers=1,
        )  # fmt: skip
        assert outcome.summary.frictions == (PhysicsConfig().friction,)
        assert outcome.summary.friction_posterior == (1.0,)
        assert outcome.samples[0].norms.shape[0] == 1


def test_the_uniform_proposal_draws_compatible_candidates_evenly_without_stability_tests():
    from collections import Counter

    from ipr_shapes.inference.sampler import Sampler

    # Object 0's deep box and object 1's deep box cannot coexist. Objects in random order,
    # each uniform over what fits: (0, 0) 1/4, (0, 1) and (1, 0) 3/8 each.
    compatible = {(0, 1): np.array([[True, True], [True, False]])}
    problem = _fabricated_problem(2, compatible)
    problem = dataclasses.replace(problem, config=InferenceConfig(proposal="uniform"))
    sampler = Sampler(problem)
    draws = [sampler.uniform_sample_explored(np.random.default_rng([0, s])) for s in range(800)]
    counts = Counter(choice for choice, _, _ in draws)
    assert set(counts) == {(0, 0), (0, 1), (1, 0)}
    assert counts[(0, 0)] / 800 == pytest.approx(0.25, abs=0.05)
    assert counts[(0, 1)] / 800 == pytest.approx(0.375, abs=0.05)
    for _, log_q, explored in draws:
        # The object placed second has one or two candidates left; the first always two.
        assert sorted(np.exp(log_q).round(3)) in ([0.5, 0.5], [0.5, 1.0])
        assert all(e.size == 0 for e in explored)
    result = sampler.sample(0)
    assert not sampler.cache and sampler.stability_tests == sampler.screened == 0
    assert result.stability_tests == 0
    assert result.choice == draws[0][0]  # the sample's draw depends on its index alone
    # The tree sampler (the default) explores by stability tests (here screened: the boxes
    # stand on the support).
    tree = Sampler(_fabricated_problem(2, compatible))
    tree.sample(0)
    assert tree.cache and tree.stability_tests + tree.screened > 0


def test_the_medoid_weighs_each_candidates_own_evidence_not_the_joint_models_it_is_in():
    """Nested cubes of 4, 5 and 6 cm for one object; beside them ten candidates of a neighbour
    that only the 4 cm cube leaves room for, and one far away. With the same evidence for
    every candidate the marginal of the 4 cm cube is 11/13 (it is in 11 of the 13 feasible
    joint models) and the marginals' medoid would be it; the medoid weights are the evidence
    alone, equal, and their medoid is the 5 cm cube, closest in IoU to the other two (as the
    Collision Checker's). Evidence still tilts them: a better fit weighs exp(alpha * gain)."""
    from ipr_shapes.factor_graph import posterior_medoid
    from ipr_shapes.inference import marginals, medoid_weights

    def cube(object_id, index, lower, size):
        half = np.full(3, size / 2)
        vertices, faces = box_mesh(half, np.asarray(lower, float) + half)
        return ShapeHypothesis(
            object_id, index, vertices, faces, size**3, np.zeros(0), np.zeros((0, 3))
        )

    first = tuple(cube(1, k, [0.0, 0.0, 0.0], s) for k, s in enumerate((0.04, 0.05, 0.06)))
    second = tuple(cube(2, k, [0.05 + 1e-4 * k, 0.0, 0.0], 0.02) for k in range(10))
    second += (cube(2, 10, [0.2, 0.0, 0.0], 0.02),)
    compatible = np.zeros((3, 11), dtype=bool)
    compatible[0, :] = True
    compatible[:, 10] = True
    problem = dataclasses.replace(
        _fabricated_problem(2, {(0, 1): compatible}),
        candidates=(first, second),
        minima=(first[0], second[0]),
        log_prior=(np.full(3, -np.log(3)), np.full(11, -np.log(11))),
    )
    drawn = [(0, 0), (1, 10), (2, 10), (0, 3)]
    results = [_result(s, c, [0.02, 0.02], (0.0, 0.0)) for s, c in enumerate(drawn)]
    assert marginals(results, problem)[0] == pytest.approx([11 / 13, 1 / 13, 1 / 13])
    weights = medoid_weights(results, problem)
    assert weights[0] == pytest.approx(np.full(3, 1 / 3))
    assert posterior_medoid(first, weights[0]) == 1
    assert posterior_medoid(first, marginals(results, problem)[0]) == 0  # the test means something
    # The 6 cm cube fits better by 0.01 of depth error norm: its weight is its evidence's.
    results[2] = _result(2, (2, 10), [0.01, 0.02], (0.0, 0.0))
    scale = problem.config.likelihood.alpha_per_m * problem.observed.decimation
    weights = medoid_weights(results, problem)[0]
    assert weights[2] / weights[0] == pytest.approx(np.exp(scale * 0.01))
    assert weights[1] == pytest.approx(weights[0])


def test_neighbour_evidence_gives_a_candidate_what_its_neighbours_terms_say_of_it():
    """Object 2 rests on object 1's hidden part: whenever object 1 takes its small candidate
    (0) object 2 falls and its term is worse by 0.04 of depth error norm, whatever object 2's
    own candidate. Object 1's own term is the same in every sample. With "own" evidence (the
    default) object 1's candidates weigh the same; with "neighbours" the candidate that holds
    object 2 up weighs exp(alpha * 0.04) more, and object 2's weights are its own evidence's
    (object 1's residuals are 0: its term is what its candidate says). Objects that cannot
    touch (no neighbours) keep their own evidence."""
    from ipr_shapes.inference import medoid_weights, neighbour_residuals

    problem = dataclasses.replace(_fabricated_problem(2), neighbours=((1,), (0,)))
    assert problem.config.evidence == "own"
    drawn = [(0, 0), (0, 1), (1, 0), (1, 1)]
    results = [
        _result(s, c, [0.02, 0.05 if c[0] == 0 else 0.01], (0.0, 0.0)) for s, c in enumerate(drawn)
    ]
    scale = problem.config.likelihood.alpha_per_m * problem.observed.decimation
    own = medoid_weights(results, problem)
    assert own[0] == pytest.approx([0.5, 0.5])
    neighbours = dataclasses.replace(
        problem, config=dataclasses.replace(problem.config, evidence="neighbours")
    )
    weights = medoid_weights(results, neighbours)
    assert weights[0][1] / weights[0][0] == pytest.approx(np.exp(scale * 0.04))
    assert weights[1] == pytest.approx(own[1])
    apart = dataclasses.replace(neighbours, neighbours=((), ()))
    assert medoid_weights(results, apart)[0] == pytest.approx([0.5, 0.5])
    # The residuals: a term minus its candidate's log mean exp; 0 for a candidate drawn once
    # and for a failed sample.
    choices = np.array([[0, 0], [0, 1], [1, 2], [1, 1], [0, 1]])
    terms = np.array([[-1.0, -2.0], [-1.0, -3.0], [-2.0, -4.0], [-np.inf, -1.0], [-1.0, -5.0]])
    residuals = neighbour_residuals(choices, terms)
    assert residuals[2, 0] == 0.0 and residuals[2, 1] == 0.0  # drawn once (finite rows)
    assert residuals[3].tolist() == [0.0, 0.0]  # failed
    mean = np.logaddexp(-3.0, -5.0) - np.log(2)
    assert residuals[1, 1] == pytest.approx(-3.0 - mean)
    assert residuals[4, 1] == pytest.approx(-5.0 - mean)
    assert residuals[0, 0] == pytest.approx(0.0)  # -1, -1 (and -1 in row 4): all equal


def test_rest_evidence_scores_each_candidates_fall_over_the_sampled_contexts_it_fits():
    """``InferenceConfig.rest_drop_m``: every candidate j of object k gets log mean exp(-drop_kj
    / rest_drop_m) over the samples whose other choices it is compatible with
    (``rest_evidence``), drop_kj its fall among that sample's other shapes
    (``SampleResult.drops``), and its chosen candidate's term is in its own term
    (``rest_log_likelihoods``). Object 0's deep candidate (1) falls 5 mm beside object 1's
    candidate 0 and would stand beside its candidate 1, with which it overlaps: that context
    does not count. Off (the default): equal weights; on: exp(4 mm / rest_drop_m) apart,
    object 1 (the same fall for both) unchanged."""
    from ipr_shapes.inference import (
        medoid_weights,
        own_log_likelihoods,
        rest_evidence,
        rest_log_likelihoods,
    )

    overlap = np.array([[True, True], [True, False]])  # object 0's 1 with object 1's 1
    problem = _fabricated_problem(2, compatible={(0, 1): overlap})
    assert problem.config.rest_drop_m is None
    drawn = [(0, 0), (1, 0), (0, 1), (0, 0)]

    def drops(choice):
        deep = 0.005 if choice[1] == 0 else 0.0
        return (np.array([0.001, deep]), np.array([0.0005, 0.0005]))

    results = [
        dataclasses.replace(_result(s, c, [0.02, 0.03], (0.0, 0.0)), drops=drops(c))
        for s, c in enumerate(drawn)
    ]
    assert medoid_weights(results, problem)[0] == pytest.approx([0.5, 0.5])
    assert rest_evidence(results, problem) is None
    on = dataclasses.replace(problem, config=dataclasses.replace(problem.config, rest_drop_m=0.002))
    evidence = rest_evidence(results, on)
    assert evidence[0] == pytest.approx([-0.001 / 0.002, -0.005 / 0.002])
    assert evidence[1] == pytest.approx([-0.0005 / 0.002] * 2)
    weights = medoid_weights(results, on)
    assert weights[0][0] / weights[0][1] == pytest.approx(np.exp(0.004 / 0.002))
    assert weights[1] == pytest.approx([0.5, 0.5])
    # The chosen candidate's term in its own term; nothing without drops; flung: impossible.
    depth = own_log_likelihoods(results[1], problem)
    assert own_log_likelihoods(results[1], on) - depth == pytest.approx(
        np.array([[-0.005, -0.0005]]) / 0.002
    )
    assert rest_log_likelihoods(dataclasses.replace(results[1], drops=None), on).tolist() == [0, 0]
    flung = dataclasses.replace(results[0], drops=(np.array([np.inf, 0.0]), np.zeros(2)))
    assert own_log_likelihoods(flung, on)[0, 0] == -np.inf
    # A candidate no sample chose takes its object's mean depth evidence and its own rest
    # evidence (not the exploration ratio, here 1/9).
    explored = (np.array([0.9, 0.1]), np.array([0.5, 0.5]))
    undrawn = [dataclasses.replace(r, exploration=explored) for r in results if r.choice[0] == 0]
    assert medoid_weights(undrawn, problem)[0][1] == pytest.approx(0.1)
    weights = medoid_weights(undrawn, on)
    assert weights[0][0] / weights[0][1] == pytest.approx(np.exp(0.004 / 0.002))


def test_rest_evidence_tells_a_shape_that_falls_from_the_true_one_where_the_depth_cannot():
    """The true box and the top slab that hangs 2.5 cm above the table, with the depth made
    nearly blind (alpha 1e-6) and the stability tests not steering the draws (alpha 0): off,
    the two weigh about the same; on, the slab's 2.5 cm fall in its test counts against it
    (``Sampler.rest_drops``), and each sample's likelihood holds the rest terms."""
    frame, labels = _frame(0, (0.0, -0.35, 0.3))
    observed = observed_frames([frame], [labels], 4)
    blind = InferenceConfig(
        max_samples=12, stability_alpha_per_m=0.0, likelihood=LikelihoodConfig(alpha_per_m=1e-6)
    )
    outcomes = {}
    for scale in (None, 0.004):
        outcomes[scale] = infer_shapes(
            _prepared(TRUE_BOX, TOP_SLAB), (SUPPORT,), observed, method="ipr+uniform",
            config=dataclasses.replace(blind, rest_drop_m=scale), workers=1,
        )  # fmt: skip
    off, on = outcomes[None], outcomes[0.004]
    assert {s.choice for s in off.samples} == {(0,), (1,)}
    assert all(s.drops is None for s in off.samples)
    assert 0.3 < off.posteriors[0].probabilities[0] < 0.7
    for s in on.samples:  # both candidates tested in every sample
        assert s.drops[0][0] < 1e-3 and s.drops[0][1] > 0.02
        depth = next(o for o in off.samples if o.choice == s.choice).log_likelihood
        assert s.log_likelihood == pytest.approx(depth - s.drops[0][s.choice[0]] / 0.004)
    assert on.posteriors[0].probabilities[0] > 0.99 and on.posteriors[0].best == 0


#: The true box with a hidden part 1.5 cm too deep: sunk into the table (the same seen surface).
SUNK_BOX = _hypothesis(1, [-0.05, -0.03, -0.015], [0.05, 0.03, 0.04])


@pytest.mark.parametrize("drawn_models", ["exact", "factorised"])
def test_rest_lift_tells_a_shape_too_large_below_the_support_from_the_true_one(drawn_models):
    """The true box and one whose hidden part reaches 1.5 cm into the table, the depth made
    nearly blind: with the rest evidence on falls alone the two weigh about the same (the sunk
    box is pushed up, it does not fall); with ``rest_lift`` its rise counts against it at the
    same scale, each sample's stability test keeps the signed motion (< 0 for the rise), and
    the tree sampler still sees the falls alone (the same draws)."""
    frame, labels = _frame(0, (0.0, -0.35, 0.3))
    observed = observed_frames([frame], [labels], 4)
    blind = InferenceConfig(
        max_samples=12,
        stability_alpha_per_m=0.0,
        likelihood=LikelihoodConfig(alpha_per_m=1e-6),
        rest_drop_m=0.004,
        drawn_models=drawn_models,  # the drawn models' own weights, or the unary factors alone
    )
    outcomes = {}
    for lift in (False, True):
        outcomes[lift] = infer_shapes(
            _prepared(TRUE_BOX, SUNK_BOX), (SUPPORT,), observed, method="ipr+uniform",
            config=dataclasses.replace(blind, rest_lift=lift), workers=1,
        )  # fmt: skip
    falls, lifts = outcomes[False], outcomes[True]
    assert [s.choice for s in falls.samples] == [s.choice for s in lifts.samples]
    assert {s.choice for s in falls.samples} == {(0,), (1,)}
    for s in falls.samples:
        assert s.drops[0][0] < 1e-3 and 0.0 <= s.drops[0][1] < 1e-3
    assert 0.3 < falls.posteriors[0].probabilities[0] < 0.7
    for s, f in zip(lifts.samples, falls.samples, strict=True):
        assert abs(s.drops[0][0]) < 1e-3 and s.drops[0][1] < -0.005  # pushed up out of the table
        assert s.log_likelihood == pytest.approx(
            f.log_likelihood
            - abs(s.drops[0][s.choice[0]]) / 0.004
            + f.drops[0][s.choice[0]] / 0.004
        )
    assert lifts.posteriors[0].probabilities[0] > 0.8 and lifts.posteriors[0].best == 0


def _box_face_points() -> np.ndarray:
    """(N, 3) points on the true box's front (y = -3 cm) and back (y = +3 cm) faces, as if
    seen from both sides (m, world), one per 5 mm cell (at the cells' centres in x and z)."""
    xs = np.arange(-0.0475, 0.048, 0.005)
    zs = np.arange(0.0025, 0.038, 0.005)
    face = np.array([[x, 0.0, z] for x in xs for z in zs])
    return np.concatenate([face + [0.0, y, 0.0] for y in (-0.03, 0.03)])


def test_surface_fit_scores_a_candidate_by_its_misfit_to_the_seen_surface():
    """``surface_log_likelihoods``: the true box passes through every point (misfit 0); the
    deep box shares the front face, and the back face's points lie inside it, each as far from
    its boundary as its nearest plane: -e^2 / (2 s^2) with e the root mean square of those
    distances over the points (one per 5 mm cell) and s^2 = pitch^2 / 12 (the floor, the
    closest candidate's distance, is 0 at every point). Fewer than two candidates or no point:
    zeros."""
    from ipr_shapes.inference import surface_log_likelihoods

    points = _box_face_points()
    pitch = TRUE_BOX.voxel_pitch_m
    low, high = np.array([-0.05, -0.03, 0.0]), np.array([0.05, 0.09, 0.04])
    inside = np.minimum(points - low, high - points).min(axis=1)
    e2 = np.mean(inside**2)  # the front face's points are on the deep box's boundary: 0
    assert e2 > 0
    scores = surface_log_likelihoods((TRUE_BOX, DEEP_BOX), points)
    assert scores[0] == 0.0
    assert scores[1] == pytest.approx(-e2 / (2 * pitch**2 / 12))
    # Reversed order, the same scores; one candidate or no point: nothing to compare.
    assert surface_log_likelihoods((DEEP_BOX, TRUE_BOX), points) == pytest.approx(scores[::-1])
    assert surface_log_likelihoods((TRUE_BOX,), points).tolist() == [0.0]
    assert surface_log_likelihoods((TRUE_BOX, DEEP_BOX), np.zeros((0, 3))).tolist() == [0.0, 0.0]


def test_surface_fit_multiplies_every_candidates_evidence_in_every_weighting():
    """With ``surface_log_likelihood`` each candidate's weight is its physics evidence times
    its surface likelihood: drawn or not, under "hypothesis" weighting (marginals and medoid
    weights), "object" and "joint"; without it (the default) the weights are main's."""
    from ipr_shapes.inference import marginals, medoid_weights

    surface = (np.array([0.0, -1.5]),)
    plain = _fabricated_problem(1)
    fitted = dataclasses.replace(plain, surface_log_likelihood=surface)
    scale = plain.config.likelihood.alpha_per_m * plain.observed.decimation
    # Candidate 1 fits the depth better by 0.01 of error norm; its surface worse by 1.5.
    results = [_result(0, (0,), [0.05], (np.log(0.5),)), _result(1, (1,), [0.04], (np.log(0.5),))]
    for estimate in (marginals, medoid_weights):
        before, after = estimate(results, plain)[0], estimate(results, fitted)[0]
        assert before[1] / before[0] == pytest.approx(np.exp(scale * 0.01))
        assert after[1] / after[0] == pytest.approx(np.exp(scale * 0.01 - 1.5))
    for weighting in ("object", "joint"):
        config = dataclasses.replace(plain.config, weighting=weighting)
        before = marginals(results, dataclasses.replace(plain, config=config))[0]
        after = marginals(results, dataclasses.replace(fitted, config=config))[0]
        assert after[1] / after[0] == pytest.approx(before[1] / before[0] * np.exp(-1.5))
    # Only candidate 0 drawn: candidate 1 has no evidence of its own, but its surface term.
    assert marginals(results[:1], plain)[0] == pytest.approx([0.5, 0.5])
    only = marginals(results[:1], fitted)[0]
    assert only[1] / only[0] == pytest.approx(np.exp(-1.5))


def test_surface_fit_tells_the_true_box_from_a_deeper_one_the_depth_cannot():
    """From the low camera the true box and the deep one (the same front and top, 6 cm deeper
    behind) render alike: gravity alone leaves them both probable. With the box's back face
    among its observed points (as a view from behind would give) and ``surface_fit`` on, the
    deep box, whose surface runs 6 cm behind that face, is ruled out; with it off (the
    default) or no points given the result is the same as before."""
    observed = _push_scene().only(1)
    points = {1: _box_face_points()}

    def run(config, points=None):
        return infer_shapes(
            _prepared(TRUE_BOX, DEEP_BOX), (SUPPORT,), observed,
            method="ipr+uniform", config=config, workers=1, points=points,
        )  # fmt: skip

    assert InferenceConfig().surface_fit is False
    off = run(InferenceConfig(max_samples=8), points)
    assert 0.2 < off.posteriors[0].probabilities[0] < 0.8
    on = run(InferenceConfig(max_samples=8, surface_fit=True), points)
    assert on.posteriors[0].probabilities[0] > 0.999 and on.posteriors[0].best == 0
    assert [s.choice for s in on.samples] == [s.choice for s in off.samples]
    missing = run(InferenceConfig(max_samples=8, surface_fit=True))
    assert missing.posteriors[0].probabilities == pytest.approx(off.posteriors[0].probabilities)


def test_the_pipeline_hands_the_objects_points_to_the_surface_fit(scene_dir, monkeypatch):
    """With ``surface_fit`` on, ``run_pipeline`` gives the physics methods each frame-0
    object's observed points (the fused ones with the views); with it off, none (on the
    "uniform" medoid base, which reads no points)."""
    from ipr_shapes import pipeline
    from ipr_shapes.config import Config
    from ipr_shapes.scene import load_scene

    seen = []
    original = pipeline.infer_shapes

    def recording(*args, **kwargs):
        seen.append(kwargs.get("points"))
        return original(*args, **kwargs)

    monkeypatch.setattr(pipeline, "infer_shapes", recording)
    base = Config()
    for fit in (True, False):
        config = dataclasses.replace(
            base,
            inference=dataclasses.replace(base.inference, surface_fit=fit, medoid_base="uniform"),
        )
        result = pipeline.run_pipeline(
            load_scene(scene_dir), config, method="ipr+uniform", samples=2, workers=1
        )
    on, off = seen
    assert off is None
    objects = result.perception.objects[0]
    assert objects and sorted(on) == sorted(o.id for o in objects)
    assert all(np.array_equal(on[o.id], o.points) for o in objects)


def test_the_collision_checkers_medoid_weights_are_the_physics_medoids_base():
    """The six 4 cm near-copies from Algorithm 1 and a 7 and a 7.2 cm cube from two other
    families, 90 % of the outline hidden, seen points on the large cubes' far face: the
    Collision Checker's default (outline-fit) medoid is a large cube, each candidate once gives
    a small one. With evidence that says nothing, the physics medoid on the
    "collision-checker" base (the default) is a large cube, on the "uniform" base each
    candidate once's; an outline all seen leaves the two bases the same; evidence still
    moves the choice: with a small cube the evidence favours 100:1, a small cube on either
    base."""
    from ipr_shapes.collision_checker import CollisionCheckerConfig, uniform_posteriors
    from ipr_shapes.inference import physics_medoid
    from tests.test_collision_checker import _three_families_of_cubes

    prepared, _, large_face = _three_families_of_cubes()
    checker = CollisionCheckerConfig(medoid_weights="outline-fit")
    (answer,) = uniform_posteriors(prepared, checker, hidden={1: 0.9}, points={1: large_face})
    (start,) = uniform_posteriors(prepared)  # the physics methods' starting answer
    generator = lambda best: start.hypotheses[best].generator  # noqa: E731
    large = ("sphere", "superquadric")
    assert generator(answer.best) in large
    assert generator(start.best) == "algorithm1"
    candidates = np.flatnonzero(start.probabilities > 0)
    flat = np.full(candidates.size, 1.0 / candidates.size)

    def medoid(weights, base, hidden=0.9):
        return physics_medoid(
            start, candidates, weights, None, base, checker, hidden, large_face
        )  # fmt: skip

    assert InferenceConfig().medoid_base == "collision-checker"
    assert generator(medoid(flat, "collision-checker")) in large
    assert medoid(flat, "uniform") == start.best
    assert medoid(flat, "collision-checker", hidden=0.0) == start.best
    favoured = flat.copy()
    favoured[2] *= 100.0
    favoured /= favoured.sum()
    assert generator(medoid(favoured, "collision-checker")) == "algorithm1"
    assert generator(medoid(favoured, "uniform")) == "algorithm1"


def test_the_pipeline_hands_the_outline_and_points_to_the_collision_checker_base(
    scene_dir, monkeypatch
):
    """With ``medoid_base = "collision-checker"`` ``run_pipeline`` gives the physics methods
    each frame-0 object's hidden outline fraction, observed points and their viewpoints (the
    camera centre for its own pixels); with "uniform", none of them."""
    from ipr_shapes import pipeline
    from ipr_shapes.config import Config
    from ipr_shapes.scene import load_scene

    seen = []
    original = pipeline.infer_shapes

    def recording(*args, **kwargs):
        seen.append({k: kwargs.get(k) for k in ("hidden", "points", "viewpoints")})
        return original(*args, **kwargs)

    monkeypatch.setattr(pipeline, "infer_shapes", recording)
    base = Config()
    scene = load_scene(scene_dir)
    for medoid_base in ("collision-checker", "uniform"):
        config = dataclasses.replace(
            base, inference=dataclasses.replace(base.inference, medoid_base=medoid_base)
        )
        result = pipeline.run_pipeline(scene, config, method="ipr+uniform", samples=2, workers=1)
    on, off = seen
    assert off == {"hidden": None, "points": None, "viewpoints": None}
    objects = result.perception.objects[0]
    ids = sorted(o.id for o in objects)
    assert objects and sorted(on["hidden"]) == ids and sorted(on["points"]) == ids
    assert all(0.0 <= h <= 1.0 for h in on["hidden"].values())
    camera = np.asarray(scene.frames[0].world_from_camera, float)[:3, 3]
    for o in objects:
        assert np.array_equal(on["points"][o.id], o.points)
        assert on["viewpoints"][o.id][0] == pytest.approx(camera)


@pytest.mark.parametrize("pushed_frames", ["each", "trajectory"])
def test_the_pushed_frames_as_one_trajectory_weigh_as_much_as_the_frame_at_rest(pushed_frames):
    from ipr_shapes.inference import marginals, medoid_weights

    # Frame 0 at rest, then two frames after two pushes. Candidate 0 fits the frame at rest
    # better by 0.3 of depth error norm; candidate 1 fits each pushed frame better by 0.2, the
    # same divergence seen twice. Summed, the pushes outweigh the rest (0.4 > 0.3); as one
    # trajectory (their mean, 0.2) they do not.
    base = _fabricated_problem(1)
    frame, labels = _frame(0, LOW_EYE)
    observed = observed_frames(
        [dataclasses.replace(frame, index=i) for i in range(3)], [labels] * 3, 4
    )
    config = dataclasses.replace(
        base.config, likelihood=LikelihoodConfig(pushed_frames=pushed_frames)
    )
    pushes = tuple(dataclasses.replace(BEHIND, before_frame=i - 1, after_frame=i) for i in (1, 2))
    problem = dataclasses.replace(
        base, observed=observed, pushes=pushes, pusher=Pusher(), config=config
    )
    from ipr_shapes.inference import SampleResult

    def result(index, choice, norms):
        norms = np.asarray(norms, float)[None, :, None]
        return SampleResult(index, (choice,), 0.0, -1.0, 0.0, 0.0, 0, norms, (0.0,))

    results = [result(0, 0, [0.1, 0.5, 0.5]), result(1, 1, [0.4, 0.3, 0.3])]
    scale = problem.config.likelihood.alpha_per_m * problem.observed.decimation
    margin = 0.3 - (0.4 if pushed_frames == "each" else 0.2)
    weights = medoid_weights(results, problem)[0]
    assert weights[0] / weights[1] == pytest.approx(np.exp(scale * margin))
    assert marginals(results, problem)[0][0] / marginals(results, problem)[0][1] == pytest.approx(
        np.exp(scale * margin)
    )
