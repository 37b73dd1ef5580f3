"""The inference methods: one registry that the CLI, the pipeline, the benchmarks and the docs
read (a light module: listing the methods loads neither MuJoCo nor numba).

A method is the paper's Collision Checker (no physics), its Zheng et al. 2013 baseline
(``ipr_shapes.baselines``; not built on the hypotheses), or one of its IPR variants: whether the
recorded pushes are replayed (and the later frames' views used), and the shape prior. The
exhaustive search scores every jointly feasible joint model, to validate the sampler.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ipr_shapes.errors import IprError

Prior = Literal["uniform", "size"]


@dataclass(frozen=True)
class Method:
    """One inference method.

    Attributes:
        name: the name ``ipr-shapes infer --method`` takes and results record.
        physics: scored by simulation (False: the Collision Checker, constraints only).
        actions: registers the later frames' views into frame 0 before the hypotheses
            (``ipr_shapes.fusion``); with ``physics``, also replays the recorded pushes and
            compares the later frames.
        prior: the shape prior, uniform or favouring smaller shapes (paper Sec. IV-F).
        exhaustive: scores every jointly feasible joint model instead of sampling.
        description: one line for ``--help`` and the docs.
    """

    name: str
    physics: bool
    actions: bool
    prior: Prior
    exhaustive: bool = False
    description: str = ""


#: Every method ``ipr-shapes infer`` accepts, in the order the docs and benchmark tables show them.
METHODS: dict[str, Method] = {
    method.name: method
    for method in (
        Method(
            "collision-checker",
            physics=False,
            actions=False,
            prior="uniform",
            description="no physics: uniform over jointly feasible shapes (the paper's baseline)",
        ),
        Method(
            "collision-checker+views",
            physics=False,
            actions=True,
            prior="uniform",
            description="no physics, with the later frames' views fused as the full method "
            "fuses them (what the physics adds is the full method's lead over this)",
        ),
        Method(
            "zheng2013",
            physics=False,
            actions=False,
            prior="uniform",
            description="Zheng et al. 2013: Manhattan boxes grown into unseen space, stability "
            "grouping (the paper's first baseline)",
        ),
        Method(
            "ipr+uniform",
            physics=True,
            actions=False,
            prior="uniform",
            description="gravity only, uniform prior",
        ),
        Method(
            "ipr+size",
            physics=True,
            actions=False,
            prior="size",
            description="gravity only, smaller shapes a priori more probable",
        ),
        Method(
            "ipr+action+uniform",
            physics=True,
            actions=True,
            prior="uniform",
            description="gravity and the recorded pushes, uniform prior (the full method)",
        ),
        Method(
            "ipr+action+size",
            physics=True,
            actions=True,
            prior="size",
            description="gravity and the recorded pushes, size prior",
        ),
        Method(
            "exhaustive",
            physics=True,
            actions=True,
            prior="uniform",
            exhaustive=True,
            description="scores every joint model (at most 4 objects; validates the sampler)",
        ),
    )
}
#: The physics-based methods (``ipr_shapes.inference``).
PHYSICS_METHODS = tuple(name for name, method in METHODS.items() if method.physics)
#: Methods that are other authors' baselines, not built on ipr's hypotheses (``ipr_shapes.baselines``).
BASELINE_METHODS = ("zheng2013",)
#: The full method: gravity and the recorded pushes, uniform prior.
DEFAULT_METHOD = "ipr+action+uniform"


def get_method(name: str) -> Method:
    """The registered method called ``name``; IprError listing the methods otherwise."""
    try:
        return METHODS[name]
    except (KeyError, TypeError):
        raise IprError(f"unknown method {name!r}; available: {', '.join(METHODS)}") from None
