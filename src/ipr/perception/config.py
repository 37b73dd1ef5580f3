"""Parameters of the perception stage, one typed object with documented defaults.

Defaults follow the paper and its authors' code (ARCHITECTURE.md) where those give a value, and
were otherwise chosen on synthetic development scenes (seeds outside every benchmark suite).
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class OccludedPiecesConfig:
    """Settings of ``ipr.perception.occlusion.join_occluded_pieces`` (metres).

    Attributes:
        enabled: join pieces at all.
        max_colour: largest Bhattacharyya distance between the pieces' colour histograms.
        max_gap_m: largest distance between the pieces' nearest observed points.
        max_inside_points: other objects' observed points allowed inside the joined hull.
        inside_margin_m: points count as inside only this far within the hull's faces.
        free_space_tolerance, free_space_tolerance_voxels: the joined hull may have this
            share, or this count, whichever is larger, of extra voxels in seen-free space or
            walls (the hypotheses' unary tolerances, ``ipr.hypotheses.UnaryTolerances``).
        wall_min_thickness_m: walls without a measured thickness are slabs this thick.
        point_stride: every this-many-th point is used for the gap between pieces.
    """

    enabled: bool = True
    max_colour: float = 0.6
    max_gap_m: float = 0.10
    max_inside_points: int = 5
    inside_margin_m: float = 0.005
    free_space_tolerance: float = 0.02
    free_space_tolerance_voxels: int = 20
    wall_min_thickness_m: float = 0.005
    point_stride: int = 20


@dataclass(frozen=True)
class TrackingConfig:
    """Weights and gates of the matching cost (dimensionless unless stated).

    Defaults were chosen on development scenes (dynamic, seeds 8000-8011 and 8100-8123,
    343 (object, later frame) pairs; checked on seeds 8050-8073), never on a suite. Share of ids
    kept (development / check): the defaults before the split-piece corrections
    (``larger_piece_takes_id``, ``larger_object_takes_segment``) 0.942 / 0.974; without the size cue 0.930 / 0.970
    (0.913 / 0.952 without size and a 3D-extent cue that was then dropped as it added nothing);
    height weight 0.1 or 0.25 0.939 / 0.970 and 0.942 / 0.961; a single gated assignment
    (``elimination_cost`` 0) 0.659 / 0.645 with these weights, and 0.875 / 0.926 with the
    former ones (overlap .5, colour 1, distance .5, height .5, gate 1.5).

    Attributes:
        overlap_weight, colour_weight, distance_weight, size_weight, height_weight: weights of
            the cues (mask overlap, colour histogram, centroid distance, visible-area ratio, top
            height); see ``ipr.perception.tracking``.
        max_motion_m: centroid displacement mapped to the full distance cost (a push moves
            objects up to about this far).
        size_ratio_scale: ratio of visible areas (larger / smaller) mapped to the full size cost.
            Size weight 0.4 and scale 8 instead of 0.25 and 4: 1127 instead of 1122 of the
            1202 development pairs kept (the pairs that changed all gained; held-out 227 of 231
            either way): a large piece no longer takes the id of a sliver of its object (a 25x
            area ratio cost what a 4x one did).
        height_scale_m: change of top height mapped to the full height cost.
        max_match_cost: first assignment stage: above this a segment is rather a new object.
        elimination_cost: second stage, between the objects and segments the first left
            unmatched: pairs up to this cost are matched (objects that moved far or toppled).
        max_sightings: each object is compared through its last this many sightings (>= 1).
        larger_piece_takes_id: when an object's id went to a small piece and a segment at
            least ``piece_area_ratio`` times larger nearby that resembles the object (cost <=
            ``piece_max_cost``) was left to start a new object, the larger piece takes the id
            (``tracking.prefer_larger_pieces``).
        larger_object_takes_segment: when a segment took the id of a small earlier piece and
            an object left unmatched, at least ``piece_area_ratio`` times larger at its latest
            sighting and nearby, costs at most ``piece_cost_margin`` more, that object takes
            the segment (``tracking.prefer_larger_objects``).
        piece_max_cost: the larger piece's or object's cost is at most this.
        piece_max_gap_m: the two pieces' centroids are at most this far apart (m).
        piece_area_ratio: visible-area ratio a piece or object needs to count as larger
            (1.0 gave 1113 / 1202 development pairs, 2.0 1114, with margin 0.6).
        piece_cost_margin: see ``larger_object_takes_segment`` (0.3: 1112; 0.6: 1114).
        merge_split_pieces: two touching segments of similar colour, each unmatched, matched
            to the same known object or to one it resembles less, whose union resembles that
            object better than either alone become one segment with its id (an object split in
            this frame; ``tracking.merge_split_pieces``). Development pairs kept (of 1202) and
            share of objects with F >= 0.75, all defaults: 1127, 0.919; without joins: 1115,
            0.909 (before ``merge_split_objects``).
        merge_max_colour: the two pieces' colour histograms are at most this Bhattacharyya
            distance apart (in [0, 1]; 0.4: 1120, 0.916; 0.8: 1128, 0.918 with more joins of
            different objects).
        merge_margin: the union's cost is below both pieces' by more than this (negative: it
            may be slightly dearer than the cheaper piece, since colour weighs most in the cost
            and the union mixes two faces' colours; 0: 1122, 0.917).
        merge_candidates: each object's this many cheapest segments are candidate pieces, and
            joins repeat with the union as a piece (3: 1125; the thin marker cut in three or
            four needs 4).
        merge_min_contact_px: the pieces share at least this many 4-neighbour pixel pairs with
            depth ...
        merge_contact_gap_m: ... whose world points are at most this far apart (m; no such
            test: 1126).
        merge_split_objects: two known objects that touched in an earlier frame, one matched
            in this frame and the other not, whose union in that frame resembles the matched
            segment better than the matched object alone (by more than
            ``object_merge_margin``) become one object in every frame (an object split in an
            earlier frame and seen whole now; ``tracking.merge_split_objects``). Development
            pairs kept and share with F >= 0.75: 1132 of 1198 (0.945), 0.922 against 1127 of
            1202 (0.938), 0.919 without; held-out 227 of 232, 0.946 against 227 of 231, 0.938
            (the joins change which objects frame 0 segments well enough to count). Without the
            contact test 1123 of 1187, 0.916 (different objects joined).
        object_merge_margin: see ``merge_split_objects`` (-0.2: 1133 of 1198, 0.924; 0.2: 1130,
            0.921; 0.4: 1128 of 1200, 0.920; held-out 227-228 of 231-232 throughout).
        split_merged_objects: an object first seen in frame t that explains part of an earlier
            object's frame t-1 pixels (seen there as it, or seen empty since) takes that part
            in frame t-1 and, carried back, in frame 0 (two touching objects one segment until
            a push separates them; ``tracking.split_merged_objects``). Development pairs kept
            and share with F >= 0.75: 1145 of 1199, 0.933 against 1143, 0.932 without (2 true
            splits, none false, in 148 scenes); held-out 227 of 232, 0.949 either way.
        split_min_share, split_min_px: each part holds at least this share of the object's
            frame t-1 pixels with depth, and this many pixels (the new object too).
        split_margin: the split's cost is below the unsplit one's by more than this. On the
            development scenes the candidates' gains were 0.37-1.57 for the true splits and
            at most -0.08 for the false ones (one true split at -0.62 is missed).
        split_merged_segments: a segment matched to one object that also holds a known object
            left unmatched in this frame (two objects pushed into contact and segmented as
            one) gives that object the pixels its colour singles out, when each part then
            resembles its object better (``tracking.split_merged_segments``). Development pairs
            kept and share with F >= 0.75: 1146 of 1200, 0.933 against 1142, 0.931 without;
            held-out 228 of 232, 0.952 against 227, 0.949 (11 splits, each part given to the
            object it shows); container sets 87 of 90, 0.900 against 86, 0.895.
        segment_split_ratio: a pixel votes for the unmatched object when its colour bin is
            this many times likelier under that object's histogram than under the segment's
            object's (1.5 and 3: 1145 and 1146 development pairs).
        segment_split_min_px: the largest 8-connected region of votes, the candidate part,
            has at least this many pixels (50: the same results).
        segment_split_margin: the rest of the segment costs less as its object than the whole
            segment did by more than this (-0.2 and 0.2: 1146 and 1145 development pairs).
    """

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
    larger_piece_takes_id: bool = True
    piece_max_cost: float = 2.5
    piece_max_gap_m: float = 0.1
    piece_area_ratio: float = 2.0
    larger_object_takes_segment: bool = True
    piece_cost_margin: float = 0.6
    merge_split_pieces: bool = True
    merge_max_colour: float = 0.6
    merge_margin: float = -0.2
    merge_candidates: int = 4
    merge_min_contact_px: int = 3
    merge_contact_gap_m: float = 0.01
    merge_split_objects: bool = True
    object_merge_margin: float = 0.0
    split_merged_objects: bool = True
    split_min_share: float = 0.2
    split_min_px: int = 200
    split_margin: float = 0.0
    split_merged_segments: bool = True
    segment_split_ratio: float = 2.0
    segment_split_min_px: int = 100
    segment_split_margin: float = 0.0


@dataclass(frozen=True)
class PerceptionConfig:
    """Perception parameters (lengths in metres, angles in degrees).

    Attributes:
        plane_threshold_m: RANSAC inlier distance for the support plane and walls (authors: 1 cm).
        plane_iterations: RANSAC iterations (authors: 1000).
        support_max_tilt_deg: the support plane's normal is within this angle of world z.
        support_clearance_m: points less than this above the support belong to it.
        min_object_height_m: segments whose 90th-percentile height above the support is lower
            are support residue (noise, a slightly curved table), not objects.
        support_min_points, support_min_fraction: the support needs at least this many inliers
            and this share of the frame's valid points.
        ransac_sample_size: points on which RANSAC hypotheses are scored (a random subset; the
            winner is refitted by least squares on its inliers).
        wall_max_candidates: vertical planes examined as possible walls per frame (0 = no walls).
        wall_iterations: RANSAC iterations per vertical plane.
        wall_max_points: the wall search uses at most this many points above the support (an
            even subset), which bounds its cost on close-up frames.
        wall_min_points: inliers a wall candidate needs.
        wall_normal_tilt_deg: only points whose (noisy) pixel normal is within this angle of
            the horizontal vote for vertical planes.
        wall_min_length_m: a wall's visible run along the support is at least this long (the
            generator's walls are >= 20 cm; YCB boxes' faces are <= 21 cm, told apart by the
            other cues).
        wall_max_gap_m: gaps (occlusions) shorter than this do not break a wall's run.
        wall_min_height_m, wall_max_height_m: range of a wall's top above the support.
        wall_support_gap_m: a wall's lowest visible points are within this of the support.
        wall_max_thickness_m: walls are thinner than this; it is also the slab removed behind a
            wall's visible face.
        wall_cap_depth_m: how far behind a wall's face points "capping" it (a box's top) count.
        wall_max_capped_fraction: share of a wall's length allowed to have such points (objects
            standing behind a drawer front and rising above it).
        wall_min_top_agreement: a wall accepted on its own (without a partner) has its top
            edge within 2 cm of its top height over at least this share of its 2 cm columns
            (a wall's rim is straight; the faces of a pile of objects are of many heights).
        wall_min_face_fill: ... and inliers in at least this share of the 2 cm cells of its face
            between its bottom and its top (a wall is a solid face).
        wall_side_range_m: distance from a wall within which the scene's other points are used
            for the one-sided test.
        wall_max_outside_fraction: share of those points allowed on the wall's minority side.
        wall_partner_min_length_m: shortest run of a wall accepted through a partner wall.
        wall_partner_separation_m: (min, max) distance between opposite walls of a container.
        wall_partner_max_top_difference_m: partner walls' tops differ by at most this (a drawer
            front is 3-5 cm taller than the sides).
        wall_partner_top_match_m: tops of a wall whose bottom is hidden and of its partner
            differ by at most this.
        wall_corner_gap_m: two perpendicular walls meet within this of the ends of their runs.
        wall_complete_corners: look for side walls seen edge-on at the ends of accepted walls
            (``planes._edge_on_walls``).
        wall_max_span_m: a wall's face may extend past its run (an object in front of it cuts it
            in two) to pieces of its plane whose top is the wall's, up to this overall length.
        wall_top_margin_m: points up to this above a wall's top (its rim, with noise) are
            removed with it.
        pusher_margin_m: points within the pusher capsule's radius plus this are removed.
        voxel_size_m: supervoxel voxel resolution (authors' VCCS: 7.5 mm).
        seed_size_m: supervoxel seed spacing (authors' VCCS: 2 cm).
        normal_radius_px: pixel normals use the neighbours this many pixels away.
        normal_max_jump_m, normal_max_jump_ratio: a neighbour whose depth differs by more than
            ``normal_max_jump_m + normal_max_jump_ratio * radius * depth`` is across a
            discontinuity and not used for the normal.
        supervoxel_iterations: k-means rounds assigning voxels to seeds.
        supervoxel_normal_weight: weight of the normal term (1 - cos) against the spatial term
            (distance / seed size)^2 in the voxel-to-seed distance (VCCS: normal 1, spatial 1).
        supervoxel_colour_weight: weight of the squared RGB distance (channels in [0, 1]) in
            that distance (authors' VCCS: 0; 3 gave 0.903 / 0.911 against 0.920 / 0.896 on the
            development scenes, within their noise, so it stays off).
        supervoxel_min_points: supervoxel pieces with fewer pixels are merged into a neighbour.
        supervoxel_max_points: supervoxel statistics use at most this many pixels (an even
            subset; every kept pixel is still labelled through its voxel).
        dominant_face_deg: a supervoxel's normal and centre come from its pixels whose normal is
            within this angle of its dominant direction (0 = all pixels).
        concavity_tolerance_deg: edges flatter than this count as convex (authors' LCCP: 10).
        sanity_angle_deg, sanity_sigmoid: a convex edge whose centre-to-centre direction is
            within this angle of the crease line is singular, not convex; with the sigmoid (LCCP)
            the angle is scaled by 1 / (1 + exp(-0.25 (normal angle - 25))) (authors' code: a
            fixed 45 degrees; LCCP: 60 with the sigmoid, better on the development scenes).
        smoothness_threshold: LCCP smoothness slack, in voxel sizes (authors: 0.1).
        concave_weight: graph weight of concave (or not smooth) edges; convex/flat edges weigh 1.
        singular_weight: graph weight of convex edges that fail the sanity check.
        dense_eigen_limit: components up to this many supervoxels use a dense eigensolver.
        eigengap_floor: noise floor added to the eigenvalues of L_sym before their ratios are
            compared (the eigengap is the largest ratio of consecutive eigenvalues).
        kmeans_restarts: k-means initialisations (seeded) on the spectral embedding.
        max_objects: upper bound on the number of objects per frame.
        min_object_pixels: segments with fewer pixels (with depth) are merged into a neighbour
            or dropped (an object peeking over a drawer front can show ~50).
        join_container_insides: join the pieces of an open container's inside to the container
            (``ipr.perception.containers``, where the rules below are explained).
        inside_footprint_fraction, inside_margin_m: share of a piece's points within the
            container's footprint on the support (its convex hull or fitted circle), grown by
            this margin (m).
        inside_circle_rms_m, inside_max_radius_m: the circle fitted to a container's
            footprint counts when its RMS distance to the points is at most the first and its
            radius at most the second (m).
        inside_top_tolerance_m, inside_bottom_tolerance_m: how far (m) the piece's top may rise
            above the container's and its bottom reach below the container's.
        inside_rim_radius_m: the container's points this close to the piece's on the support
            (m) are its rim around the piece.
        inside_max_chroma: largest L1 distance between the two mean chromaticities.
        inside_max_front_ratio: the piece stands in front of the container along at most this
            share of the pixel pairs where they meet.
        inside_min_contact_px: the two meet (touch, or the container hides the piece) along at
            least this many 4-neighbour pixel pairs.
        inside_contact_gap_m: two neighbouring pixels whose points are closer than this (m)
            belong to touching surfaces.
        inside_front_step_m: (low, high) depth step (m) between neighbouring pixels at which
            the nearer one stands in front of the other (above ``high``: unrelated surfaces).
        label_fill_px: pixels without depth take the label of the nearest pixel with depth up
            to this distance in pixels (edge dropout, small holes); 0 = no filling.
        facet_bandwidth: mean-shift bandwidth on unit normals for facets (chord length).
        min_facet_area_m2: facets smaller than this are ignored by hypotheses (paper: (3 cm)^2).
        free_space_voxel_m: free/unknown voxel grid resolution (paper: 5 mm).
        surface_margin_m: voxels this close to an observed surface are occupied, not free.
        workspace_margin_m: the free-space grid extends this far around the objects.
        temporal_anchoring: segment frames after the first with the previous frame's help:
            supervoxels on surfaces that did not move keep the previous grouping
            (``ipr.perception.temporal``).
        temporal_depth_tolerance_m, temporal_depth_tolerance_quadratic: a pixel is unchanged
            when its depth seen from the previous camera differs from the previous reading by at
            most ``tolerance_m + quadratic * depth^2`` (m; quadratic in 1/m, as sensor noise
            grows); the generator's frames differ by <= 4 mm on 99 % of static pixels.
        temporal_static_fraction: a previous segment stayed when at least this share of its
            unchanged-or-revealed pixels are unchanged (one that moved away reveals what was
            behind it).
        temporal_anchor_fraction: a supervoxel is anchored to a segment that stayed when at
            least this share of its pixels are that segment's unchanged pixels.
        temporal_near_m: pixels of a segment that stayed which came nearer by at most this
            (m) are its own small shift (a nudged object), not something that arrived in front.
        temporal_walls: frames after the first keep the previous frame's walls, and a wall
            found for the first time is rejected when most of its pixels arrived since the
            previous frame (a pushed or toppled box's face; ``temporal.consistent_walls``).
        temporal_wall_angle_deg, temporal_wall_offset_m: two walls within this angle and
            offset (m) are the same wall.
        temporal_wall_max_arrived: largest share of arrived pixels a new wall may have.
        seed: seed of every random choice (RANSAC, k-means), for reproducible runs.
        denoise_window_px: partial objects' points come from depth replaced by a local plane
            fit over this many pixels square of the same object (``ipr.perception.denoise``;
            < 3: raw readings), so hulls of the points no longer bulge out by the noise.
            Development scenes (``benchmarks.dev_inference``'s seeds 9100 / 9400, frame-0
            hypotheses, 46 / 44 objects), Collision Checker object IoU and the best candidate's:
            raw 0.641 / 0.720 and 0.589 / 0.726; window 5 0.660 / 0.752 and 0.601 / 0.740;
            window 3 and 9 on 9100: 0.664 / 0.737 and 0.652 / 0.747. The minimum shapes'
            precision rose 0.823 -> 0.888 on 9100 (fewer than 0.2 % of the raw points lie more
            than 5 mm outside the true object). About 6 ms per real 640x480 frame.
        tracking: matching of segments across frames.
        occluded_pieces: joining frame 0's pieces of one object cut apart by an occluder
            (``ipr.perception.occlusion``; used by ``ipr infer``, not by the label images).
    """

    plane_threshold_m: float = 0.01
    plane_iterations: int = 1000
    support_max_tilt_deg: float = 30.0
    support_clearance_m: float = 0.01
    min_object_height_m: float = 0.015
    support_min_points: int = 200
    support_min_fraction: float = 0.1
    ransac_sample_size: int = 1000
    wall_max_candidates: int = 6
    wall_max_points: int = 30000
    wall_iterations: int = 200
    wall_min_points: int = 100
    wall_normal_tilt_deg: float = 25.0
    wall_min_length_m: float = 0.18
    wall_max_gap_m: float = 0.05
    wall_min_height_m: float = 0.05
    wall_max_height_m: float = 0.25
    wall_support_gap_m: float = 0.03
    wall_max_thickness_m: float = 0.018
    wall_cap_depth_m: float = 0.10
    wall_max_capped_fraction: float = 0.5
    wall_min_top_agreement: float = 0.6
    wall_min_face_fill: float = 0.5
    wall_side_range_m: float = 0.5
    wall_max_outside_fraction: float = 0.03
    wall_partner_min_length_m: float = 0.1
    wall_partner_separation_m: tuple[float, float] = (0.15, 0.55)
    wall_partner_max_top_difference_m: float = 0.06
    wall_partner_top_match_m: float = 0.015
    wall_corner_gap_m: float = 0.04
    wall_complete_corners: bool = True
    wall_max_span_m: float = 0.6
    wall_top_margin_m: float = 0.005
    pusher_margin_m: float = 0.005
    voxel_size_m: float = 0.0075
    seed_size_m: float = 0.02
    normal_radius_px: int = 2
    normal_max_jump_m: float = 0.01
    normal_max_jump_ratio: float = 0.02
    supervoxel_iterations: int = 3
    supervoxel_normal_weight: float = 1.0
    supervoxel_colour_weight: float = 0.0
    supervoxel_min_points: int = 12
    supervoxel_max_points: int = 50000
    dominant_face_deg: float = 30.0
    concavity_tolerance_deg: float = 10.0
    sanity_angle_deg: float = 60.0
    sanity_sigmoid: bool = True
    smoothness_threshold: float = 0.1
    concave_weight: float = 0.001
    singular_weight: float = 0.001
    dense_eigen_limit: int = 400
    eigengap_floor: float = 0.001
    kmeans_restarts: int = 4
    max_objects: int = 20
    min_object_pixels: int = 40
    label_fill_px: float = 3.0
    join_container_insides: bool = True
    inside_footprint_fraction: float = 0.9
    inside_margin_m: float = 0.01
    inside_circle_rms_m: float = 0.004
    inside_max_radius_m: float = 0.15
    inside_top_tolerance_m: float = 0.005
    inside_bottom_tolerance_m: float = 0.005
    inside_max_chroma: float = 0.2
    inside_rim_radius_m: float = 0.02
    inside_max_front_ratio: float = 0.5
    inside_min_contact_px: int = 3
    inside_contact_gap_m: float = 0.01
    inside_front_step_m: tuple[float, float] = (0.01, 0.1)
    facet_bandwidth: float = 0.35
    min_facet_area_m2: float = 0.03**2
    free_space_voxel_m: float = 0.005
    surface_margin_m: float = 0.01
    workspace_margin_m: float = 0.15
    temporal_anchoring: bool = True
    temporal_depth_tolerance_m: float = 0.005
    temporal_depth_tolerance_quadratic: float = 0.004
    temporal_static_fraction: float = 0.8
    temporal_anchor_fraction: float = 0.5
    temporal_near_m: float = 0.02
    temporal_walls: bool = True
    temporal_wall_angle_deg: float = 10.0
    temporal_wall_offset_m: float = 0.02
    temporal_wall_max_arrived: float = 0.1
    seed: int = 0
    denoise_window_px: int = 5
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    occluded_pieces: OccludedPiecesConfig = field(default_factory=OccludedPiecesConfig)

    def __post_init__(self) -> None:
        window = self.denoise_window_px
        if window >= 3 and window % 2 == 0:
            raise ValueError(
                f"perception.denoise_window_px must be odd (a window centred on its pixel) or "
                f"below 3 to use raw depth, got {window}"
            )
