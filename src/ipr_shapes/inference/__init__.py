"""Inverse physics reasoning (paper Sec. IV-F, Algorithm 2): marginal shape posteriors from
tree sampling of joint models scored by physics simulation.

Hypotheses come from ``ipr_shapes.hypotheses.prepare_hypotheses`` (Algorithm 1 with the unary
and pairwise constraints); only hypotheses the Collision Checker gives non-zero probability (part
of some jointly feasible model) are candidates. Then, repeated until the time budget:

1. **Tree sampling of one joint model.** Starting from the support (and walls) alone, at each
   stage every unplaced object i gets exploration probabilities over its candidates j:
   exp(-alpha_s * dist_ij), where dist_ij is how far (m; ``InferenceConfig.stability_measure``:
   by default how far its centre of mass drops, or its mean vertex displacement) hypothesis j
   moves in ``stability_s`` of simulated gravity among the placed objects (at their sampled
   shapes) and the unplaced ones (at their minimum shapes), and 0 when j overlaps a placed
   object's sampled shape (Constraints(X)). The object with the largest total ("mass") is
   placed, with a hypothesis drawn from its normalised exploration probabilities.
   - The other objects are static during a stability test (only i's hypotheses move): all of
     i's candidates are tested in one simulation as mutually transparent bodies
     (``ipr_shapes.physics``), and dist_ij depends only on i's *neighbours* (objects whose candidate
     envelopes come within ``neighbour_margin_m`` of i's). The result is cached under (i, the
     neighbours' current shapes), so the same partial scene is never simulated twice; the first
     stage is shared by every sample.
   - Throughput (docs/experiments/2026-11-26-sampling-throughput.md): each object's test world
     is compiled once, with every shape its neighbours can take switched on or off per
     context; a candidate is held where it is once at rest; a candidate that clearly stands on
     the support alone, clear of every other shape, is settled without simulation
     (``InferenceConfig.screen_resting``); samples run in threads sharing the caches.
   - Opt-in (``InferenceConfig.proposal`` "uniform"): objects in random order, each taking a
     candidate uniformly among those compatible with the placed ones, with no stability test
     (more joint models per second on small problems;
     docs/experiments/2026-11-27-sampler-agreement.md).
2. **Simulation of the full model** under gravity (settling) and, for the ``+action`` variants,
   the recorded pushes; the depth images rendered from each frame's camera give the likelihood
   (``ipr_shapes.likelihood``, Eq. 2). A simulation that explodes or flings an object scores 0.
   - Friction (paper Sec. IV-E: "mechanical properties ... can be searched along with the
     geometric model"; on by default, ``InferenceConfig.frictions``): the scene's sliding
     friction mu is one more unknown with a uniform prior over ``InferenceConfig.frictions``,
     marginalised rather than sampled: each joint
     model settles once (at ``physics.friction``; a scene at rest says little about friction)
     and its frames before the first push are rendered once, then its pushes and the frames
     after them are replayed under every friction from a copy of that state. Scoring every
     friction costs the pushes F times but compares the frictions on the same shapes, where
     sampling mu would leave a few samples per friction, each with other shapes.
3. **From samples to marginals** (``InferenceConfig.weighting``). Eq. 2's exponent is a sum over
   objects, so each object's evidence is its own term. Default ``"hypothesis"``: each
   candidate's likelihood is the mean over the samples that chose it of exp(its own term);
   with the priors as unary factors and the pairwise constraints as 0/1 factors, the marginals
   follow by exact variable elimination (as the Collision Checker's do). A candidate no sample
   chose has no likelihood of its own: it takes the mean likelihood of its object's sampled
   candidates times its mean exploration probability over theirs (the stability tests are
   the evidence there is of it), so that a few samples tilt the Collision Checker's
   marginals instead of replacing them with the handful of candidates drawn, and a
   candidate that falls is still unlikely. The exploration probabilities decide what is visited,
   not how much it weighs, so rare draws do not carry huge weights. The per-candidate means
   drop how a neighbour's shape changes an object's own term, so (``drawn_models`` "exact",
   the default) each distinct joint model drawn and simulated is scored in the elimination's
   sum by its own P(O | X) P(X) instead of the product of its candidates' factors (0 if it
   failed): exhaustive search's marginals once the draws cover the joint models
   (docs/experiments/2026-11-28-drawn-models-exact.md). ``"object"``: Algorithm
   2's per-object update, w_i = P(O_i | X, mu) P(X_i) / q_i with q_i the exploration
   probability with which X_i was drawn; the estimate of P(X_i^j | O, mu) is the
   self-normalised sum of w_i over the samples that chose j. ``"joint"``: the full
   w = P(O | X, mu) P(X) / q(X) for every object (q(X) the product of the draws' exploration
   probabilities; the object order is a deterministic function of earlier draws): consistent
   for the joint posterior, but at the sample counts a budget allows the proposal correction
   1/q(X) sets its weights and its shapes were worse (docs/DESIGN_NOTES.md, 'Weighting:
   "hypothesis" (default), "object", "joint"').
   With friction searched, each weighting gives P(X_k | O, mu) under each friction and the
   marginals are sum_mu P(mu | O) P(X_k | O, mu). P(mu | O) is proportional to the evidence
   of the same samples under mu, as each weighting models it: the product over objects of
   sum_j P(X_k^j) times candidate j's mean likelihood ("hypothesis"), of the per-object
   importance weights' sums ("object"), or the sum of the joint weights ("joint", exact for
   ``exhaustive``); ``result.json`` reports it (``SamplingSummary.friction_posterior``).

Priors: ``uniform``, or ``size``: P(X_i^j) proportional to volume(X_i^j)^-size_prior_exponent
(smaller models are more probable, the paper's informed prior), normalised per object.

Output per object: the medoid under voxel IoU of its candidates (every one jointly feasible),
each weighted by its own unary factor, evidence times prior (``medoid_weights``; "object" and
"joint" weighting: by their marginals), not by its marginal: a marginal also counts the joint
models the candidate is in, how many of the neighbours' generated candidates it fits with (small
ones fit with more), as the Collision Checker's marginals do and its medoid leaves out
(``ipr_shapes.collision_checker``; docs/experiments/2026-11-27-physics-posterior-weights.md).
The written probabilities stay the marginals. Anytime: before the first sample finishes the
answer is the Collision Checker's; a budget too small for one sample returns it and says so. Samples are independent
given their index (each draws from ``default_rng([seed, index])``), so a run with ``max_samples``
and no deadline gives the same result with any number of workers, and a run that stops later
(a larger budget) has the same samples first and only adds others (common random numbers: a
budget curve's differences are the added samples').

``exhaustive`` scores every jointly feasible joint model with the same likelihood (for scenes of
at most ``max_exhaustive_objects`` objects and ``max_exhaustive_models`` models): the exact
posterior the sampler estimates, to validate it.

Modules: ``config`` (settings), ``problem`` (what a sampler solves), ``sampler`` (tree sampling
and likelihood), ``pool`` (sampling threads and deadlines), ``estimators`` (samples to
marginals), ``exhaustive`` (the exact posterior), ``infer`` (``infer_shapes``).
"""

from ipr_shapes.inference.config import (
    EVIDENCES,
    FRICTION_GRID,
    PROPOSALS,
    WEIGHTINGS,
    InferenceConfig,
)
from ipr_shapes.inference.estimators import (
    at_friction,
    effective_sample_size,
    factor_marginals,
    friction_posterior,
    hypothesis_log_likelihoods,
    hypothesis_unary,
    marginals,
    medoid_weights,
    neighbour_residuals,
    object_log_weights,
    own_log_likelihoods,
    rest_evidence,
    rest_log_likelihoods,
    sample_log_weights,
)
from ipr_shapes.inference.exhaustive import exhaustive_models
from ipr_shapes.inference.infer import InferenceOutcome, infer_shapes, physics_medoid
from ipr_shapes.inference.pool import default_workers, run_samples
from ipr_shapes.inference.problem import (
    InferenceProblem,
    SampleResult,
    build_problem,
    size_log_prior,
    surface_log_likelihoods,
)
from ipr_shapes.inference.sampler import Sampler

__all__ = [
    "FRICTION_GRID",
    "PROPOSALS",
    "EVIDENCES",
    "WEIGHTINGS",
    "at_friction",
    "InferenceConfig",
    "InferenceOutcome",
    "InferenceProblem",
    "SampleResult",
    "Sampler",
    "build_problem",
    "default_workers",
    "effective_sample_size",
    "exhaustive_models",
    "factor_marginals",
    "friction_posterior",
    "hypothesis_log_likelihoods",
    "hypothesis_unary",
    "infer_shapes",
    "marginals",
    "medoid_weights",
    "neighbour_residuals",
    "object_log_weights",
    "own_log_likelihoods",
    "physics_medoid",
    "rest_evidence",
    "rest_log_likelihoods",
    "run_samples",
    "sample_log_weights",
    "size_log_prior",
    "surface_log_likelihoods",
]
