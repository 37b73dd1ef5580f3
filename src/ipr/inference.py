"""Inverse physics reasoning (paper Sec. IV-F, Algorithm 2): marginal shape posteriors from
tree sampling of joint models scored by physics simulation.

Hypotheses come from ``ipr.collision_checker.prepare_hypotheses`` (Algorithm 1 with the unary
and pairwise constraints); only hypotheses the Collision Checker gives non-zero probability (part
of some jointly feasible model) are candidates. Then, repeated until the time budget:

1. **Tree sampling of one joint model.** Starting from the support (and walls) alone, at each
   stage every unplaced object i gets exploration probabilities over its candidates j:
   exp(-alpha_s * dist_ij), where dist_ij is how far (mean vertex displacement, m) hypothesis j
   moves in ``stability_s`` of simulated gravity among the placed objects (at their sampled
   shapes) and the unplaced ones (at their minimum shapes), and 0 when j overlaps a placed
   object's sampled shape (Constraints(X)). The object with the largest total ("mass") is
   placed, with a hypothesis drawn from its normalised exploration probabilities.
   - The other objects are static during a stability test (only i's hypotheses move): all of
     i's candidates are tested in one simulation as mutually transparent bodies
     (``ipr.physics``), and dist_ij depends only on i's *neighbours* (objects whose candidate
     envelopes come within ``neighbour_margin_m`` of i's). The result is cached under (i, the
     neighbours' current shapes), so the same partial scene is never simulated twice; the first
     stage is shared by every sample.
2. **Simulation of the full model** under gravity (settling) and, for the ``+action`` variants,
   the recorded pushes; the depth images rendered from each frame's camera give the likelihood
   (``ipr.likelihood``, Eq. 2). A simulation that explodes or flings an object scores 0.
3. **From samples to marginals** (``InferenceConfig.weighting``). Eq. 2's exponent is a sum over
   objects, so each object's evidence is its own term. Default ``"hypothesis"``: each
   candidate's likelihood is the mean over the samples that chose it of exp(its own term);
   with the priors as unary factors and the pairwise constraints as 0/1 factors, the marginals
   follow by exact variable elimination (as the Collision Checker's do). Candidates no sample
   chose get no probability, as with importance weights. The exploration probabilities decide what is visited,
   not how much it weighs, so rare draws do not carry huge weights. ``"object"``: Algorithm
   2's per-object update, w_i = P(O_i | X, mu) P(X_i) / q_i with q_i the exploration
   probability with which X_i was drawn; the estimate of P(X_i^j | O, mu) is the
   self-normalised sum of w_i over the samples that chose j. ``"joint"``: the full
   w = P(O | X, mu) P(X) / q(X) for every object (q(X) the product of the draws' exploration
   probabilities; the object order is a deterministic function of earlier draws): consistent
   for the joint posterior, but at the sample counts a budget allows its effective sample size
   was about 1 on development scenes and its shapes were worse (docs/DESIGN_NOTES.md).

Priors: ``uniform``, or ``size``: P(X_i^j) proportional to volume(X_i^j)^-size_prior_exponent
(smaller models are more probable, the paper's informed prior), normalised per object.

Output per object: the posterior medoid under voxel IoU (the Bayes choice under IoU loss), as the
Collision Checker does. Anytime: before the first sample finishes the answer is the Collision
Checker's; a budget too small for one sample returns it and says so. Samples are independent
given their index (each draws from ``default_rng([seed, index])``), so a run with ``max_samples``
and no deadline gives the same result with any number of workers.

``exhaustive`` scores every jointly feasible joint model with the same likelihood (for scenes of
at most ``max_exhaustive_objects`` objects and ``max_exhaustive_models`` models): the exact
posterior the sampler estimates, to validate it.
"""

from __future__ import annotations

import itertools
import logging
import math
import multiprocessing
import os
import queue
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ipr.collision_checker import (
    CollisionCheckerConfig,
    ObjectPosterior,
    PreparedHypotheses,
    TableTooLarge,
    exact_marginals,
    interaction_components,
    posterior_medoid,
    uniform_posteriors,
)
from ipr.errors import IprError
from ipr.hypotheses import ShapeHypothesis
from ipr.likelihood import (
    LikelihoodConfig,
    ObservedFrames,
    depth_error_norms,
    log_likelihood,
)
from ipr.methods import DEFAULT_METHOD, PHYSICS_METHODS
from ipr.perception.types import KnownPlane
from ipr.physics import Body, PhysicsConfig, build_world
from ipr.scene import Push, Pusher

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Variant:
    """An inference method: whether the pushes are replayed, and the shape prior."""

    actions: bool
    prior: str  # "uniform" or "size"
    exhaustive: bool = False


#: The physics-based methods (the paper's names) and the sampler's validation.
VARIANTS: dict[str, Variant] = {
    "ipr+uniform": Variant(False, "uniform"),
    "ipr+size": Variant(False, "size"),
    "ipr+action+uniform": Variant(True, "uniform"),
    "ipr+action+size": Variant(True, "size"),
    "exhaustive": Variant(True, "uniform", exhaustive=True),
}
assert tuple(VARIANTS) == PHYSICS_METHODS, "ipr.methods lists the same methods"


#: How samples become marginals (``InferenceConfig.weighting``).
WEIGHTINGS = ("hypothesis", "object", "joint")
#: How far a candidate moves in a stability test (``InferenceConfig.stability_measure``).
STABILITY_MEASURES = ("drop", "displacement")


@dataclass(frozen=True)
class InferenceConfig:
    """Settings of IPR inference (module doc).

    Attributes:
        physics: the simulated world's parameters.
        likelihood: Eq. 2's parameters.
        stability_alpha_per_m: alpha of the exploration probabilities exp(-alpha * dist)
            (1/m): a hypothesis that moves 1 cm while settling is e^-1 as likely to be explored
            as one that stays put.
        neighbour_margin_m: objects whose candidate envelopes are this close interact in
            stability tests.
        budget_per_object_s: default inference budget (s) per object when no time budget is
            given (hypotheses and perception come on top: about 0.5 s per object more, so that
            a whole run stays within 3 s per object on two cores).
        max_samples: stop after this many samples (None: only the budget stops).
        workers: processes evaluating samples (None: all cores; 1: in this process).
        size_prior_exponent: the size prior's exponent (module doc).
        max_exhaustive_objects: largest scene ``exhaustive`` accepts.
        max_exhaustive_models: largest number of joint models ``exhaustive`` accepts.
        weighting: how samples become marginals (module doc, step 3): "hypothesis" (each
            candidate's own likelihood term averaged over the samples that chose it, combined
            with the priors and the pairwise constraints by exact elimination), "object" (each
            object's marginal weighs samples by its own likelihood term, prior and exploration
            probability, Algorithm 2's per-object update) or "joint" (every object by the
            joint weight).
        stability_measure: a candidate's distance in a stability test: "drop" (how far its
            centre of mass fell) or "displacement" (how far its vertices moved, on average).
        max_factor_table: largest table (entries) of the exact elimination of "hypothesis"
            weighting; larger components combine their objects' factors independently.
    """

    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    likelihood: LikelihoodConfig = field(default_factory=LikelihoodConfig)
    stability_alpha_per_m: float = 100.0
    neighbour_margin_m: float = 0.02
    budget_per_object_s: float = 1.75
    max_samples: int | None = None
    workers: int | None = None
    size_prior_exponent: float = 1.0
    max_exhaustive_objects: int = 4
    max_exhaustive_models: int = 20_000
    weighting: str = "hypothesis"
    stability_measure: Literal["drop", "displacement"] = "drop"
    max_factor_table: float = 1e6

    def __post_init__(self) -> None:
        if not self.stability_alpha_per_m >= 0:
            raise ValueError("stability_alpha_per_m must be >= 0")
        if not self.budget_per_object_s > 0:
            raise ValueError("budget_per_object_s must be positive")
        if self.max_samples is not None and self.max_samples < 1:
            raise ValueError("max_samples must be at least 1")
        if self.workers is not None and self.workers < 1:
            raise ValueError("workers must be at least 1")
        if not self.max_factor_table >= 1:
            raise ValueError(f"max_factor_table must be >= 1, got {self.max_factor_table}")
        if self.weighting not in WEIGHTINGS:
            raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {self.weighting!r}")
        if self.stability_measure not in STABILITY_MEASURES:
            raise ValueError(
                f"stability_measure must be one of {STABILITY_MEASURES}, "
                f"got {self.stability_measure!r}"
            )


# --------------------------------------------------------------------------------------------
# The problem every worker solves


@dataclass(frozen=True, eq=False)
class InferenceProblem:
    """Everything a sampler needs (picklable, sent once to each worker).

    Objects are referred to by position k (0..n-1) and candidates by position j into
    ``candidates[k]``.

    Attributes:
        ids: (n,) object ids.
        candidates: per object, its candidate hypotheses.
        minima: per object, its minimum shape.
        compatible: (a, b) with a < b -> (m_a, m_b) bool, False where the pair overlaps too much.
        neighbours: per object, the positions of the objects it can touch.
        log_prior: per object, (m_k,) log prior probabilities (normalised).
        planes: frame-0 support and walls.
        pusher: the pusher (None: no pushes).
        pushes: the pushes replayed (empty for the gravity-only variants).
        observed: the observed frames compared (frame 0 first).
        config: settings.
        seed: samples draw from ``default_rng([seed, index])``.
    """

    ids: tuple[int, ...]
    candidates: tuple[tuple[ShapeHypothesis, ...], ...]
    minima: tuple[ShapeHypothesis, ...]
    compatible: dict[tuple[int, int], np.ndarray]
    neighbours: tuple[tuple[int, ...], ...]
    log_prior: tuple[np.ndarray, ...]
    planes: tuple[KnownPlane, ...]
    pusher: Pusher | None
    pushes: tuple[Push, ...]
    observed: ObservedFrames
    config: InferenceConfig
    seed: int

    @property
    def count(self) -> int:
        """Number of objects n."""
        return len(self.ids)

    def compatibility(self, i: int, k: int) -> np.ndarray:
        """(m_i, m_k) bool: candidates of i that may coexist with each candidate of k."""
        if (i, k) in self.compatible:
            return self.compatible[(i, k)]
        if (k, i) in self.compatible:
            return self.compatible[(k, i)].T
        return np.ones((len(self.candidates[i]), len(self.candidates[k])), dtype=bool)


@dataclass(frozen=True)
class SampleResult:
    """One evaluated joint model.

    ``choice`` (n,) candidate positions; ``log_proposal`` log q(X) (0 for exhaustive);
    ``log_likelihood`` log P(O | X, mu) (-inf: exploded or flung); ``log_prior`` log P(X);
    ``seconds`` wall time spent; ``stability_tests`` simulations run for exploration;
    ``norms`` (T, n) the depth error norms per compared frame and object (at the comparison
    resolution; None when the simulation failed); ``object_log_proposal`` (n,) each object's
    own log exploration probability.
    """

    index: int
    choice: tuple[int, ...]
    log_proposal: float
    log_likelihood: float
    log_prior: float
    seconds: float
    stability_tests: int
    norms: np.ndarray | None = None
    object_log_proposal: tuple[float, ...] = ()

    @property
    def log_weight(self) -> float:
        """log of the importance weight P(O|X) P(X) / q(X)."""
        return self.log_likelihood + self.log_prior - self.log_proposal


class _Deadline(Exception):
    """The time budget ran out in the middle of a sample."""


class Sampler:
    """Tree sampling and likelihood evaluation of one problem, with its stability cache.

    One per process: it owns an offscreen renderer (created on first use).
    """

    def __init__(self, problem: InferenceProblem) -> None:
        self.problem = problem
        self.cache: dict[tuple, np.ndarray] = {}
        # Depth error norms of the joint models already simulated: the simulation and
        # rendering are deterministic, so a model drawn again costs only its tree sampling.
        self.evaluated: dict[tuple[int, ...], np.ndarray | None] = {}
        self.stability_tests = 0
        self._renderer = None

    # ----------------------------------------------------------------------------------------
    # Exploration probabilities

    def _distances(self, i: int, placed: dict[int, int], deadline: float) -> np.ndarray:
        """(m_i,) how far each candidate of i falls among its neighbours (cached).

        A world per context: compiling it (about 18 ms for 7 objects) cost the same as
        keeping one world per object with every neighbour shape and switching them on and off,
        whose extra geoms slowed every step (measured on development scenes)."""
        problem = self.problem
        context = tuple((k, placed.get(k, -1)) for k in problem.neighbours[i])
        key = (i, context)
        cached = self.cache.get(key)
        if cached is not None:
            return cached
        if time.perf_counter() > deadline:
            raise _Deadline
        bodies = [
            Body(shape.vertices, shape.faces, dynamic=False)
            for shape in (
                problem.candidates[k][j] if j >= 0 else problem.minima[k] for k, j in context
            )
        ]
        candidates = problem.candidates[i]
        bodies += [Body(h.vertices, h.faces, candidate=True) for h in candidates]
        world = build_world(bodies, problem.planes, problem.config.physics)
        world.settle(problem.config.physics.stability_s)
        self.stability_tests += 1
        if world.exploded and len(candidates) > 1:
            # One unstable candidate spoils a shared simulation: test them one by one.
            distances = np.concatenate(
                [self._single_distance(bodies[: len(context)], h) for h in candidates]
            )
        else:
            distances = self._measure(world)[len(context) :]
        self.cache[key] = distances
        return distances

    def _single_distance(self, context: list[Body], h: ShapeHypothesis) -> np.ndarray:
        world = build_world(
            [*context, Body(h.vertices, h.faces)], self.problem.planes, self.problem.config.physics
        )
        world.settle(self.problem.config.physics.stability_s)
        self.stability_tests += 1
        return self._measure(world)[-1:]

    def _measure(self, world) -> np.ndarray:
        """Per body, the stability test's distance (``InferenceConfig.stability_measure``)."""
        if self.problem.config.stability_measure == "drop":
            return world.drops()
        return world.displacements()

    def exploration(self, i: int, placed: dict[int, int], deadline: float = math.inf):
        """(m_i,) unnormalised exploration probabilities of object i's candidates given the
        placed objects' candidate positions (module doc, step 1)."""
        problem = self.problem
        allowed = np.ones(len(problem.candidates[i]), dtype=bool)
        for k, j in placed.items():
            allowed &= problem.compatibility(i, k)[:, j]
        distances = self._distances(i, placed, deadline)
        with np.errstate(over="ignore"):
            probabilities = np.exp(-problem.config.stability_alpha_per_m * distances)
        return np.where(allowed, probabilities, 0.0)

    def tree_sample(
        self, rng: np.random.Generator, deadline: float = math.inf
    ) -> tuple[tuple[int, ...], tuple[float, ...]]:
        """Draw one joint model (candidate positions) and each object's log exploration
        probability (their sum is log q(X))."""
        n = self.problem.count
        placed: dict[int, int] = {}
        log_proposal = [0.0] * n
        for _ in range(n):
            best, best_mass, best_probabilities = -1, -1.0, None
            for i in range(n):
                if i in placed:
                    continue
                probabilities = self.exploration(i, placed, deadline)
                mass = float(probabilities.sum())
                if mass > best_mass:
                    best, best_mass, best_probabilities = i, mass, probabilities
            if best_mass <= 0:
                # Nothing of this object fits or stays: explore its candidates uniformly.
                best_probabilities = np.ones(len(self.problem.candidates[best]))
                best_mass = float(best_probabilities.size)
            distribution = best_probabilities / best_mass
            j = int(rng.choice(distribution.size, p=distribution))
            placed[best] = j
            log_proposal[best] = math.log(distribution[j])
        return tuple(placed[i] for i in range(n)), tuple(log_proposal)

    # ----------------------------------------------------------------------------------------
    # Likelihood

    def _renderer_for(self, width: int, height: int):
        from ipr.rendering import Renderer

        if self._renderer is None or (self._renderer.width, self._renderer.height) != (
            width,
            height,
        ):
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = Renderer(width, height)
        return self._renderer

    def depth_norms(self, choice: Sequence[int], deadline: float = math.inf) -> np.ndarray | None:
        """(T, n) depth error norms of the joint model ``choice`` per compared frame and object
        (module doc, step 2); None when the simulation exploded or flung an object."""
        problem = self.problem
        observed = problem.observed
        shapes = [problem.candidates[k][j] for k, j in enumerate(choice)]
        world = build_world(
            [Body(h.vertices, h.faces) for h in shapes],
            problem.planes,
            problem.config.physics,
            pusher=problem.pusher if problem.pushes else None,
            cameras=observed.cameras,
            render_static=True,
        )
        world.settle()
        width = max(c.width for c in observed.cameras)
        height = max(c.height for c in observed.cameras)
        renderer = self._renderer_for(width, height)
        ids = np.asarray(problem.ids, dtype=np.int32)
        norms = []
        for position, frame in enumerate(observed.frames):
            for push in problem.pushes:
                if push.after_frame == frame:
                    if time.perf_counter() > deadline:
                        raise _Deadline
                    world.push(push)
            if world.exploded or world.flung().any():
                return None
            depth, index = world.render(renderer, world.cameras[position])
            predicted_ids = np.where(index >= 0, ids[np.maximum(index, 0)], 0)
            norms.append(
                depth_error_norms(
                    observed.depth_m[position],
                    observed.labels[position],
                    observed.ignore[position],
                    depth,
                    predicted_ids,
                    problem.ids,
                    problem.config.likelihood,
                )
            )
        return np.array(norms)

    def _norms_of(self, choice: tuple[int, ...], deadline: float) -> np.ndarray | None:
        """``depth_norms`` of ``choice``, simulated once per sampler."""
        if choice not in self.evaluated:
            self.evaluated[choice] = self.depth_norms(choice, deadline)
        return self.evaluated[choice]

    def log_likelihood_of(self, norms: np.ndarray | None) -> float:
        """log P(O | X, mu) from ``depth_norms`` (-inf for a failed simulation)."""
        if norms is None:
            return -math.inf
        return log_likelihood(
            norms, self.problem.observed.decimation, self.problem.config.likelihood
        )

    def log_prior(self, choice: Sequence[int]) -> float:
        """log P(X) of a joint model (product of the objects' priors)."""
        return float(sum(self.problem.log_prior[k][j] for k, j in enumerate(choice)))

    def sample(self, index: int, deadline: float = math.inf) -> SampleResult:
        """Tree-sample joint model number ``index`` and score it."""
        started = time.perf_counter()
        tests = self.stability_tests
        rng = np.random.default_rng([self.problem.seed, index])
        choice, object_log_proposal = self.tree_sample(rng, deadline)
        norms = self._norms_of(choice, deadline)
        return SampleResult(
            index,
            choice,
            float(sum(object_log_proposal)),
            self.log_likelihood_of(norms),
            self.log_prior(choice),
            time.perf_counter() - started,
            self.stability_tests - tests,
            norms,
            object_log_proposal,
        )

    def score(self, index: int, choice: Sequence[int], deadline: float = math.inf):
        """Score a given joint model (exhaustive enumeration): proposal probability 1."""
        started = time.perf_counter()
        norms = self._norms_of(tuple(choice), deadline)
        return SampleResult(
            index, tuple(choice), 0.0, self.log_likelihood_of(norms), self.log_prior(choice),
            time.perf_counter() - started, 0, norms, (0.0,) * len(choice),
        )  # fmt: skip

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


# --------------------------------------------------------------------------------------------
# Running samples in this process or in a pool of workers

_WORKER: Sampler | None = None
#: Seconds to wait past the deadline for samples in flight to stop themselves.
_GRACE_S = 10.0


def _init_worker(problem: InferenceProblem) -> None:
    global _WORKER
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    _WORKER = Sampler(problem)


def _worker_task(task: tuple[int, tuple[int, ...] | None, float]) -> SampleResult | None:
    index, choice, monotonic_deadline = task
    # time.monotonic is one clock for every process of the machine; perf_counter may not be.
    deadline = time.perf_counter() + (monotonic_deadline - time.monotonic())
    try:
        if choice is None:
            return _WORKER.sample(index, deadline)
        return _WORKER.score(index, choice, deadline)
    except _Deadline:
        return None


def default_workers() -> int:
    """All cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def run_samples(
    problem: InferenceProblem,
    tasks: Iterable[tuple[int, tuple[int, ...] | None]],
    *,
    workers: int,
    deadline: float,
) -> list[SampleResult]:
    """Evaluate ``tasks`` ((index, None) = tree sample ``index``; (index, choice) = score that
    joint model) until they run out or ``deadline`` (``time.perf_counter()``) passes; results
    in task order, unfinished tasks dropped."""
    results: list[SampleResult] = []
    tasks = iter(tasks)
    if workers <= 1:
        sampler = Sampler(problem)
        try:
            for index, choice in tasks:
                if time.perf_counter() >= deadline:
                    break
                try:
                    if choice is None:
                        results.append(sampler.sample(index, deadline))
                    else:
                        results.append(sampler.score(index, choice, deadline))
                except _Deadline:
                    break
        finally:
            sampler.close()
        return sorted(results, key=lambda r: r.index)

    if time.perf_counter() >= deadline:
        return results
    # A fork server starts workers from a clean process (no GL context inherited).
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["ipr.inference"])
    finished: queue.Queue = queue.Queue()
    monotonic_deadline = time.monotonic() + min(deadline - time.perf_counter(), 1e9)
    pool = context.Pool(workers, initializer=_init_worker, initargs=(problem,))
    in_flight = 0
    clean = False
    try:
        exhausted = False
        while True:
            while not exhausted and in_flight < 2 * workers:
                task = next(tasks, None)
                if task is None or time.perf_counter() >= deadline:
                    exhausted = True
                    break
                pool.apply_async(
                    _worker_task,
                    ((task[0], task[1], monotonic_deadline),),
                    callback=finished.put,
                    error_callback=finished.put,
                )
                in_flight += 1
            if in_flight == 0:
                break
            # Past the deadline, wait for the tasks in flight: each stops itself at the
            # deadline (between stability tests and pushes), so this takes a fraction of a
            # second; terminating workers instead can hang CPython's pool (a killed worker may
            # hold the task queue's lock).
            wait = deadline - time.perf_counter()
            if wait <= 0:
                exhausted = True
                wait = _GRACE_S
            try:
                outcome = finished.get(timeout=min(max(wait, 0.0), 3600.0) + 0.05)
            except queue.Empty:
                if exhausted:
                    break  # stragglers past the grace period: terminated below
                continue
            in_flight -= 1
            if isinstance(outcome, BaseException):
                raise outcome
            if outcome is not None:
                results.append(outcome)
        clean = in_flight == 0
    finally:
        if clean:
            pool.close()
        else:
            logger.warning("sampling workers did not stop in time; terminating them")
            pool.terminate()
        pool.join()
    return sorted(results, key=lambda r: r.index)


# --------------------------------------------------------------------------------------------
# Building the problem and reading the posterior


def _envelope(shapes: Sequence[ShapeHypothesis]) -> np.ndarray:
    return np.stack(
        [np.min([s.bounds[0] for s in shapes], axis=0), np.max([s.bounds[1] for s in shapes], 0)]
    )


def size_log_prior(shapes: Sequence[ShapeHypothesis], exponent: float) -> np.ndarray:
    """(m,) normalised log P(X^j) proportional to volume^-exponent (module doc)."""
    volumes = np.array([max(s.volume_m3, 1e-12) for s in shapes])
    log_prior = -exponent * np.log(volumes)
    return log_prior - np.logaddexp.reduce(log_prior)


def build_problem(
    prepared: PreparedHypotheses,
    uniform: Sequence[ObjectPosterior],
    planes: tuple[KnownPlane, ...],
    observed: ObservedFrames,
    *,
    variant: Variant,
    pusher: Pusher | None,
    pushes: Sequence[Push],
    config: InferenceConfig,
    seed: int,
) -> tuple[InferenceProblem, list[np.ndarray]]:
    """The sampler's problem and, per object, the indices into its generated hypotheses of its
    candidates (those with non-zero Collision Checker probability)."""
    ids = tuple(prepared.ids)
    indices, candidates = [], []
    for i, posterior in zip(ids, uniform, strict=True):
        keep = np.flatnonzero(posterior.probabilities > 0)
        indices.append(keep)
        candidates.append(tuple(prepared.generated[i][k] for k in keep))
    position_of = {i: k for k, i in enumerate(ids)}
    compatible = {}
    for (a, b), depths in prepared.depths.items():
        if prepared.generated[a][0].index == -1 or prepared.generated[b][0].index == -1:
            continue  # an object reduced to its minimum shape constrains nothing
        pa, pb = position_of[a], position_of[b]
        # Depth matrices index the unary-feasible hypotheses; restrict to the candidates.
        rows = np.searchsorted(prepared.candidates[a], indices[pa])
        cols = np.searchsorted(prepared.candidates[b], indices[pb])
        matrix = depths[np.ix_(rows, cols)] <= prepared.thresholds[(a, b)]
        if not matrix.all():
            compatible[(pa, pb) if pa < pb else (pb, pa)] = matrix if pa < pb else matrix.T
    envelopes = [_envelope([*c, prepared.minima[i]]) for c, i in zip(candidates, ids, strict=True)]
    margin = config.neighbour_margin_m
    neighbours = []
    for a, box in enumerate(envelopes):
        near = []
        for b, other in enumerate(envelopes):
            if (
                a != b
                and np.all(box[0] - margin <= other[1])
                and np.all(other[0] <= box[1] + margin)
            ):
                near.append(b)
        neighbours.append(tuple(near))
    if variant.prior == "size":
        log_prior = tuple(size_log_prior(c, config.size_prior_exponent) for c in candidates)
    else:
        log_prior = tuple(np.full(len(c), -math.log(len(c))) for c in candidates)
    problem = InferenceProblem(
        ids,
        tuple(candidates),
        tuple(prepared.minima[i] for i in ids),
        compatible,
        tuple(neighbours),
        log_prior,
        tuple(planes),
        pusher if variant.actions else None,
        tuple(pushes) if variant.actions else (),
        observed,
        config,
        seed,
    )
    return problem, indices


def object_log_weights(results: Sequence[SampleResult], problem: InferenceProblem) -> np.ndarray:
    """(S, n) per-object log importance weights of the samples (module doc):
    log P(O_i | X, mu) + log P(X_i) - log q_i, with object i's own term of Eq. 2 and its own
    exploration probability; -inf for failed simulations."""
    config = problem.config.likelihood
    scale = config.alpha_per_m * problem.observed.decimation
    weights = np.full((len(results), problem.count), -np.inf)
    for row, result in enumerate(results):
        if result.norms is None:
            continue
        for k, j in enumerate(result.choice):
            weights[row, k] = (
                -scale * float(result.norms[:, k].sum())
                + float(problem.log_prior[k][j])
                - float(result.object_log_proposal[k])
            )
    return weights


def hypothesis_log_likelihoods(
    results: Sequence[SampleResult], problem: InferenceProblem
) -> list[np.ndarray]:
    """Per object, (m_k,) the log of the mean over the samples that chose each candidate of
    exp(its own Eq. 2 term) (module doc, step 3); NaN for candidates no sample chose."""
    config = problem.config.likelihood
    scale = config.alpha_per_m * problem.observed.decimation
    terms: list[list[list[float]]] = [[[] for _ in c] for c in problem.candidates]
    for result in results:
        if result.norms is None:
            continue
        own = -scale * result.norms.sum(axis=0)
        for k, j in enumerate(result.choice):
            terms[k][j].append(float(own[k]))
    return [
        np.array([np.logaddexp.reduce(t) - math.log(len(t)) if t else math.nan for t in per_object])
        for per_object in terms
    ]


def factor_marginals(unary_log: Sequence[np.ndarray], problem: InferenceProblem) -> list:
    """Marginals of P(X) proportional to prod_k exp(unary_log[k][X_k]) times the pairwise
    constraints (``problem.compatible``), exact by variable elimination per connected group of
    interacting objects; a group whose tables would exceed ``max_factor_table`` (or that has
    no feasible assignment) combines its unary factors alone."""
    nodes = list(range(problem.count))
    unary = {k: np.exp(u - np.max(u)) for k, u in enumerate(unary_log)}
    sizes = {k: len(c) for k, c in enumerate(problem.candidates)}
    estimates: dict[int, np.ndarray] = {}
    for component in interaction_components(nodes, problem.compatible):
        edges = {
            pair: matrix
            for pair, matrix in problem.compatible.items()
            if pair[0] in component and pair[1] in component
        }
        result = None
        if len(component) > 1 and len(component) <= 52:
            try:
                result = exact_marginals(
                    component, edges, sizes, problem.config.max_factor_table, unary
                )
            except TableTooLarge:
                result = None
        for k in component:
            estimates[k] = result[k] if result else unary[k] / unary[k].sum()
    return [estimates[k] for k in nodes]


def marginals(
    results: Sequence[SampleResult], problem: InferenceProblem, *, joint: bool = False
) -> list[np.ndarray] | None:
    """Each object's marginal over its candidates (``InferenceConfig.weighting``; the joint
    weight when ``joint``: exact marginals for an exhaustive enumeration); None when no
    sample has a positive weight."""
    if not any(math.isfinite(r.log_likelihood) for r in results):
        return None
    if not joint and problem.config.weighting == "hypothesis":
        unary = []
        for k, means in enumerate(hypothesis_log_likelihoods(results, problem)):
            # Candidates no sample chose get no probability, as with importance weights (every
            # sample's own choice is jointly feasible, so the constraints stay satisfiable); an
            # object whose samples all failed keeps its prior.
            chosen = np.isfinite(means)
            evidence = np.where(chosen, means, -np.inf) if chosen.any() else np.zeros(len(means))
            unary.append(evidence + problem.log_prior[k])
        return factor_marginals(unary, problem)
    log_weights = sample_log_weights(results, problem, joint=joint)
    estimates = []
    for k, candidates in enumerate(problem.candidates):
        column = log_weights[:, k]
        weights = np.exp(column - column.max())
        estimate = np.zeros(len(candidates))
        np.add.at(estimate, [r.choice[k] for r in results], weights)
        estimates.append(estimate / estimate.sum())
    return estimates


def sample_log_weights(
    results: Sequence[SampleResult], problem: InferenceProblem, *, joint: bool = False
) -> np.ndarray:
    """(S, n) log importance weights per sample and object: per object
    (``object_log_weights``), or the joint weight repeated for every object when ``joint`` or
    ``InferenceConfig.weighting`` is "joint". With "hypothesis" weighting these per-object
    weights only serve as the effective-sample-size diagnostic of the summary."""
    if joint or problem.config.weighting == "joint":
        joint_weights = np.array([r.log_weight for r in results], dtype=float)
        return np.repeat(joint_weights[:, None], problem.count, axis=1)
    return object_log_weights(results, problem)


def effective_sample_size(log_weights: np.ndarray) -> float:
    """Kish's effective sample size of (S,) log importance weights (0 when none is finite)."""
    log_weights = np.asarray(log_weights, float)
    log_weights = log_weights[np.isfinite(log_weights)]
    if log_weights.size == 0:
        return 0.0
    weights = np.exp(log_weights - log_weights.max())
    return float(weights.sum() ** 2 / np.sum(weights**2))


def exhaustive_models(problem: InferenceProblem) -> list[tuple[int, ...]]:
    """Every jointly feasible joint model (candidate positions), depth-first with pruning."""
    config = problem.config
    if problem.count > config.max_exhaustive_objects:
        raise IprError(
            f"exhaustive search takes scenes of at most {config.max_exhaustive_objects} objects; "
            f"this one has {problem.count} (fix: use an ipr+ method)"
        )
    total = math.prod(len(c) for c in problem.candidates)
    if total > config.max_exhaustive_models * 50:
        raise IprError(
            f"exhaustive search would enumerate {total} joint models (fix: use an ipr+ method)"
        )
    models = [
        choice
        for choice in itertools.product(*(range(len(c)) for c in problem.candidates))
        if all(problem.compatible[(a, b)][choice[a], choice[b]] for (a, b) in problem.compatible)
    ]
    if len(models) > config.max_exhaustive_models:
        raise IprError(
            f"exhaustive search would simulate {len(models)} joint models, more than "
            f"{config.max_exhaustive_models} (fix: use an ipr+ method)"
        )
    return models


@dataclass(frozen=True, eq=False)
class InferenceOutcome:
    """Posteriors of a physics-based method and how they were obtained.

    ``fallback`` names why the Collision Checker's answer was returned (None when the
    physics-based estimate was); ``samples`` the evaluated joint models (in index order);
    ``timing_s`` seconds spent sampling (``sampling``) and in the Collision Checker.
    """

    method: str
    posteriors: list[ObjectPosterior]
    samples: list[SampleResult]
    fallback: str | None
    timing_s: dict[str, float]
    summary: dict


def infer_shapes(
    prepared: PreparedHypotheses,
    planes: tuple[KnownPlane, ...],
    observed: ObservedFrames,
    *,
    method: str = DEFAULT_METHOD,
    pusher: Pusher | None = None,
    pushes: Sequence[Push] = (),
    config: InferenceConfig | None = None,
    collision_checker_config: CollisionCheckerConfig | None = None,
    seed: int = 0,
    deadline: float | None = None,
    workers: int | None = None,
) -> InferenceOutcome:
    """Marginal shape posteriors by IPR (module doc).

    Args:
        prepared: hypotheses and constraints of the frame-0 objects.
        planes: frame-0 support and walls.
        observed: the observed frames (frame 0 first) with tracked labels.
        method: a key of ``VARIANTS``.
        pusher, pushes: the robot's pusher and pushes (world frame).
        config: settings (default ``InferenceConfig()``).
        collision_checker_config: settings of the Collision Checker (fallback answer).
        seed: seed of the samples.
        deadline: ``time.perf_counter()`` time to stop at (None: ``budget_per_object_s`` per
            object from now, unless ``config.max_samples`` is set).
        workers: overrides ``config.workers``.
    """
    if method not in VARIANTS:
        raise IprError(f"unknown method {method!r}; available: {', '.join(VARIANTS)}")
    variant = VARIANTS[method]
    config = config or InferenceConfig()
    started = time.perf_counter()
    uniform = uniform_posteriors(
        prepared,
        collision_checker_config,
        np.random.default_rng([seed, 2**31]),
        math.inf if deadline is None else deadline,
    )
    checked = time.perf_counter()
    n = len(prepared.ids)
    timing = {"collision_checker": checked - started}
    if n == 0:
        return InferenceOutcome(method, [], [], None, {**timing, "sampling": 0.0}, {})
    if deadline is None:
        deadline = math.inf if config.max_samples else started + config.budget_per_object_s * n
    frames = observed
    if not variant.actions:
        first_push = min((p.after_frame for p in pushes), default=None)
        if first_push is not None:
            frames = observed.only(max(1, observed.frames.index(first_push)))
    problem, indices = build_problem(
        prepared, uniform, planes, frames,
        variant=variant, pusher=pusher, pushes=pushes, config=config, seed=seed,
    )  # fmt: skip
    workers = workers or config.workers or default_workers()
    if variant.exhaustive:
        models = exhaustive_models(problem)
        tasks: Iterable = ((index, choice) for index, choice in enumerate(models))
        workers = min(workers, max(1, len(models)))
    else:
        limit = config.max_samples if config.max_samples else None
        tasks = ((index, None) for index in (range(limit) if limit else itertools.count()))
    samples = run_samples(problem, tasks, workers=workers, deadline=deadline)
    sampled = time.perf_counter()
    timing["sampling"] = sampled - checked
    estimate = marginals(samples, problem, joint=variant.exhaustive)
    fallback = None
    if not samples:
        fallback = "the time budget ran out before the first sample; Collision Checker answer"
    elif estimate is None:
        fallback = "every sampled model exploded or was impossible; Collision Checker answer"
    if fallback:
        logger.warning("%s: %s", method, fallback)
        posteriors = uniform
    else:
        posteriors = []
        for k, base in enumerate(uniform):
            probabilities = np.zeros(len(base.hypotheses))
            probabilities[indices[k]] = estimate[k]
            posteriors.append(
                ObjectPosterior(
                    base.object_id,
                    base.hypotheses,
                    probabilities,
                    posterior_medoid(base.hypotheses, probabilities),
                    base.minimum,
                    method,
                    base.generation_s,
                )
            )
    finite = [r for r in samples if math.isfinite(r.log_likelihood)]
    summary = {
        "samples": len(samples),
        "impossible_samples": len(samples) - len(finite),
        "effective_sample_size": float(
            np.median(
                [
                    effective_sample_size(column)
                    for column in sample_log_weights(samples, problem, joint=variant.exhaustive).T
                ]
            )
        )
        if samples and problem.count
        else 0.0,
        "stability_tests": int(sum(r.stability_tests for r in samples)),
        "workers": workers,
        "pushes_replayed": len(problem.pushes),
        "frames_compared": len(problem.observed.frames),
        "fallback": fallback,
    }
    logger.info(
        "%s: %d samples (%d impossible, ESS %.1f) in %.2f s with %d workers",
        method, len(samples), summary["impossible_samples"], summary["effective_sample_size"],
        timing["sampling"], workers,
    )  # fmt: skip
    return InferenceOutcome(method, posteriors, samples, fallback, timing, summary)
