"""Tree sampling of joint models (Algorithm 2's exploration probabilities from stability tests)
and their likelihood (full simulation under gravity and the pushes, rendered depth vs observed).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from ipr_shapes.inference.problem import InferenceProblem, SampleResult
from ipr_shapes.likelihood import depth_error_norms, log_likelihood
from ipr_shapes.physics import (
    Body,
    World,
    build_world,
    convex_centroid,
    resting_drop,
    support_of,
    wall_boxes,
)
from ipr_shapes.products import ShapeHypothesis

#: ``Sampler._swept``'s choice of a neighbour whose shape does not enter a swept box.
_ABSENT = -2


def _enters(boxes: np.ndarray, swept: np.ndarray) -> np.ndarray:
    """(E, K) bool: which of ``boxes`` (K, 2, 3) come within 1 mm of each swept box
    (E, 2, 3) (m, world)."""
    return np.all(boxes[None, :, 0] <= swept[:, None, 1] + 0.001, axis=2) & np.all(
        swept[:, None, 0] - 0.001 <= boxes[None, :, 1], axis=2
    )


class _Deadline(Exception):
    """The time budget ran out in the middle of a sample."""


@dataclass(frozen=True, eq=False)
class _ObjectWorld:
    """Object i's compiled stability-test world: ``options[(k, j)]`` the static shape of
    neighbour k's candidate j (-1: its minimum shape), ``first`` the first of i's candidates
    (one switchable body each, in order)."""

    world: World
    options: dict[tuple[int, int], int]
    first: int


class Sampler:
    """Tree sampling and likelihood evaluation of one problem, with its stability cache.

    Shared by the threads that sample one problem (``ipr_shapes.inference.pool``): the stability
    cache and the evaluated models are shared; each thread has its own renderer and its own
    copies of the compiled stability-test worlds (created on first use).
    """

    def __init__(self, problem: InferenceProblem) -> None:
        self.problem = problem
        self.cache: dict[tuple, np.ndarray] = {}
        # Depth error norms of the joint models already simulated: the simulation and
        # rendering are deterministic, so a model drawn again costs only its tree sampling.
        self.evaluated: dict[tuple[int, ...], np.ndarray | None] = {}
        self.stability_tests = 0
        self.screened = 0
        # Stability tests' candidates reused in another context (``_reuse``), and per
        # object what its E tested candidates saw: the candidates (E,), their swept boxes
        # (E, 2, 3), the choice of each neighbour whose shape entered the box (E, K;
        # ``_ABSENT`` for the others), their distances (E,).
        self.reused = 0
        self._swept: dict[int, tuple[np.ndarray, ...]] = {}
        self._lock = threading.Lock()
        # Stability tests under way in some thread, by cache key: another thread that needs
        # the same test waits for it instead of running it again (``_distances``).
        self._pending: dict[tuple, threading.Event] = {}
        self._compiled: dict[int, _ObjectWorld] = {}
        # Object worlds being compiled, by object: another thread waits for them.
        self._compiling: dict[int, threading.Event] = {}
        self._centroids: dict[tuple[int, int], np.ndarray | None] = {}
        self._alone: dict[tuple[int, int], float | None] = {}
        self._walls = wall_boxes(problem.planes, problem.config.physics)
        # Per thread: its copies of the stability-test worlds, its renderer, its test count.
        self._local = threading.local()
        self._renderers: list = []

    # ----------------------------------------------------------------------------------------
    # Exploration probabilities

    def _thread_state(self):
        local = self._local
        if not hasattr(local, "worlds"):
            local.worlds = {}
            local.tests = 0
            local.renderer = None
        return local

    def _object_world(self, i: int) -> _ObjectWorld:
        """Object i's stability-test world for this thread (module doc, step 1): compiled once
        per sampler (``_compile_world``), each thread simulating its own copy of the compiled
        model."""
        local = self._thread_state()
        if i in local.worlds:
            return local.worlds[i]
        compiled = self._compiled_world(i)
        world = compiled.world
        own = dataclasses.replace(world, model=copy.copy(world.model))
        own.data = mujoco.MjData(own.model)
        local.worlds[i] = _ObjectWorld(own, compiled.options, compiled.first)
        return local.worlds[i]

    def _compiled_world(self, i: int, wait: bool = True) -> _ObjectWorld | None:
        """Object i's compiled world: compiled here unless another thread compiles it, whose
        world is then waited for (``wait``) or None returned at once (not ``wait``)."""
        while True:
            with self._lock:
                compiled = self._compiled.get(i)
                if compiled is not None:
                    return compiled
                running = self._compiling.get(i)
                if running is None:
                    running = self._compiling[i] = threading.Event()
                    break
            if not wait:
                return None
            running.wait()
        try:
            compiled = self._compile_world(i)
            with self._lock:
                self._compiled[i] = compiled
            return compiled
        finally:
            with self._lock:
                self._compiling.pop(i).set()

    def _compile_world(self, i: int) -> _ObjectWorld:
        """Compile object i's world: every shape its neighbours can take (each candidate and
        the minimum) as static geometry switched on and off per context, and its candidates
        as switchable transparent bodies. MuJoCo releases the GIL while it compiles, so two
        threads compile two objects' worlds at once (``prepare_worlds``)."""
        problem = self.problem
        options, bodies = {}, []
        for k in problem.neighbours[i]:
            for j, shape in (*enumerate(problem.candidates[k]), (-1, problem.minima[k])):
                options[(k, j)] = len(bodies)
                bodies.append(Body(shape.vertices, shape.faces, dynamic=False))
        first = len(bodies)
        bodies += [
            Body(h.vertices, h.faces, candidate=True, switchable=True)
            for h in problem.candidates[i]
        ]
        world = build_world(bodies, problem.planes, problem.config.physics)
        # The switched-off shapes stay in the static bodies' collision tree; without it (the
        # same contacts) a step costs what it does in a world of the context alone
        # (docs/experiments/2026-11-26-sampling-throughput.md).
        world.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_MIDPHASE
        return _ObjectWorld(world, options, first)

    def prepare_worlds(self, deadline: float = math.inf) -> None:
        """Compile the objects' stability-test worlds not yet compiled or being compiled by
        another thread, the most candidates first (the order of the first stage's tests),
        until none is left or ``deadline`` (``time.perf_counter()``) passes. Each sampling
        thread calls it before its first tree sample: the threads then compile different
        worlds at once, where the first sample's tests would have asked for them one after
        the other, the other thread waiting (the same worlds: each is compiled once, from the
        problem alone). Not for the "uniform" proposal, which runs no stability test."""
        if self.problem.config.proposal != "tree":
            return
        candidates = self.problem.candidates
        for i in sorted(range(self.problem.count), key=lambda i: (-len(candidates[i]), i)):
            if time.perf_counter() >= deadline:
                return
            self._compiled_world(i, wait=False)

    def _centroid(self, i: int, j: int) -> np.ndarray | None:
        key = (i, j)
        if key not in self._centroids:
            self._centroids[key] = convex_centroid(self.problem.candidates[i][j].vertices)
        return self._centroids[key]

    def _screen(self, i: int, context: tuple[tuple[int, int], ...]) -> np.ndarray:
        """(m_i,) the stability-test distance of each candidate of i that clearly stands on
        the support alone (``ipr_shapes.physics.resting_drop``), NaN for the others (simulated)."""
        problem = self.problem
        candidates = problem.candidates[i]
        distances = np.full(len(candidates), np.nan)
        support = support_of(problem.planes)
        config = problem.config
        if not config.screen_resting or support is None:
            return distances
        obstacles = np.concatenate(
            [self._context_boxes(context), np.reshape(self._walls, (-1, 2, 3))]
        )
        margin = config.screen_margin_m
        for j, h in enumerate(candidates):
            drop = self._resting_alone(i, j, support)
            if drop is None:
                continue
            # ``resting_drop``'s obstacle test, the one part that depends on the context.
            low, high = h.bounds[0] - margin, h.bounds[1] + margin
            near = np.all(low <= obstacles[:, 1], axis=1) & np.all(obstacles[:, 0] <= high, axis=1)
            if not near.any():
                distances[j] = drop
        return distances

    @property
    def _signed(self) -> bool:
        """Whether the stability tests keep the signed vertical motion (a rise < 0) rather
        than the fall: for the rest evidence's lifts (``InferenceConfig.rest_lift``). The
        tree sampler sees the falls alone either way (``_distances``)."""
        config = self.problem.config
        return (
            config.rest_lift
            and config.rest_drop_m is not None
            and config.stability_measure == "drop"
        )

    def _resting_alone(self, i: int, j: int, support) -> float | None:
        """``resting_drop`` of candidate j of object i with no obstacle (cached: the screen's
        footprint and centroid do not depend on the context)."""
        key = (i, j)
        if key not in self._alone:
            centroid = self._centroid(i, j)
            config = self.problem.config
            self._alone[key] = None if centroid is None else resting_drop(
                self.problem.candidates[i][j].vertices, centroid, support, [],
                gap_m=config.screen_gap_m, margin_m=config.screen_margin_m, signed=self._signed,
            )  # fmt: skip
        return self._alone[key]

    def _distances(self, i: int, placed: dict[int, int], deadline: float) -> np.ndarray:
        """(m_i,) how far each candidate of i falls among its neighbours (``_motions``, a
        rise counted as 0)."""
        motions = self._motions(i, placed, deadline)
        return np.maximum(motions, 0.0) if self._signed else motions  # the cached array when off

    def _motions(self, i: int, placed: dict[int, int], deadline: float) -> np.ndarray:
        """(m_i,) each candidate of i's stability-test distance among its neighbours (cached):
        how far it fell, or with the rest lifts (``_signed``) its signed vertical motion.

        Candidates that clearly stand on the support are screened (``_screen``), those whose
        result in another context applies here are reused (``_reuse``); the others are
        simulated together in object i's compiled world with the context switched in
        (``_object_world``), each held as soon as it is at rest (``World.settle_each``), and
        their swept boxes kept for reuse (``_remember``)."""
        problem = self.problem
        context = tuple((k, placed.get(k, -1)) for k in problem.neighbours[i])
        key = (i, context)
        while True:
            cached = self.cache.get(key)
            if cached is not None:
                return cached
            if time.perf_counter() > deadline:
                raise _Deadline
            with self._lock:
                cached = self.cache.get(key)  # cached before its test left ``_pending``
                if cached is not None:
                    return cached
                running = self._pending.get(key)
                if running is None:
                    running = self._pending[key] = threading.Event()
                    break
            # Another thread runs this very test (two threads start from the same first
            # stage): its result, once cached; the deadline (checked above), else.
            left = deadline - time.perf_counter()
            running.wait(None if math.isinf(left) else max(left, 0.0))
        try:
            return self._test(i, context, deadline)
        finally:
            with self._lock:
                self._pending.pop(key).set()

    def _test(self, i: int, context: tuple[tuple[int, int], ...], deadline: float) -> np.ndarray:
        """``_distances`` of object i in ``context`` (the neighbours' choices), computed and
        cached (one thread per key at a time)."""
        problem = self.problem
        key = (i, context)
        candidates = problem.candidates[i]
        distances = self._screen(i, context)
        simulate = np.flatnonzero(np.isnan(distances))
        with self._lock:
            self.screened += len(candidates) - len(simulate)
        chosen_boxes = self._context_boxes(context)
        if len(simulate):
            reused = self._reuse(i, simulate, context, chosen_boxes)
            hits = ~np.isnan(reused)
            distances[simulate[hits]] = reused[hits]
            simulate = simulate[~hits]
            with self._lock:
                self.reused += int(hits.sum())
        if len(simulate):
            state = self._thread_state()
            object_world = self._object_world(i)
            world = object_world.world
            chosen = dict(context)
            for (k, j), body in object_world.options.items():
                world.set_colliding(body, chosen[k] == j)
            shapes = object_world.first + np.arange(len(candidates))
            for j, body in enumerate(shapes):
                world.hold(body, j not in simulate)
            world.reset()
            swept = np.zeros((len(simulate), 2, 3))
            world.settle_each(shapes[simulate], problem.config.physics.stability_s, swept)
            state.tests += 1
            with self._lock:
                self.stability_tests += 1
            if world.exploded and len(simulate) > 1:
                # One unstable candidate spoils a shared simulation: test them one by one.
                context_bodies = [
                    Body(shape.vertices, shape.faces, dynamic=False)
                    for shape in (
                        problem.candidates[k][j] if j >= 0 else problem.minima[k]
                        for k, j in context
                    )
                ]
                distances[simulate] = np.concatenate(
                    [self._single_distance(context_bodies, candidates[j]) for j in simulate]
                )
            else:
                distances[simulate] = self._measure(world)[shapes[simulate]]
                self._remember(i, simulate, context, chosen_boxes, swept, distances[simulate])
        self.cache[key] = distances
        return distances

    def _context_boxes(self, context: tuple[tuple[int, int], ...]) -> np.ndarray:
        """(K, 2, 3) the boxes (m, world) of the neighbours' shapes in ``context``."""
        problem = self.problem
        return np.array(
            [(problem.candidates[k][j] if j >= 0 else problem.minima[k]).bounds for k, j in context]
        ).reshape(-1, 2, 3)

    def _remember(self, i, simulated, context, chosen_boxes, swept, distances) -> None:
        """Keep the test results (S,) of object i's ``simulated`` candidates (S,) with their
        swept boxes (S, 2, 3) and the choices of the neighbours whose shapes enter each
        (``_reuse``)."""
        near = _enters(chosen_boxes, swept)
        choices = np.where(near, np.array([c for _, c in context], dtype=np.int64), _ABSENT)
        with self._lock:
            kept = self._swept.get(i)
            new = (np.asarray(simulated, dtype=np.int64), swept, choices, distances)
            self._swept[i] = (
                new
                if kept is None
                else tuple(np.concatenate([a, b]) for a, b in zip(kept, new, strict=True))
            )

    def _reuse(self, i, candidates, context, chosen_boxes) -> np.ndarray:
        """(len(candidates),) the distances of object i's ``candidates`` from earlier tests in
        other contexts, NaN where none applies. A result applies when the shapes that enter
        the candidate's swept box in that test (``World.settle_each``) are the same in this
        context and no other shape enters it: it then touched nothing that differs, and its
        simulation is its own (candidates do not collide with each other), so it moves the
        same. Not bit for bit: which other candidates share the world moves a distance by up
        to about 1e-4 m (5663 reuses on six ycb-dynamic scenes: 98.9 % identical, all but two
        within 1.1e-7 m; docs/experiments/2026-11-27-samples-per-second.md). Why: a context
        differs from the earlier ones in a neighbour or two, which most candidates of an
        object never reach."""
        result = np.full(len(candidates), np.nan)
        kept = self._swept.get(i)
        if kept is None:
            return result
        owners, swept, choices, distances = kept
        mine = np.isin(owners, candidates)
        if not mine.any():
            return result
        owners, swept, choices, distances = (
            owners[mine],
            swept[mine],
            choices[mine],
            distances[mine],
        )
        now = np.where(
            _enters(chosen_boxes, swept),
            np.array([c for _, c in context], dtype=np.int64),
            _ABSENT,
        )
        same = np.flatnonzero((now == choices).all(axis=1))
        # The first applicable result of each candidate (any would do: they agree).
        found, first = np.unique(owners[same], return_index=True)
        result[np.searchsorted(candidates, found)] = distances[same[first]]
        return result

    def _single_distance(self, context: list[Body], h: ShapeHypothesis) -> np.ndarray:
        world = build_world(
            [*context, Body(h.vertices, h.faces)], self.problem.planes, self.problem.config.physics
        )
        world.settle(self.problem.config.physics.stability_s)
        self._thread_state().tests += 1
        with self._lock:
            self.stability_tests += 1
        return self._measure(world)[-1:]

    def _measure(self, world) -> np.ndarray:
        """Per body, the stability test's distance (``InferenceConfig.stability_measure``)."""
        if self.problem.config.stability_measure == "drop":
            return world.vertical_motions() if self._signed else world.drops()
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

    def _mass_bound(self, i: int, placed: dict[int, int]) -> float:
        """An upper bound of object i's exploration mass (the sum of ``exploration``) given
        ``placed``, without a stability test: the mass itself when its test is cached, else
        the number of its candidates compatible with the placed ones (each explored with a
        probability exp(-alpha * distance) <= 1, distances being >= 0)."""
        problem = self.problem
        context = tuple((k, placed.get(k, -1)) for k in problem.neighbours[i])
        allowed = np.ones(len(problem.candidates[i]), dtype=bool)
        for k, j in placed.items():
            allowed &= problem.compatibility(i, k)[:, j]
        cached = self.cache.get((i, context))
        if cached is None:
            return float(allowed.sum())
        with np.errstate(over="ignore"):
            probabilities = np.exp(-problem.config.stability_alpha_per_m * np.maximum(cached, 0))
        return float(np.where(allowed, probabilities, 0.0).sum())

    def tree_sample(
        self, rng: np.random.Generator, deadline: float = math.inf
    ) -> tuple[tuple[int, ...], tuple[float, ...]]:
        """Draw one joint model (candidate positions) and each object's log exploration
        probability (their sum is log q(X))."""
        choice, log_proposal, _ = self.tree_sample_explored(rng, deadline)
        return choice, log_proposal

    def tree_sample_explored(
        self, rng: np.random.Generator, deadline: float = math.inf
    ) -> tuple[tuple[int, ...], tuple[float, ...], tuple[np.ndarray, ...]]:
        """``tree_sample`` and, per object, the (m_k,) normalised exploration probabilities
        its candidate was drawn from."""
        n = self.problem.count
        placed: dict[int, int] = {}
        log_proposal = [0.0] * n
        explored: list[np.ndarray] = [np.zeros(0)] * n
        for _ in range(n):
            # The object of largest mass (the first such): each object's bound (``_mass_bound``)
            # first, then the tests in the order of the bounds; an object whose bound is below
            # the largest mass found cannot be it, and is not tested.
            bounds = sorted((-self._mass_bound(i, placed), i) for i in range(n) if i not in placed)
            best, best_mass, best_probabilities = -1, -1.0, None
            for negative_bound, i in bounds:
                if -negative_bound < best_mass:
                    continue
                probabilities = self.exploration(i, placed, deadline)
                mass = float(probabilities.sum())
                if mass > best_mass or (mass == best_mass and i < best):
                    best, best_mass, best_probabilities = i, mass, probabilities
            if best_mass <= 0:
                # Nothing of this object fits or stays: explore its candidates uniformly.
                best_probabilities = np.ones(len(self.problem.candidates[best]))
                best_mass = float(best_probabilities.size)
            distribution = best_probabilities / best_mass
            j = int(rng.choice(distribution.size, p=distribution))
            placed[best] = j
            log_proposal[best] = math.log(distribution[j])
            explored[best] = distribution
        return tuple(placed[i] for i in range(n)), tuple(log_proposal), tuple(explored)

    def uniform_sample_explored(
        self, rng: np.random.Generator, attempts: int = 20
    ) -> tuple[tuple[int, ...], tuple[float, ...], tuple[np.ndarray, ...]]:
        """Like ``tree_sample_explored`` for ``InferenceConfig.proposal`` "uniform": objects in
        random order, each taking a candidate uniformly among those compatible with the
        objects placed before it; no stability test, so the exploration probabilities are
        empty. Each object's log proposal is log(1 / its compatible candidates) in the order
        drawn (the probability of that order's draw, not summed over the orders). A draw
        that reaches an object with no compatible candidate starts again, up to ``attempts``
        times; then that object's candidates are drawn uniformly, as the tree sampler does
        when nothing of an object fits."""
        problem = self.problem
        n = problem.count
        for attempt in range(attempts):
            placed: dict[int, int] = {}
            log_proposal = [0.0] * n
            for i in (int(i) for i in rng.permutation(n)):
                allowed = np.ones(len(problem.candidates[i]), dtype=bool)
                for k, j in placed.items():
                    allowed &= problem.compatibility(i, k)[:, j]
                if not allowed.any():
                    if attempt < attempts - 1:
                        break
                    allowed[:] = True
                options = np.flatnonzero(allowed)
                placed[i] = int(rng.choice(options))
                log_proposal[i] = -math.log(options.size)
            if len(placed) == n:
                break
        explored = tuple(np.zeros(0) for _ in range(n))
        return tuple(placed[i] for i in range(n)), tuple(log_proposal), explored

    # ----------------------------------------------------------------------------------------
    # Likelihood

    def _renderer_for(self, width: int, height: int):
        """This thread's renderer (a GL context belongs to the thread that made it)."""
        from ipr_shapes.rendering import Renderer

        local = self._thread_state()
        renderer = local.renderer
        if renderer is None or (renderer.width, renderer.height) != (width, height):
            if renderer is not None:
                renderer.close()
                with self._lock:
                    self._renderers.remove(renderer)
            renderer = local.renderer = Renderer(width, height)
            with self._lock:
                self._renderers.append(renderer)
        return renderer

    def depth_norms(self, choice: Sequence[int], deadline: float = math.inf) -> np.ndarray | None:
        """(F, T, n) depth error norms of the joint model ``choice`` per friction
        (``InferenceProblem.friction_values``), compared frame and object (module doc, step 2);
        inf under a friction whose simulation exploded or flung an object, None when every one
        did. The model settles once (at ``physics.friction``) and the frames before the first
        push are rendered once; only the pushes and the frames after them are simulated per
        friction, each from a copy of that state."""
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
        frictions = problem.friction_values
        norms = np.full((len(frictions), len(observed.frames), problem.count), np.inf)

        def render(position: int) -> np.ndarray | None:
            if world.exploded or world.flung().any():
                return None
            depth, index = world.render(renderer, world.cameras[position])
            predicted_ids = np.where(index >= 0, ids[np.maximum(index, 0)], 0)
            return depth_error_norms(
                observed.depth_m[position],
                observed.labels[position],
                observed.ignore[position],
                depth,
                predicted_ids,
                problem.ids,
                problem.config.likelihood,
            )

        pushed_frames = {push.after_frame for push in problem.pushes}
        first = 0  # the frames before the first replayed push are the same under any friction
        while first < len(observed.frames) and observed.frames[first] not in pushed_frames:
            row = render(first)
            if row is None:
                return None
            norms[:, first] = row
            first += 1
        if first == len(observed.frames):
            return norms
        start = (world.data, world.at_rest)
        for f, friction in enumerate(frictions):
            if problem.frictions:
                # A copy of the settled state (the world had not exploded: it rendered).
                world.data, world.at_rest = copy.copy(start[0]), start[1]
                world.exploded = False
                world.set_friction(friction)
            for position in range(first, len(observed.frames)):
                for push in problem.pushes:
                    if push.after_frame == observed.frames[position]:
                        if time.perf_counter() > deadline:
                            raise _Deadline
                        world.push(push)
                row = render(position)
                if row is None:
                    norms[f] = np.inf
                    break
                norms[f, position] = row
        return None if np.isinf(norms).all(axis=(1, 2)).all() else norms

    def _norms_of(self, choice: tuple[int, ...], deadline: float) -> np.ndarray | None:
        """``depth_norms`` of ``choice``, simulated once per sampler."""
        if choice not in self.evaluated:
            self.evaluated[choice] = self.depth_norms(choice, deadline)
        return self.evaluated[choice]

    def log_likelihood_of(self, norms: np.ndarray | None) -> float:
        """log P(O | X, mu) from ``depth_norms``, averaged over the frictions (their uniform
        prior; -inf for a failed simulation)."""
        if norms is None:
            return -math.inf
        problem = self.problem
        weights = problem.frame_weights()
        per_friction = [
            log_likelihood(n, problem.observed.decimation, problem.config.likelihood, weights)
            if np.isfinite(n).all()
            else -math.inf
            for n in norms
        ]
        return float(np.logaddexp.reduce(per_friction) - math.log(len(per_friction)))

    def rest_drops(
        self, choice: Sequence[int], deadline: float = math.inf
    ) -> tuple[np.ndarray, ...]:
        """Per object k, (m_k,) how far (m) each of its candidates falls in its stability test
        with every other object static at its chosen shape in ``choice`` (with
        ``InferenceConfig.rest_lift`` its signed vertical motion, a rise < 0): the evidence
        that the object is at rest where seen, its neighbours at rest where seen
        (``InferenceConfig.rest_drop_m``). The tests are the tree sampler's (``_distances``,
        cached by the neighbours' shapes), in the context of the whole joint model rather
        than of the objects placed before it; every candidate is tested (they share one
        simulation), the chosen one and the others."""
        choice = tuple(choice)
        return tuple(
            self._motions(k, {i: c for i, c in enumerate(choice) if i != k}, deadline)
            for k in range(len(choice))
        )

    def _rest(self, choice: Sequence[int], norms, deadline: float):
        """``rest_drops`` of ``choice`` when the rest evidence is on and its simulation did not
        fail (``norms`` not None), else None."""
        if self.problem.config.rest_drop_m is None or norms is None:
            return None
        return self.rest_drops(choice, deadline)

    def rest_log_likelihood(self, choice: Sequence[int], drops) -> float:
        """The chosen candidates' rest terms' sum (log; ``InferenceConfig.rest_drop_m``; 0 when
        ``drops`` is None)."""
        if drops is None:
            return 0.0
        total = sum(abs(float(d[j])) for d, j in zip(drops, choice, strict=True))
        return -total / self.problem.config.rest_drop_m

    def log_prior(self, choice: Sequence[int]) -> float:
        """log P(X) of a joint model (product of the objects' priors)."""
        return float(sum(self.problem.log_prior[k][j] for k, j in enumerate(choice)))

    def sample(self, index: int, deadline: float = math.inf) -> SampleResult:
        """Tree-sample joint model number ``index`` and score it."""
        started = time.perf_counter()
        tests = self._thread_state().tests
        rng = np.random.default_rng([self.problem.seed, index])
        if self.problem.config.proposal == "uniform":
            choice, object_log_proposal, explored = self.uniform_sample_explored(rng)
        else:
            choice, object_log_proposal, explored = self.tree_sample_explored(rng, deadline)
        norms = self._norms_of(choice, deadline)
        drops = self._rest(choice, norms, deadline)
        return SampleResult(
            index,
            choice,
            float(sum(object_log_proposal)),
            self.log_likelihood_of(norms) + self.rest_log_likelihood(choice, drops),
            self.log_prior(choice),
            time.perf_counter() - started,
            self._thread_state().tests - tests,
            norms,
            object_log_proposal,
            explored,
            drops,
        )

    def score(self, index: int, choice: Sequence[int], deadline: float = math.inf):
        """Score a given joint model (exhaustive enumeration): proposal probability 1."""
        started = time.perf_counter()
        norms = self._norms_of(tuple(choice), deadline)
        drops = self._rest(choice, norms, deadline)
        return SampleResult(
            index, tuple(choice), 0.0,
            self.log_likelihood_of(norms) + self.rest_log_likelihood(choice, drops),
            self.log_prior(choice), time.perf_counter() - started, 0, norms,
            (0.0,) * len(choice), (), drops,
        )  # fmt: skip

    def release(self) -> None:
        """Close this thread's renderer and drop its worlds (a sampling thread's last call:
        a GL context is closed by the thread that made it)."""
        local = self._thread_state()
        if local.renderer is not None:
            with self._lock:
                self._renderers.remove(local.renderer)
            local.renderer.close()
        local.renderer = None
        local.worlds = {}

    def close(self) -> None:
        """Close this thread's renderer and any left by threads that did not ``release``."""
        self.release()
        with self._lock:
            renderers, self._renderers = self._renderers, []
        for renderer in renderers:
            renderer.close()
