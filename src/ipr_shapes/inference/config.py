"""Settings of IPR inference (``ipr_shapes.inference``): the simulated world, the likelihood, tree
sampling and how samples become marginals."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal, get_args

from ipr_shapes.checks import Checks, Interval, Options, OrNone, Predicate, check_fields
from ipr_shapes.likelihood import LikelihoodConfig
from ipr_shapes.physics import PhysicsConfig

#: How samples become marginals (``InferenceConfig.weighting``).
Weighting = Literal["hypothesis", "object", "joint"]
WEIGHTINGS: tuple[str, ...] = get_args(Weighting)
#: How joint models are drawn (``InferenceConfig.proposal``).
Proposal = Literal["tree", "uniform"]
PROPOSALS: tuple[str, ...] = get_args(Proposal)
#: Scene frictions to search (``InferenceConfig.frictions``): ratio sqrt(2) from 0.25 to 1.0,
#: the range of everyday objects sliding on a table.
FRICTION_GRID: tuple[float, ...] = (0.25, 0.35, 0.5, 0.7, 1.0)
#: Which terms of Eq. 2 are a candidate's evidence (``InferenceConfig.evidence``).
Evidence = Literal["own", "neighbours"]
EVIDENCES: tuple[str, ...] = get_args(Evidence)
#: How the joint models drawn enter "hypothesis" weighting's marginals
#: (``InferenceConfig.drawn_models``).
DrawnModels = Literal["factorised", "exact"]
DRAWN_MODELS: tuple[str, ...] = get_args(DrawnModels)
#: What the output medoid's weights start from (``InferenceConfig.medoid_base``).
MedoidBase = Literal["uniform", "collision-checker"]
MEDOID_BASES: tuple[str, ...] = get_args(MedoidBase)
#: What a stability test measures per hypothesis (``InferenceConfig.stability_measure``).
StabilityMeasure = Literal["drop", "displacement"]
STABILITY_MEASURES: tuple[str, ...] = get_args(StabilityMeasure)


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
        budget_per_object_s: default sampling budget (s) per object when no time budget is
            given (perception, fusion, hypotheses and the Collision Checker come on top); 0.8
            keeps the whole run within 1.5 s per object on an idle 2-core machine.
        max_samples: stop after this many samples (None: only the budget stops).
        workers: threads evaluating samples (None: all cores; 1: only the calling thread).
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
        screen_resting: settle the stability tests of candidates that clearly stand on the
            support alone without simulating them (``ipr_shapes.physics.resting_drop``).
        screen_gap_m: a screened candidate's lowest vertex is at most this far from the
            support (m), above or below.
        screen_margin_m: a screened candidate's centre of mass is this far inside its
            footprint, and no other shape or wall comes this close to its box (m).
        frictions: the sliding frictions of the scene searched with the shapes (module doc,
            step 2), a uniform prior over them: each joint model's pushes are replayed under
            each, from one settled start; empty (the default): ``physics.friction`` alone;
            ``FRICTION_GRID`` is the searched grid to opt in with. Why: a push's outcome
            depends on friction as much as on the hidden shape, and the scene's friction is
            unknown; off by default because the pushes cost F times as much, a default
            budget then draws 3-7 samples instead of about 12, and at equal time the search
            won on one development set and lost on the other (docs/DESIGN_NOTES.md,
            "Friction search (opt-in)").
        proposal: how joint models are drawn: "tree" (the paper's tree sampler, each object's
            candidates explored by their stability tests given the objects placed before it)
            or "uniform" (objects in random order, each taking a candidate uniformly among
            those compatible with the objects placed: no stability tests, so more joint models
            in the same time on small problems). Why "tree" stays the default: at 18 % of
            exhaustive search's compute "uniform" agreed with it as often on the development
            tables (0.837 against 0.806-0.828 of the objects with a clear exact favourite) but
            less on the ycb-dynamic check (0.650 against 0.771), and its object IoU at 30 samples
            fell on one development set (0.639 against 0.651; 0.587 against 0.588)
            (docs/experiments/2026-11-27-sampler-agreement.md).
        evidence: which of a sample's Eq. 2 terms count for a candidate under "hypothesis"
            weighting: "own" (its object's own term) or "neighbours" (its own term plus, for
            each object it can touch (``InferenceProblem.neighbours``), the part of that
            object's term its own candidate does not explain: the term minus the log mean of
            exp(term) over the samples that chose the same candidate for it). Why: in the
            simulation an object's settled and pushed pose depends on the shapes it rests on
            or is pushed against, so a hidden part too small to hold a neighbour up shows in
            the neighbour's term, which "own" gives to the neighbour alone. "own" stays the
            default: on the development sets the residuals' signal on an occluded object's
            hidden extent was small against their noise and moved object IoU by less than
            0.01 either way; with the pushes a set lost, as did ycb-dynamic
            (docs/experiments/2026-11-28-neighbour-evidence.md).
        drawn_models: how the joint models drawn enter "hypothesis" weighting's marginals (the
            written probabilities; not the output shape, which the candidates' own evidence
            chooses, ``medoid_weights``): "factorised" (every joint model scored by the
            product of its candidates' unary factors of ``evidence``) or "exact" (each
            distinct joint model drawn and simulated scored by its own likelihood times
            prior, as exhaustive search scores it, and an impossible one by 0; the others by
            the product of the unary factors of "neighbours" evidence, the joint term's
            additive expansion to first order in the neighbours;
            ``estimators.drawn_exact_marginals``). Why: own-term unary factors drop how a
            neighbour's shape changes an object's own term (a candidate that makes the
            object beside it render or settle worse is not blamed for it), a bias that more
            samples do not remove; with the drawn models' own likelihoods the marginals
            become exhaustive search's as the draws cover the joint models, and the
            neighbours' residuals carry what the drawn models say of that to the undrawn
            ones. "exact" is the default since 2026-11-28: emulated on the development
            exhaustive tables (32 objects with a clear exact favourite, 20 seeds) it agreed
            with exhaustive on 0.797 / 0.863 / 0.934 of them at 0.18 / 0.3 / 0.5 of its
            compute against 0.698 / 0.745 / 0.727 (the drawn models alone: 0.734 / 0.802 /
            0.866), 1.000 against 0.719 at the full compute; the output shapes do not change:
            they are chosen by ``evidence``
            (docs/experiments/2026-11-28-drawn-models-exact.md).
        rest_drop_m: the rest evidence's scale (m; None: off). Each object is seen at rest,
            its neighbours too: P(object k at rest where seen | X) is modelled as
            exp(-drop_k / rest_drop_m) / rest_drop_m, drop_k being how far its candidate falls
            in its stability test with every other object static at its chosen shape
            (``Sampler.rest_drops``): an exponential law (the maximum-entropy law of a
            non-negative quantity of known mean) whose mean, 5 mm, is the measured mean fall
            of the candidates nearest the true shapes (within 0.05 IoU of the best) in those
            tests on development scenes not otherwise used (dynamic seed 9700: 5.0 mm). Under
            "hypothesis" weighting every candidate gets the log mean of that over the sampled
            contexts it fits (``rest_evidence``), in place of the exploration ratio for the
            candidates no sample chose; "object" and "joint" weighting score the chosen
            candidate's term. Why: an occluded object's hidden part is where its predicted
            depth is not compared, so a short hidden part and a true-size one score alike
            in Eq. 2, while the short one cannot hold the object where it is seen. Off by
            default: it gained on the three development sets (+0.001 to +0.020 object IoU at
            equal samples) but lost on ycb-dynamic (-0.005 with either method): it only
            says "not too short", and with nothing as strong saying "not too large" (a
            hidden extent is not compared, the prior is uniform) it moves choices to larger
            shapes, right where they were too small and wrong where they were not; and
            each joint model's contexts not already tested cost stability tests
            (docs/experiments/2026-11-28-stability-evidence.md).
        rest_lift: with the rest evidence, score how far the candidate's centre of mass moved
            along gravity either way (its fall or its rise) rather than its fall alone, at the same
            ``rest_drop_m`` (no new scale). Why: seen at rest means neither fallen nor lifted:
            a hidden part too large to fit where it is drawn (sunk into the support, pressed
            into a neighbour within the compatibility tolerance) is pushed out upwards in the
            stability test, which the fall alone ignores. Only with ``stability_measure``
            "drop" (a displacement counts lifts already); the tree proposal still sees the
            falls alone (the same samples as off). Off by default: the lifts measured are
            sub-millimetre (docs/experiments/2026-11-28-rest-evidence-both-ways.md).
        surface_fit: also score each candidate by how its surface passes through the
            object's observed points at its perceived pose, a factor of every candidate's
            evidence known without simulation (``surface_log_likelihoods``: the Collision
            Checker's "fit" likelihood, ``ipr_shapes.collision_checker.fit_weights`` within
            one family, over the object's candidates; the points are the frame-0 object's, fused
            over the views for the ``+action`` methods). Why: Eq. 2 is P(observed depth |
            shapes, physics); the seen surface where the object is seen is part of that
            observation and is sharp (the candidate as placed, no simulated settling or push
            and its sim-to-real mismatch), while the simulated frames' term is weighed at
            ``likelihood.alpha_per_m``, low because of that mismatch. Applies to every
            weighting (a unary factor like the prior); the samples drawn are the same. Off by
            default: at equal samples it lost on both development sets with gravity alone
            (-0.005, -0.004 object IoU) and on ycb-dynamic (-0.002); it moves choices both
            ways in every band of visible fraction (on dev 9100 it fixed the well-seen objects
            and lost occluded ones, on ycb-dynamic the reverse)
            (docs/experiments/2026-11-28-surface-fit-evidence.md).
        medoid_base: the weights the output medoid starts from before each candidate's
            evidence (and prior) multiplies them: "collision-checker" (the Collision Checker's
            medoid weights, ``CollisionCheckerConfig.medoid_weights``, from the object's
            hidden outline fraction and observed points: ``collision_checker.
            medoid_base_weights``) or "uniform" (each candidate once, the Collision Checker's
            "candidate" weights; the default before 2026-11-28). Why: the Collision Checker's
            weights are a judgement of the candidates made before any physics (which families
            to trust where the outline is hidden), which the physics' evidence, nearly flat on
            a hidden extent, should refine rather than replace: prior times likelihood. The
            marginals (written probabilities) are not changed. Measured on the same 30
            samples per scene: ycb-static +0.003, ycb-dynamic +0.010 (gravity) / +0.005
            (pushes), bins-real +0.001, ycbv-real 0, development sets +0.002 to +0.015
            object IoU (docs/experiments/2026-11-28-medoid-base.md).
    """

    CHECKS: ClassVar[Checks] = {
        "stability_alpha_per_m": Interval(0, None),
        "neighbour_margin_m": Interval(0, None),
        "budget_per_object_s": Interval(0, None, closed="neither"),
        "max_samples": OrNone(Interval(1, None, integer=True)),
        "workers": OrNone(Interval(1, None, integer=True)),
        "size_prior_exponent": Interval(0, None),
        "max_exhaustive_objects": Interval(1, None, integer=True),
        "max_exhaustive_models": Interval(1, None, integer=True),
        "weighting": Options(*WEIGHTINGS),
        "stability_measure": Options(*STABILITY_MEASURES),
        "proposal": Options(*PROPOSALS),
        "evidence": Options(*EVIDENCES),
        "drawn_models": Options(*DRAWN_MODELS),
        "rest_drop_m": OrNone(Interval(0, None, closed="neither")),
        "rest_lift": Options(False, True),
        "surface_fit": Options(False, True),
        "medoid_base": Options(*MEDOID_BASES),
        "max_factor_table": Interval(1, None),
        "screen_gap_m": Interval(0, None),
        "screen_margin_m": Interval(0, None),
        "frictions": Predicate(
            lambda v: (
                isinstance(v, tuple)
                and all(isinstance(f, int | float) and 0 < f <= 5 for f in v)
                and len(set(v)) == len(v)
            ),
            "a tuple of distinct frictions in (0, 5]",
        ),
    }

    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    likelihood: LikelihoodConfig = field(default_factory=LikelihoodConfig)
    stability_alpha_per_m: float = 100.0
    neighbour_margin_m: float = 0.02
    budget_per_object_s: float = 0.8
    max_samples: int | None = None
    workers: int | None = None
    size_prior_exponent: float = 1.0
    max_exhaustive_objects: int = 4
    max_exhaustive_models: int = 20_000
    weighting: Weighting = "hypothesis"
    stability_measure: StabilityMeasure = "drop"
    max_factor_table: float = 1e6
    screen_resting: bool = True
    screen_gap_m: float = 0.002
    screen_margin_m: float = 0.005
    frictions: tuple[float, ...] = ()
    proposal: Proposal = "tree"
    evidence: Evidence = "own"
    drawn_models: DrawnModels = "exact"
    rest_drop_m: float | None = None
    rest_lift: bool = False
    surface_fit: bool = False
    medoid_base: MedoidBase = "collision-checker"

    def __post_init__(self) -> None:
        check_fields(self)
