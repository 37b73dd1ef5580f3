"""Parameters of the perception stage: one typed object of nested groups, one per step.

``PerceptionConfig`` holds a frozen group per step of perception, in the order they run:
``planes`` (RANSAC shared by the support and the walls), ``support``, ``walls``, ``robot``,
``supervoxels``, ``segmentation``, ``containers``, ``seams``, ``occluder_splits``, ``temporal``, ``tracking``, ``denoise``,
``facets``, ``free_space`` and ``occluded_pieces``, plus the ``seed`` of every random choice.
Change one value with ``dataclasses.replace``::

    config = replace(config, walls=replace(config.walls, max_span_m=0.0))

Defaults follow the paper and its authors' code (ARCHITECTURE.md) where those give a value, and
were otherwise chosen on synthetic development scenes (seeds outside every benchmark suite);
the measurements behind them are in ``docs/experiments/perception-config-notes.md``. Lengths
are in metres, angles in degrees, shares in [0, 1]. Every group checks its fields on
construction against its ``CHECKS`` table (``ipr_shapes.checks``): a bad value raises ValueError
naming the field, the value and the allowed range.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from typing import ClassVar

from ipr_shapes.checks import Checks, Interval, Pair, Predicate, check_fields

# Shorthands for the tables below.
_POSITIVE = Interval(0, None, closed="neither")
_NON_NEGATIVE = Interval(0, None)
_SHARE = Interval(0, 1)
_TILT = Interval(0, 90)
_ANGLE = Interval(0, 180)
_ANY = Interval(None, None)
_COUNT = Interval(0, None, integer=True)
_AT_LEAST_ONE = Interval(1, None, integer=True)


@dataclass(frozen=True)
class PlanesConfig:
    """RANSAC settings shared by the support plane and the walls (``ipr_shapes.perception.planes``).

    Attributes:
        threshold_m: inlier distance (m) of a point to a plane; also the margin in front of a
            known plane's face within which points belong to it. The authors use 1 cm.
        sample_size: points (a random subset) on which hypotheses are scored; the winner is
            refitted by least squares on its inliers, so the subset only has to rank them.
    """

    CHECKS: ClassVar[Checks] = {"threshold_m": _POSITIVE, "sample_size": _AT_LEAST_ONE}

    threshold_m: float = 0.01
    sample_size: int = 1000

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class SupportConfig:
    """The support (table) plane (``planes.find_support_plane``) and what lies on it.

    The support is the plane the objects rest on, not always the largest plane
    (``ipr_shapes.geometry.support.choose_support``: the tops of packed boxes and a floor seen beyond
    a table are not the support).

    Attributes:
        iterations: RANSAC hypotheses for the support plane (the authors use 1000).
        max_tilt_deg: the support's normal is within this angle (deg) of world +z, so that a
            large wall or box face is not taken for the table.
        clearance_m: points less than this (m) above the support belong to it (sensor noise
            and the table's texture).
        min_points, min_fraction: the support needs at least this many inliers and this share
            of the frame's valid points, so that a small flat face is not taken for the table.
        candidates: further planes (RANSAC with removal) examined in a scene's first frame to
            tell whether the largest plane is the support (0: the largest plane always is, as
            before; later frames keep the first frame's support when their largest plane is
            not it: the support does not move).
        see_through: share of the largest plane's extent (or of the space between the walls
            around it) seen below it from which it is the tops of objects, not the support (a
            table is opaque).
    """

    CHECKS: ClassVar[Checks] = {
        "iterations": _AT_LEAST_ONE,
        "max_tilt_deg": _TILT,
        "clearance_m": _NON_NEGATIVE,
        "min_points": _COUNT,
        "min_fraction": _SHARE,
        "candidates": _COUNT,
        "see_through": _SHARE,
    }

    iterations: int = 1000
    max_tilt_deg: float = 30.0
    clearance_m: float = 0.01
    min_points: int = 200
    min_fraction: float = 0.1
    candidates: int = 8
    see_through: float = 0.01

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class WallsConfig:
    """Walls of containers and drawers (``planes.find_walls``): vertical planes standing on the
    support, told apart from objects' faces by the cues below.

    Attributes:
        max_candidates: vertical planes examined per frame (0 = no walls); a frame shows at
            most a drawer's front and sides.
        max_points: the wall search uses at most this many points above the support (an even
            subset), which bounds its cost on close-up frames.
        iterations: RANSAC hypotheses per vertical plane.
        min_points: inliers a wall candidate needs (fewer are noise or a thin edge).
        normal_tilt_deg: only points whose (noisy) pixel normal is within this angle (deg) of
            the horizontal vote for vertical planes, so that the table and tops do not.
        min_length_m: a wall's visible run along the support is at least this long (m; the
            generator's walls are >= 20 cm; YCB boxes' faces, up to 21 cm, are told apart by
            the other cues).
        max_gap_m: gaps (occlusions) shorter than this (m) do not break a wall's run.
        min_height_m, max_height_m: range (m) of a wall's top above the support (a wall is
            taller than a rim and lower than the scene's tall objects).
        support_gap_m: a wall's lowest visible points are within this (m) of the support (a
            wall stands on the table; a box's face lifted by what is below it does not).
        hidden_bottom: a wall whose lowest visible points are higher also stands when the
            plane's face below them is hidden from the camera by nearer surfaces (the far wall
            of a bin behind its contents), not seen through (``planes._bottom_hidden``).
        frame_cut_tops: columns of a wall's face whose top edge is the image's border do not
            tell its top (``planes._wall_cues``).
        max_seen_through: ... at most this share of the face points probed below the visible
            bottom may show a surface beyond the plane (depth noise at the occluders' edges).
        max_thickness_m: walls are thinner than this (m); it is also the slab removed behind a
            wall's visible face (its hidden inner face).
        cap_depth_m: how far (m) behind a wall's face points "capping" it (a box's top) count.
        max_capped_fraction: share of a wall's length allowed to have such points (objects
            standing behind a drawer front and rising above it).
        min_top_agreement: a wall accepted on its own (without a partner) has its top edge
            within 2 cm of its top height over at least this share of its 2 cm columns (a
            wall's rim is straight; the faces of a pile of objects are of many heights).
        min_face_fill: ... and inliers in at least this share of the 2 cm cells of its face
            between its bottom and its top (a wall is a solid face).
        side_range_m: distance (m) from a wall within which the scene's other points are used
            for the one-sided test (everything is in front of a wall, nothing behind it).
        max_outside_fraction: share of those points allowed on the wall's minority side.
        partner_min_length_m: shortest run (m) of a wall accepted through a partner wall (a
            side wall seen at a grazing angle shows little of its length).
        partner_separation_m: (min, max) distance (m) between opposite walls of a container.
        partner_max_top_difference_m: partner walls' tops differ by at most this (m; a drawer
            front is 3-5 cm taller than the sides).
        partner_top_match_m: tops (m) of a wall whose bottom is hidden and of its partner
            differ by at most this (one container's walls have one height).
        corner_gap_m: two perpendicular walls meet within this (m) of the ends of their runs.
        complete_corners: look for side walls seen edge-on at the ends of accepted walls
            (``planes._edge_on_walls``), which the normal vote misses.
        max_span_m: a wall's face may extend past its run (an object in front of it cuts it
            in two) to pieces of its plane whose top is the wall's, up to this overall length
            (m; 0 = the run only).
        top_margin_m: points up to this (m) above a wall's top (its rim, with noise) are
            removed with it.
    """

    CHECKS: ClassVar[Checks] = {
        "max_candidates": _COUNT,
        "max_points": _AT_LEAST_ONE,
        "iterations": _AT_LEAST_ONE,
        "min_points": _AT_LEAST_ONE,
        "normal_tilt_deg": _TILT,
        "min_length_m": _NON_NEGATIVE,
        "max_gap_m": _NON_NEGATIVE,
        ("min_height_m", "max_height_m"): Pair(_NON_NEGATIVE),
        "support_gap_m": _NON_NEGATIVE,
        "max_seen_through": _SHARE,
        "max_thickness_m": _POSITIVE,
        "cap_depth_m": _NON_NEGATIVE,
        "max_capped_fraction": _SHARE,
        "min_top_agreement": _SHARE,
        "min_face_fill": _SHARE,
        "side_range_m": _NON_NEGATIVE,
        "max_outside_fraction": _SHARE,
        "partner_min_length_m": _NON_NEGATIVE,
        "partner_separation_m": Pair(_NON_NEGATIVE),
        "partner_max_top_difference_m": _NON_NEGATIVE,
        "partner_top_match_m": _NON_NEGATIVE,
        "corner_gap_m": _NON_NEGATIVE,
        "max_span_m": _NON_NEGATIVE,
        "top_margin_m": _NON_NEGATIVE,
    }

    max_candidates: int = 6
    max_points: int = 30000
    iterations: int = 200
    min_points: int = 100
    normal_tilt_deg: float = 25.0
    min_length_m: float = 0.18
    max_gap_m: float = 0.05
    min_height_m: float = 0.05
    max_height_m: float = 0.25
    support_gap_m: float = 0.03
    hidden_bottom: bool = True
    max_seen_through: float = 0.05
    frame_cut_tops: bool = True
    max_thickness_m: float = 0.018
    cap_depth_m: float = 0.10
    max_capped_fraction: float = 0.5
    min_top_agreement: float = 0.6
    min_face_fill: float = 0.5
    side_range_m: float = 0.5
    max_outside_fraction: float = 0.03
    partner_min_length_m: float = 0.1
    partner_separation_m: tuple[float, float] = (0.15, 0.55)
    partner_max_top_difference_m: float = 0.06
    partner_top_match_m: float = 0.015
    corner_gap_m: float = 0.04
    complete_corners: bool = True
    max_span_m: float = 0.6
    top_margin_m: float = 0.005

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class RobotConfig:
    """Removal of the robot's and the pusher's pixels (``ipr_shapes.perception.robot``).

    Attributes:
        pusher_margin_m: points within the pusher capsule's radius plus this (m) are removed
            (the capsule's pose and the depth are both a little off).
    """

    CHECKS: ClassVar[Checks] = {"pusher_margin_m": _NON_NEGATIVE}

    pusher_margin_m: float = 0.005

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class SupervoxelsConfig:
    """Pixel normals and VCCS-style supervoxels (``ipr_shapes.perception.supervoxels``).

    Attributes:
        voxel_size_m: voxel resolution (m; the authors' VCCS: 7.5 mm).
        seed_size_m: seed spacing (m; the authors' VCCS: 2 cm): the size of a supervoxel.
        normal_radius_px: pixel normals use the neighbours this many pixels away (px; further
            neighbours average more noise away but blur edges).
        normal_max_jump_m, normal_max_jump_ratio: a neighbour whose depth differs by more than
            ``normal_max_jump_m + normal_max_jump_ratio * radius * depth`` (m; the ratio per
            pixel of radius) is across a discontinuity and not used for the normal.
        iterations: k-means rounds assigning voxels to seeds.
        normal_weight: weight of the normal term (1 - cos) against the spatial term
            (distance / seed size)^2 in the voxel-to-seed distance (VCCS: normal 1, spatial 1).
        colour_weight: weight of the squared RGB distance (channels in [0, 1]) in that distance
            (the authors' VCCS: 0; it stays off, as colour helped no more than noise).
        min_points: supervoxel pieces with fewer pixels are merged into a neighbour (too few
            for a normal).
        max_points: supervoxel statistics use at most this many pixels (an even subset; every
            kept pixel is still labelled through its voxel), which bounds the cost per frame.
        dominant_face_deg: a supervoxel's normal and centre come from its pixels whose normal
            is within this angle (deg) of its dominant direction (0 = all pixels), so that a
            supervoxel across an edge takes its larger face's orientation.
    """

    CHECKS: ClassVar[Checks] = {
        "voxel_size_m": _POSITIVE,
        "seed_size_m": _POSITIVE,
        "normal_radius_px": _AT_LEAST_ONE,
        "normal_max_jump_m": _NON_NEGATIVE,
        "normal_max_jump_ratio": _NON_NEGATIVE,
        "iterations": _COUNT,
        "normal_weight": _NON_NEGATIVE,
        "colour_weight": _NON_NEGATIVE,
        "min_points": _COUNT,
        "max_points": _AT_LEAST_ONE,
        "dominant_face_deg": _ANGLE,
    }

    voxel_size_m: float = 0.0075
    seed_size_m: float = 0.02
    normal_radius_px: int = 2
    normal_max_jump_m: float = 0.01
    normal_max_jump_ratio: float = 0.02
    iterations: int = 3
    normal_weight: float = 1.0
    colour_weight: float = 0.0
    min_points: int = 12
    max_points: int = 50000
    dominant_face_deg: float = 30.0

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class SegmentationConfig:
    """The convexity-weighted supervoxel graph, its spectral clustering and the segments kept
    (``ipr_shapes.perception.segmentation``).

    Attributes:
        concavity_tolerance_deg: edges flatter than this (deg) count as convex (the authors'
            LCCP: 10), so that noise on a flat face does not cut it.
        sanity_angle_deg, sanity_sigmoid: a convex edge whose centre-to-centre direction is
            within this angle (deg) of the crease line is singular, not convex (two objects
            touching along a line); with the sigmoid (LCCP) the angle is scaled by
            1 / (1 + exp(-0.25 (normal angle - 25))) (the authors' code: a fixed 45 degrees;
            LCCP: 60 with the sigmoid).
        smoothness_threshold: LCCP smoothness slack, in voxel sizes (the authors: 0.1).
        concave_join_deg: a concave edge whose normals differ by less than this (deg) is still
            strong when its two supervoxels have alike colours (``concave_join_colour``): a
            curved concave surface (a bowl's inside) changes its normal a little at every
            step, while two objects meet at a crease or a colour edge. 0: off (LCCP).
        concave_join_colour: largest distance between the two supervoxels' mean
            chromaticities (r, g, b over their sum) for ``concave_join_deg`` to apply.
        curved_join_deg: a concave edge whose normals differ by less than this (deg) is a
            "smooth concave" edge when the surface beyond both its ends keeps bending
            concavely (``ipr_shapes.perception.curvature``): a bowl's inside bends at every
            step, two objects meet at a crease between flat or convex faces. 0: none.
        curved_join_ratio: ... by a mean bend of at least this share of the edge's own.
        curved_join_edges: smooth concave edges weigh 1 in the graph, before the clustering
            (loses 1.7 points on bins-real: docs/experiments/2026-11-26-curved-objects.md).
        curved_segment_vote: after the clustering, two neighbouring segments of alike colour
            (``curved_segment_colour``) are joined when at least this share of the edges
            between them (and 2) are smooth concave edges
            (``curvature.join_curved_segments``); 0: off.
        curved_segment_colour: largest distance between the two segments' mean
            chromaticities (r, g, b over their sum) for the vote to join them.
        concave_weight: graph weight of concave (or not smooth) edges; convex and flat edges
            weigh 1, so the clustering cuts at concavities.
        singular_weight: graph weight of convex edges that fail the sanity check.
        dense_eigen_limit: components up to this many supervoxels use a dense eigensolver,
            larger ones the sparse one in shift-invert mode (the dense one is faster below
            about 300 supervoxels, docs/experiments/2026-11-26-perception-speed.md).
        eigen_tolerance: relative accuracy of the sparse eigensolver (ARPACK ``tol``; 0 =
            machine precision); the embedding only feeds k-means, which needs no more
            (docs/experiments/2026-11-26-bin-walls.md).
        eigengap_floor: noise floor added to the eigenvalues of L_sym before their ratios are
            compared (the eigengap is the largest ratio of consecutive eigenvalues), so that
            near-zero eigenvalues do not make huge ratios.
        kmeans_restarts: k-means initialisations (seeded) on the spectral embedding.
        max_objects: upper bound on the number of objects per frame.
        eigengap_extend: when the eigengap's largest ratio is the last of the ``max_objects``
            + 1 eigenvalues computed, twice as many are computed and the gap searched again
            (a truncated spectrum, not a gap), until it lies inside them.
        min_object_pixels: segments with fewer pixels (with depth) are merged into a neighbour
            or dropped (an object peeking over a drawer front can show ~50).
        min_object_height_m: segments whose 90th-percentile height above the support is lower
            (m) are support residue (noise, a slightly curved table), not objects.
        workspace_share: a segment with less than this share of its points over the support's
            seen extent (their projection within its inliers' convex hull) stands beyond the
            table, not on it, and is dropped (``ipr_shapes.perception.workspace``); 0: off.
        workspace_margin_m: the hull is grown by this (m): an object at the table's edge hides
            the edge beneath it.
        workspace_cell_m: cell (m) of the grid whose connected region holding most support
            points is the table, the cells under the segments joining the regions they touch
            (a chair's seat at the table's height beyond it is another region).
        label_fill_px: pixels without depth take the label of the nearest pixel with depth up
            to this distance (px; edge dropout, small holes); 0 = no filling.
        fragment_area_m2: a segment smaller than this (m^2, its pixels' footprints facing the
            camera) joins the neighbour its surface continues into
            (``ipr_shapes.perception.fragments``); 0: off.
        fragment_contact_share: ... when the pixel pairs along which the two surfaces meet
            are at least this share of the small segment's outline.
        fragment_gap_m: two neighbouring pixels whose world points are closer than this (m)
            lie on one continuing surface.
        fragment_bend_deg: ... and the surface normals of their supervoxels differ by at most
            this (deg): a surface running on, not two objects meeting at a crease.
        fragment_colour: ... and the two segments' mean chromaticities are at most this far
            apart (as ``curved_segment_colour``),
        fragment_on_body: ... or, whatever the colours, the small segment lies on its
            neighbour (``fragments.lies_on``: within its footprint on the support, by the
            containers' ``footprint_fraction`` and ``margin_m``, and not lower by median
            height): a cap, a lid or a printed band carried by its body, where a separate
            object wedged under another lies below it. Off: a golf ball resting on a box
            lies on it too (docs/experiments/2026-11-28-lab-frames-joins.md).
        fragment_surface: ... or, whatever the colours, the small segment's points lie on the
            smooth surface of its neighbour around it (``fragments.continues_surface``: a
            quadric fitted to the neighbour's points in a window three times the piece's
            size, their scatter about it at most the support's about its plane, the piece's
            median distance from it at most twice that scatter): a printed band or a label's
            sliver runs on with its body; an object touching a face tangentially bends away.
        fragment_specks: after the fragments, a segment smaller than one supervoxel seed's
            square (``supervoxels.seed_size_m`` squared: below the graph's resolution) joins
            the segment it touches (points within ``fragment_gap_m``, any normals; colours
            not compared: mixed pixels take both sides' colours) when it is mixed pixels at
            that segment's silhouette: most of its pixels on supervoxels seen edge-on
            (``contour_facing_cos``: mixed pixels lie along the rays across a depth step),
            its outline only that segment (touched along at least
            ``fragment_contact_share`` of it) and the background or support, which is not
            nearer than it by more than ``fragment_gap_m`` at the median (a speck seen past
            a wall is an object's part).
        thin_radius_m: touching segments are joined when the points of both lie on one
            cylinder of at most this radius (m; a marker, a pen, a handle: the seen half of its
            circumference, pi r, at most two supervoxel seeds, where the graph's convexity
            test is singular; ``ipr_shapes.perception.thin``; docs/DESIGN_NOTES.md "Thin
            cylinders joined"). 0: off.
        thin_rms_m: ... with an RMS radial residual of at most this (m): the depth noise,
            1.2-2.3 mm on flat surfaces of the generated and real frames.
        thin_min_contact_px: ... and they touch along at least this many neighbouring pixel
            pairs (world points within ``fragment_gap_m``).
        contour_split_px: after the clustering, a segment whose supervoxels fall into exactly
            two parts of at least this many pixels that meet in the image only across depth
            steps is split between them (one object in front of another; the surface of a
            convex object has no step; ``ipr_shapes.perception.contours``). 0: off.
        contour_min_pairs: ... when the two parts are image neighbours along at least this
            many pixel pairs (an outline, not a corner: parts on both sides of an occluder
            share none and stay together) whose supervoxels both face the camera:
        contour_facing_cos: ... the cosine of the supervoxel's normal with the ray to the
            camera at least this (0.25: within 75 degrees; next to a surface seen edge-on,
            neighbouring pixels of one surface are centimetres apart).
        contour_gap_m: two neighbouring pixels whose world points are closer than this (m)
            connect their supervoxels into one part (as ``fragment_gap_m``).
        crease_split_depth_m: after the contour split, a segment one of whose supervoxel
            centres lies at least this deep (m) inside the 3D convex hull of the segment's
            points is cut along that crease (two convex objects meeting flush, a bottle lying
            on a block: the crease lies inside the union's hull, a convex object's surface on
            its own; ``ipr_shapes.perception.creases``). 0: off. 2 cm: at 1.5 cm a large
            single box of the development sets was cut; a container's floor, as deep, leaves
            its rim and walls in one piece, which is not cut.
        crease_cut_depth_m: ... the supervoxels deeper than a cut depth are the crease, and the
            segment is cut when the rest falls into exactly two parts of at least
            ``crease_split_px`` pixels (the crease going to the part whose flood reaches it
            first); cut depths are tried from 0.8 ``crease_split_depth_m`` down by factors of
            0.8 to this one (m; 5 mm: shallower is the noise and the curvature of single
            objects' supervoxel centres).
        crease_split_px: ... (pixels; as ``contour_split_px``).
    """

    CHECKS: ClassVar[Checks] = {
        "concavity_tolerance_deg": _ANGLE,
        "sanity_angle_deg": _ANGLE,
        "smoothness_threshold": _NON_NEGATIVE,
        "concave_join_deg": _ANGLE,
        "concave_join_colour": _NON_NEGATIVE,
        "curved_join_deg": _ANGLE,
        "curved_join_ratio": _NON_NEGATIVE,
        "curved_segment_vote": _SHARE,
        "curved_segment_colour": _NON_NEGATIVE,
        "concave_weight": _NON_NEGATIVE,
        "singular_weight": _NON_NEGATIVE,
        "dense_eigen_limit": _COUNT,
        "eigen_tolerance": _NON_NEGATIVE,
        "eigengap_floor": _POSITIVE,
        "kmeans_restarts": _AT_LEAST_ONE,
        "max_objects": _AT_LEAST_ONE,
        "min_object_pixels": _COUNT,
        "min_object_height_m": _NON_NEGATIVE,
        "label_fill_px": _NON_NEGATIVE,
        "workspace_share": _SHARE,
        "workspace_margin_m": _NON_NEGATIVE,
        "workspace_cell_m": _POSITIVE,
        "fragment_area_m2": _NON_NEGATIVE,
        "fragment_contact_share": _SHARE,
        "fragment_gap_m": _NON_NEGATIVE,
        "fragment_colour": _NON_NEGATIVE,
        "fragment_bend_deg": _ANGLE,
        "thin_radius_m": _NON_NEGATIVE,
        "thin_rms_m": _NON_NEGATIVE,
        "thin_min_contact_px": _COUNT,
        "contour_split_px": _COUNT,
        "contour_min_pairs": _AT_LEAST_ONE,
        "contour_facing_cos": Interval(-1, 1),
        "contour_gap_m": _POSITIVE,
        "crease_split_depth_m": _NON_NEGATIVE,
        "crease_cut_depth_m": _POSITIVE,
        "crease_split_px": _AT_LEAST_ONE,
    }

    concavity_tolerance_deg: float = 10.0
    sanity_angle_deg: float = 60.0
    sanity_sigmoid: bool = True
    smoothness_threshold: float = 0.1
    concave_join_deg: float = 0.0
    concave_join_colour: float = 0.02
    curved_join_deg: float = 40.0
    curved_join_ratio: float = 0.3
    curved_join_edges: bool = False
    curved_segment_vote: float = 0.3
    curved_segment_colour: float = 0.04
    concave_weight: float = 0.001
    singular_weight: float = 0.001
    dense_eigen_limit: int = 300
    eigen_tolerance: float = 1e-6
    eigengap_floor: float = 0.001
    kmeans_restarts: int = 4
    max_objects: int = 20
    eigengap_extend: bool = True
    min_object_pixels: int = 40
    min_object_height_m: float = 0.015
    label_fill_px: float = 3.0
    workspace_share: float = 0.5
    workspace_margin_m: float = 0.02
    workspace_cell_m: float = 0.02
    fragment_area_m2: float = 0.0016
    fragment_contact_share: float = 0.5
    fragment_gap_m: float = 0.01
    fragment_colour: float = 0.04
    fragment_bend_deg: float = 45.0
    fragment_on_body: bool = False
    fragment_surface: bool = True
    fragment_specks: bool = True
    thin_radius_m: float = 0.0125
    thin_rms_m: float = 0.003
    thin_min_contact_px: int = 5
    contour_split_px: int = 150
    contour_min_pairs: int = 10
    contour_facing_cos: float = 0.25
    contour_gap_m: float = 0.01
    crease_split_depth_m: float = 0.02
    crease_cut_depth_m: float = 0.005
    crease_split_px: int = 150

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class ContainersConfig:
    """Joining the pieces of an open container's inside to the container
    (``ipr_shapes.perception.containers``, where the rules are explained).

    Attributes:
        join_insides: join them at all (the convexity graph cuts an inside into pieces).
        footprint_fraction, margin_m: share of a piece's points within the container's
            footprint on the support (its convex hull or fitted circle), grown by this margin
            (m): an inside lies within its container.
        circle_rms_m, max_radius_m: the circle fitted to a container's footprint counts when
            its RMS distance to the points is at most the first and its radius at most the
            second (m): a round wall, which surrounds its inside at its full height.
        top_tolerance_m, bottom_tolerance_m: how far (m) the piece's top may rise above the
            container's and its bottom reach below the container's (an inside is below the
            rim and above the container's floor).
        max_chroma: largest L1 distance between the two mean chromaticities (shading does
            not change chromaticity; an inside is darker than the outside).
        chroma_floor: added to each 8-bit channel before the chromaticity: near black a
            channel is the camera's noise and black level (a few to ten levels), so a dark
            surface's chromaticity is noise unless it is pulled towards grey there.
        rim_radius_m: the container's points this close (m) to the piece's on the support
            are its rim around the piece.
        join_rims: also join two segments that are together one open container (a circular
            rim around both, whichever is the inside), as a real sensor's containers need.
        piece_within_share: with ``join_rims``, each of the two must lie at least this share
            within the rim (and the two together ``footprint_fraction``): a mug's handle
            sticks out of the rim, a neighbour of the same colour lies beside it.
        rim_band_m, rim_inlier_share: two segments are one open container when the points
            of both within ``rim_band_m`` (m) of their joint top lie on a circle (a rim) around
            both; the robust circle fit must keep at least ``rim_inlier_share`` of them (the
            rest: flying pixels, a handle). 1 cm holds a rim a few mm thick and the wall just
            below it under a real sensor's noise.
        rim_seen_past_share, rim_clear_m: with ``join_rims``, a rim the camera sees past
            (at more than this share of the directions around the circle it sees a surface
            more than ``rim_clear_m`` (m) beyond where the rim would be,
            ``containers._seen_past``) holds only pieces wholly within it
            (``footprint_fraction`` each, not ``piece_within_share``): the leniency for a
            handle or mixed pixels presumes a rim that is there, whereas a circle through a
            tilted bowl's high arc and the top of a mug beside it runs through air. 1.0 = off.
        max_front_ratio: the piece stands in front of the container along at most this share
            of the pixel pairs where they meet (an object resting on a box stands in front).
        min_contact_px: the two meet (touch, or the container hides the piece) along at least
            this many 4-neighbour pixel pairs.
        contact_gap_m: two neighbouring pixels whose points are closer than this (m) belong to
            touching surfaces.
        front_step_m: (low, high) depth step (m) between neighbouring pixels at which the
            nearer one stands in front of the other (above ``high``: unrelated surfaces).
    """

    CHECKS: ClassVar[Checks] = {
        "footprint_fraction": _SHARE,
        "margin_m": _NON_NEGATIVE,
        "circle_rms_m": _NON_NEGATIVE,
        "max_radius_m": _NON_NEGATIVE,
        "top_tolerance_m": _NON_NEGATIVE,
        "bottom_tolerance_m": _NON_NEGATIVE,
        "max_chroma": _NON_NEGATIVE,
        "chroma_floor": _NON_NEGATIVE,
        "rim_radius_m": _NON_NEGATIVE,
        "rim_band_m": _NON_NEGATIVE,
        "rim_inlier_share": _SHARE,
        "rim_seen_past_share": _SHARE,
        "rim_clear_m": _NON_NEGATIVE,
        "piece_within_share": _SHARE,
        "max_front_ratio": _SHARE,
        "min_contact_px": _COUNT,
        "contact_gap_m": _NON_NEGATIVE,
        "front_step_m": Pair(_NON_NEGATIVE),
    }

    join_insides: bool = True
    join_rims: bool = True
    footprint_fraction: float = 0.9
    margin_m: float = 0.01
    circle_rms_m: float = 0.004
    max_radius_m: float = 0.15
    top_tolerance_m: float = 0.005
    bottom_tolerance_m: float = 0.005
    max_chroma: float = 0.2
    chroma_floor: float = 10.0
    rim_radius_m: float = 0.02
    rim_band_m: float = 0.01
    rim_inlier_share: float = 0.8
    rim_seen_past_share: float = 0.45
    rim_clear_m: float = 0.02
    piece_within_share: float = 0.5
    max_front_ratio: float = 0.5
    min_contact_px: int = 3
    contact_gap_m: float = 0.01
    front_step_m: tuple[float, float] = (0.01, 0.1)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class SeamsConfig:
    """Cutting segments along straight colour seams where the geometry is silent
    (``ipr_shapes.perception.seams``): packed boxes of one height whose coplanar tops the convexity
    graph cannot tell apart.

    Off by default for its time, not its accuracy: with it on, every development, container
    and tabletop set scores as with it off (a frame it leaves uncut keeps the seams-off labels,
    numbering included) and the real bins gain (28.6 -> 63.4 % of boxes found), but the
    perception costs 2.7-3 times as much CPU per bin frame (285 ms on the page's run at
    10052ac) and 1.05-1.6 times per tabletop frame: within the 150 ms budget on the generated
    and YCB-Video frames, over it on the real lab frames (about 180 ms against 130), which gain
    nothing (docs/experiments/2026-11-27-seams-default.md, 2026-11-28-seam-search-structure.md,
    2026-11-28-seams-bins-cost.md). Turn it on for packed boxes (bin picking:
    ``configs/bins.toml``).

    Attributes:
        enabled: cut segments along seams (False: labels as the graph gives them).
        edge_factor: an edge pixel's colour gradient exceeds this many times the median
            gradient of the frame's pixels with depth (a noise scale of the camera and
            lighting).
        coverage: share of a seam's pixels that lie on (within a pixel of) an edge pixel.
        min_length_m: shortest seam (m, between its ends in 3D).
        min_width_m: narrowest piece a cut may leave (m, twice the largest inscribed radius).
        min_area_m2: smallest piece a cut may leave (m^2, its pixels' footprints at their
            depth facing the camera).
        max_normal_deg: the surfaces on both sides of a seam differ by at most this (deg):
            a colour edge along a crease is an object's own edge, not a seam.
        max_step_m: and they are offset along their normal by at most this (m).
        max_bend_m: the seam's 3D points lie within this of one straight line (m, 90th
            percentile of its middle 80 %): a straight image line on a curved surface (a ball,
            a can) bends in 3D.
        strip_tolerance: a seam is kept when the strips on its two sides (to a parallel seam
            or the segment's outline, in 3D) differ by at most this share of the wider: packed
            boxes of one size repeat at one spacing, a printed border lies anywhere (1: neither
            this test nor the strips' flatness; bins-real 44.5 % instead of 37.9 %, and the
            generated boxes' end panels cut).
        pair_needs_grid: a seam bounded by the segment's outline on both sides (one seam
            midway across it: two boxes, or one box with a printed line through its middle)
            is kept only where it meets a seam bounded by another seam (a grid of packed
            boxes); False keeps it whenever it lies midway.
        pair_sizes: with ``pair_needs_grid``, such a seam is also kept when both its strips
            have the size of a face of another segment or piece in the frame, or of a strip of
            such a seam in another segment (packed boxes repeat across the frame; a printed
            line through one box makes halves nothing else matches).
        size_tolerance_m: the strips' and the face's extents agree within this (m; the error
            of an extent measured to a real outline: side faces, dropouts).
        rows_of_three: a seam is also repeated when two parallel seams on one side of it lie at
            one spacing with it (three seams of a row of boxes of one size), whatever the row's
            end strips measure to the outline (side faces, occluders): without it a row's end
            seam drops when its end strip is off, and the row's other seams drop after it.
        hysteresis: the edges also take the faint edge pixels (gradient above half the edge
            threshold, thinned) connected to a strong one (Canny's hysteresis at his 2:1
            ratio), in the segments and a 3 px ring: the seam between two boxes of one colour
            fades along its length, and a stretch that stops short of the outline cannot cut.
        extend_planes: the seams between packed boxes go on as 3D planes (each seam's line
            and the surface normal) across the boxes' other faces: when a piece faces several
            pieces across a seam (undone: the boxes of a row beyond a printed line across it;
            or kept: the second row of a grid, whose seams bend over the boxes' front faces)
            and kept seams lie between those pieces, the piece is cut along their planes, each
            part as wide as the piece it faces (``strip_tolerance``), unless the piece's own
            seams along them lie off them (rows offset like bricks); an undone seam's parts
            then join the pieces they face. False: an undone seam's piece joins the one piece
            it faces most, and nothing is cut across kept seams.
        max_cuts: most cuts per segment (bounds the time on a textured segment).
        settled: in frames after the first (with ``temporal.anchoring``), a segment that is
            mostly (``temporal.static_fraction`` of its pixels) supervoxels anchored to one
            previous segment that stayed is not searched: the previous frame decided its seams
            on the same unmoved surface. Without it a printed line that one frame's pass missed
            and the next found (the potted meat can's label, dev 8100) cuts an unmoved object,
            and the tracker carries the cut back to the earlier frames.
        flat_face_gate: a segment is searched only when it holds a flat face (normals within
            ``max_normal_deg`` of one) at least ``min_length_m`` by twice ``min_width_m``
            across: room for a seam and a strip each side (``seams._has_flat_face``). Cans,
            bottles, bowls and small objects are then kept whole before any edge work.
        shadow_lines: in a frame where the strip tests kept a cut (packed boxes seen), a
            seam with flat strips is also kept, whatever its strips measure to a parallel seam
            or the outline, when it is a shadow line: across it, every colour channel is darker
            within a pixel of it than on both sides (2-10 px) by more than the two sides
            differ, and the channels darken alike (their ratios to the darker side differ by
            less than the light lost). Two touching boxes leave a gap the light does not reach,
            dark in every channel whatever their print; a printed border is a step, and
            coloured ink darkens the channels it absorbs; black or grey ink darkens all alike,
            hence the frame's kept cut (a tabletop box's printed lines stay whole). Without it
            a pair of boxes with no twin in the frame, or a row whose other seams were not
            found, stays one segment.
    """

    CHECKS: ClassVar[Checks] = {
        "edge_factor": _POSITIVE,
        "coverage": _SHARE,
        "min_length_m": _NON_NEGATIVE,
        "min_width_m": _NON_NEGATIVE,
        "min_area_m2": _NON_NEGATIVE,
        "max_normal_deg": _ANGLE,
        "max_step_m": _NON_NEGATIVE,
        "max_bend_m": _NON_NEGATIVE,
        "strip_tolerance": _SHARE,
        "size_tolerance_m": _NON_NEGATIVE,
        "max_cuts": _COUNT,
    }

    enabled: bool = False
    edge_factor: float = 4.0
    coverage: float = 0.75
    min_length_m: float = 0.04
    min_width_m: float = 0.02
    min_area_m2: float = 0.016**2
    max_normal_deg: float = 15.0
    max_step_m: float = 0.005
    max_bend_m: float = 0.005
    strip_tolerance: float = 0.25
    pair_needs_grid: bool = True
    pair_sizes: bool = True
    size_tolerance_m: float = 0.01
    max_cuts: int = 32
    rows_of_three: bool = True
    hysteresis: bool = True
    extend_planes: bool = True
    settled: bool = True
    flat_face_gate: bool = True
    shadow_lines: bool = True

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class OccluderSplitsConfig:
    """Joining, in every frame's label image, the two pieces of an object that a nearer object
    cuts in two (``ipr_shapes.perception.occluder_splits``; the last step of the segmentation).

    Off by default: see docs/experiments/2026-11-27-occluder-splits.md for its figures.

    Attributes:
        enabled: join such pieces at all.
        step_m: depth difference (m) that makes one surface nearer than another (across a
            segment border, and against the depth interpolated along the lines between the
            pieces).
        max_gap_px: pieces farther apart than this in the image (px) are not compared.
        band_px: the lines start at the pieces' nearest pixel pairs, those at most this much
            (px) farther apart than the nearest.
        pairs: lines drawn per pair of pieces at most (spread over that band).
        min_piece_px: pieces with fewer pixels with depth are left alone.
        min_occluded: share of the pixels between the pieces that must be nearer than them.
        max_seen_beyond: share of those pixels allowed farther than the pieces or unlabelled
            (seen past the gap: free space between them).
        max_gap_m: largest median 3D distance (m) between the lines' ends (the hidden part).
        normal_radius_m: the local tangent plane at a line's end is fitted to the piece's
            points within this radius (m).
        max_step_m: largest median distance (m) of a line's end off the other end's tangent
            plane (one surface runs on under the occluder; two surfaces meet in a step).
        max_joint_rms_m: largest RMS residual (m) of one quadric surface fitted to both pieces.
        max_rms_increase_m: that residual may exceed the rougher piece's own by this much (m).
        max_colour: largest Bhattacharyya distance between the pieces' colour histograms.
        max_extent_m: the union's extent along each world axis at most this (m; one object).
    """

    CHECKS: ClassVar[Checks] = {
        "step_m": _NON_NEGATIVE,
        "max_gap_px": _NON_NEGATIVE,
        "band_px": _NON_NEGATIVE,
        "pairs": _AT_LEAST_ONE,
        "min_piece_px": _COUNT,
        "min_occluded": _SHARE,
        "max_seen_beyond": _SHARE,
        "max_gap_m": _NON_NEGATIVE,
        "normal_radius_m": _POSITIVE,
        "max_step_m": _NON_NEGATIVE,
        "max_joint_rms_m": _NON_NEGATIVE,
        "max_rms_increase_m": _NON_NEGATIVE,
        "max_colour": _SHARE,
        "max_extent_m": _POSITIVE,
    }

    enabled: bool = False
    step_m: float = 0.01
    max_gap_px: float = 80.0
    band_px: float = 10.0
    pairs: int = 24
    min_piece_px: int = 30
    min_occluded: float = 0.5
    max_seen_beyond: float = 0.03
    max_gap_m: float = 0.06
    normal_radius_m: float = 0.015
    max_step_m: float = 0.02
    max_joint_rms_m: float = 0.01
    max_rms_increase_m: float = 0.002
    max_colour: float = 0.75
    max_extent_m: float = 0.3

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class TemporalConfig:
    """Segmenting frames after the first with the previous frame's help
    (``ipr_shapes.perception.temporal``): objects that did not move keep their grouping.

    Attributes:
        anchoring: supervoxels on surfaces that did not move keep the previous grouping.
        depth_tolerance_m, depth_tolerance_quadratic: a pixel is unchanged when its depth seen
            from the previous camera differs from the previous reading by at most
            ``depth_tolerance_m + depth_tolerance_quadratic * depth^2`` (m; the quadratic term
            in 1/m, as sensor noise grows with depth squared).
        static_fraction: a previous segment stayed when at least this share of its
            unchanged-or-revealed pixels are unchanged (one that moved away reveals what was
            behind it).
        anchor_fraction: a supervoxel is anchored to a segment that stayed when at least this
            share of its pixels are that segment's unchanged pixels.
        near_m: pixels of a segment that stayed which came nearer by at most this (m) are its
            own small shift (a nudged object), not something that arrived in front.
        walls: frames after the first keep the previous frame's walls, and a wall found for
            the first time is rejected when most of its pixels arrived since the previous
            frame (a pushed or toppled box's face; ``temporal.consistent_walls``).
        wall_angle_deg, wall_offset_m: two walls within this angle (deg) and offset (m) are
            the same wall (walls do not move).
        wall_max_arrived: largest share of arrived pixels a new wall may have.
        wall_max_object: largest share of a new wall's compared pixels that may be unchanged
            pixels of an object segment of the previous frame (1: no limit).
    """

    CHECKS: ClassVar[Checks] = {
        "depth_tolerance_m": _NON_NEGATIVE,
        "depth_tolerance_quadratic": _NON_NEGATIVE,
        "static_fraction": _SHARE,
        "anchor_fraction": _SHARE,
        "near_m": _NON_NEGATIVE,
        "wall_angle_deg": _ANGLE,
        "wall_offset_m": _NON_NEGATIVE,
        "wall_max_arrived": _SHARE,
        "wall_max_object": _SHARE,
    }

    anchoring: bool = True
    depth_tolerance_m: float = 0.005
    depth_tolerance_quadratic: float = 0.004
    static_fraction: float = 0.8
    anchor_fraction: float = 0.5
    near_m: float = 0.02
    walls: bool = True
    wall_angle_deg: float = 10.0
    wall_offset_m: float = 0.02
    wall_max_arrived: float = 0.1
    wall_max_object: float = 0.5

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class TrackingConfig:
    """Matching of segments across frames (``ipr_shapes.perception.tracking``): weights and gates of
    the matching cost (dimensionless unless stated) and the split-piece corrections.

    Attributes:
        overlap_weight, colour_weight, distance_weight, size_weight, height_weight: weights of
            the cues (mask overlap, colour histogram, centroid distance, visible-area ratio, top
            height); colour is the most telling cue across a push, the top height adds nothing
            next to the size cue (weight 0).
        max_motion_m: centroid displacement (m) mapped to the full distance cost (a push moves
            objects up to about this far).
        size_ratio_scale: ratio of visible areas (larger / smaller) mapped to the full size
            cost, so that a large piece does not take the id of a sliver of its object.
        height_scale_m: change of top height (m) mapped to the full height cost.
        max_match_cost: first assignment stage: above this a segment is rather a new object.
        elimination_cost: second stage, between the objects and segments the first left
            unmatched: pairs up to this cost are matched (objects that moved far or toppled).
        max_sightings: each object is compared through its last this many sightings (>= 1), so
            that a face turned away by a push can still be recognised.
        gated_elimination: opt-in: the second stage is solved, as the first, with the gate
            inside the optimisation (a leftover segment may stay unmatched at
            ``elimination_cost``) instead of pairing every leftover segment and dropping the
            pairs above the gate afterwards, which can leave an object that one segment matched
            within the gate to another segment above it (``tracking.assign_segments``). Off by
            default: held-out set 8050 +1 pair, ycb-dynamic -1 (docs/DESIGN_NOTES.md, "The
            elimination stage").
        separated_piece_guard: opt-in: the second stage does not give a segment the id of an
            object seen in the previous frame when at least ``separated_min_share`` of the
            segment's pixels with depth show, in place, the surface they showed in the previous
            frame (world points at most ``separated_unchanged_m`` apart, m, and each colour
            channel within ``separated_unchanged_rgb`` of 255) and were then another tracked
            object's: the segment is a piece a push left in place out of that object's segment
            (a frame-0 union pushed apart), not the free object, which was elsewhere
            (``tracking.separated_pieces``). Off by default: it refuses 2 wrong pairs and no
            right one on the development sets but moves no figure (docs/DESIGN_NOTES.md, "The
            elimination stage").
        separated_unchanged_m, separated_unchanged_rgb, separated_min_share: see
            ``separated_piece_guard``.
        pushed_out_guard: a segment matched, above ``max_match_cost`` (by the second stage),
            to an object seen in the previous frame starts a new object instead when it is a
            part pushed out of another matched object's previous-frame segment (a frame-0
            union of two objects pushed apart): ``split_merged_objects``' test with the pair's
            cost in place of a new object's, each side of the split better on its own (the
            other object's segment resembles its previous pixels better without the part,
            the segment resembles the part better than the paired object). The part of the
            previous frame takes the new object's id, and ``split_merged_objects`` carries it
            back to frame 0 (``tracking.pushed_out_pieces``; needs the frames' cameras,
            ``track_segments``' ``follow``). On: development ids 947 -> 949 of 977, every
            other set unchanged (docs/DESIGN_NOTES.md, "The elimination stage").
        larger_piece_takes_id: when an object's id went to a small piece and a segment at
            least ``piece_area_ratio`` times larger nearby that resembles the object almost as
            well (cost <= ``elimination_cost`` and at most ``piece_cost_margin`` more than the
            small piece's) was left to start a new object, the larger piece takes the id
            (``tracking.prefer_larger_pieces``).
        larger_object_takes_segment: when a segment took the id of a small earlier piece and
            an object left unmatched, at least ``piece_area_ratio`` times larger at its latest
            sighting and nearby, costs at most ``piece_cost_margin`` more, that object takes
            the segment (``tracking.prefer_larger_objects``).
        piece_max_cost: the larger object's cost (``larger_object_takes_segment``) and a
            piece's cost (``merge_split_pieces``) are at most this.
        piece_max_gap_m: the two pieces' centroids are at most this far apart (m;
            ``larger_object_takes_segment``, and ``larger_piece_takes_id`` when
            ``piece_gap_relative`` is off).
        piece_gap_relative: ``larger_piece_takes_id``'s gap is relative to the object's size
            rather than ``piece_max_gap_m``: the two pieces' centroids are at most
            ``piece_gap_extent_share`` times the object's size apart, the largest size
            (``tracking.extent_m``, the diagonal of the points' principal-axes box, m) of its
            recent sightings and of the larger piece (pieces of one object lie within it,
            whatever its size).
        piece_gap_extent_share: see ``piece_gap_relative``.
        piece_area_ratio: visible-area ratio a piece or object needs to count as larger.
        piece_cost_margin: see ``larger_piece_takes_id`` and ``larger_object_takes_segment``.
        merge_split_pieces: two touching segments of similar colour, each unmatched, matched
            to the same known object or to one it resembles less, whose union resembles that
            object better than either alone become one segment with its id (an object split in
            this frame; ``tracking.merge_split_pieces``).
        merge_keeps_seen_objects: a segment the assignment gave to another object seen in the
            previous frame is that object's, not a piece to take (``merge_split_pieces``):
            only an object not seen the frame before (the elimination stage's guess at a
            hidden object) gives its segment up.
        merge_max_colour: the two pieces' colour histograms are at most this Bhattacharyya
            distance apart (in [0, 1]).
        merge_margin: the union's cost is below both pieces' by more than this (negative: it
            may be slightly dearer than the cheaper piece, since colour weighs most in the cost
            and the union mixes two faces' colours).
        merge_candidates: each object's this many cheapest segments are candidate pieces, and
            joins repeat with the union as a piece (the thin marker cut in three or four needs
            4).
        merge_min_contact_px: the pieces share at least this many 4-neighbour pixel pairs with
            depth ...
        merge_contact_gap_m: ... whose world points are at most this far apart (m).
        merge_split_objects: two known objects that touched in an earlier frame, one matched
            in this frame and the other not, whose union in that frame resembles the matched
            segment better than the matched object alone (by more than
            ``object_merge_margin``) become one object in every frame (an object split in an
            earlier frame and seen whole now; ``tracking.merge_split_objects``).
        object_merge_margin: see ``merge_split_objects``.
        split_merged_objects: an object first seen in frame t that explains part of an earlier
            object's frame t-1 pixels (seen there as it, or seen empty since) takes that part
            in frame t-1 and, carried back, in frame 0 (two touching objects one segment until
            a push separates them; ``tracking.split_merged_objects``).
        split_min_share, split_min_px: each part holds at least this share of the object's
            frame t-1 pixels with depth, and this many pixels (the new object too). 0.05: a
            can pushed out of a frame-0 union held 9.6 % of it (development 8400/011), and
            0.2 left it the union's sliver id; the pixel floor keeps slivers out
            (docs/experiments/2026-11-27-flush-contacts.md).
        split_margin: the split's cost is below the unsplit one's by more than this.
        split_merged_segments: a segment matched to one object that also holds a known object
            left unmatched in this frame (two objects pushed into contact and segmented as
            one) gives that object the pixels its colour singles out, when each part then
            resembles its object better (``tracking.split_merged_segments``).
        segment_split_ratio: a pixel votes for the unmatched object when its colour bin is
            this many times likelier under that object's histogram than under the segment's
            object's.
        segment_split_min_px: the largest 8-connected region of votes, the candidate part,
            has at least this many pixels.
        segment_split_margin: the rest of the segment costs less as its object than the whole
            segment did by more than this.
        segment_split_leftover_gate: opt-in: the part may cost up to ``elimination_cost`` as
            the unmatched object, not only ``max_match_cost`` (the object is left over after
            both stages, and the part, once split off, is a leftover segment: the second
            stage's gate; a pushed object costs more than ``max_match_cost`` to its earlier
            view), when the split also explains the frame better by ``split_merged_objects``'
            test: the rest's cost plus the part's is below the whole's plus ``max_match_cost``
            (the part as a new object) by more than ``segment_split_margin`` (implied below
            ``max_match_cost``). Off: development 967 -> 968 of 989 ids, F >= 0.75 rows
            1540 -> 1542, but 8100 loses a piece flip and held-out 8050 a row (a piece of the
            same object handed back to its own id; docs/DESIGN_NOTES.md, "Objects pushed into
            one segment are split again").
        moved_wholes: an object ``b`` seen in frame t-1 and not in frame t, whose
            nearest point lies within ``whole_max_gap_m`` of an object ``a`` seen in both, is
            joined to ``a`` in every frame when ``a`` moved between the frames and its frame-t
            segment, registered rigidly onto the two frame-(t-1) segments, covers each of them
            (an object split in frame t-1, touching or across an occluder, moved and seen
            whole: the rigid motion is the evidence a single frame lacks;
            ``tracking.join_moved_wholes``). On: it loses on no set; docs/DESIGN_NOTES.md, "Objects
            split in an earlier frame are joined".
        whole_max_gap_m: largest distance (m) between the two frame-(t-1) segments' nearest
            points (the occluder join's hidden parts are up to 6 cm; 10 cm leaves room).
        whole_inlier_m: a point is covered, or in place, when a point of the other set lies
            within this distance (m).
        whole_min_cover: each frame-(t-1) segment has at least this share of its points covered
            by the registered frame-t segment.
        whole_static_share: ``a`` moved: less than this share of its frame-(t-1) points are in
            place in frame t (an object that did not move gives no evidence: the segmentation
            may merely have seen two objects as one there).
        whole_min_motion_m: ``a`` moved: the registration moves its frame-t points by a median
            of at least this (m).
    """

    CHECKS: ClassVar[Checks] = {
        "overlap_weight": _NON_NEGATIVE,
        "colour_weight": _NON_NEGATIVE,
        "distance_weight": _NON_NEGATIVE,
        "size_weight": _NON_NEGATIVE,
        "height_weight": _NON_NEGATIVE,
        "max_motion_m": _POSITIVE,
        "size_ratio_scale": Interval(1, None, closed="neither"),
        "height_scale_m": _POSITIVE,
        "max_match_cost": _NON_NEGATIVE,
        "elimination_cost": _NON_NEGATIVE,
        "max_sightings": _AT_LEAST_ONE,
        "separated_unchanged_m": _NON_NEGATIVE,
        "separated_unchanged_rgb": _COUNT,
        "separated_min_share": _SHARE,
        "piece_max_cost": _NON_NEGATIVE,
        "piece_max_gap_m": _NON_NEGATIVE,
        "piece_gap_extent_share": _NON_NEGATIVE,
        "piece_area_ratio": Interval(1, None),
        "piece_cost_margin": _ANY,
        "merge_max_colour": _SHARE,
        "merge_margin": _ANY,
        "merge_candidates": _COUNT,
        "merge_min_contact_px": _COUNT,
        "merge_contact_gap_m": _NON_NEGATIVE,
        "object_merge_margin": _ANY,
        "split_min_share": _SHARE,
        "split_min_px": _COUNT,
        "split_margin": _ANY,
        "segment_split_ratio": _POSITIVE,
        "segment_split_min_px": _COUNT,
        "segment_split_margin": _ANY,
        "whole_max_gap_m": _NON_NEGATIVE,
        "whole_inlier_m": _POSITIVE,
        "whole_min_cover": _SHARE,
        "whole_static_share": _SHARE,
        "whole_min_motion_m": _NON_NEGATIVE,
    }

    overlap_weight: float = 1.0
    colour_weight: float = 2.0
    distance_weight: float = 0.5
    size_weight: float = 0.4
    height_weight: float = 0.0
    max_motion_m: float = 0.3
    size_ratio_scale: float = 8.0
    height_scale_m: float = 0.05
    max_match_cost: float = 1.5
    elimination_cost: float = 3.0
    max_sightings: int = 3
    gated_elimination: bool = False
    separated_piece_guard: bool = False
    separated_unchanged_m: float = 0.01
    separated_unchanged_rgb: int = 30
    separated_min_share: float = 0.5
    pushed_out_guard: bool = True
    larger_piece_takes_id: bool = True
    piece_max_cost: float = 2.5
    piece_max_gap_m: float = 0.1
    piece_gap_relative: bool = True
    piece_gap_extent_share: float = 1.0
    piece_area_ratio: float = 2.0
    larger_object_takes_segment: bool = True
    piece_cost_margin: float = 0.6
    merge_split_pieces: bool = True
    merge_keeps_seen_objects: bool = False
    merge_max_colour: float = 0.6
    merge_margin: float = -0.2
    merge_candidates: int = 4
    merge_min_contact_px: int = 3
    merge_contact_gap_m: float = 0.01
    merge_split_objects: bool = True
    object_merge_margin: float = 0.0
    split_merged_objects: bool = True
    split_min_share: float = 0.05
    split_min_px: int = 200
    split_margin: float = 0.0
    split_merged_segments: bool = True
    segment_split_ratio: float = 2.0
    segment_split_min_px: int = 100
    segment_split_margin: float = 0.0
    segment_split_leftover_gate: bool = False
    moved_wholes: bool = True
    whole_max_gap_m: float = 0.10
    whole_inlier_m: float = 0.01
    whole_min_cover: float = 0.7
    whole_static_share: float = 0.5
    whole_min_motion_m: float = 0.01

    def __post_init__(self) -> None:
        check_fields(self)


def _window(value: object) -> bool:
    """An odd integer, or any integer below 3 (raw depth)."""
    integer = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    return integer and (value < 3 or value % 2 == 1)


@dataclass(frozen=True)
class DenoiseConfig:
    """Partial objects' points from depth replaced by a local plane fit
    (``ipr_shapes.perception.denoise``), so that hulls of the points no longer bulge out by the noise.

    Attributes:
        window_px: the fit runs over this many pixels square of the same object (px; odd, a
            window centred on its pixel; < 3: raw readings).
    """

    CHECKS: ClassVar[Checks] = {
        "window_px": Predicate(
            _window, "odd (a window centred on its pixel) or below 3 to use raw depth"
        ),
    }

    window_px: int = 5

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class FacetsConfig:
    """Facets of the partial objects (``ipr_shapes.perception.facets``).

    Attributes:
        bandwidth: mean-shift bandwidth on unit normals (chord length, in (0, 2]): normals
            closer than about this form one facet.
        min_area_m2: facets smaller than this (m^2) are ignored by hypotheses (the paper:
            (3 cm)^2: smaller ones are noise). Hypotheses read their own copy,
            ``ipr_shapes.hypotheses.HypothesisConfig.min_facet_area_m2``; perception does not use it.
    """

    CHECKS: ClassVar[Checks] = {
        "bandwidth": Interval(0, 2, closed="right"),
        "min_area_m2": _NON_NEGATIVE,
    }

    bandwidth: float = 0.35
    min_area_m2: float = 0.03**2

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class FreeSpaceConfig:
    """The free / occupied / unknown voxel map of each frame (``ipr_shapes.perception.free_space``).

    Attributes:
        voxel_m: grid resolution (m; the paper: 5 mm).
        surface_margin_m: voxels this close (m) to an observed surface are occupied, not free
            (depth noise must not carve the objects' own surfaces).
        workspace_margin_m: the grid extends this far (m) around the objects (room for the
            hypotheses' hidden parts).
    """

    CHECKS: ClassVar[Checks] = {
        "voxel_m": _POSITIVE,
        "surface_margin_m": _NON_NEGATIVE,
        "workspace_margin_m": _NON_NEGATIVE,
    }

    voxel_m: float = 0.005
    surface_margin_m: float = 0.01
    workspace_margin_m: float = 0.15

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class OccludedPiecesConfig:
    """Joining frame 0's pieces of one object cut apart by an occluder
    (``ipr_shapes.perception.occlusion.join_occluded_pieces``; used by ``ipr-shapes infer``, not by the label
    images).

    Attributes:
        enabled: join pieces at all.
        max_colour: largest Bhattacharyya distance between the pieces' colour histograms (in
            [0, 1]; pieces of one object look alike).
        max_gap_m: largest distance (m) between the pieces' nearest observed points (an
            occluder hides a few centimetres).
        max_inside_points: other objects' observed points allowed inside the joined hull (a
            hull through another object is two objects).
        inside_margin_m: points count as inside only this far (m) within the hull's faces.
        free_space_tolerance, free_space_tolerance_voxels: the joined hull may have this
            share, or this count, whichever is larger, of extra voxels in seen-free space or
            walls (the hypotheses' unary tolerances, ``ipr_shapes.hypotheses.UnaryTolerances``).
        wall_min_thickness_m: walls without a measured thickness are slabs this thick (m).
        point_stride: every this-many-th point is used for the gap between pieces (the gap
            needs no more).
    """

    CHECKS: ClassVar[Checks] = {
        "max_colour": _SHARE,
        "max_gap_m": _NON_NEGATIVE,
        "max_inside_points": _COUNT,
        "inside_margin_m": _NON_NEGATIVE,
        "free_space_tolerance": _SHARE,
        "free_space_tolerance_voxels": _COUNT,
        "wall_min_thickness_m": _NON_NEGATIVE,
        "point_stride": _AT_LEAST_ONE,
    }

    enabled: bool = True
    max_colour: float = 0.6
    max_gap_m: float = 0.10
    max_inside_points: int = 5
    inside_margin_m: float = 0.005
    free_space_tolerance: float = 0.02
    free_space_tolerance_voxels: int = 20
    wall_min_thickness_m: float = 0.005
    point_stride: int = 20

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class PerceptionConfig:
    """Perception parameters, one group per step (lengths in metres, angles in degrees).

    Attributes:
        seed: seed of every random choice (RANSAC, k-means), for reproducible runs.
        planes: RANSAC settings shared by the support and the walls.
        support: the support (table) plane.
        walls: walls of containers and drawers.
        robot: removal of the robot's and the pusher's pixels.
        supervoxels: pixel normals and supervoxels.
        segmentation: the supervoxel graph, its clustering and the segments kept.
        containers: joining an open container's inside to the container.
        seams: cutting segments along straight colour seams (packed boxes; off by default).
        occluder_splits: joining the two pieces of an object cut in two by a nearer object in
            every frame's label image (off by default).
        temporal: segmenting later frames with the previous frame's help.
        tracking: matching of segments across frames.
        denoise: the plane-fitted depth of partial objects' points.
        facets: facets of the partial objects.
        free_space: the free / occupied / unknown voxel map of each frame.
        occluded_pieces: joining frame 0's pieces of one object cut apart by an occluder
            (used by ``ipr-shapes infer``, not by the label images).
    """

    CHECKS: ClassVar[Checks] = {"seed": _COUNT}

    seed: int = 0
    planes: PlanesConfig = field(default_factory=PlanesConfig)
    support: SupportConfig = field(default_factory=SupportConfig)
    walls: WallsConfig = field(default_factory=WallsConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    supervoxels: SupervoxelsConfig = field(default_factory=SupervoxelsConfig)
    segmentation: SegmentationConfig = field(default_factory=SegmentationConfig)
    containers: ContainersConfig = field(default_factory=ContainersConfig)
    seams: SeamsConfig = field(default_factory=SeamsConfig)
    occluder_splits: OccluderSplitsConfig = field(default_factory=OccluderSplitsConfig)
    temporal: TemporalConfig = field(default_factory=TemporalConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    denoise: DenoiseConfig = field(default_factory=DenoiseConfig)
    facets: FacetsConfig = field(default_factory=FacetsConfig)
    free_space: FreeSpaceConfig = field(default_factory=FreeSpaceConfig)
    occluded_pieces: OccludedPiecesConfig = field(default_factory=OccludedPiecesConfig)

    def __post_init__(self) -> None:
        check_fields(self)
