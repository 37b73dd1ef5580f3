"""Mutation testing of the core: does the test suite fail when the method is broken?

A curated list of single-line mutations (``MUTANTS``), each located by a source snippet that
must occur exactly once in all of ``src/ipr_shapes/**/*.py`` (not by file or line: modules move). For
each mutant the harness

1. copies ``src/`` to a private workspace (the working tree is never modified) and applies the
   mutation there, first on ``PYTHONPATH``;
2. runs the test files most likely to kill it (``pytest -x -q -p no:cacheprovider -m "not
   slow"``); if they pass, the whole default test set (``tests -m "not slow"``) to confirm
   that it survives;
3. restores the file (always: ``try``/``finally``, also on Ctrl-C).

Results: killed (by which test), survived, or error (snippet missing or ambiguous: not
counted as killed). The report, with the kill rate and why each known survivor survives, is
written to ``docs/MUTANTS.md``.

Usage: ``python scripts/mutants.py [--only ID ...] [--no-full] [--list] [--report PATH]``
(``make mutants`` runs them all). Numba's compile cache is kept in a persistent temporary
folder, and the workspace's copies keep the sources' modification times, so that the compiled
kernels are reused from one mutant (and one run) to the next.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import fcntl
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "src"
PACKAGE = SOURCE / "ipr_shapes"
WORKSPACE = Path(tempfile.gettempdir()) / "ipr-mutants"
NUMBA_CACHE = Path(tempfile.gettempdir()) / "ipr-mutants-numba-cache"
FULL = ("tests",)
PYTEST = ("-x", "-q", "-p", "no:cacheprovider", "-m", "not slow")


@dataclass(frozen=True)
class Mutant:
    """One mutation: replace ``find`` (unique in the package) by ``replace``.

    ``tests``: test files run first (the likeliest to kill it). ``survives``: why the mutant
    is expected to survive (equivalent or benign), written to the report if it does.
    """

    id: str
    area: str
    what: str
    find: str
    replace: str
    tests: tuple[str, ...]
    survives: str = ""


T = "tests/test_"


def _t(*names: str) -> tuple[str, ...]:
    return tuple(f"{T}{name}.py" for name in names)


MUTANTS: tuple[Mutant, ...] = (
    # ---------------------------------------------------------------- likelihood (Eq. 2)
    Mutant(
        "robot-mask-ignored",
        "likelihood",
        "the robot mask of the frames is dropped: robot pixels count as evidence",
        "robot = frame.robot_mask if frame.robot_mask is not None else np.zeros_like(label, bool)",
        "robot = np.zeros_like(label, bool)",
        _t("inference_method", "likelihood"),
    ),
    Mutant(
        "ignore-not-applied",
        "likelihood",
        "the depth comparison ignores the ignore (robot) mask",
        "valid = (observed_depth > 0) & ~ignore",
        "valid = observed_depth > 0",
        _t("likelihood", "inference_method"),
    ),
    Mutant(
        "occlusion-rule-dropped",
        "likelihood",
        "predicted pixels hidden by a nearer observed surface count as evidence",
        "only_predicted = predicted & ~observed & ~hidden",
        "only_predicted = predicted & ~observed",
        _t("likelihood"),
    ),
    Mutant(
        "error-cap-dropped",
        "likelihood",
        "per-pixel depth errors are not capped",
        "difference = np.minimum(np.abs(observed_depth - predicted_depth), config.error_cap_m)",
        "difference = np.abs(observed_depth - predicted_depth)",
        _t("likelihood"),
    ),
    Mutant(
        "observed-only-pixels-dropped",
        "likelihood",
        "observed pixels the model does not cover cost nothing",
        "+ float(np.sum(difference[only_observed] ** 2))",
        "+ 0.0",
        _t("likelihood", "inference"),
    ),
    Mutant(
        "decimation-dropped",
        "likelihood",
        "log P(O|X) is not scaled by the decimation (norms at reduced resolution)",
        "return -config.alpha_per_m * decimation * float(np.sum(norms))",
        "return -config.alpha_per_m * float(np.sum(norms))",
        _t("likelihood"),
    ),
    # ---------------------------------------------------------------- inference (Algorithm 2)
    Mutant(
        "constraints-ignored-in-tree-sampling",
        "inference",
        "placed objects' shapes do not restrict the next object's candidates (Constraints(X))",
        "allowed &= problem.compatibility(i, k)[:, j]\n        distances = self._distances(",
        "pass\n        distances = self._distances(",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "log-q-sign-flipped",
        "inference",
        "the importance weight multiplies by q(X) instead of dividing",
        "return self.log_likelihood + self.log_prior - self.log_proposal",
        "return self.log_likelihood + self.log_prior + self.log_proposal",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "medoid-replaced-by-mode",
        "inference",
        "the output shape is the most probable hypothesis, not the posterior medoid under IoU",
        "posterior_medoid(base.hypotheses, medoid_weight, tables.get(base.object_id)),",
        "int(np.argmax(probabilities)),",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "physics-medoid-weighted-by-marginals",
        "inference",
        "the physics-based medoid weights candidates by their marginals (which count the "
        "neighbours' candidates they fit with), not by their own evidence",
        'if joint or problem.config.weighting != "hypothesis":',
        "if True:",
        _t("inference"),
    ),
    Mutant(
        "neighbour-evidence-ignored",
        "inference",
        'evidence "neighbours" gives each candidate its own term alone, as "own" does',
        'if problem.config.evidence == "neighbours":',
        "if False:",
        _t("inference"),
    ),
    Mutant(
        "neighbour-residual-not-centred",
        "inference",
        "a neighbour's whole term counts for the candidate, its own candidate's fit included",
        "residuals[rows, k] = values - _log_mean_exp(values)",
        "residuals[rows, k] = values",
        _t("inference"),
    ),
    Mutant(
        "drawn-models-counted-twice",
        "inference",
        "a drawn joint model's own weight is added to its factorised weight instead of replacing it",
        "correction = np.exp(exact - scale) - np.exp(factorised - scale)",
        "correction = np.exp(exact - scale)",
        _t("inference"),
    ),
    Mutant(
        "undrawn-models-own-terms-only",
        "inference",
        "the undrawn joint models are scored by the candidates' own terms alone, not their first-order expansion in the neighbours",
        'config = dataclasses.replace(problem.config, evidence="neighbours")',
        "config = problem.config",
        _t("inference"),
    ),
    Mutant(
        "drawn-failed-model-kept",
        "inference",
        "a drawn joint model whose simulation failed keeps its factorised weight",
        "drawn[choice] = own",
        "drawn.update({choice: own} if result.norms is not None else {})",
        _t("inference"),
    ),
    Mutant(
        "rest-evidence-ignored",
        "inference",
        "with rest_drop_m set, the candidates' rest evidence is not added to their unary factor",
        "evidence = evidence + rest[k]",
        "evidence = evidence",
        _t("inference"),
    ),
    Mutant(
        "rest-evidence-context-unmasked",
        "inference",
        "a candidate's rest evidence also averages its falls in sampled contexts it overlaps",
        "usable[row] = allowed",
        "usable[row] = True",
        _t("inference"),
    ),
    Mutant(
        "rest-drops-without-the-others",
        "inference",
        "the rest tests leave out the other objects' chosen shapes (their minimum shapes instead)",
        "self._motions(k, {i: c for i, c in enumerate(choice) if i != k}, deadline)",
        "self._motions(k, {}, deadline)",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "rest-lift-ignored",
        "inference",
        "with rest_lift, a candidate's rise in its rest tests counts as no motion (falls alone)",
        "drops = np.abs(np.asarray(result.drops[k], float))",
        "drops = np.maximum(np.asarray(result.drops[k], float), 0.0)",
        _t("inference"),
    ),
    Mutant(
        "rest-lift-not-measured",
        "inference",
        "with rest_lift, the stability tests still measure the falls alone",
        "return world.vertical_motions() if self._signed else world.drops()",
        "return world.drops()",
        _t("inference"),
    ),
    Mutant(
        "surface-fit-ignored",
        "inference",
        "with surface_fit, a candidate's unary factor leaves out its seen surface's likelihood",
        "unary.append(evidence + problem.surface_term(k) + problem.log_prior[k])",
        "unary.append(evidence + problem.log_prior[k])",
        _t("inference"),
    ),
    Mutant(
        "surface-fit-reversed",
        "inference",
        "the seen surface's likelihood favours the candidates whose surface runs farthest from it",
        "    return log_weights - log_weights.max()",
        "    return log_weights.max() - log_weights",
        _t("inference"),
    ),
    Mutant(
        "surface-fit-points-not-passed",
        "inference",
        "the pipeline does not hand the objects' observed points to the physics methods",
        "points={o.id: o.points for o in fused.objects}",
        "points=None and {o.id: o.points for o in fused.objects}",
        _t("inference"),
    ),
    Mutant(
        "gravity-only-compares-every-frame",
        "inference",
        "gravity-only variants also compare the frames after the first push",
        "frames = observed.only(max(1, before))",
        "frames = observed",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "first-push-from-list-order",
        "inference",
        "gravity-only variants cut at the first push listed, not the first in time",
        "first_push = min((p.after_frame for p in pushes), default=None)",
        "first_push = next((p.after_frame for p in pushes), None)",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "pushes-not-replayed",
        "inference",
        "the recorded pushes are not replayed in the simulation of a joint model",
        "raise _Deadline\n                        world.push(push)",
        "raise _Deadline\n                        pass",
        _t("inference", "inference_method"),
    ),
    Mutant(
        "friction-not-applied",
        "inference",
        "every searched friction replays the pushes at the physics' own friction",
        "world.set_friction(friction)",
        "pass",
        _t("inference"),
    ),
    Mutant(
        "undrawn-candidates-dropped",
        "inference",
        "a candidate no sample drew gets no probability (the estimator before 2026-11-26)",
        "evidence = np.where(chosen, means, mean + _exploration_ratio(results, k, chosen))",
        "evidence = np.where(chosen, means, -np.inf)",
        _t("inference"),
    ),
    Mutant(
        "undrawn-exploration-ignored",
        "inference",
        "an undrawn candidate takes the plain mean, not scaled by its exploration probability",
        "evidence = np.where(chosen, means, mean + _exploration_ratio(results, k, chosen))",
        "evidence = np.where(chosen, means, mean)",
        _t("inference"),
    ),
    Mutant(
        "placement-order-ignored",
        "inference",
        "tree sampling places the first object it tests (largest mass bound), not the one with the"
        " largest mass",
        "if mass > best_mass or (mass == best_mass and i < best):",
        "if best < 0:",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "placed-shapes-ignored-in-stability-tests",
        "inference",
        "stability tests stand every neighbour at its minimum shape, placed ones included",
        "context = tuple((k, placed.get(k, -1)) for k in problem.neighbours[i])\n        key = ",
        "context = tuple((k, -1) for k in problem.neighbours[i])\n        key = ",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "exploration-alpha-dropped",
        "inference",
        "exploration probabilities exp(-dist) instead of exp(-alpha dist)",
        "probabilities = np.exp(-problem.config.stability_alpha_per_m * distances)",
        "probabilities = np.exp(-distances)",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "joint-weighting-uses-object-weights",
        "inference",
        'weighting="joint" falls back to the per-object weights',
        'if joint or problem.config.weighting == "joint":',
        "if joint:",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "hypothesis-weighting-sums",
        "inference",
        '"hypothesis" weighting sums exp(own term) over the draws instead of averaging',
        "means[j] = _log_mean_exp(values)",
        "means[j] = np.logaddexp.reduce(values)",
        _t("inference", "inference_method"),
    ),
    Mutant(
        "object-weight-proposal-sign",
        "inference",
        '"object" weighting multiplies by the exploration probability instead of dividing',
        "- float(result.object_log_proposal[k])",
        "+ float(result.object_log_proposal[k])",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "ess-not-squared",
        "inference",
        "Kish's effective sample size without the square of the sum",
        "return float(weights.sum() ** 2 / np.sum(weights**2))",
        "return float(weights.sum() / np.sum(weights**2))",
        _t("inference_method"),
    ),
    Mutant(
        "size-prior-inverted",
        "inference",
        "the size prior favours larger shapes",
        "log_prior = -exponent * np.log(volumes)",
        "log_prior = exponent * np.log(volumes)",
        _t("inference", "inference_method"),
    ),
    Mutant(
        "compatibility-not-built",
        "inference",
        "the sampler's problem records no pairwise constraint",
        "if not matrix.all():",
        "if False:",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "zero-probability-candidates",
        "inference",
        "hypotheses in no jointly feasible model (Collision Checker 0) become candidates",
        "keep = np.flatnonzero(posterior.probabilities > 0)\n        indices.append(keep)",
        "keep = np.arange(len(posterior.probabilities))\n        indices.append(keep)",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "flung-not-impossible",
        "inference",
        "a model whose simulation flings an object is still scored",
        "if world.exploded or world.flung().any():",
        "if world.exploded:",
        _t("inference"),
    ),
    Mutant(
        "factor-marginals-ignore-constraints",
        "inference",
        '"hypothesis" weighting combines the unary factors without the pairwise constraints',
        "if len(component) > 1 and len(component) <= 52:",
        "if False:",
        _t("inference"),
    ),
    Mutant(
        "unchosen-candidates-keep-prior",
        "inference",
        "candidates no sample chose keep their prior probability",
        "evidence = np.where(chosen, means, mean + _exploration_ratio(results, k, chosen))",
        "evidence = np.where(chosen, means, 0.0)",
        _t("inference"),
    ),
    Mutant(
        "stability-cache-ignores-context",
        "inference",
        "stability distances are cached per object, whatever the placed neighbours",
        "cached = self.cache.get(key)\n            if cached is not None:\n                return cached\n            if time",
        "cached = next((v for (o, *_), v in list(self.cache.items()) if o == i), None)\n"
        "            if cached is not None:\n                return cached\n            if time",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "reused-world-keeps-every-neighbour-shape",
        "inference",
        "the reused stability-test world switches on every shape a neighbour can take",
        "world.set_colliding(body, chosen[k] == j)",
        "world.set_colliding(body, True)",
        _t("inference_method"),
    ),
    Mutant(
        "screening-ignores-other-shapes",
        "physics",
        "a candidate touching another shape is screened as if it stood on the support alone",
        "if np.all(low <= box[1]) and np.all(box[0] <= high):",
        "if False:",
        _t("physics", "inference_method"),
    ),
    Mutant(
        "no-neighbours",
        "inference",
        "no object is another's neighbour: stability tests stand every candidate alone",
        "and np.all(box[0] - margin <= other[1])",
        "and False",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "exploded-stability-test-not-split",
        "inference",
        "a stability test that explodes is not redone candidate by candidate",
        "if world.exploded and len(simulate) > 1:",
        "if False:",
        _t("inference_method", "inference"),
        survives="no test scene makes a stability test explode: MuJoCo stayed stable with every "
        "box scene tried (candidates sunk 4 cm into a static box, 2 mm cubes inside one, 50 ms "
        "steps), so the branch that retests candidates one by one after an explosion is never "
        "taken. Killing it needs a reproducible exploding candidate (real, noisy hypotheses "
        "produce them); not pinned.",
    ),
    Mutant(
        "exhaustive-not-exact",
        "inference",
        "exhaustive enumeration weighs models like the sampler instead of by the joint weight",
        "estimate = marginals(samples, problem, joint=variant.exhaustive)",
        "estimate = marginals(samples, problem, joint=False)",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "samples-share-one-seed",
        "inference",
        "every sample draws from the same random stream (the same joint model each time)",
        "rng = np.random.default_rng([self.problem.seed, index])",
        "rng = np.random.default_rng(self.problem.seed)",
        _t("inference_method", "inference"),
    ),
    Mutant(
        "physics-medoid-base-ignored",
        "inference",
        "the physics methods' medoid starts from each candidate once, not from the Collision "
        "Checker's medoid weights (medoid_base)",
        'if medoid_base == "collision-checker":',
        "if False:",
        _t("inference"),
    ),
    Mutant(
        "silhouette-cut-never-made",
        "hypotheses",
        "an object with no feasible hypothesis is not made again within its own silhouette",
        "return _generate(obj, space, planes, config, again, bounds, True)",
        "return hypotheses",
        _t("hypotheses"),
    ),
    # ---------------------------------------------------------------- collision checker
    Mutant(
        "collision-checker-mode-not-medoid",
        "collision_checker",
        "the Collision Checker outputs its most probable hypothesis, not the medoid",
        "posterior_medoid(hyps, weights, table, leave_one_out=leave_one_out),",
        "int(np.argmax(probabilities)),",
        _t("inference_method", "collision_checker"),
    ),
    Mutant(
        "medoid-weighted-by-marginals",
        "collision_checker",
        "the Collision Checker's medoid weights the feasible candidates by their marginals",
        "hyps, weights, table, leave_one_out=",
        "hyps, probabilities, table, leave_one_out=",
        _t("collision_checker"),
    ),
    Mutant(
        "nearest-medoid-leaves-its-own-vote-out",
        "collision_checker",
        "the unequal-weights medoid scores each candidate against the others only, blind to "
        "its own weight, instead of crediting it as far as its nearest other candidate matches",
        "expected = iou @ w - w + w * others.max(axis=1)",
        "expected = (iou @ w - w) / np.maximum(w.sum() - w, 1e-300)",
        _t("collision_checker"),
    ),
    Mutant(
        "family-medoid-counts-its-own-vote",
        "collision_checker",
        "the family-weighted medoid scores each candidate against itself too, so a family's "
        "lone candidate votes for itself with its family's whole share",
        'leave_one_out = config.medoid_weights == "family"',
        "leave_one_out = False",
        _t("collision_checker"),
    ),
    Mutant(
        "outline-medoid-ignores-the-hidden-outline",
        "collision_checker",
        "the outline-weighted medoid counts each candidate once whatever the object's hidden "
        "outline fraction",
        "weights = outline_weights([h.generator for h in hyps], feasible, hidden[i])",
        "weights = outline_weights([h.generator for h in hyps], feasible, 0.0)",
        _t("collision_checker"),
    ),
    Mutant(
        "hidden-outline-counts-farther-neighbours",
        "collision_checker",
        "the hidden outline fraction counts an outside pixel farther than the object as hiding it",
        "nearer = read & (outside_depth < depth - step_m)",
        "nearer = read & (np.abs(outside_depth - depth) > step_m)",
        _t("collision_checker"),
    ),
    Mutant(
        "fit-medoid-ignores-the-surface-misfit",
        "collision_checker",
        "the fit-weighted medoid gives each family its equal share whatever its candidates' "
        "surfaces' distance from the observed points",
        "weights[kept] *= np.exp(log_likelihood - log_likelihood.max())",
        "weights[kept] *= 1.0",
        _t("collision_checker"),
    ),
    Mutant(
        "fit-misfit-keeps-the-shared-floor",
        "collision_checker",
        "the fit weights score each candidate's whole distance from the observed points, not its "
        "excess over the closest candidate's",
        "excess = np.sqrt(np.mean((distances - floor) ** 2, axis=1))",
        "excess = np.sqrt(np.mean(distances**2, axis=1))",
        _t("collision_checker"),
    ),
    Mutant(
        "fit-distance-counts-faces-behind-the-point",
        "collision_checker",
        "a seen point's distance from a candidate is measured to every face, so a thin "
        "candidate's far face behind the point explains it",
        "front = np.where(facing, signed, -np.inf).max(axis=1)",
        "front = signed.max(axis=1)",
        _t("collision_checker"),
    ),
    Mutant(
        "outline-fit-ignores-the-fit",
        "collision_checker",
        "the default medoid gives the families equal shares for the hidden share of the outline, "
        'whatever their surfaces\' fit (the "outline" rule)',
        "judged = _object_fit_weights(hyps, feasible, points[i], (viewpoints or {}).get(i))",
        "judged = family_weights([h.generator for h in hyps], feasible)",
        _t("collision_checker"),
    ),
    Mutant(
        "outline-fit-ignores-the-outline",
        "collision_checker",
        "the default medoid gives the fit weights to every object with a hidden outline, however "
        "little of it is hidden",
        "weights = (1.0 - hidden[i]) * feasible / feasible.sum() + hidden[i] * judged",
        "weights = judged",
        _t("collision_checker"),
    ),
    Mutant(
        "collision-checker-ignores-the-camera",
        "collision_checker",
        "the Collision Checker run hands no viewpoint to the fit, which then measures every face",
        "viewpoints = {o.id: object_viewpoints(o, camera_m) for o in objects}",
        "viewpoints = None",
        _t("collision_checker"),
    ),
    Mutant(
        "fit-medoid-not-given-the-points",
        "collision_checker",
        "the Collision Checker run does not hand the objects' observed points to the fit-weighted "
        "medoid, which then counts each candidate once",
        "points = {o.id: o.points for o in objects}",
        "points = None",
        _t("collision_checker"),
    ),
    Mutant(
        "medoid-families-not-weighted",
        "collision_checker",
        "the Collision Checker's medoid counts each feasible candidate once, so one family's "
        "many near-copies outvote the other families",
        'if config.medoid_weights == "family":',
        "if False:",
        _t("collision_checker"),
    ),
    Mutant(
        "medoid-ignores-iou",
        "collision_checker",
        "the posterior medoid ranks by probability alone",
        "expected = table.matrix(support) @ weights",
        "expected = weights.copy()",
        _t("inference_method", "collision_checker"),
    ),
    Mutant(
        "medoid-among-improbable",
        "collision_checker",
        "the medoid may be a hypothesis with zero probability",
        "support = np.flatnonzero(probabilities > 0)",
        "support = np.arange(len(probabilities))",
        _t("inference_method", "collision_checker"),
    ),
    Mutant(
        "gibbs-ignores-conflicts",
        "collision_checker",
        "the Gibbs sampler draws values regardless of their conflicts",
        "best = np.flatnonzero(conflicts == conflicts.min())",
        "best = np.arange(sizes[i])",
        _t("collision_checker"),
    ),
    # ---------------------------------------------------------------- constraints
    Mutant(
        "forced-overlap-not-relaxed",
        "constraints",
        "overlaps forced by the observations forbid every pair",
        "if config.relax_forced_overlap and least > tolerance:",
        "if False:",
        _t("constraints"),
    ),
    Mutant(
        "box-pretest-interval-overlap",
        "constraints",
        "the box pre-test takes the boxes' interval overlap for a depth bound (a thin candidate "
        "across a neighbour passes unqueried)",
        "move = np.minimum(hi_a[:, None, :] - lo_b[None, :, :], hi_b[None, :, :] - lo_a[:, None, :])",
        "move = np.minimum(hi_a[:, None, :], hi_b[None, :, :]) - np.maximum(lo_a[:, None, :], lo_b[None, :, :])",
        _t("constraints", "collision_checker"),
    ),
    Mutant(
        "thin-candidates-not-scaled",
        "constraints",
        "a candidate thinner than the tolerance may sink wholly into a neighbour",
        "return np.where(limits < tolerance_m, tolerance_m / np.maximum(limits, _FLAT_M), 1.0)",
        "return np.ones_like(limits)",
        _t("constraints"),
    ),
    Mutant(
        "support-constraint-dropped",
        "constraints",
        "hypotheses below the support are unary-feasible",
        "if report.below_support_m > config.support_tolerance_m:",
        "if False:",
        _t("constraints", "collision_checker"),
    ),
    Mutant(
        "penetration-sign",
        "constraints",
        "penetration depth read with the wrong sign (distance instead)",
        "cached = max(-float(distance), 0.0)",
        "cached = max(float(distance), 0.0)",
        _t("constraints", "collision_checker"),
    ),
    Mutant(
        "joint-feasibility-ignores-pairs",
        "constraints",
        "Constraints(X) of a joint model ignores intersecting pairs",
        "if not matrix[choice[i], choice[j]]:",
        "if False:",
        _t("constraints"),
    ),
    Mutant(
        "forced-free-voxels-not-forgiven",
        "constraints",
        "unary check counts the seen-free voxels the observed points' own hull forces",
        "free = report.free_voxels - h.excused_free_voxels - h.forced_free_voxels",
        "free = report.free_voxels - h.excused_free_voxels",
        _t("constraints", "hypotheses", "collision_checker"),
    ),
    # ---------------------------------------------------------------- physics
    Mutant(
        "gravity-upwards",
        "physics",
        "gravity along the support normal instead of against it",
        "spec.option.gravity = (-config.gravity_m_s2 * up).tolist()",
        "spec.option.gravity = (config.gravity_m_s2 * up).tolist()",
        _t("physics"),
    ),
    Mutant(
        "candidates-collide",
        "physics",
        "an object's candidates collide with each other in a stability test",
        "contype=2 if body.candidate else 1,",
        "contype=1,",
        _t("physics", "inference_method"),
    ),
    Mutant(
        "drop-measures-rise",
        "physics",
        "the stability drop measures how far a shape rose, not fell",
        "return np.maximum(self.vertical_motions(), 0.0)",
        "return np.maximum(-self.vertical_motions(), 0.0)",
        _t("inference_method", "inference", "physics"),
    ),
    Mutant(
        "pusher-stays-at-start",
        "physics",
        "the pusher does not travel along its push",
        " mocap[self.pusher_mocap] = start + direction * travelled",
        " mocap[self.pusher_mocap] = start",
        _t("physics", "inference"),
    ),
    Mutant(
        "never-flung",
        "physics",
        "no object is ever flung",
        "result[dynamic] = moved > self.config.flung_m",
        "result[dynamic] = False",
        _t("physics", "inference"),
    ),
    Mutant(
        "decimated-camera-offset",
        "physics",
        "the decimated camera's principal point ignores the sampling offset",
        "small[0, 2] = (K[0, 2] - factor // 2) / factor",
        "small[0, 2] = K[0, 2] / factor",
        _t("physics", "inference_method"),
    ),
    # ---------------------------------------------------------------- fusion
    Mutant(
        "icp-rotation-frozen",
        "fusion",
        "ICP never updates the rotation",
        "rotations[start] = step @ rotations[start]",
        "rotations[start] = rotations[start]",
        _t("fusion"),
    ),
    Mutant(
        "static-push-inverted",
        "fusion",
        "a push that moved the object is taken as one that passed it by, and vice versa",
        "if moved < config.static_tolerance_m:",
        "if moved >= config.static_tolerance_m:",
        _t("fusion"),
    ),
    Mutant(
        "later-free-space-ignored",
        "fusion",
        "space seen free in later frames never frees frame 0's unknown voxels",
        "states[hidden[seen_free]] = FREE",
        "pass",
        _t("fusion"),
    ),
    Mutant(
        "registration-free-space-penalty-dropped",
        "fusion",
        "view registration scores overlap only, not landing in seen-free space",
        "score = overlap - config.free_weight * (free[slot] + reverse[slot])",
        "score = overlap",
        _t("fusion"),
    ),
    # ---------------------------------------------------------------- carving
    Mutant(
        "carving-margin-sign",
        "carving",
        "voxels up to a margin behind the observed surface are carved",
        "return inside & (surface > 0) & (z < surface - view.margin_m)",
        "return inside & (surface > 0) & (z < surface + view.margin_m)",
        _t("carving"),
    ),
    Mutant(
        "carving-robot-mask-ignored",
        "carving",
        "the robot's pixels carve the objects behind it",
        "depth[np.asarray(frame.robot_mask, bool)] = 0.0",
        "pass",
        _t("carving"),
    ),
    Mutant(
        "carving-ignores-motion",
        "carving",
        "later views carve the objects at their frame-0 pose",
        "moved = centres @ motion[:3, :3].T + motion[:3, 3]",
        "moved = centres",
        _t("carving"),
    ),
    # ---------------------------------------------------------------- hypotheses (Algorithm 1)
    Mutant(
        "mirror-not-reflected",
        "hypotheses",
        "a facet is translated by d instead of mirrored about its plane and moved",
        "return facet.points - (2.0 * offsets + d)[:, None] * n",
        "return facet.points - d * n",
        _t("hypotheses"),
    ),
    Mutant(
        "min-thickness-ignored",
        "hypotheses",
        "sampled distances may be thinner than D_min",
        "lower = np.maximum(facet.cells, config.min_thickness_m)",
        "lower = facet.cells",
        _t("hypotheses"),
    ),
    Mutant(
        "contains-any-plane",
        "hypotheses",
        "a point is inside a hull when inside any one face plane",
        "return np.all(points @ planes[:, :3].T + planes[:, 3] <= tolerance_m, axis=1)",
        "return np.any(points @ planes[:, :3].T + planes[:, 3] <= tolerance_m, axis=1)",
        _t("hypotheses", "fusion"),
    ),
    Mutant(
        "support-cut-skipped",
        "hypotheses",
        "hypotheses are not cut at the support plane",
        "for cut in ctx.cuts:",
        "for cut in ():",
        _t("hypotheses"),
    ),
    # ---------------------------------------------------------------- metrics
    Mutant(
        "iou-is-precision",
        "metrics",
        "IoU divides by the predicted voxels instead of the union",
        "iou = intersection / union if union else 0.0",
        "iou = intersection / predicted if predicted else 0.0",
        _t("metrics"),
    ),
    Mutant(
        "f1-halved",
        "metrics",
        "F1 without its factor 2",
        "f1 = 2 * precision * recall / (precision + recall)",
        "f1 = precision * recall / (precision + recall)",
        _t("metrics"),
    ),
    Mutant(
        "visibility-needs-a-reading",
        "metrics",
        "pixels without a depth reading never show an object",
        "consistent = (observed <= 0) | (depth <= observed + tolerance_m)",
        "consistent = depth <= observed + tolerance_m",
        _t("metrics"),
    ),
    Mutant(
        "matching-keeps-disjoint-pairs",
        "metrics",
        "the Hungarian assignment's pairs that do not overlap count as matches",
        "for r, c in zip(rows, cols, strict=True) if intersections[r, c] > 0",
        "for r, c in zip(rows, cols, strict=True) if True",
        _t("metrics"),
    ),
    # ---------------------------------------------------------------- perception
    Mutant(
        "surface-continuation-never-joins",
        "perception",
        "a small piece of another colour never counts as continuing its neighbour's smooth "
        "surface (the colour gate alone decides, as before 2026-11-28)",
        "return bool(residual <= _EXTRAPOLATED_SCATTER * scatter)",
        "return False",
        _t("fragments"),
    ),
    Mutant(
        "eigengap-never-extended",
        "perception",
        "the number of clusters is read from the first max_objects + 1 eigenvalues only, even "
        "when their largest gap is the last one",
        "while config.segmentation.eigengap_extend and k == wanted - 1 and wanted < m - 1:",
        "while False:",
        _t("segmentation"),
    ),
)


# --------------------------------------------------------------------------------------------
# Locating and applying


@dataclass
class Located:
    """Where a mutant's snippet is: the file (relative to ``src/``), its line and function."""

    path: Path
    line: int
    function: str


@dataclass
class Outcome:
    mutant: Mutant
    status: str  # "killed", "survived", "error"
    where: Located | None = None
    killer: str = ""
    detail: str = ""
    seconds: float = 0.0
    stages: list[str] = field(default_factory=list)


def _sources() -> dict[Path, str]:
    return {p.relative_to(SOURCE): p.read_text() for p in sorted(PACKAGE.rglob("*.py"))}


def locate(mutant: Mutant, sources: dict[Path, str]) -> Located:
    """The single file holding ``mutant.find`` exactly once; ValueError otherwise."""
    hits = [(path, text.count(mutant.find)) for path, text in sources.items()]
    hits = [(path, count) for path, count in hits if count]
    if not hits:
        raise ValueError("snippet not found in src/ipr_shapes")
    if len(hits) > 1 or hits[0][1] > 1:
        where = ", ".join(f"{path} ({count}x)" for path, count in hits)
        raise ValueError(f"snippet ambiguous: {where}")
    path = hits[0][0]
    text = sources[path]
    offset = text.index(mutant.find)
    line = text.count("\n", 0, offset) + 1
    return Located(path, line, _enclosing(text.splitlines(), line - 1))


def _enclosing(lines: list[str], index: int) -> str:
    """Dotted name of the functions and classes enclosing line ``index`` (0-based)."""

    def indent(text: str) -> int:
        return len(text) - len(text.lstrip())

    limit = indent(lines[index])
    names = []
    for previous in reversed(lines[:index]):
        if not previous.strip() or indent(previous) >= limit or previous.strip()[0] in ")]}":
            continue  # blank, deeper, or the closing bracket of a multi-line signature
        limit = indent(previous)
        match = re.match(r"\s*(?:async\s+)?(?:def|class)\s+(\w+)", previous)
        if match:
            names.append(match.group(1))
        if limit == 0:
            break
    return ".".join(reversed(names)) or "(module)"


def _prepare_workspace() -> Path:
    """A fresh copy of ``src/`` with the sources' modification times (numba's cache keys)."""
    src = WORKSPACE / "src"
    if src.exists():
        shutil.rmtree(src)
    shutil.copytree(SOURCE, src, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    return src


def _environment(src: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(src), str(ROOT)])
    env["NUMBA_CACHE_DIR"] = str(NUMBA_CACHE)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    env.pop("PYTEST_ADDOPTS", None)
    return env


def _run(args: list[str], env: dict[str, str], timeout_s: float) -> tuple[int, str]:
    """Run pytest in its own process group (killed whole on timeout or Ctrl-C)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "pytest", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        output, _ = process.communicate(timeout=timeout_s)
        return process.returncode, output
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        output, _ = process.communicate()
        return -1, output + f"\n[timeout after {timeout_s:.0f} s]"
    except BaseException:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.communicate()
        raise


def _killer(output: str) -> str:
    """The first failing test (or collection error) of a pytest run's output."""
    for pattern in (r"^FAILED (\S+)", r"^ERROR (\S+)"):
        match = re.search(pattern, output, re.MULTILINE)
        if match:
            return match.group(1)
    if "[timeout after" in output:
        return "(timeout)"
    tail = [line for line in output.strip().splitlines() if line.strip()]
    return tail[-1][:120] if tail else "(no output)"


def run_mutant(
    mutant: Mutant,
    sources: dict[Path, str],
    src: Path,
    env: dict[str, str],
    *,
    full: bool,
    timeout_s: float,
) -> Outcome:
    started = time.perf_counter()
    try:
        where = locate(mutant, sources)
    except ValueError as error:
        return Outcome(mutant, "error", detail=str(error))
    target = src / where.path
    original = sources[where.path]
    stat = (SOURCE / where.path).stat()
    mutated = original.replace(mutant.find, mutant.replace, 1)
    try:
        compile(mutated, str(where.path), "exec")
    except SyntaxError as error:
        return Outcome(mutant, "error", where, detail=f"the mutation does not compile: {error}")
    outcome = Outcome(mutant, "survived", where)
    try:
        target.write_text(mutated)
        stages = [list(mutant.tests)] if mutant.tests else []
        if full:
            stages.append(list(FULL))
        for files in stages:
            missing = [f for f in files if not (ROOT / f).exists()]
            if missing:
                return Outcome(mutant, "error", where, detail=f"missing tests {missing}")
            outcome.stages.append(" ".join(files))
            code, output = _run([*PYTEST, *files], env, timeout_s)
            if code != 0 and code != 5:  # 5: no test collected (e.g. all slow)
                outcome.status, outcome.killer = "killed", _killer(output)
                break
    finally:
        target.write_text(original)
        os.utime(target, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    outcome.seconds = time.perf_counter() - started
    return outcome


# --------------------------------------------------------------------------------------------
# Report


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _code(text: str) -> str:
    text = " ⏎ ".join(line.strip() for line in text.splitlines())
    return f"`{text}`" if "`" not in text else _cell(text)


def report(outcomes: list[Outcome], seconds: float, full: bool) -> str:
    killed = sum(o.status == "killed" for o in outcomes)
    survived = [o for o in outcomes if o.status == "survived"]
    errors = [o for o in outcomes if o.status == "error"]
    total = len(outcomes)
    rate = killed / total if total else 0.0
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    lines = [
        "# Mutation testing of the core",
        "",
        "Generated by `make mutants` (`scripts/mutants.py`): each curated single-line mutation "
        "of `src/ipr_shapes` is applied to a private copy of the sources (located by a snippet that "
        "must occur exactly once in `src/ipr_shapes/**/*.py`), then the test files likeliest to kill "
        'it run (`pytest -x -q -m "not slow"`), then, if they pass, the whole default test '
        'set (`pytest -m "not slow" tests`)'
        + ("" if full else " (skipped in this run: `--no-full`)")
        + ". A mutant whose snippet is missing or ambiguous is an error, not a kill.",
        "",
        f"- Commit: `{commit}`, {datetime.date.today().isoformat()}",
        f"- **Kill rate: {killed}/{total} = {100 * rate:.1f} %** "
        f"({len(survived)} survived, {len(errors)} errors)",
        f"- Wall time: {seconds / 60:.1f} min",
        "",
        "| id | where | mutation | result |",
        "| --- | --- | --- | --- |",
    ]
    for o in outcomes:
        m = o.mutant
        where = f"`{o.where.path}:{o.where.line}` `{o.where.function}`" if o.where else "?"
        mutation = f"{_cell(m.what)}: {_code(m.find)} → {_code(m.replace)}"
        if o.status == "killed":
            result = f"killed by `{o.killer}` ({o.seconds:.0f} s)"
        elif o.status == "survived":
            result = "**survived**" + (f": {_cell(m.survives)}" if m.survives else "")
        else:
            result = f"error: {_cell(o.detail)}"
        lines.append(f"| {m.id} | {where} | {mutation} | {result} |")
    lines.append("")
    if survived:
        lines += ["## Survivors", ""]
        for o in survived:
            why = o.mutant.survives or "not explained: add a test that kills it"
            lines.append(f"- **{o.mutant.id}** ({o.mutant.area}): {why}")
        lines.append("")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", metavar="ID", help="run only these mutants")
    parser.add_argument("--list", action="store_true", help="list the mutants and where")
    parser.add_argument("--no-full", action="store_true", help="skip the full-suite stage")
    parser.add_argument("--timeout", type=float, default=1200.0, help="per pytest run (s)")
    parser.add_argument("--report", type=Path, default=ROOT / "docs" / "MUTANTS.md")
    parser.add_argument("--min-kill-rate", type=float, default=0.9)
    args = parser.parse_args(argv)

    sources = _sources()
    mutants = list(MUTANTS)
    ids = [m.id for m in mutants]
    if len(set(ids)) != len(ids):
        raise SystemExit("duplicate mutant ids")
    if args.only:
        unknown = set(args.only) - set(ids)
        if unknown:
            raise SystemExit(f"unknown mutants: {sorted(unknown)}")
        mutants = [m for m in mutants if m.id in args.only]
    if args.list:
        for m in mutants:
            try:
                where = locate(m, sources)
                print(f"{m.id:45s} {where.path}:{where.line} {where.function}")
            except ValueError as error:
                print(f"{m.id:45s} ERROR {error}")
        return 0

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    # Ctrl-C and a plain kill both stop the tests in flight and clean up (the finally blocks).
    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    WORKSPACE.mkdir(parents=True, exist_ok=True)
    NUMBA_CACHE.mkdir(parents=True, exist_ok=True)
    lock = open(WORKSPACE / ".lock", "w")  # noqa: SIM115 (held for the whole run)
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        raise SystemExit(f"another mutation run holds {WORKSPACE}") from None
    started = time.perf_counter()
    outcomes: list[Outcome] = []
    try:
        src = _prepare_workspace()
        env = _environment(src)
        # The copy, not the installed package, must be what the tests import.
        probe = subprocess.run(
            [sys.executable, "-c", "import ipr_shapes, sys; sys.stdout.write(ipr_shapes.__file__)"],
            cwd=ROOT, env=env, capture_output=True, text=True, check=True,
        )  # fmt: skip
        if not Path(probe.stdout).resolve().is_relative_to(src.resolve()):
            raise SystemExit(f"tests would import {probe.stdout}, not the mutated copy")
        for number, mutant in enumerate(mutants, 1):
            outcome = run_mutant(
                mutant, sources, src, env, full=not args.no_full, timeout_s=args.timeout
            )
            outcomes.append(outcome)
            result = outcome.status + (f" by {outcome.killer}" if outcome.killer else "")
            result += f" {outcome.detail}" if outcome.detail else ""
            print(
                f"[{number}/{len(mutants)}] {mutant.id}: {result} ({outcome.seconds:.0f} s)",
                flush=True,
            )
    except KeyboardInterrupt:
        print("interrupted: the working tree was never modified", file=sys.stderr)
        return 130
    finally:
        shutil.rmtree(WORKSPACE / "src", ignore_errors=True)
        lock.close()
    seconds = time.perf_counter() - started
    text = report(outcomes, seconds, not args.no_full)
    if args.only:
        print(text)
    else:
        args.report.write_text(text)
        print(f"report written to {args.report}")
    killed = sum(o.status == "killed" for o in outcomes)
    rate = killed / len(outcomes) if outcomes else 0.0
    print(f"kill rate {killed}/{len(outcomes)} = {100 * rate:.1f} % in {seconds / 60:.1f} min")
    return 0 if rate >= args.min_kill_rate else 1


if __name__ == "__main__":
    sys.exit(main())
