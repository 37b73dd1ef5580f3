"""Names of the inference methods (a light module: the CLI lists them without loading MuJoCo).

``ipr.inference.VARIANTS`` defines the physics-based ones; ``ipr.pipeline.METHODS`` runs all.
"""

from __future__ import annotations

#: The paper's IPR variants (gravity only / with the pushes; uniform / size prior) and the
#: exhaustive search that validates the sampler.
PHYSICS_METHODS = (
    "ipr+uniform",
    "ipr+size",
    "ipr+action+uniform",
    "ipr+action+size",
    "exhaustive",
)
#: Every method ``ipr infer`` accepts.
METHODS = ("collision-checker", *PHYSICS_METHODS)
#: The full method: gravity and the recorded pushes, uniform prior.
DEFAULT_METHOD = "ipr+action+uniform"
