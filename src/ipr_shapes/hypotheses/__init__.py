"""The hypotheses stage: complete shapes for each partial object and the constraints on them.

- ``generate``: Algorithm 1 (paper Sec. IV-B): mirrored facets, convex hulls, the unary checks
  at generation, and each object's minimum shape; beside Algorithm 1's, a share of the count
  (``HypothesisConfig.structure_share``) goes to structure-aware candidates.
- ``structure``: the structure-aware families: symmetry planes, surfaces of revolution, boxes,
  cylinders and spheres fitted to the observed points (issue 28).
- ``superquadric``: superquadrics with fitted exponents, the seen-free space kept out
  (``HypothesisConfig.superquadric_count`` of the structure-aware candidates).
- ``constraints``: Constraints(X) (Sec. IV-C): unary feasibility and pairwise penetration.
- ``prepare``: both together for all objects of frame 0, the ``PreparedHypotheses`` every
  inference method starts from.
"""

from ipr_shapes.hypotheses.constraints import (
    ConstraintConfig,
    OverlapCache,
    intersection_volume,
    joint_feasible,
    overlap_matrix,
    overlap_threshold,
    penetration_depth,
    unary_feasible,
)
from ipr_shapes.hypotheses.generate import (
    HypothesisConfig,
    UnaryTolerances,
    generate_hypotheses,
    minimum_shape,
)
from ipr_shapes.hypotheses.prepare import Carve, prepare_hypotheses
from ipr_shapes.products import PreparedHypotheses, ShapeHypothesis, volume_spread

__all__ = [
    "Carve",
    "ConstraintConfig",
    "HypothesisConfig",
    "OverlapCache",
    "PreparedHypotheses",
    "ShapeHypothesis",
    "UnaryTolerances",
    "generate_hypotheses",
    "intersection_volume",
    "joint_feasible",
    "penetration_depth",
    "minimum_shape",
    "overlap_matrix",
    "overlap_threshold",
    "prepare_hypotheses",
    "unary_feasible",
    "volume_spread",
]
