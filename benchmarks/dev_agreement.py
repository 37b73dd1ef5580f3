"""Development measurement: how often the sampler's most probable hypothesis is exhaustive
search's, emulated offline on exhaustive tables (docs/experiments/2026-11-27-sampler-agreement.md).

Usage: ``python -m benchmarks.dev_agreement [--sets 9100:10 9400:10] [--scenes DIR]
[--perception-sets 8100:24 8200:24] [--tables DIR] [--seeds 10] [--share 0.18 0.3]
[--proposal tree cover uniform] [--scene DIR ...]``

1. Tables: per development scene that exhaustive search accepts (at most 4 objects after
   perception, 6 hypotheses per object, as the benchmark's comparison), the method
   ``exhaustive`` is run through ``run_pipeline`` (one worker, seed 0) and its
   ``InferenceProblem``, every jointly feasible joint model's depth error norms and the CPU
   seconds of its simulation are kept (pickled in ``--tables``, reused).
2. Emulation: a sampler draws joint models as it would (``--proposal``: "tree", the tree sampler
   with its real stability tests, whose CPU seconds are measured once per context; "uniform",
   ``InferenceConfig.proposal`` "uniform"; "cover", each object's least drawn compatible
   candidate, emulated here only) and looks their norms up in the table, charging the CPU
   of each stability-test context and each joint model the first time the run needs it,
   until ``--share`` of exhaustive's CPU (the sum over its models) is spent; a run with no sample returns the Collision Checker's
   answer, as the pipeline does (the marginals of the feasibility counts). Each of
   ``--seeds`` runs draws its own samples, so agreement is a distribution, not one draw.
3. Estimators on the same samples (``InferenceConfig.weighting`` "hypothesis" with
   ``drawn_models`` "factorised" and, as "drawn-exact", "exact" (the default), "object",
   "joint"; "models": the exact posterior restricted to the distinct joint models evaluated,
   which becomes exhaustive's as they cover the table).

Agreement is counted on the objects whose exact favourite leads the runner-up by more than
``benchmarks.inference_score.CLEAR_MARGIN`` (the benchmark's target). Development scenes only
(``benchmarks.common.development_scenes``; never the suites).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import pickle
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np

#: Hypotheses per object of the tables (``benchmarks.inference_run.COMPARISON_HYPOTHESES``).
HYPOTHESES = 6
#: CPU seconds charged per sample for drawing it once its stability tests are cached.
DRAW_S = 0.0005
PROPOSALS = ("tree", "cover", "uniform")


# --------------------------------------------------------------------------------------------
# Tables


@contextlib.contextmanager
def _captured() -> Iterator[dict]:
    """While open, the pipeline's ``run_samples`` (called as it is) leaves its problem and
    results in the yielded dict, and ``Sampler.depth_norms`` each joint model's CPU seconds."""
    import ipr_shapes.inference.infer as infer_module
    from ipr_shapes.inference.sampler import Sampler

    captured: dict = {"cpu": {}}
    run_samples, depth_norms = infer_module.run_samples, Sampler.depth_norms

    def capturing_run(problem, tasks, **options):
        captured["problem"] = problem
        captured["results"] = run_samples(problem, tasks, **options)
        return captured["results"]

    def timed_norms(self, choice, deadline=math.inf):
        started = time.process_time()
        norms = depth_norms(self, choice, deadline)
        captured["cpu"][tuple(choice)] = time.process_time() - started
        return norms

    infer_module.run_samples, Sampler.depth_norms = capturing_run, timed_norms
    try:
        yield captured
    finally:
        infer_module.run_samples, Sampler.depth_norms = run_samples, depth_norms


def build_table(scene_path: Path) -> dict | None:
    """{"problem", "models", "norms", "cpu"} of exhaustive search on one scene (``HYPOTHESES``
    per object, one worker, seed 0); None when exhaustive refuses it."""
    from benchmarks.inference_run import with_hypotheses
    from ipr_shapes.errors import IprError
    from ipr_shapes.pipeline import run_pipeline
    from ipr_shapes.scene import load_scene

    config = with_hypotheses(None, HYPOTHESES)
    with _captured() as captured:
        try:
            run_pipeline(
                load_scene(scene_path), config, method="exhaustive", seed=0, workers=1,
                samples=config.inference.max_exhaustive_models,
            )  # fmt: skip
        except IprError:
            return None
    if "problem" not in captured or not captured["results"]:
        return None
    results = captured["results"]
    return {
        "problem": captured["problem"],
        "models": [r.choice for r in results],
        "norms": [r.norms for r in results],
        "cpu": [captured["cpu"][r.choice] for r in results],
    }


def cached_table(scene_path: Path, folder: Path) -> dict | None:
    """``build_table``, read from / written to ``folder`` (a refused scene is remembered)."""
    file = folder / f"{scene_path.parent.name}-{scene_path.name}.pkl"
    if file.exists():
        return pickle.loads(file.read_bytes())
    table = build_table(scene_path)
    folder.mkdir(parents=True, exist_ok=True)
    partial = file.with_suffix(".part")
    partial.write_bytes(pickle.dumps(table))
    partial.rename(file)
    return table


# --------------------------------------------------------------------------------------------
# Estimators


def models_marginals(results, problem) -> list[np.ndarray] | None:
    """Each object's marginal under the exact posterior restricted to the distinct joint
    models of ``results``: P(X) proportional to P(O | X) P(X) over the models evaluated, each
    once whatever its draws (the proposal does not enter); exhaustive's marginals when they
    are every feasible model."""
    from ipr_shapes.inference.estimators import marginals

    distinct = {r.choice: dataclasses.replace(r, log_proposal=0.0) for r in results}
    return marginals(list(distinct.values()), problem, joint=True)


def _weighted(weighting: str, drawn_models: str = "factorised") -> Callable:
    from ipr_shapes.inference.estimators import marginals

    def estimate(results, problem):
        config = dataclasses.replace(problem.config, weighting=weighting, drawn_models=drawn_models)
        return marginals(results, dataclasses.replace(problem, config=config))

    return estimate


ESTIMATORS: dict[str, Callable] = {
    "hypothesis": _weighted("hypothesis", "factorised"),
    "drawn-exact": _weighted("hypothesis", "exact"),
    "object": _weighted("object"),
    "joint": _weighted("joint"),
    "models": models_marginals,
}


def clear_agreements(
    exact: Sequence[np.ndarray], estimate: Sequence[np.ndarray], min_margin: float
) -> list[bool]:
    """Per object whose exact favourite leads the runner-up by more than ``min_margin``
    (probability), whether ``estimate``'s most probable candidate is that favourite."""
    out = []
    for reference, values in zip(exact, estimate, strict=True):
        ranked = np.sort(reference)[::-1]
        if ranked[0] - (ranked[1] if ranked.size > 1 else 0.0) > min_margin:
            out.append(int(np.argmax(values)) == int(np.argmax(reference)))
    return out


# --------------------------------------------------------------------------------------------
# Emulation


class Emulation:
    """A sampler's runs on one table (module doc, step 2)."""

    def __init__(self, table: dict, name: str = "") -> None:
        from ipr_shapes.inference.estimators import marginals
        from ipr_shapes.inference.sampler import Sampler

        self.name = name
        self.problem = table["problem"]
        self.norms = dict(zip(table["models"], table["norms"], strict=True))
        self.cpu = dict(zip(table["models"], table["cpu"], strict=True))
        self.total_cpu = float(sum(table["cpu"]))
        self.sampler = Sampler(self.problem)
        self.test_cpu: dict = {}
        self._touched: set | None = None
        distances = self.sampler._distances

        def timed(i, placed, deadline):
            key = (i, tuple((k, placed.get(k, -1)) for k in self.problem.neighbours[i]))
            if key not in self.test_cpu:
                started = time.process_time()
                out = distances(i, placed, deadline)
                self.test_cpu[key] = time.process_time() - started
            else:
                out = distances(i, placed, deadline)
            if self._touched is not None:
                self._touched.add(key)
            return out

        self.sampler._distances = timed
        every = [self.result(0, m, (0.0,) * self.problem.count, ()) for m in self.norms]
        self.exact = marginals(every, self.problem, joint=True)
        counts = [np.zeros(len(c)) for c in self.problem.candidates]
        for model in self.norms:
            for k, j in enumerate(model):
                counts[k][j] += 1
        self.checker = [c / c.sum() for c in counts]

    def result(self, index, choice, object_log_proposal, explored):
        """The ``SampleResult`` the sampler would return for ``choice``, from the table."""
        from ipr_shapes.inference.problem import SampleResult

        norms = self.norms[choice]
        return SampleResult(
            index, choice, float(sum(object_log_proposal)),
            self.sampler.log_likelihood_of(norms), self.sampler.log_prior(choice),
            0.0, 0, norms, tuple(object_log_proposal), tuple(explored),
        )  # fmt: skip

    def _spread(self, rng, drawn):
        """A joint model of the "cover" proposal (no stability tests; not in the library):
        objects in random order, each taking one of the candidates compatible with those
        placed, uniformly among the least drawn so far in this run; None at a dead end."""
        problem = self.problem
        placed: dict[int, int] = {}
        logq = [0.0] * problem.count
        for i in rng.permutation(problem.count):
            allowed = np.ones(len(problem.candidates[i]), dtype=bool)
            for k, j in placed.items():
                allowed &= problem.compatibility(int(i), k)[:, j]
            if not allowed.any():
                return None
            counts = np.where(allowed, drawn[i], np.inf)
            placed[int(i)] = int(rng.choice(np.flatnonzero(counts == counts.min())))
            logq[i] = -math.log(int(allowed.sum()))
        return tuple(placed[i] for i in range(problem.count)), tuple(logq), ()

    def run(self, seed: int, share: float, proposal: str = "tree", max_samples: int = 100_000):
        """(samples, share of exhaustive's CPU spent) of one run (module doc, step 2)."""
        budget, spent = share * self.total_cpu, 0.0
        seen: set = set()
        charged: set = set()
        drawn = [np.zeros(len(c)) for c in self.problem.candidates]
        results = []
        self._touched = set()
        try:
            for index in range(max_samples):
                rng = np.random.default_rng([seed, index])
                if proposal == "tree":
                    choice, logq, explored = self.sampler.tree_sample_explored(rng)
                elif proposal == "uniform":
                    choice, logq, explored = self.sampler.uniform_sample_explored(rng)
                else:
                    drawn_model = None
                    while drawn_model is None:
                        drawn_model = self._spread(rng, drawn)
                    choice, logq, explored = drawn_model
                new = self._touched - charged
                cost = DRAW_S + sum(self.test_cpu[key] for key in new)
                cost += self.cpu[choice] if choice not in seen else 0.0
                if spent + cost > budget:
                    break
                spent += cost
                charged |= new
                seen.add(choice)
                for k, j in enumerate(choice):
                    drawn[k][j] += 1
                results.append(self.result(index, choice, logq, explored))
        finally:
            self._touched = None
        return results, spent / self.total_cpu

    def agreements(self, results, estimator: str, min_margin: float) -> list[bool]:
        """``clear_agreements`` of one run's estimate (the Collision Checker's without
        samples)."""
        estimate = ESTIMATORS[estimator](results, self.problem) if results else None
        return clear_agreements(self.exact, estimate or self.checker, min_margin)


# --------------------------------------------------------------------------------------------
# Command line


def _sets(values: Sequence[str], root: Path) -> list[Path]:
    from benchmarks.common import development_scenes

    paths = []
    for value in values:
        seed, count = (int(v) for v in value.split(":"))
        paths += development_scenes(root, seed, count)
    return paths


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sets", nargs="*", default=["9100:10", "9400:10"], help="SEED:COUNT")
    parser.add_argument("--scenes", type=Path, default=Path("/tmp/ipr-dev-inference"))
    parser.add_argument("--perception-sets", nargs="*", default=[], help="SEED:COUNT")
    parser.add_argument("--perception-scenes", type=Path, default=Path("/tmp/ipr-dev-perception"))
    parser.add_argument(
        "--scene", type=Path, action="append", default=[], help="a further scene (repeatable)"
    )
    parser.add_argument("--tables", type=Path, default=Path("/tmp/ipr-dev-agreement"))
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--share", type=float, nargs="*", default=[0.18])
    parser.add_argument("--proposal", nargs="*", default=["tree"], choices=PROPOSALS)
    args = parser.parse_args(argv)
    # Checked before any table is built: a scene that cannot be read would otherwise be cached
    # as one that exhaustive search refuses.
    for scene in args.scene:
        if not (scene / "scene_camera.json").is_file():
            parser.error(f"--scene {scene}: not a scene folder (no scene_camera.json there)")
    for value in (*args.sets, *args.perception_sets):
        parts = value.split(":")
        if len(parts) != 2 or not all(p.isdigit() for p in parts) or int(parts[1]) < 1:
            parser.error(f"a set is SEED:COUNT with a count of at least 1, got {value!r}")
    if not all(0.0 < share <= 1.0 for share in args.share):
        parser.error(f"--share takes shares of exhaustive's CPU in (0, 1], got {args.share}")
    if args.seeds < 1:
        parser.error(f"--seeds must be at least 1, got {args.seeds}")
    from benchmarks.inference_score import CLEAR_MARGIN

    paths = _sets(args.sets, args.scenes) + _sets(args.perception_sets, args.perception_scenes)
    paths += args.scene
    emulations = []
    for path in paths:
        table = cached_table(path, args.tables)
        if table is not None:
            emulations.append(Emulation(table, f"{path.parent.name}/{path.name}"))
    clear = sum(len(clear_agreements(e.exact, e.exact, CLEAR_MARGIN)) for e in emulations)
    print(
        f"{len(emulations)} of {len(paths)} scenes accepted by exhaustive; {clear} objects with "
        f"an exact margin > {CLEAR_MARGIN}",
        flush=True,
    )
    for share in args.share:
        for proposal in args.proposal:
            same = {name: np.zeros(args.seeds) for name in ESTIMATORS}
            samples, distinct, spent = [], [], []
            for emulation in emulations:
                for seed in range(args.seeds):
                    results, used = emulation.run(seed, share, proposal)
                    samples.append(len(results))
                    distinct.append(len({r.choice for r in results}))
                    spent.append(used)
                    for name in ESTIMATORS:
                        same[name][seed] += sum(emulation.agreements(results, name, CLEAR_MARGIN))
            print(
                f"share {share:g}, proposal {proposal}: samples per scene median "
                f"{np.median(samples):.0f} ({np.median(distinct):.0f} distinct), CPU spent "
                f"median {np.median(spent):.2f}; " + "; ".join(
                    f"{name} {np.mean(v) / clear:.3f} ({np.min(v) / clear:.3f}-"
                    f"{np.max(v) / clear:.3f})"
                    for name, v in same.items()
                ),
                flush=True,
            )  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
