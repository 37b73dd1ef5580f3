"""Parameters of the perception stage, one typed object with documented defaults.

Defaults follow the paper and its authors' code (ARCHITECTURE.md) where those give a value, and
were otherwise chosen on synthetic development scenes (seeds outside every benchmark suite).
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class TrackingConfig:
    """Weights and gates of the matching cost (dimensionless unless stated).

    Attributes:
        overlap_weight, colour_weight, distance_weight: weights of the three cues.
        max_motion_m: centroid displacement mapped to the full distance cost (a push moves
            objects up to about this far).
        max_match_cost: above this a segment is a new object.
    """

    overlap_weight: float = 1.0
    colour_weight: float = 1.0
    distance_weight: float = 1.0
    max_motion_m: float = 0.2
    max_match_cost: float = 1.6


@dataclass(frozen=True)
class PerceptionConfig:
    """Perception parameters (lengths in metres, angles in degrees).

    Attributes:
        plane_threshold_m: RANSAC inlier distance for the support plane and walls (authors: 1 cm).
        plane_iterations: RANSAC iterations (authors: 1000).
        support_max_tilt_deg: the support plane's normal is within this angle of world z.
        support_clearance_m: points less than this above the support belong to it.
        pusher_margin_m: points within the pusher capsule's radius plus this are removed.
        voxel_size_m: supervoxel voxel resolution (authors' VCCS: 7.5 mm).
        seed_size_m: supervoxel seed spacing (authors' VCCS: 2 cm).
        concavity_tolerance_deg: edges flatter than this count as convex (authors' LCCP: 10).
        max_objects: upper bound on the number of objects per frame.
        min_object_pixels: segments smaller than this are merged into a neighbour or dropped.
        facet_bandwidth: mean-shift bandwidth on unit normals for facets (chord length).
        min_facet_area_m2: facets smaller than this are ignored by hypotheses (paper: (3 cm)^2).
        free_space_voxel_m: free/unknown voxel grid resolution (paper: 5 mm).
        surface_margin_m: voxels this close to an observed surface are occupied, not free.
        workspace_margin_m: the free-space grid extends this far around the objects.
        seed: seed of every random choice (RANSAC, k-means), for reproducible runs.
        tracking: matching of segments across frames.
    """

    plane_threshold_m: float = 0.01
    plane_iterations: int = 1000
    support_max_tilt_deg: float = 30.0
    support_clearance_m: float = 0.01
    pusher_margin_m: float = 0.01
    voxel_size_m: float = 0.0075
    seed_size_m: float = 0.02
    concavity_tolerance_deg: float = 10.0
    max_objects: int = 20
    min_object_pixels: int = 100
    facet_bandwidth: float = 0.35
    min_facet_area_m2: float = 0.03**2
    free_space_voxel_m: float = 0.005
    surface_margin_m: float = 0.01
    workspace_margin_m: float = 0.15
    seed: int = 0
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
