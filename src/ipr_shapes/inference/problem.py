"""The problem every sampler solves: the candidates, their constraints and priors, the world and
the observations (picklable, sent once to each worker), and one evaluated joint model."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ipr_shapes.collision_checker import fit_weights, surface_cells, surface_distances
from ipr_shapes.inference.config import InferenceConfig
from ipr_shapes.likelihood import ObservedFrames, frame_weights
from ipr_shapes.methods import Method
from ipr_shapes.perception.types import KnownPlane
from ipr_shapes.products import ObjectPosterior, PreparedHypotheses, ShapeHypothesis
from ipr_shapes.scene import Push, Pusher


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
        frictions: the sliding frictions the pushes are replayed under (uniform prior; empty:
            ``config.physics.friction`` alone, as without pushes).
        surface_log_likelihood: per object, (m_k,) log likelihood of its observed surface
            points given each candidate (``surface_log_likelihoods``; up to a constant per
            object), a factor of every candidate's evidence; empty: no such factor
            (``InferenceConfig.surface_fit`` off).
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
    frictions: tuple[float, ...] = ()
    surface_log_likelihood: tuple[np.ndarray, ...] = ()

    def frame_weights(self) -> np.ndarray:
        """(T,) each observed frame's weight in Eq. 2's sum (``likelihood.frame_weights``,
        ``LikelihoodConfig.pushed_frames``) given the pushes replayed."""
        return frame_weights(
            self.observed.frames,
            {push.after_frame for push in self.pushes},
            self.config.likelihood,
        )

    def surface_term(self, k: int) -> np.ndarray:
        """(m_k,) object k's ``surface_log_likelihood`` (zeros when there is none)."""
        if self.surface_log_likelihood:
            return self.surface_log_likelihood[k]
        return np.zeros(len(self.candidates[k]))

    def surface_of(self, choice: Sequence[int]) -> float:
        """The joint model ``choice``'s surface term: the sum over the objects of their
        chosen candidates' ``surface_log_likelihood`` (0 when there is none)."""
        if not self.surface_log_likelihood:
            return 0.0
        return float(sum(self.surface_log_likelihood[k][j] for k, j in enumerate(choice)))

    @property
    def count(self) -> int:
        """Number of objects n."""
        return len(self.ids)

    @property
    def friction_values(self) -> tuple[float, ...]:
        """(F,) the frictions every joint model is scored under (``frictions``, or the
        physics' one)."""
        return self.frictions or (self.config.physics.friction,)

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
    ``norms`` (F, T, n) the depth error norms per friction (``InferenceProblem.friction_values``),
    compared frame and object (at the comparison resolution; inf under a friction whose
    simulation failed; None when it failed under every one); ``object_log_proposal`` (n,) each
    object's own log exploration probability; ``exploration`` per object (m_k,) the
    normalised exploration probabilities it was drawn from (empty for exhaustive): what the
    stability tests said of the candidates the sample did not choose; ``drops`` per object
    (m_k,) how far (m) each of its candidates falls in its stability test with every other
    object static at its chosen shape (``Sampler.rest_drops``; None when the rest evidence is
    off or the simulation failed): what ``InferenceConfig.rest_drop_m`` scores.
    ``log_likelihood`` is the depth terms averaged over the frictions (their uniform prior)
    plus the chosen candidates' rest terms.
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
    exploration: tuple[np.ndarray, ...] = ()
    drops: tuple[np.ndarray, ...] | None = None

    @property
    def log_weight(self) -> float:
        """log of the importance weight P(O|X) P(X) / q(X)."""
        return self.log_likelihood + self.log_prior - self.log_proposal


def _envelope(shapes: Sequence[ShapeHypothesis]) -> np.ndarray:
    return np.stack(
        [np.min([s.bounds[0] for s in shapes], axis=0), np.max([s.bounds[1] for s in shapes], 0)]
    )


def size_log_prior(shapes: Sequence[ShapeHypothesis], exponent: float) -> np.ndarray:
    """(m,) normalised log P(X^j) proportional to volume^-exponent (module doc)."""
    volumes = np.array([max(s.volume_m3, 1e-12) for s in shapes])
    log_prior = -exponent * np.log(volumes)
    return log_prior - np.logaddexp.reduce(log_prior)


def surface_log_likelihoods(
    candidates: Sequence[ShapeHypothesis], points: np.ndarray
) -> np.ndarray:
    """(m,) log likelihood of an object's observed surface given each of its ``candidates``
    (convex, world frame, at the perceived pose), up to a constant shared by them (its
    largest is 0; -inf only if the likelihood underflows).

    ``points``: (N, 3) the object's observed points (world, m). The Collision Checker's "fit"
    likelihood (``ipr_shapes.collision_checker.fit_weights`` with every candidate in one
    family, so no family share): one point per cell of the candidates' voxel pitch
    (``surface_cells``), each point's distance from each candidate's boundary
    (``surface_distances``), the candidate's root mean square excess ``e`` over the closest
    candidate's at each point, exp(-e^2 / (2 s^2)) with s^2 the pitch's quantisation variance
    plus the shared part's mean square. Zeros for fewer than two candidates or no point."""
    count = len(candidates)
    points = np.asarray(points, float).reshape(-1, 3)
    if count < 2 or not len(points):
        return np.zeros(count)
    pitch = candidates[0].voxel_pitch_m
    cells = surface_cells(points, pitch)
    distances = np.array([surface_distances(h, cells) for h in candidates])
    weights = fit_weights(("",) * count, np.ones(count, dtype=bool), distances, pitch)
    with np.errstate(divide="ignore"):
        log_weights = np.log(weights)
    return log_weights - log_weights.max()


def build_problem(
    prepared: PreparedHypotheses,
    uniform: Sequence[ObjectPosterior],
    planes: tuple[KnownPlane, ...],
    observed: ObservedFrames,
    *,
    variant: Method,
    pusher: Pusher | None,
    pushes: Sequence[Push],
    config: InferenceConfig,
    seed: int,
    points: Mapping[int, np.ndarray] | None = None,
) -> tuple[InferenceProblem, list[np.ndarray]]:
    """The sampler's problem and, per object, the indices into its generated hypotheses of its
    candidates (those with non-zero Collision Checker probability). ``points``: per object id
    its observed points ((N, 3), world, m) for ``config.surface_fit`` (an object absent: no
    surface factor for it; None: none at all)."""
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
    surface: tuple[np.ndarray, ...] = ()
    if config.surface_fit and points is not None:
        surface = tuple(
            surface_log_likelihoods(c, points[i]) if i in points else np.zeros(len(c))
            for c, i in zip(candidates, ids, strict=True)
        )
    # Friction only changes what the pushes do: without them, one value scores the same.
    frictions = tuple(config.frictions) if variant.actions and pushes else ()
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
        frictions,
        surface,
    )
    return problem, indices
