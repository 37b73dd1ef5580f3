"""Exhaustive enumeration of the jointly feasible joint models: the exact posterior the sampler
estimates, for scenes small enough to enumerate."""

from __future__ import annotations

import itertools
import math

from ipr_shapes.errors import IprError
from ipr_shapes.inference.problem import InferenceProblem


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
