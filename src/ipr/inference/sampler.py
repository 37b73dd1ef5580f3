"""Tree sampling of joint models (Algorithm 2's exploration probabilities from stability tests)
and their likelihood (full simulation under gravity and the pushes, rendered depth vs observed).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from ipr.inference.problem import InferenceProblem, SampleResult
from ipr.likelihood import depth_error_norms, log_likelihood
from ipr.physics import Body, build_world
from ipr.products import ShapeHypothesis


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

        A world per context: compiling it costs about as much as keeping one world per object
        with every neighbour shape and switching them on and off, whose extra geoms slow every
        step (docs/DESIGN_NOTES.md, "Stability tests per object")."""
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
