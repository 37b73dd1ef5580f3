"""Hidden-shape hypotheses of partial objects: Algorithm 1 of the paper (Sec. IV-B, IV-C).

An object model is its observed facets plus imagined hidden ones. Each observed facet F (normal
N out of the object, centre c) is mirrored about its tangent plane L = {x : N . (x - c) = 0} and
the mirror image is pushed back by a distance d ~ U(D_min, D_max) against N; it becomes a
hypothesised hidden facet (the far side of the object). The convex hull of all the facets then
shows new facets (the sides joining front and back); those whose normal is not already present
are mirrored and pushed in their turn, and so on until no new normal appears or time runs out.
A hypothesis is the convex hull of everything: a closed convex mesh built on every observed
point of the object (all observed points take part in every hull, even those of facets that are
too small to be mirrored); optionally shrunk by the points' scatter (below).

Choices made here (the paper leaves them open):

- D_max by ray tracing. From each of a facet's points p a ray runs along -N through the frame's
  free-space map; it ends at the first voxel seen FREE, where it enters the support (below the
  plane) or a known wall's slab, where it leaves the object's bound beyond the camera's view
  or the support's seen outline (below), or at ``max_depth_m`` (``border_max_depth_m`` for an
  object cut by the image border, whose hidden part may extend beyond the picture). The mirror
  image of p lies on the same line, t = 2 N.(p - c) + d behind p, and the paper asks that the space
  between a facet and its mirror be hidden: 0 <= t <= limit(p), i.e. each ray allows
  d in [-2 N.(p - c), limit(p) - 2 N.(p - c)]. The lower end matters for curved facets: a
  smaller d puts the mirrored rim in front of the seen surface.
- Robustness: the admissible d are those (on cells of the ray step) that violate at most a
  ``ray_quantile`` share of the rays, so a single noisy voxel shortens one ray, not the facet.
  The outline matters most: mirroring moves points along N, which is tilted from the camera's
  rays wherever a facet is curved or oblique, so the mirror of a facet's rim can leave the
  object's silhouette into seen-free space while most of its rays are fine. The rays from the
  points within ``rim_width_m`` of the facet's outline (on its tangent plane) therefore form a
  second set that must be satisfied on its own. D_max is the largest admissible d, and d is
  drawn uniformly from the admissible d of at least D_min (``min_thickness_m``).
- Conflicts: a strongly curved facet (a bottle's whole side) can have no d that suits enough
  rays (its mirrored rim wants d large, its mirrored crest wants d small); then the d with the
  fewest violations are used (logged) and the unary check below decides.
- No room (D_max < D_min): the object is thinner than D_min there (a plate, a book lying flat),
  so d = D_max, floored at ``min_room_m`` so the hypothesis keeps a volume; logged.
- Sampling: for the observed facets, the uniform variates of the m hypotheses are stratified
  (one per m-quantile, shuffled per facet). Each d is still uniform marginally, but the
  m hypotheses cover the whole range, so their volumes are spread even for m = 16.
- Hull facets: coplanar hull triangles are grouped greedily (largest first) with their
  neighbours within ``hull_group_deg`` of the seed's normal; groups smaller than
  ``min_facet_area_m2`` are ignored like small observed facets. "Shares a normal" means within
  ``normal_merge_deg`` of an observed facet's normal, or of the normal (or its opposite) of a
  facet already mirrored: the mirror of a facet is the opposite face, so both directions are done.
- Scatter (``shrink_by_scatter``, opt-in): a hull takes the outermost of the points, and a
  sensor's points scatter about the surface (white noise per pixel on generated frames, which
  the perception's plane fit mostly removes; a smooth error over centimetres on real ones,
  which it cannot), so every face of a hull over them stands in front of the surface they
  scatter about, by about the depth of the median point inside it. The object's *scatter* is
  that depth, measured on its own points against their own convex hull; with the option every
  hypothesis (the minimum shape too) is shrunk by it, each face plane moved that far inwards,
  before it is set on the support and cut, so that its faces pass through the points' middle
  rather than their extremes (about half the observed points then lie outside it). The
  median is the central estimate of where the surface lies, not a tuned share; but on a
  concave or many-sided object the points' depth inside their hull is also its shape, and
  the shrink then takes real volume: off by default, it raised the best candidate on the real
  sets and lost the Collision Checker on generated ones and on the bins
  (docs/experiments/2026-11-28-hull-scatter.md).
- Resting on the support: a hull whose lowest point is within ``support_snap_m`` (2 cm) above
  the support is extended down to it (its bottom vertices projected onto the plane). The
  support's band removes an object's lowest centimetre of points with the table, so without
  this every standing object floats a few millimetres to a centimetre above its support and
  misses its bottom (docs/DESIGN_NOTES.md, "Shapes rest on the support they nearly touch").
- Unary constraints at generation (the checks of ``ipr_shapes.hypotheses.constraints`` with this module's
  tolerances): the hull is clipped at the support plane (exact, convex), so nothing is below it;
  voxels (the free-space grid's pitch) in seen-free space or inside a wall's slab may not exceed
  ``free_space_tolerance`` (share) or ``free_space_tolerance_voxels`` (count), whichever is larger,
  *beyond those the observed points already force* (the hull of a concave object such as a bowl
  covers seen-free space whatever is hidden). The voxel map calls everything within its surface
  margin (1 cm) of an observed surface occupied, so it cannot stop growth just in front of a facet;
  instead every hypothesis is cut at each observed facet's support plane (the object's outermost
  observed point along N, plus ``facet_tolerance_m``): for a convex object the point with normal N
  lies on that facet, so nothing of the object is in front of it; and at the bound beyond each
  side of the camera's view (above). A hypothesis that fails is
  resampled with its observed facets' variates halved each attempt (pulling d towards D_min), at
  most ``max_attempts`` times; if every attempt fails, the one with the fewest offending voxels is
  kept with ``feasible=False`` (logged) for the constraint stage to reject. When *no* hypothesis
  of the object passes, they are checked again with the seen-free voxels within the object's
  surface allowance excused (``ipr_shapes.hypotheses.allowance``; ``surface_allowance_quantile``):
  a real sensor's depth bent behind the true surface, measured on the object's own points
  (docs/DESIGN_NOTES.md, "A second seen-free check within the object's own surface allowance").
- Beyond the camera's view (``outside_view_ratio``): space outside the image is UNKNOWN to
  the free-space map, like space hidden behind a surface, but nothing there was ever in
  sight: no seen-free voxel, no surface, no support edge bounds it, and an object cut by the
  image border grew candidates of tens of litres into it (docs/experiments/
  2026-11-27-giant-candidates-real.md). The seen part is the only evidence there is, so the
  paper's own rule for the hidden is applied to the border: across each side of the view
  (the image border's plane through the camera centre, ``SpaceMap.view``) a hypothesis may
  reach past the side at most ``outside_view_ratio`` (1: the mirror image of the seen part
  about the border) times as far as the object's observed points reach inside it, and never
  less far than its observed points do. Each such side is a half-space every hypothesis is
  cut to (with the others below) and every ray stops at, like the support. An object far from
  the border reaches far inside, so its bound lies far outside and never binds.
- Beyond the support's seen extent (``outside_support_ratio``): the support plane is known
  everywhere, but the support itself was seen only within the outline of its seen points
  (their convex hull in the plane). Beyond it lies space the camera may never have seen (behind
  an object at the table's far edge, behind a bin's rim), where no support edge, wall or free
  voxel stops a ray: a piece of a bin's wall in full view grew 12-litre candidates into it
  (docs/experiments/2026-11-27-support-extent.md). The same mirror rule bounds it: across each
  side of the outline (a half-space across the support plane through a hull edge) a
  hypothesis reaches past the side at most ``outside_support_ratio`` (1) times as far as the
  object's observed points reach inside it, and never less far than they do. Where the
  camera saw that space, the seen-free voxels bound it first; an object well inside the
  outline is unchanged.
- Within the object's own silhouette (``silhouette_cut``; by default only for an object none
  of whose hypotheses passes the seen-free check, made again from the same draws): the rays
  through the pixels just beyond the object's outline saw the background behind it, so no
  part of the object lies on them in front of it; where the outline is the object's own, its
  hidden part projects inside the outline. Each side of the convex hull of the observed
  points as seen from the camera centre (a plane through the centre) is such a bound when the
  voxels just beyond its line, at the depth of the points on that side, are seen-free (all but
  ``ray_quantile`` of the probes along it, the rays' own share), over the silhouette's width
  and as far again beyond each end (the plane cuts beyond the side's segment too, where a
  neighbouring side may be hidden): the hypotheses are cut to it at the observed points'
  extent plus ``facet_tolerance_m`` (like an observed facet's outer plane); the hidden
  extent's rays do not stop at it (beyond it they meet the seen-free space anyway). A side a
  nearer surface, a missing reading or the image border hides bounds nothing. Without the cut
  a fitted box or superquadric whose corners leave the silhouette is only rejected (a bottle
  whose foot a box hides had no feasible candidate at all).
- Structure-aware candidates (``ipr_shapes.hypotheses.structure``; docs/DESIGN_NOTES.md,
  "Structure-aware candidates beside Algorithm 1"): ``structure_share`` of the m hypotheses
  (rounded) are made by the structure-aware generators that apply to the object, taking turns
  (symmetry, revolution, box, cylinder, sphere); Algorithm 1 makes the rest, and all of them
  when none applies. Each is labelled with its generator (``ShapeHypothesis.generator``), goes
  through the same hull, support snap, cuts and unary checks, and has two attempts: its
  variates, then the family's own fit with no hidden extension. With
  ``superquadric_count`` > 0 that many of them are superquadrics
  (``ipr_shapes.hypotheses.superquadric``; second attempt: its smallest variant) when the
  fit applies, and the other families take turns over the rest.
- Work and time: an object costs at most ``count * max_attempts * max_rounds`` rounds of
  Algorithm 1, so by default there is no wall-clock limit and the output is a function of the
  inputs and the rng alone, on any machine and under any load (docs/DESIGN_NOTES.md, "No
  wall-clock limit on hypothesis generation"). With ``timeout_s`` set (a run given a time budget
  sets it), the hypotheses left after ``timeout_s`` for an object use one round and one attempt
  (logged); output then depends on the machine's speed.
"""

from __future__ import annotations

import bisect
import copy
import dataclasses
import functools
import logging
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from scipy.spatial import ConvexHull, HalfspaceIntersection, QhullError

from ipr_shapes import voxels
from ipr_shapes.checks import Checks, Interval, Options, OrNone, Predicate, check_fields
from ipr_shapes.geometry.convex import (
    clip_halfspace,
    convex_mesh,
    row_norms,
    triangle_cross,
    unique_rows,
)
from ipr_shapes.hypotheses import allowance, structure, superquadric
from ipr_shapes.hypotheses.kernels import (
    first_state_samples,
    first_wall_samples,
    greedy_labels,
    hull_parts,
    outside_shares,
)
from ipr_shapes.perception.free_space import FREE, UNKNOWN, SeenSpace, SpaceMap
from ipr_shapes.perception.occupancy import PlaneRegion, allowed_voxels, plane_regions, unary_report
from ipr_shapes.perception.types import KnownPlane, PartialObject
from ipr_shapes.products import ShapeHypothesis, volume_spread

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class UnaryTolerances:
    """Tolerances of the unary constraints, for sensor noise (one object at a time).

    Attributes:
        free_space_tolerance: share of a shape's voxels allowed in seen-free space (frame 0's,
            or with ``ipr_shapes.fusion.TrackedFreeSpace`` later frames' too) or inside walls, beyond
            those its observed points' own hull has.
        free_space_tolerance_voxels: the same as a count; the larger of the two applies.
        support_tolerance_m: hypotheses are cut at the support plane, or at the lowest observed
            point when lower (every observed point stays inside); points more than this below
            the plane are logged as outliers, and a shape reaching further below is infeasible.
        wall_min_thickness_m: walls without a measured thickness are slabs this thick (m).
        surface_allowance_quantile: when none of an object's hypotheses passes the seen-free
            check, the seen-free voxels within its *surface allowance* of its own observed
            points are excused and its hypotheses checked again; the allowance is this quantile
            (0-1) of how deep its points lie inside their own convex hull, how far the sensor
            bent the measured surface behind a convex solid (``ipr_shapes.hypotheses.allowance``).
            None: no second check (an object with no feasible hypothesis keeps its minimum shape).
    """

    CHECKS: ClassVar[Checks] = {
        "free_space_tolerance": Interval(0, 1),
        "free_space_tolerance_voxels": Interval(0, None, integer=True),
        "support_tolerance_m": Interval(0, None),
        "wall_min_thickness_m": Interval(0, None),
        "surface_allowance_quantile": OrNone(Interval(0, 1)),
    }

    free_space_tolerance: float = 0.02
    free_space_tolerance_voxels: int = 20
    support_tolerance_m: float = 0.005
    wall_min_thickness_m: float = 0.005
    surface_allowance_quantile: float | None = 0.95

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class HypothesisConfig:
    """Settings of hypothesis generation (metres, square metres, degrees, seconds).

    Attributes:
        count: m, hypotheses per object (paper: 16-32).
        min_thickness_m: D_min, the smallest distance between a facet and its mirror image.
        max_depth_m: cap on D_max (rays stop here), about the largest object size.
        border_max_depth_m: the cap for objects cut by the image border.
        min_room_m: floor of d when a facet has no room (D_max below this).
        min_facet_area_m2: facets (observed or hull) smaller than this are not mirrored
            (paper: (3 cm)^2); their points stay in every hull.
        normal_merge_deg: a hull facet within this angle of a normal already handled is skipped.
        hull_group_deg: hull triangles within this angle of a group's seed triangle (and
            connected to it) form one hull facet.
        ray_quantile: share of a facet's rays (of each ray set) an admissible d may violate.
        max_rays: rays per observed facet (its points subsampled evenly).
        hull_facet_rays: rays per hull facet (points sampled on its triangles).
        max_hull_facets: new hull facets mirrored per round at most (the largest): curved
            outlines give a ring of narrow side facets, each a small change, all costing rays.
        hull_spacing_m: the hulls inside Algorithm 1's loop and the mirrored point clouds use
            one point per cell of this size (the final hull keeps every observed point).
        rim_width_m: observed facets' points this close to their outline form a second ray
            set that admissible d must satisfy too (0: no rim set).
        ray_step_m: spacing of the samples along rays (None: the space grid's pitch).
        max_rounds: rounds of Algorithm 1's repeat loop at most (mirroring, then hull).
        facet_tolerance_m: hypotheses are cut this far in front of each observed facet's
            outermost point along its normal (seen-free space the voxel map's surface margin
            cannot resolve).
        max_attempts: samples tried per hypothesis before keeping an infeasible one.
        support_snap_m: a hull whose lowest point is at most this far above the support is
            extended down to it (0: never), the minimum shape included. The points within
            ``PerceptionConfig.support.clearance_m`` (1 cm) of the support are removed with it,
            an object's lowest centimetre among them, so the observed points stop short of a
            support the object rests on.
        support_band_m: the hull's vertices within this height of its lowest one are the
            bottom projected onto the support.
        unary: tolerances of the unary constraints (support, seen-free space, walls), shared
            with ``ipr_shapes.hypotheses.constraints.unary_feasible`` so generation and checking
            agree.
        timeout_s: seconds per object before the remaining hypotheses are simplified; None
            (default): no wall-clock limit, so results do not depend on the machine's load.
        seed: seed used when no rng is given (combined with the object id).
        budget_share: share of a run's time budget given to generation (when a budget is
            given), split over the objects as their ``timeout_s``; inference gets the rest.
        structure_share: share of ``count`` made by the structure-aware generators (rounded;
            0: Algorithm 1 alone, as in the paper); the total stays ``count``.
        neighbour_surfaces: other objects' observed points stop the rays that bound each
            object's hidden extent (``prepare_hypotheses``; ``ipr_shapes.hypotheses.neighbours``);
            the unary checks still use the frame's free space alone. Off by default: it raises
            the best candidate but not the Collision Checker's choice (docs/DESIGN_NOTES.md,
            "Other objects' seen surfaces bound the hidden extent: opt-in").
        superquadric_count: of the structure-aware candidates, how many are superquadrics
            fitted to the observed points with the seen-free space kept out
            (``ipr_shapes.hypotheses.superquadric``) when the fit applies; the other
            structure-aware generators take turns over the rest (0: none, as before).
            Default 3: one smooth family with fitted exponents covers rounded boxes, cans and
            fruit that the exact families miss by a voxel or two; 3 of the 16 raised the best
            candidate by 0.009-0.013 and lost the Collision Checker nothing on any set, where 4
            lost 0.0015 on one development set and 2 did less (docs/DESIGN_NOTES.md,
            "Superquadric candidates"); costs about 0.06 s CPU per object (0.21 -> 0.27).
        fitted_revolution_axis: besides the support normal and the horizontal directions,
            the revolution and cylinder families try the axis the object's own surface
            normals meet (``structure.revolution_axis``): a can leaning on another object is
            a surface of revolution about a tilted axis, and a perceived facet spanning its
            lid and side hides it from the fixed axes. Off by default (opt-in): it completes
            leaning cans (development candidates' share 0.118 -> 0.111) but its candidates
            take slots from the symmetry and box families and lost 0.0007-0.0013 on the YCB
            suites (docs/DESIGN_NOTES.md, "Surfaces of revolution about the axis their
            normals meet: opt-in").
        revolution_radius: the radius of the cylinder's and of each slice of the revolution's
            rings about the fitted axis. ``"largest"`` (default): the largest distance of any
            point, which grows with every stray point (a silhouette's mixed pixels lie on the
            rim's rays behind the surface, so further from the axis): the cans' cylinders
            3.4 mm too wide on average, up to 12 mm. ``"wall_mean"`` (opt-in): the mean
            distance of the side wall's points (``structure._wall``), the least-squares
            radius of a circle about the fitted centre, which depth noise moves neither way;
            and the cylinder only where the slices' radii are one radius
            (``structure.constant_radius``: a ball's wall-mean cylinder is no shape of its).
            Raises the oracle on the YCB suites, ycbv-real and the development sets but the
            now better-fitting cylinders and revolutions move the Collision Checker's medoid
            (dev 9400 0.6744 -> 0.6712), so off by default
            (docs/experiments/2026-11-28-can-radius.md).
        outside_view_ratio: beyond each side of the camera's view (the image border's plane,
            ``SpaceMap.view``) a hypothesis reaches at most this multiple of how far the
            object's observed points reach inside that side (and at least as far as they do
            beyond it; module doc). Default 1: the mirror image of the seen part about the
            border, the paper's mirror rule applied where the image ends, not a tuned value;
            space outside the image is unknown and nothing else bounds it there (an object cut
            by the border grew 5-60 litre candidates, docs/experiments/
            2026-11-27-border-cut-extent.md). None: unbounded (before 2026-11-27); also
            unbounded for a space without a ``view``.
        outside_support_ratio: beyond each side of the support's seen outline (the convex
            hull of its seen points in its plane, ``KnownPlane.points``; each side a half-space
            across the plane) a hypothesis reaches at most this multiple of how far the
            object's observed points reach inside that side (and at least as far as they do
            beyond it; module doc). Default 1: the same mirror rule as ``outside_view_ratio``,
            not a tuned value; beyond the support's seen extent the camera saw no support, and
            what it did not see there (behind the object, behind a bin's rim) bounded nothing
            (docs/experiments/2026-11-27-support-extent.md). None: unbounded (before
            2026-11-27); also unbounded for a support with fewer than three seen points.
        silhouette_cut: cut hypotheses to the object's own silhouette cone: each side of the
            convex hull of its observed points seen from the camera (a plane through the
            camera centre) beyond which the camera saw free space at the object's depth
            (``_silhouette_bounds``; module doc); sides where a nearer surface, no reading or
            the image border hides what lies beyond are not cut. "fallback" (default): only
            for an object none of whose hypotheses passes the seen-free check (after the
            surface allowance), which are then made again, cut; "always": every object's;
            "off": never (before 2026-11-28). "always" raised the oracle on every set but the
            Collision Checker's choice among the larger feasible sets lost on two
            development sets and bins-real (docs/experiments/2026-11-28-silhouette-cut.md).
        shrink_by_scatter: every hypothesis (the minimum shape too) is shrunk by the object's
            *scatter*, the median depth of its observed points inside their own convex hull
            (``_scatter``), before it is set on the support and cut: a hull takes the outermost
            of the noisy points, so each of its faces stands about that far in front of the
            surface the points scatter about (module doc, "Scatter"). Off by default (opt-in):
            the depth also measures a concave object's shape, and the shrink lost the
            Collision Checker on generated scenes and the bins while raising the best
            candidate on the real sets (docs/DESIGN_NOTES.md, "Hulls shrunk by the points'
            scatter: opt-in").
    """

    CHECKS: ClassVar[Checks] = {
        "count": Interval(1, None, integer=True),
        "min_room_m": Interval(0, None, closed="neither"),
        "min_thickness_m": Interval(0, None, closed="neither"),
        "max_depth_m": Interval(0, None, closed="neither"),
        "border_max_depth_m": Interval(0, None, closed="neither"),
        ("min_room_m", "min_thickness_m", "max_depth_m"): Predicate(
            lambda v: v[0] <= v[1] <= v[2], "ordered: min_room_m <= min_thickness_m <= max_depth_m"
        ),
        "min_facet_area_m2": Interval(0, None),
        "normal_merge_deg": Interval(0, 180),
        "hull_group_deg": Interval(0, 180),
        "ray_quantile": Interval(0, 1),
        "ray_step_m": OrNone(Interval(0, None, closed="neither")),
        "rim_width_m": Interval(0, None),
        "max_rays": Interval(1, None, integer=True),
        "hull_facet_rays": Interval(1, None, integer=True),
        "max_hull_facets": Interval(0, None, integer=True),
        "hull_spacing_m": Interval(0, None, closed="neither"),
        "max_rounds": Interval(1, None, integer=True),
        "facet_tolerance_m": Interval(0, None),
        "max_attempts": Interval(1, None, integer=True),
        "support_snap_m": Interval(0, None),
        "support_band_m": Interval(0, None),
        "timeout_s": OrNone(Interval(0, None, closed="neither")),
        "seed": Interval(0, None, integer=True),
        "budget_share": Interval(0, 1, closed="neither"),
        "structure_share": Interval(0, 1),
        "neighbour_surfaces": Options(True, False),
        "superquadric_count": Interval(0, None, integer=True),
        "fitted_revolution_axis": Options(True, False),
        "revolution_radius": Options("wall_mean", "largest"),
        "outside_view_ratio": OrNone(Interval(0, None)),
        "outside_support_ratio": OrNone(Interval(0, None)),
        "silhouette_cut": Options("always", "fallback", "off"),
        "shrink_by_scatter": Options(True, False),
    }

    count: int = 32
    min_thickness_m: float = 0.02
    max_depth_m: float = 0.3
    border_max_depth_m: float = 0.5
    min_room_m: float = 0.005
    min_facet_area_m2: float = 0.03**2
    normal_merge_deg: float = 25.0
    hull_group_deg: float = 12.0
    ray_quantile: float = 0.1
    ray_step_m: float | None = None
    rim_width_m: float = 0.01
    max_rays: int = 96
    hull_facet_rays: int = 24
    max_hull_facets: int = 8
    hull_spacing_m: float = 0.01
    max_rounds: int = 4
    facet_tolerance_m: float = 0.002
    unary: UnaryTolerances = field(default_factory=UnaryTolerances)
    max_attempts: int = 4
    support_snap_m: float = 0.02
    support_band_m: float = 0.01
    timeout_s: float | None = None
    seed: int = 0
    budget_share: float = 0.6
    structure_share: float = 0.5
    neighbour_surfaces: bool = False
    superquadric_count: int = 3
    fitted_revolution_axis: bool = False
    revolution_radius: str = "largest"
    outside_view_ratio: float | None = 1.0
    outside_support_ratio: float | None = 1.0
    silhouette_cut: str = "fallback"
    shrink_by_scatter: bool = False

    def __post_init__(self) -> None:
        check_fields(self)


# --------------------------------------------------------------------------------------------
# Known planes: the support as a half-space, walls as slabs bounded by their points' outline


# --------------------------------------------------------------------------------------------
# Convex hull meshes


def _thicken(points: np.ndarray, direction: np.ndarray, thickness_m: float) -> np.ndarray:
    """Points (M, 3) that span a volume: ``points`` plus a copy ``thickness_m`` along
    -``direction``; if that is still flat (points collinear, or in a plane containing
    ``direction``), also copies +-``thickness_m``/2 along the two directions across it."""
    thick = np.concatenate([points, points - thickness_m * direction])
    if convex_mesh(thick) is not None:
        return thick
    across = points - points.mean(axis=0)
    across -= np.outer(across @ direction, direction)
    if np.abs(across).max(initial=0.0) > 1e-12:
        second = np.linalg.svd(across, full_matrices=False)[2][0]
    else:
        second = np.cross(direction, np.eye(3)[int(np.argmin(np.abs(direction)))])
    second /= np.linalg.norm(second)
    third = np.cross(direction, second)
    half = 0.5 * thickness_m
    offsets = [half * second, -half * second, half * third, -half * third]
    return np.concatenate([thick, *(thick + offset for offset in offsets)])


def _thin(points: np.ndarray, spacing_m: float) -> np.ndarray:
    """One point (the first) per cubic cell of ``spacing_m`` (fewer, coarser hull vertices)."""
    if spacing_m <= 0 or len(points) < 64:
        return points
    cells = np.floor(points / spacing_m).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)
    return points[np.sort(first)]


def _extreme_points(points: np.ndarray) -> np.ndarray:
    """The points that matter for hulls: 3-D hull vertices, or all points when flat."""
    if len(points) < 5:
        return points
    try:
        return points[ConvexHull(points).vertices]
    except (QhullError, ValueError):
        return points


#: The last object's observed points (as a key) and their hull vertices (``_observed_extremes``).
_LAST_EXTREMES: list[tuple[tuple, np.ndarray]] = [((), np.zeros((0, 3)))]


def _observed_extremes(points: np.ndarray) -> np.ndarray:
    """``_extreme_points`` of an object's observed points, remembered for the next call with
    the same points: ``prepare_hypotheses`` asks for them twice per object (its hypotheses'
    set-up, then its minimum shape), and their hull is the largest one of the set-up. A copy
    (safe across threads: the entry is read and replaced whole)."""
    key = (points.shape, points.dtype.str, points.tobytes())
    entry = _LAST_EXTREMES[0]
    if entry[0] != key:
        entry = (key, _extreme_points(points))
        _LAST_EXTREMES[0] = entry
    return entry[1].copy()


#: The last planes (kept alive, so that their ids stay theirs), their key and their regions.
_LAST_REGIONS: list[tuple[tuple, tuple, tuple[PlaneRegion, ...]]] = [((), (), ())]


def _plane_regions(planes: tuple[KnownPlane, ...], thickness_m: float) -> tuple[PlaneRegion, ...]:
    """``plane_regions(planes, thickness_m)``, remembered for the next call with the same plane
    objects: every object's set-up and minimum shape ask for the frame's regions again, and a
    wall's outline is a hull of all its points (4 ms a call on ycb-static). The regions are
    read-only and a function of the planes alone; sharing them also lets ``_wall_arrays``
    (keyed by identity) serve every object of a frame. Safe across threads (the entry is
    read and replaced whole)."""
    key = (tuple(map(id, planes)), float(thickness_m))
    entry = _LAST_REGIONS[0]
    if entry[0] != key:
        planes = tuple(planes)
        entry = (key, planes, plane_regions(planes, thickness_m))
        _LAST_REGIONS[0] = entry
    return entry[2]


#: The last observed hull vertices (as a key) and their mesh (``_observed_hull``).
_LAST_HULL: list[tuple[tuple, tuple | None]] = [((), None)]


def _observed_hull(base: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """``convex_mesh(base)`` of an object's observed hull vertices, remembered for the next
    call with the same points: the set-up measures it, then the minimum shape tests and
    finishes the same hull. Copies (the caller may keep them)."""
    key = (base.shape, base.dtype.str, base.tobytes())
    entry = _LAST_HULL[0]
    if entry[0] != key:
        entry = (key, convex_mesh(base))
        _LAST_HULL[0] = entry
    mesh = entry[1]
    return None if mesh is None else (mesh[0].copy(), mesh[1].copy(), mesh[2])


# --------------------------------------------------------------------------------------------
# Generation


@dataclass(frozen=True, eq=False)
class _SourceFacet:
    """A facet to mirror: unit normal (3,), centre (3,), points to mirror (K, 3), and the d its
    rays allow: the union of cells [c, c + width) for the lower edges ``cells`` (C,), metres
    (``_admissible``); ``conflict`` when no d satisfies enough rays (the best compromise)."""

    normal: np.ndarray
    centre: np.ndarray
    points: np.ndarray
    cells: np.ndarray
    width: float
    source: str
    conflict: bool = False
    #: ``_distance``'s tables per D_min (an observed facet serves every hypothesis).
    tables: dict = field(default_factory=dict, repr=False)

    @property
    def d_max(self) -> float:
        """Largest admissible d (m): D_max."""
        return float(self.cells.max()) + self.width if self.cells.size else 0.0


@dataclass(frozen=True, eq=False)
class _Context:
    """Everything per object that does not change between hypotheses.

    ``base_points`` are the observed points that matter for hulls (exact), ``loop_points`` the
    same thinned to one per ``hull_spacing_m`` cell for the hulls inside Algorithm 1's loop.
    ``cuts`` (C, 4) are half-spaces n . x + offset >= 0 every hypothesis is cut to: the support
    planes (lowered to the lowest observed point), the observed facets' support planes and the
    bounds beyond the camera's view and the support's seen outline; ``stops`` (S, 4) are the
    last of these, which the hidden extent's rays also stop at (``_view_bounds``,
    ``_support_bounds``).
    """

    object_id: int
    base_points: np.ndarray
    loop_points: np.ndarray
    observed: tuple[_SourceFacet, ...]
    space: SeenSpace | None
    regions: tuple[PlaneRegion, ...]
    cuts: np.ndarray
    cap_m: float
    fallback_normal: np.ndarray
    forced_free: int
    forced_wall: int
    pitch_m: float
    config: HypothesisConfig
    rays: SeenSpace | None = None  # the space hidden-extent rays stop in (``bounds``)
    stops: np.ndarray | None = None  # half-spaces (S, 4) rays stop at leaving (``_view_bounds``)
    shrink_m: float = 0.0  # every hull is shrunk by this before the snap and cuts (``_scatter``)


def dominant_normal(obj: PartialObject, planes: tuple[KnownPlane, ...]) -> np.ndarray:
    """(3,) unit direction towards the camera side of the object: area-weighted mean facet normal,
    else the points' least-spread axis oriented along the support normal (else +z)."""
    up = np.array([0.0, 0.0, 1.0])
    for plane in planes:
        if plane.kind == "support":
            up = np.asarray(plane.normal, float)
            break
    if obj.facets:
        total = sum(f.area_m2 * np.asarray(f.normal, float) for f in obj.facets)
        norm = float(np.linalg.norm(total))
        if norm > 1e-9:
            return total / norm
    points = np.asarray(obj.points, float)
    if len(points) >= 3:
        _, _, vt = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)
        normal = vt[-1]
        return normal if normal @ up >= 0 else -normal
    return up


def _ray_limits(
    origins: np.ndarray,
    normal: np.ndarray,
    space: SeenSpace | None,
    regions: tuple[PlaneRegion, ...],
    cap: float,
    step: float,
    stops: np.ndarray | None = None,
) -> np.ndarray:
    """Distance (R,) from each origin (R, 3) along -``normal`` to the first blocked point, at
    most ``cap`` (m): a voxel seen FREE (sampled every ``step``), the support plane (exact), a
    wall's slab, or leaving one of the half-spaces ``stops`` (S, 4) n . x + b >= 0 (exact)."""
    direction = -normal
    limits = np.full(len(origins), cap)
    if stops is not None:
        for stop in stops:
            rate = float(direction @ stop[:3])  # d(n . x + b) / dt
            if rate < -1e-9:
                reach = (origins @ stop[:3] + stop[3]) / -rate
                limits = np.minimum(limits, np.maximum(reach, 0.0))
    for region in regions:
        if region.is_support:
            rate = float(direction @ region.plane.normal)  # d(signed distance) / dt
            if rate < -1e-9:
                reach = region.plane.signed_distance(origins) / -rate
                limits = np.minimum(limits, np.maximum(reach, 0.0))
    walls = [r for r in regions if not r.is_support]
    if space is None and not walls:
        return limits
    t = _ray_samples(cap, step)
    # Index of each ray's first blocked sample (len(t): none). On a ``SpaceMap`` a compiled
    # loop marches each ray and stops at its first free voxel (the same voxels, same bits).
    samples = None
    if isinstance(space, SpaceMap):
        first = first_state_samples(
            np.ascontiguousarray(origins, dtype=float),
            np.ascontiguousarray(direction, dtype=float),
            t,
            np.asarray(space.grid.origin, float),
            float(space.grid.voxel_size_m),
            space.state,
            FREE,
        )
    elif space is not None:
        samples = (origins[:, None, :] + t[None, :, None] * direction).reshape(-1, 3)
        first = _first_true((space.state_at(samples) == FREE).reshape(len(origins), len(t)))
    else:
        first = np.full(len(origins), len(t), dtype=np.int64)
    if walls:
        in_walls = None
        if samples is None:
            # Compiled too, up to each ray's first free sample; numpy's path when a sample is
            # too close to a wall's boundary to be certain of numpy's answer.
            in_walls, certain = first_wall_samples(
                np.ascontiguousarray(origins, dtype=float),
                np.ascontiguousarray(direction, dtype=float),
                t,
                first,
                *_wall_arrays(tuple(walls)),
                _CERTAIN_BAND,
            )
            if not certain:
                in_walls = None
                samples = (origins[:, None, :] + t[None, :, None] * direction).reshape(-1, 3)
        if in_walls is None:
            in_wall = np.zeros(len(samples), dtype=bool)
            for region in walls:
                in_wall |= region.in_wall(samples)
            in_walls = _first_true(in_wall.reshape(len(origins), len(t)))
        first = np.minimum(first, in_walls)
    hit = first < len(t)
    sampled = np.where(hit, t[np.minimum(first, len(t) - 1)] - 0.5 * step, cap)
    return np.minimum(limits, sampled)


@functools.lru_cache(maxsize=16)
def _ray_samples(cap: float, step: float) -> np.ndarray:
    """Distances (T,) m of a ray's samples: every ``step`` up to ``cap`` (``_ray_limits``),
    the same for every ray of a frame; remembered, read-only."""
    t = (np.arange(int(np.ceil(cap / step))) + 1.0) * step
    t.setflags(write=False)
    return t


@functools.lru_cache(maxsize=16)
def _wall_arrays(walls: tuple[PlaneRegion, ...]) -> tuple[np.ndarray, ...]:
    """The walls as ``kernels.first_wall_samples`` takes them: normals (W, 3), offsets (W,),
    thicknesses (W,), in-plane axes (W, 2, 3), stacked outlines (E, 3) and their starts
    (W + 1,); remembered per walls (regions compare by identity)."""
    outlines = [r.outline if r.outline is not None else np.zeros((0, 3)) for r in walls]
    return (
        np.array([np.asarray(r.plane.normal, float) for r in walls]).reshape(-1, 3),
        np.array([float(r.plane.offset) for r in walls]),
        np.array([float(r.thickness_m) for r in walls]),
        np.array([r.axes for r in walls], dtype=float).reshape(-1, 2, 3),
        np.ascontiguousarray(np.concatenate(outlines), dtype=float).reshape(-1, 3),
        np.concatenate([[0], np.cumsum([len(o) for o in outlines])]).astype(np.int64),
    )


def _first_true(blocked: np.ndarray) -> np.ndarray:
    """Per row of (R, T) bool, the index (R,) of its first True, T when it has none."""
    first = np.argmax(blocked, axis=1)
    return np.where(blocked[np.arange(len(blocked)), first], first, blocked.shape[1])


def _ray_bounds(
    ray_points: np.ndarray, centre: np.ndarray, normal: np.ndarray, ctx_parts: tuple
) -> tuple[np.ndarray, np.ndarray]:
    """Per ray, the range (low (R,), high (R,)) of d that keeps the mirror of its point p in
    hidden space: the mirror lands t = 2 N.(p - c) + d behind p, and 0 <= t <= limit(p)."""
    space, regions, cap, step, stops = ctx_parts
    limits = _ray_limits(ray_points, normal, space, regions, cap, step, stops)
    offsets = 2.0 * (ray_points - centre) @ normal
    return -offsets, limits - offsets


def _admissible(
    ray_sets: list[tuple[np.ndarray, np.ndarray]], tolerance: float, step: float
) -> tuple[np.ndarray, bool]:
    """Lower edges (C,) of the cells of width ``step`` (from d = 0) whose centre violates at
    most a ``tolerance`` share of the rays of every set, and whether none did (then the cells
    with the fewest violations are returned: a compromise)."""
    highs = [high for _, high in ray_sets if high.size]
    top = max(float(max(h.max() for h in highs)), step) if highs else step
    centres = np.arange(0.0, top + step, step) + 0.5 * step
    worst = np.zeros(len(centres))
    for low, high in ray_sets:
        if low.size:
            # The share of rays each centre violates, compiled (``kernels.outside_shares``:
            # numpy's ``outside.mean(axis=1)`` is a count over R, the same bits).
            shares = outside_shares(
                centres, np.ascontiguousarray(low, float), np.ascontiguousarray(high, float)
            )
            worst = np.maximum(worst, shares)
    good = worst <= tolerance
    conflict = not good.any()
    if conflict:
        good = worst <= worst.min() + 1e-12
    return centres[good] - 0.5 * step, conflict


def _support_cuts(
    regions: tuple[PlaneRegion, ...],
    points: np.ndarray,
    tolerance_m: float = np.inf,
    object_id: int = -1,
) -> list[np.ndarray]:
    """Half-spaces (4,) n . x + offset >= 0 above each support plane, lowered to the lowest
    observed point (noisy points slightly below the plane are never cut off); points more than
    ``tolerance_m`` below it are logged (segmentation outliers: the hull then reaches down)."""
    cuts = []
    for region in regions:
        if region.is_support:
            lowest = float(region.plane.signed_distance(points).min())
            if lowest < -tolerance_m:
                logger.info(
                    "object %d: observed points %.1f mm below the support; hypotheses reach there",
                    object_id,
                    -lowest * 1e3,
                )
            level = min(0.0, lowest) - 1e-9
            cuts.append(np.append(region.plane.normal, region.plane.offset - level))
    return cuts


def _rim_points(points: np.ndarray, normal: np.ndarray, width_m: float) -> np.ndarray:
    """The points (K, 3) within ``width_m`` of the outline of their projection on the plane
    across ``normal`` (empty when the projection is degenerate or ``width_m`` <= 0)."""
    if width_m <= 0 or len(points) < 8:
        return points[:0]
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    flat = np.column_stack([points @ u, points @ np.cross(normal, u)])
    try:
        outline = ConvexHull(flat).equations
    except (QhullError, ValueError):
        return points[:0]
    depth = -(flat @ outline[:, :2].T + outline[:, 2]).max(axis=1)  # distance inside
    return points[depth <= width_m]


def _even_subsample(points: np.ndarray, count: int) -> np.ndarray:
    """At most ``count`` points taken evenly (deterministic) from (N, 3) points."""
    if len(points) <= count:
        return points
    return points[np.linspace(0, len(points) - 1, count).round().astype(np.int64)]


def _prepare(
    obj: PartialObject,
    space: SeenSpace | None,
    planes: tuple[KnownPlane, ...],
    config: HypothesisConfig,
    bounds: SeenSpace | None = None,
    silhouette: bool = False,
) -> _Context:
    """Per-object set-up: observed facets to mirror with their D_max, clip levels, baselines;
    rays stop in ``bounds`` (default: ``space``); with ``silhouette`` the clip levels include
    the object's own silhouette sides (``_silhouette_bounds``)."""
    points = np.asarray(obj.points, float).reshape(-1, 3)
    points = points[np.all(np.isfinite(points), axis=1)]
    if len(points) == 0:
        raise ValueError(f"object {obj.id} has no finite observed point")
    regions = _plane_regions(planes, config.unary.wall_min_thickness_m)
    cap = config.border_max_depth_m if obj.touches_border else config.max_depth_m
    pitch = space.grid.voxel_size_m if space is not None else voxels.DEFAULT_PITCH_M
    step = config.ray_step_m or pitch
    rays = bounds if bounds is not None else space
    stops = _view_bounds(points, space, config.outside_view_ratio)
    sides = _support_bounds(points, regions, config.outside_support_ratio)
    if len(sides):
        stops = np.concatenate([stops, sides])
    ray_parts = (rays, regions, cap, step, stops)
    fallback = dominant_normal(obj, planes)

    used = [
        f
        for f in obj.facets
        if f.area_m2 >= config.min_facet_area_m2
        and np.isfinite(f.normal).all()
        and np.linalg.norm(f.normal) > 1e-9
        and np.isfinite(np.asarray(f.points, float)).all(axis=-1).any()
    ]
    if len(used) < len(obj.facets):
        logger.debug(
            "object %d: %d of %d facets are below %.1f cm^2 and are not mirrored",
            obj.id,
            len(obj.facets) - len(used),
            len(obj.facets),
            config.min_facet_area_m2 * 1e4,
        )
    sources = []
    for f in used:
        facet_points = np.asarray(f.points, float).reshape(-1, 3)
        facet_points = facet_points[np.all(np.isfinite(facet_points), axis=1)]
        sources.append((np.asarray(f.normal, float), facet_points, "observed"))
    if not sources:
        logger.info(
            "object %d: no facet of at least %.1f cm^2; mirroring all its points as one facet",
            obj.id,
            config.min_facet_area_m2 * 1e4,
        )
        sources = [(fallback, points, "object")]
    observed = []
    for normal, facet_points, source in sources:
        normal = normal / np.linalg.norm(normal)
        centre = facet_points.mean(axis=0)
        ray_sets = [
            _ray_bounds(_even_subsample(facet_points, config.max_rays), centre, normal, ray_parts)
        ]
        rim = _rim_points(facet_points, normal, config.rim_width_m)
        if len(rim):
            # The outline's rays decide whether the mirror leaves the silhouette (module doc).
            ray_sets.append(
                _ray_bounds(_even_subsample(rim, config.max_rays), centre, normal, ray_parts)
            )
        cells, conflict = _admissible(ray_sets, config.ray_quantile, step)
        d_max = float(cells.max()) + step
        if conflict:
            logger.info(
                "object %d: no shift of a %s facet keeps its mirror out of seen-free space; "
                "using the least violating (%.1f-%.1f mm)",
                obj.id,
                source,
                cells.min() * 1e3,
                d_max * 1e3,
            )
        elif d_max < config.min_room_m:
            logger.info(
                "object %d: a %s facet has no room behind it (D_max %.1f mm); d = %.1f mm",
                obj.id,
                source,
                d_max * 1e3,
                config.min_room_m * 1e3,
            )
        elif d_max < config.min_thickness_m:
            logger.debug("object %d: facet thinner than D_min (D_max %.1f mm)", obj.id, d_max * 1e3)
        mirror_points = _thin(_extreme_points(facet_points), config.hull_spacing_m)
        observed.append(_SourceFacet(normal, centre, mirror_points, cells, step, source, conflict))

    cuts = _support_cuts(regions, points, config.unary.support_tolerance_m, obj.id)
    for facet in observed:
        if facet.source == "observed":
            # An observed facet is the object's extreme part along its normal N (for a convex
            # object the point with normal N lies on it): nothing is in front of it. The reach
            # is taken over all observed points, so that a non-convex object's other parts
            # (a handle beyond a curved side's plane) are never cut off.
            reach = float((points @ facet.normal).max()) + config.facet_tolerance_m
            cuts.append(np.append(-facet.normal, reach))
    cuts.extend(stops)
    if silhouette:
        # Cuts only: a ray leaving the silhouette meets seen-free space beyond it anyway (the
        # unknown band next to the outline is the free-space map's footprint, not room).
        sides = _silhouette_bounds(points, space, config.ray_quantile, pitch, regions)
        sides[:, 3] += config.facet_tolerance_m
        cuts.extend(sides)
    forced_free = forced_wall = 0
    base = _observed_extremes(points)
    observed_hull = _observed_hull(base)
    if observed_hull is not None and (space is not None or any(not r.is_support for r in regions)):
        keys = voxels.scanline_voxels(observed_hull[0], observed_hull[1], pitch)
        report = unary_report(observed_hull[0], keys, pitch, space, regions)
        forced_free, forced_wall = report.free_voxels, report.wall_voxels
        if forced_free or forced_wall:
            logger.debug(
                "object %d: its observed hull already has %d free and %d wall voxels",
                obj.id,
                forced_free,
                forced_wall,
            )
    return _Context(
        obj.id,
        base,
        _thin(base, config.hull_spacing_m),
        tuple(observed),
        space,
        regions,
        np.array(cuts).reshape(-1, 4),
        cap,
        fallback,
        forced_free,
        forced_wall,
        pitch,
        config,
        rays,
        stops,
        _scatter(points, base, observed_hull) if config.shrink_by_scatter else 0.0,
    )


#: Scatter below this (m) is rounding (points exactly on planes), far below any depth sensor's
#: resolution; shrinking by it would only make sliver faces.
MIN_SCATTER_M = 1e-6

#: The last object's points and hull vertices (as a key) and their median depth (``_scatter``):
#: the set-up and the minimum shape ask for it in turn. Safe across threads (read and replaced
#: whole).
_LAST_SCATTER: list[tuple[tuple, float]] = [((), 0.0)]


def _scatter(
    points: np.ndarray,
    base: np.ndarray,
    hull: tuple[np.ndarray, np.ndarray, float] | None,
) -> float:
    """The object's scatter (m, >= 0): the median depth of its observed points (N, 3) inside
    their convex hull (``base``, its vertices; ``hull``, its mesh or None when flat). A convex
    object's points all lie on the boundary of their hull when measured exactly; with noise the
    hull's faces pass through the outermost points and the median point lies this far inside
    every face (module doc, "Scatter"). 0 for a flat hull."""
    if hull is None:
        return 0.0
    key = (points.shape, points.tobytes(), base.tobytes())
    entry = _LAST_SCATTER[0]
    if entry[0] != key:
        entry = (key, allowance.surface_allowance(points, 0.5, base))
        _LAST_SCATTER[0] = entry
    depth = entry[1]
    # Below a micrometre the depth is the hull's rounding, not a measurement's scatter.
    return depth if depth >= MIN_SCATTER_M else 0.0


def _shrunk(
    mesh: tuple[np.ndarray, np.ndarray, float], shrink_m: float, interior: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The convex mesh with every face plane moved ``shrink_m`` (m) inwards (qhull's half-space
    intersection about ``interior``, a point that must stay strictly inside); None when the
    shrunk shape would not hold ``interior`` or qhull fails (the caller keeps the mesh)."""
    halfspaces = _face_halfspaces(mesh)
    halfspaces[:, 3] += shrink_m
    corners = _halfspace_corners(halfspaces, interior)
    if corners is None:
        return None
    # A noisy hull's many near-coplanar planes meet in clusters of corners a few micrometres
    # to nanometres apart, which would multiply the mesh's vertices for every later step:
    # merged on a 0.1 mm grid (far below a voxel and the sensors' depth steps), else finer,
    # whichever first leaves no sliver face that other vertices cross by more than rounding.
    for decimals in (4, 6, 8):
        result = convex_mesh(unique_rows(np.round(corners, decimals)))
        if result is not None and _is_convex(result):
            return result
    return None


def _face_halfspaces(mesh: tuple[np.ndarray, np.ndarray, float]) -> np.ndarray:
    """(F, 4) rows (n, b) of a convex mesh's face planes, n . x + b <= 0 inside (n unit, m;
    one row per non-degenerate triangle, coplanar triangles repeating their plane)."""
    vertices, faces, _ = mesh
    tri = vertices[faces]
    normals = triangle_cross(tri)
    lengths = row_norms(normals)
    keep = lengths > 1e-12
    normals = normals[keep] / lengths[keep, None]
    return np.column_stack([normals, -np.einsum("ij,ij->i", normals, tri[keep, 0])])


def _halfspace_corners(halfspaces: np.ndarray, interior: np.ndarray) -> np.ndarray | None:
    """(K, 3) corners of the intersection of ``halfspaces`` (H, 4) rows (a, b), a . x + b <= 0
    inside, about ``interior`` (3,) (qhull); rows rounded to 1e-9 and made unique first, so
    that coplanar triangles give one plane. None when ``interior`` is not strictly inside or
    qhull fails."""
    halfspaces = unique_rows(np.round(halfspaces, 9))  # np.unique(axis=0), the same rows
    if float((halfspaces[:, :3] @ interior + halfspaces[:, 3]).max()) >= -1e-7:
        return None
    try:
        return HalfspaceIntersection(halfspaces, interior).intersections
    except (QhullError, ValueError):
        return None


def _is_convex(mesh: tuple[np.ndarray, np.ndarray, float]) -> bool:
    """Whether no vertex of a mesh lies beyond one of its face planes by more than rounding
    (1e-9 of its extent)."""
    vertices, faces, _ = mesh
    tri = vertices[faces]
    normals = triangle_cross(tri)
    lengths = row_norms(normals)
    keep = lengths > 1e-15
    normals = normals[keep] / lengths[keep, None]
    excess = vertices @ normals.T - np.einsum("ij,ij->i", normals, tri[keep, 0])
    return float(excess.max()) <= 1e-9 * float(np.ptp(vertices, axis=0).max())


def _view_bounds(points: np.ndarray, space: SeenSpace | None, ratio: float | None) -> np.ndarray:
    """Half-spaces (S, 4) n . x + b >= 0 bounding an object beyond the camera's view (module
    doc): per side (n, b) of ``space``'s ``view`` (unit n into the view, so n . p + b is a
    point's distance inside that side, m), the observed points (N, 3) reach s_max inside and
    s_min at least; a hypothesis may reach ``ratio`` * s_max beyond it, or s_min when lower.
    Empty without a view or a ratio."""
    view = getattr(space, "view", None) if ratio is not None else None
    if view is None or len(points) == 0:
        return np.zeros((0, 4))
    return _mirror_levels(points, np.asarray(view, float).reshape(-1, 4), ratio)


def _camera_centre(view: np.ndarray) -> np.ndarray | None:
    """The point (3,) all of a view's side planes (S, 4) pass through (m, world; least squares),
    None when they do not meet in one point (fewer than three independent sides)."""
    normals, offsets = view[:, :3], view[:, 3]
    if np.linalg.matrix_rank(normals) < 3:
        return None
    centre, *_ = np.linalg.lstsq(normals, -offsets, rcond=None)
    return centre


#: The voxels beyond a silhouette side each probe looks at (one after another outwards: the
#: min-filter windows of the free-space map span up to about two footprints,
#: ``ipr_shapes.perception.free_space``).
_PROBE_STEPS = 4


def _silhouette_bounds(
    points: np.ndarray,
    space: SeenSpace | None,
    tolerance: float,
    pitch: float,
    regions: tuple[PlaneRegion, ...] = (),
) -> np.ndarray:
    """Half-spaces (S, 4) n . x + b >= 0 (unit n inwards, m) through the camera centre along the
    sides of the object's silhouette cone that are its own outline (module doc): the convex hull
    of the observed points (N, 3) in the central projection about their mean viewing direction.
    A side cuts the whole plane through it, not only its segment, so it is checked along its
    line over the silhouette's width along it and as far again beyond each end (the mirror
    rule's reach, as beyond the image border): a probe every ``pitch`` (at the depth of the
    side's nearer end), each looking outwards 1-4 voxels beyond the line to the first voxel
    that is not unknown; the side bounds when at most a ``tolerance`` share of the probes see
    no seen-free voxel and lie above the support planes of ``regions`` (below the support no
    object can be either; a nearer surface, no reading or the image border hide the rest).
    Sides finer than a voxel are dropped (``_fewer_sides``); b places each side at the points'
    own extent. Empty without a view (no camera centre) or a hull."""
    view = getattr(space, "view", None)
    if view is None or len(points) < 3:
        return np.zeros((0, 4))
    centre = _camera_centre(np.asarray(view, float).reshape(-1, 4))
    if centre is None:
        return np.zeros((0, 4))
    rays = points - centre
    lengths = row_norms(rays)
    if not (lengths > 0).all():
        return np.zeros((0, 4))
    axis = (rays / lengths[:, None]).mean(axis=0)
    axis /= np.linalg.norm(axis)
    u = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    depth = rays @ axis
    if not (depth > 0).all():
        return np.zeros((0, 4))
    flat = np.column_stack([rays @ u, rays @ v]) / depth[:, None]
    try:
        hull = ConvexHull(flat)
    except (QhullError, ValueError):
        return np.zeros((0, 4))
    sides = []
    for (i, j), (a, b, c) in zip(hull.simplices, hull.equations, strict=True):
        # a s + b t + c <= 0 inside, (a, b) unit: outward in the projection; e along the side.
        e = np.array([-b, a])
        along = flat @ e
        low, high = float(along.min()), float(along.max())
        z = float(min(depth[i], depth[j]))
        step = pitch / z
        width = high - low
        offsets = np.arange(low - width, high + width + step, step)
        foot = flat[i] + (offsets - float(flat[i] @ e))[:, None] * e
        # A voxel is seen-free only when its whole footprint (a min-filter window about its
        # centre pixel) saw past it, so the voxels next to the outline are unknown: a probe
        # is free when the first of the voxels 1-4 pitches beyond the line that is not unknown
        # is seen-free or below the support (a seen surface there, as the object's own foot
        # the support band took, is not).
        free = np.zeros(len(offsets), dtype=bool)
        open_ = np.ones(len(offsets), dtype=bool)
        for steps in range(1, _PROBE_STEPS + 1):
            beyond = foot + steps * step * np.array([a, b])
            probes = centre + z * (axis + beyond[:, :1] * u + beyond[:, 1:] * v)
            state = space.state_at(probes)
            below = np.zeros(len(offsets), dtype=bool)
            for region in regions:
                if region.is_support:
                    below |= region.plane.signed_distance(probes) < 0
            free |= open_ & ((state == FREE) | below)
            open_ &= (state == UNKNOWN) & ~below
        if (~free).mean() > tolerance:
            continue
        sides.append((a, b, c, step))
    lines = _fewer_sides(np.array(sides).reshape(-1, 4))
    bounds = []
    for a, b, c in lines[:, :3]:
        # (x - centre) . (a u + b v + c axis) <= 0 inside (multiplied by the depth > 0).
        normal = -(a * u + b * v + c * axis)
        normal /= np.linalg.norm(normal)
        offset = -float(normal @ centre)
        offset -= min(float((points @ normal).min() + offset), 0.0)
        bounds.append(np.append(normal, offset))
    return np.array(bounds).reshape(-1, 4)


def _fewer_sides(lines: np.ndarray) -> np.ndarray:
    """The silhouette's kept sides (S, 4) rows (a, b, c, step): a s + b t + c <= 0 inside in the
    central projection, (a, b) unit, ``step`` one voxel there; without the sides whose removal
    lets the polygon of the others grow by at most one voxel beyond all of them (their two
    neighbours meet within it), fewest growth first. Every side is one more plane every
    hypothesis is cut by; a cut finer than the voxel grid changes no voxel the checks count."""
    lines = lines[np.argsort(np.arctan2(lines[:, 1], lines[:, 0]), kind="stable")]
    original = lines
    while len(lines) > 3:
        best, best_growth = -1, np.inf
        for k in range(len(lines)):
            p, q = lines[k - 1], lines[(k + 1) % len(lines)]
            det = p[0] * q[1] - p[1] * q[0]
            if det <= 1e-12:  # the neighbours do not close a corner beyond this side
                continue
            apex = np.linalg.solve(np.array([p[:2], q[:2]]), -np.array([p[2], q[2]]))
            growth = float((original[:, :2] @ apex + original[:, 2]).max())
            if growth <= lines[k, 3] and growth < best_growth:
                best, best_growth = k, growth
        if best < 0:
            break
        lines = np.delete(lines, best, axis=0)
    return lines


def _mirror_levels(points: np.ndarray, sides: np.ndarray, ratio: float) -> np.ndarray:
    """Half-spaces (S, 4) n . x + b >= 0 bounding (N, 3) observed points beyond each side
    (n, b) of ``sides`` (S, 4) (unit n inwards, so n . p + b is a point's distance inside,
    m): the points reach s_max inside and s_min at least, and a hypothesis may reach
    ``ratio`` * s_max beyond the side, or s_min when lower (the seen part's mirror image
    about the side, never less than the seen part itself)."""
    inside = points @ sides[:, :3].T + sides[:, 3]  # (N, S) distances inside each side
    level = np.minimum(inside.min(axis=0), -ratio * np.maximum(inside.max(axis=0), 0.0))
    return np.column_stack([sides[:, :3], sides[:, 3] - level])


@functools.lru_cache(maxsize=8)
def _support_sides(region: PlaneRegion) -> np.ndarray:
    """The sides (F, 4) n . x + b >= 0 of the support's seen outline (unit n in the plane,
    pointing inwards; m): the convex hull of its seen points (``KnownPlane.points``) in the
    plane's axes, each hull edge a half-space across the plane. Empty when the points span
    no area. Remembered per region (regions are shared per frame, ``_plane_regions``)."""
    points = np.asarray(region.plane.points, float).reshape(-1, 3)
    points = points[np.all(np.isfinite(points), axis=1)]
    sides = np.zeros((0, 4))
    if len(points) >= 3:
        try:
            # 2-D rows (a, b, c): a s + b t + c <= 0 inside, (a, b) unit.
            edges = ConvexHull(points @ region.axes.T).equations
        except (QhullError, ValueError):
            edges = None
        if edges is not None:
            normals = -(edges[:, :1] * region.axes[0] + edges[:, 1:2] * region.axes[1])
            sides = np.column_stack([normals, -edges[:, 2]])
    sides.setflags(write=False)
    return sides


def _support_bounds(
    points: np.ndarray, regions: tuple[PlaneRegion, ...], ratio: float | None
) -> np.ndarray:
    """Half-spaces (S, 4) n . x + b >= 0 bounding an object beyond the support's seen outline
    (module doc): per side of each support's outline (``_support_sides``), the observed
    points' (N, 3) mirror level (``_mirror_levels``). Empty without a ratio or an outline."""
    if ratio is None or len(points) == 0:
        return np.zeros((0, 4))
    sides = [_support_sides(r) for r in regions if r.is_support]
    sides = [s for s in sides if len(s)]
    if not sides:
        return np.zeros((0, 4))
    return _mirror_levels(points, np.concatenate(sides), ratio)


def _distance(facet: _SourceFacet, u: float, config: HypothesisConfig) -> float:
    """d for variate u in [0, 1): uniform over the admissible d at least D_min; when none is
    (no room), the largest admissible d, at least ``min_room_m``."""
    table = facet.tables.get(config.min_thickness_m)
    if table is None:
        lower = np.maximum(facet.cells, config.min_thickness_m)
        lengths = np.clip(facet.cells + facet.width - lower, 0.0, None)
        # Python floats: the same IEEE values and arithmetic as numpy's scalars, and
        # ``bisect_right`` is ``np.searchsorted(side="right")`` on the sorted ends.
        table = (
            lower.tolist(),
            lengths.tolist(),
            float(lengths.sum()),
            np.cumsum(lengths).tolist(),
        )
        facet.tables[config.min_thickness_m] = table
    lower, lengths, total, ends = table
    if total <= 0:
        return max(facet.d_max, config.min_room_m)
    # Inverse CDF of the uniform distribution on the union of cells (monotone in u, so the
    # stratification of u carries over to d).
    target = u * total
    index = min(bisect.bisect_right(ends, target), len(ends) - 1)
    return float(lower[index] + (target - (ends[index] - lengths[index])))


def _mirror(facet: _SourceFacet, d: float) -> np.ndarray:
    """The facet's points mirrored about its tangent plane, then moved d against its normal."""
    n = facet.normal
    offsets = (facet.points - facet.centre) @ n
    return facet.points - (2.0 * offsets + d)[:, None] * n


#: How far (absolute for unit-normal products, relative for area sums) a compiled comparison
#: must be from its threshold to be certain of numpy's outcome (their values differ by
#: ~1e-15 at most: BLAS and pairwise summation round differently from a plain loop).
_CERTAIN_BAND = 1e-9


def _greedy_labels_numpy(
    areas: np.ndarray, normals: np.ndarray, cos_group: float, min_area_m2: float
) -> np.ndarray:
    """``kernels.greedy_labels`` in numpy (the reference, and the fallback when the compiled
    loop is not certain): labels (T,) of a hull's triangles (``_hull_groups``)."""
    label = np.full(len(areas), -1, dtype=np.int64)
    number = 0
    unassigned = np.arange(len(areas))
    while unassigned.size and areas[unassigned].sum() >= min_area_m2:
        seed = unassigned[int(np.argmax(areas[unassigned]))]
        close = normals[unassigned] @ normals[seed] >= cos_group
        label[unassigned[close]] = number
        unassigned = unassigned[~close]
        number += 1
    label[unassigned] = np.arange(number, number + unassigned.size)  # too small to matter
    return label


def _hull_groups(
    hull: ConvexHull, cos_group: float, min_area_m2: float
) -> Iterator[tuple[np.ndarray, Callable[[], np.ndarray], float]]:
    """Facets of a hull of at least ``min_area_m2``, largest first: (unit normal (3,), a
    function giving its triangle indices, area m^2) each, yielded one at a time (Algorithm 1
    stops after ``max_hull_facets`` new ones and needs the triangles of those alone).

    The largest unassigned triangle claims every unassigned triangle within the angle of its
    normal, repeatedly; each such set is then split into connected parts (triangles sharing an
    edge), so two parallel faces are two facets. Both steps compiled (``kernels.greedy_labels``
    with numpy's loop as the fallback, ``kernels.hull_parts``): the same facets as numpy.
    """
    normals = hull.equations[:, :3]
    tri = hull.points[hull.simplices]
    areas = 0.5 * row_norms(triangle_cross(tri))
    # The greedy grouping, compiled; numpy's loop when a comparison is too close to call.
    label, certain = greedy_labels(
        areas, np.ascontiguousarray(normals), cos_group, min_area_m2, _CERTAIN_BAND
    )
    if not certain:
        label = _greedy_labels_numpy(areas, normals, cos_group, min_area_m2)
    # Connected parts of each label and their area and area-weighted normal (compiled).
    part, part_area, part_normal = hull_parts(
        label, np.ascontiguousarray(hull.neighbors, dtype=np.int64), areas, normals
    )
    for index in np.argsort(-part_area, kind="stable").tolist():
        area = part_area[index]
        if area < min_area_m2:
            return
        vector = part_normal[index]
        # np.linalg.norm of a vector is sqrt(x.dot(x)): the same bits without its overhead.
        normal = vector / (math.sqrt(vector.dot(vector)) + 1e-15)
        yield normal, functools.partial(_members, part, index), float(area)


def _members(part: np.ndarray, index: int) -> np.ndarray:
    """Indices of the triangles whose part is ``index`` (``_hull_groups``)."""
    return np.flatnonzero(part == index)


def _hull_source(
    hull: ConvexHull,
    normal: np.ndarray,
    members: np.ndarray,
    ctx: _Context,
    rng: np.random.Generator,
) -> _SourceFacet:
    """A hull facet as a facet to mirror: its vertices, area-weighted centre and D_max from rays
    cast from points sampled on it (pulled 15 % towards its centre, off the edges)."""
    simplices = hull.simplices[members]
    tri = hull.points[simplices]
    areas = 0.5 * row_norms(triangle_cross(tri))
    total = areas.sum()
    # tri.mean(axis=1): the three corners summed in order, over 3 (the same bits).
    centre = ((tri[:, 0] + tri[:, 1] + tri[:, 2]) / 3.0 * areas[:, None]).sum(axis=0) / max(
        total, 1e-15
    )
    count = ctx.config.hull_facet_rays
    pick = _weighted_choice(rng, areas / total, count)
    r1, r2 = rng.random(count), rng.random(count)
    flip = r1 + r2 > 1
    r1, r2 = np.where(flip, 1 - r1, r1), np.where(flip, 1 - r2, r2)
    samples = tri[pick, 0] + r1[:, None] * (tri[pick, 1] - tri[pick, 0])
    samples = samples + r2[:, None] * (tri[pick, 2] - tri[pick, 0])
    samples = centre + 0.85 * (samples - centre)
    step = ctx.config.ray_step_m or ctx.pitch_m
    parts = (ctx.rays, ctx.regions, ctx.cap_m, step, ctx.stops)
    cells, conflict = _admissible(
        [_ray_bounds(samples, centre, normal, parts)], ctx.config.ray_quantile, step
    )
    used = np.zeros(len(hull.points), dtype=bool)
    used[simplices] = True  # np.unique(simplices) without its sort
    points = hull.points[used]
    return _SourceFacet(normal, centre, points, cells, step, "hull", conflict)


def _weighted_choice(rng: np.random.Generator, p: np.ndarray, count: int) -> np.ndarray:
    """``rng.choice(len(p), size=count, p=p)`` (int64 (count,)): the same draws and the same
    state afterwards, by the same steps as numpy's ``Generator.choice`` with replacement
    (cumulative sum normalised by its last entry, ``count`` uniforms, a right-sided search),
    without its validation of ``p``, which costs more than the draw for a hull facet's few
    triangles. ``p`` not a distribution (non-finite, negative, not summing to 1): numpy's
    ``choice`` itself (its error)."""
    total = float(p.sum()) if p.size else math.nan
    if not (abs(total - 1.0) <= 1e-8 and p.min() >= 0):
        return rng.choice(len(p), size=count, p=p)
    cdf = p.cumsum()
    cdf /= cdf[-1]
    return cdf.searchsorted(rng.random(count), side="right").astype(np.int64, copy=False)


@dataclass(frozen=True, eq=False)
class _Sample:
    """One run of Algorithm 1: the hull points and what produced them."""

    points: np.ndarray
    distances: list[float]
    normals: list[np.ndarray]
    sources: list[str]
    rounds: int


def _algorithm1(
    ctx: _Context,
    observed_u: np.ndarray,
    rng: np.random.Generator,
    max_rounds: int,
) -> _Sample:
    """Algorithm 1 for one hypothesis: mirror, hull, new hull facets, repeat."""
    config = ctx.config
    cos_merge = np.cos(np.radians(config.normal_merge_deg))
    cos_group = np.cos(np.radians(config.hull_group_deg))
    cloud = ctx.loop_points
    hidden: list[np.ndarray] = []  # the hypothesised (mirrored) facets' points
    handled = [f.normal for f in ctx.observed]
    distances: list[float] = []
    normals: list[np.ndarray] = []
    sources: list[str] = []
    todo = list(zip(ctx.observed, observed_u, strict=True))
    rounds = 0
    while todo:
        rounds += 1
        mirrored = []
        for facet, u in todo:
            d = _distance(facet, float(u), config)
            mirrored.append(_mirror(facet, d))
            handled.extend([facet.normal, -facet.normal])
            distances.append(d)
            normals.append(facet.normal)
            sources.append(facet.source)
        hidden.extend(mirrored)
        cloud = np.concatenate([cloud, *mirrored])
        if rounds >= max_rounds:
            break
        try:
            hull = ConvexHull(cloud)
        except (QhullError, ValueError):
            break  # still flat: the final hull is thickened
        # Only hull vertices matter from now on (``hull.vertices``, np.unique of the
        # simplices, without its sort).
        used = np.zeros(len(hull.points), dtype=bool)
        used[hull.simplices] = True
        cloud = hull.points[used]
        known = np.array(handled)
        todo = []
        for normal, members, _ in _hull_groups(hull, cos_group, config.min_facet_area_m2):
            if (known @ normal).max() >= cos_merge:
                continue
            if any(f.normal @ normal >= cos_merge for f, _ in todo):
                continue
            todo.append((_hull_source(hull, normal, members(), ctx, rng), rng.random()))
            if len(todo) >= config.max_hull_facets:
                break
    points = np.concatenate([ctx.base_points, *hidden])
    return _Sample(points, distances, normals, sources, rounds)


def rest_on_support(
    vertices: np.ndarray, regions: tuple[PlaneRegion, ...], snap_m: float, band_m: float
) -> np.ndarray | None:
    """Points (K, 3) that extend a hull whose lowest vertex is at most ``snap_m`` above a
    support plane down to it: the vertices within ``band_m`` of the lowest one, projected onto
    the plane along its normal; None when no support is that close (module doc)."""
    for region in regions:
        if not region.is_support:
            continue
        heights = region.plane.signed_distance(vertices)
        lowest = float(heights.min())
        if 0.0 < lowest <= snap_m:
            bottom = vertices[heights <= lowest + band_m]
            normal = np.asarray(region.plane.normal, float)
            return bottom - heights[heights <= lowest + band_m, None] * normal
    return None


def _finish(
    ctx: _Context, points: np.ndarray, hull: tuple | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """Closed convex mesh of the hypothesis' points: thickened if flat, extended down to a
    support it nearly touches, cut at the support. ``hull``: ``convex_mesh(points)`` when the
    caller has it already (None: computed here)."""
    mesh = hull if hull is not None else convex_mesh(points)
    if mesh is None:
        logger.info("object %d: flat hypothesis; thickened by D_min", ctx.object_id)
        mesh = convex_mesh(_thicken(points, ctx.fallback_normal, ctx.config.min_thickness_m))
        if mesh is None:  # pragma: no cover - _thicken always spans a volume
            raise RuntimeError(f"object {ctx.object_id}: cannot build a hull")
    if ctx.shrink_m > 0:
        shrunk = _shrunk(mesh, ctx.shrink_m, mesh[0].mean(axis=0))
        mesh = shrunk if shrunk is not None else mesh
    if ctx.config.support_snap_m > 0:
        footprint = rest_on_support(
            mesh[0], ctx.regions, ctx.config.support_snap_m, ctx.config.support_band_m
        )
        if footprint is not None:
            extended = convex_mesh(np.concatenate([mesh[0], footprint]))
            mesh = extended if extended is not None else mesh
    violated = []
    for cut in ctx.cuts:
        if float((mesh[0] @ cut[:3]).min()) + cut[3] < -1e-12:
            violated.append(cut)
    if len(violated) >= 2:
        # Several cuts at once: one half-space intersection and one hull instead of a hull per
        # cut (the same polytope; the sequential cuts below remain the fallback).
        cut_all = _cut_all(mesh, violated, ctx.base_points.mean(axis=0))
        if cut_all is not None:
            return cut_all
    for cut in violated:
        vertices, faces, _ = mesh
        if float((vertices @ cut[:3]).min()) + cut[3] < -1e-12:
            clipped = convex_mesh(clip_halfspace(vertices, faces, cut[:3], float(cut[3])))
            if clipped is None:
                logger.info("object %d: a cut would leave no volume; skipped", ctx.object_id)
                continue
            mesh = clipped
    return mesh


def _cut_all(
    mesh: tuple[np.ndarray, np.ndarray, float], cuts: list[np.ndarray], interior: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The convex mesh cut to every half-space n . x + offset >= 0 of ``cuts`` (4,) at once
    (qhull's half-space intersection about ``interior``, a point strictly inside all of them:
    the observed points' centroid); None when that point is not strictly inside or qhull
    fails (the caller cuts one by one)."""
    halfspaces = np.concatenate([_face_halfspaces(mesh), -np.asarray(cuts, float)])
    corners = _halfspace_corners(halfspaces, interior)
    if corners is None:
        return None
    # Planes meeting at one corner give copies of it a rounding apart: merge them (10 nm).
    result = convex_mesh(unique_rows(np.round(corners, 8)))
    # Corners that stayed a hair apart can leave sliver faces whose planes other vertices
    # cross by more than rounding: then the one-cut-at-a-time path decides.
    return result if result is not None and _is_convex(result) else None


def _evaluate(
    ctx: _Context, mesh: tuple[np.ndarray, np.ndarray, float]
) -> tuple[np.ndarray | None, int, int, bool]:
    """Voxels, excess free and wall voxels, and feasibility of a mesh."""
    vertices, faces, _ = mesh
    needs_voxels = ctx.space is not None or any(not r.is_support for r in ctx.regions)
    if not needs_voxels:
        return None, 0, 0, True
    keys = voxels.scanline_voxels(vertices, faces, ctx.pitch_m)
    report = unary_report(vertices, keys, ctx.pitch_m, ctx.space, ctx.regions)
    free = max(report.free_voxels - ctx.forced_free, 0)
    wall = max(report.wall_voxels - ctx.forced_wall, 0)
    allowed = allowed_voxels(
        report.voxel_count,
        ctx.config.unary.free_space_tolerance,
        ctx.config.unary.free_space_tolerance_voxels,
    )
    return keys, free, wall, free <= allowed and wall <= allowed


def _finished(
    ctx: _Context, points: np.ndarray, memo: dict[tuple, tuple]
) -> tuple[tuple[np.ndarray, np.ndarray, float], np.ndarray | None, int, int, bool]:
    """``_finish`` and ``_evaluate`` of a cloud, computed once per distinct cloud (``memo``,
    keyed by its bytes): the structure-aware generators repeat clouds (a family's own fit is
    its first candidates' cloud and every second attempt's of the same frame), and both steps
    are functions of the cloud alone. Returns copies, so no two hypotheses share arrays."""
    key = (points.shape, points.dtype.str, points.tobytes())
    if key not in memo:
        mesh = _finish(ctx, points)
        memo[key] = (mesh, *_evaluate(ctx, mesh))
    (vertices, faces, volume), keys, free, wall, feasible = memo[key]
    keys = None if keys is None else keys.copy()
    return (vertices.copy(), faces.copy(), volume), keys, free, wall, feasible


_Maker = Callable[[np.ndarray, int], np.ndarray]


def _structure_makers(
    obj: PartialObject, ctx: _Context
) -> tuple[dict[str, _Maker], dict[str, int]]:
    """The structure-aware generators (``ipr_shapes.hypotheses.structure``) that apply to an object,
    fitted: name -> make(variates (6,), variant number) -> candidate points (K, 3); and per
    generator the frames its variants cycle through."""
    config = ctx.config
    settings = structure.StructureSettings(
        rim_m=max(config.rim_width_m, ctx.pitch_m),
        max_rays=max(config.max_rays // 2, 1),
        quantile=config.ray_quantile,
        pitch_m=ctx.pitch_m,
        mean_radius=config.revolution_radius == "wall_mean",
    )
    points, point_normals = _point_normals(obj, 2000)
    towards = ctx.fallback_normal
    step = config.ray_step_m or ctx.pitch_m

    def reach(origins: np.ndarray, direction: np.ndarray) -> np.ndarray:
        return _ray_limits(origins, -direction, ctx.rays, ctx.regions, ctx.cap_m, step, ctx.stops)

    makers: dict[str, _Maker] = {}
    support = next((r.plane for r in ctx.regions if r.is_support), None)
    facets = [(np.asarray(f.normal, float), float(f.area_m2)) for f in obj.facets]
    frames = []  # (frame, plane subsets)
    upright = None
    if support is not None and len(points) >= 8:
        upright = structure.upright_frame(
            points, facets, np.asarray(support.normal, float), float(support.offset), towards
        )
        frames.append((upright, ((0, 1), (0,), (1,))))
    own = structure.facet_frame(points, facets, towards) if len(points) >= 8 else None
    if own is not None and not any(structure.same_frame(own, f) for f, _ in frames):
        frames.append((own, ((0, 1, 2), (0, 1), (2,), (0,), (1,))))
    fitted = []
    for frame, subsets in frames:
        room = structure.reaches(frame, frame.local(points), points, reach, settings)
        # Extents and hulls only need the observed hull's vertices (reflections are affine).
        fitted.append((frame, room, frame.local(ctx.base_points), subsets))
    if fitted:

        def symmetric(t: np.ndarray, k: int) -> np.ndarray:
            frame, room, extreme, subsets = fitted[k % len(fitted)]
            axes = subsets[(k // len(fitted)) % len(subsets)]
            return structure.symmetry_points(frame, extreme, t * room, axes)

        def box(t: np.ndarray, k: int) -> np.ndarray:
            frame, room, extreme, _ = fitted[k % len(fitted)]
            return structure.box_points(frame, extreme, t * room)

        makers["symmetry"], makers["box"] = symmetric, box
    if upright is not None:
        found = structure.best_axis(
            upright,
            points,
            point_normals,
            towards,
            settings,
            fitted_axis=config.fitted_revolution_axis,
        )
        if found is not None:
            axis, axis_local, fit = found
            makers["revolution"] = lambda t, k: structure.revolution_points(
                axis, axis_local, ctx.base_points, fit, float(t[0]), settings
            )
            if not settings.mean_radius or structure.constant_radius(axis_local, fit, settings):
                makers["cylinder"] = lambda t, k: structure.revolution_points(
                    axis, axis_local, ctx.base_points, fit, float(t[0]), settings, constant=True
                )
    sphere = structure.fit_sphere(points)
    if (
        sphere is not None
        and sphere.residual <= settings.sphere_residual
        and sphere.radius <= float(np.ptp(points, axis=0).max())
    ):
        makers["sphere"] = lambda t, k: structure.sphere_points(
            ctx.base_points, points, sphere, float(t[0]), settings, towards
        )
    fits = {"symmetry": len(fitted), "box": len(fitted)}
    if config.superquadric_count > 0 and fitted:
        sq_settings = superquadric.SuperquadricSettings()
        # The fit's bounds: a high quantile of the rays (a curved side's hidden part reaches
        # past its silhouette's rays); the seen-free voxels in the fit keep it out of free space.
        loose = dataclasses.replace(settings, quantile=sq_settings.room_quantile)
        found = []
        for frame, _, _, _ in fitted:
            if found and found[0].residual <= 0.5 * sq_settings.residual:
                break  # the first frame's fit is good: the object's own frame is not needed
            room = structure.reaches(frame, frame.local(points), points, reach, loose)
            f = superquadric.fit(frame, points, room, ctx.rays, sq_settings)
            if f is not None:
                found.append(f)
        if found:

            def superquadric_points(t: np.ndarray, k: int) -> np.ndarray:
                return superquadric.surface_points(
                    found[k % len(found)], t, ctx.base_points, sq_settings
                )

            makers["superquadric"] = superquadric_points
            fits["superquadric"] = len(found)
    return makers, fits


#: Spawn key (under the object's seed sequence) of the root of the structure-aware families'
#: streams: a constant, so the families' draws do not depend on how many Algorithm 1 slots
#: were spawned before them (keys 0 .. m1 - 1); below 2**32 (one word of the key).
_STRUCTURE_STREAM = 2**31


def _structure_root(rng: np.random.Generator) -> np.random.SeedSequence:
    """The root of the structure-aware families' streams: the child of ``rng``'s seed sequence
    with spawn key ``(..., _STRUCTURE_STREAM)``, made without advancing its spawn counter."""
    seq = rng.bit_generator.seed_seq
    if not isinstance(seq, np.random.SeedSequence):
        raise TypeError("generate_hypotheses needs an rng seeded from a SeedSequence")
    return np.random.SeedSequence(
        seq.entropy, spawn_key=(*seq.spawn_key, _STRUCTURE_STREAM), pool_size=seq.pool_size
    )


def _structure_plan(
    makers: dict[str, _Maker],
    fits: dict[str, int],
    count: int,
    root: np.random.SeedSequence,
    ctx: _Context,
) -> list[tuple[str, Callable[[float], _Sample]]]:
    """``count`` structure-aware candidates, the applicable generators taking turns: (generator,
    make) pairs, ``make(scale)`` the candidate's points with its variates scaled by ``scale``
    (1, then 0 for the second attempt). Variates: ``structure.variates``, each generator's from
    its own stream under ``root`` (``structure.family_rng``), so a generator's candidates
    depend on its own count and fits alone, not on the other families'."""
    towards, min_thickness = ctx.fallback_normal, ctx.config.min_thickness_m
    order = [name for name in structure.STRUCTURE_GENERATORS if name in makers]
    if not order or count <= 0:
        return []
    counts = dict.fromkeys(order, 0)
    if "superquadric" in counts:
        # Its own share first (``HypothesisConfig.superquadric_count``); the others take turns.
        counts["superquadric"] = min(ctx.config.superquadric_count, count)
        order.remove("superquadric")
        if not order:
            order = ["superquadric"]
    for slot in range(count - sum(counts.values())):
        counts[order[slot % len(order)]] += 1
    plan = []
    for name in counts:
        n = counts[name]
        width = superquadric.PARAMETERS if name == "superquadric" else structure.DIRECTIONS
        stream = structure.family_rng(root, name)
        variates = structure.variates(name, n, stream, fits.get(name, 1), width)
        for k in range(n):

            def make(scale: float, name=name, t=variates[k], k=k) -> _Sample:
                cloud = makers[name](t * scale, k)
                # At least D_min thick towards the camera, like the minimum shape: a face seen
                # alone with no room behind it would otherwise give a sub-voxel sliver.
                extent = float(np.ptp(cloud @ towards))
                if extent < min_thickness:
                    cloud = np.concatenate([cloud, cloud - (min_thickness - extent) * towards])
                return _Sample(cloud, [], [], [], 0)

            plan.append((name, make))
    logger.debug("object %d: structure-aware candidates %s", ctx.object_id, counts)
    return plan


def _point_normals(obj: PartialObject, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The finite observed points taken evenly, at most ``count`` (K, 3), and the normal of the
    facet each belongs to (K, 3; zero for none)."""
    points = np.asarray(obj.points, float).reshape(-1, 3)
    index = np.flatnonzero(np.all(np.isfinite(points), axis=1))
    if len(index) > count:
        index = index[np.linspace(0, len(index) - 1, count).round().astype(np.int64)]
    normals = np.zeros((len(index), 3))
    if obj.facet_of_point is not None and obj.facets:
        facet_normals = np.array([np.asarray(f.normal, float) for f in obj.facets])
        owner = np.asarray(obj.facet_of_point)[index]
        normals[owner >= 0] = facet_normals[owner[owner >= 0]]
    return points[index], normals


def generate_hypotheses(
    obj: PartialObject,
    space: SeenSpace | None,
    planes: tuple[KnownPlane, ...],
    config: HypothesisConfig | None = None,
    rng: np.random.Generator | None = None,
    bounds: SeenSpace | None = None,
) -> tuple[ShapeHypothesis, ...]:
    """``config.count`` complete-shape hypotheses of a partial object: Algorithm 1's first, then
    the structure-aware candidates (``structure_share``; module doc).

    Args:
        obj: the observed part (points and facets, world frame, m).
        space: the frame's free/occupied/unknown voxel map (None: no free-space limit).
        planes: the frame's support and walls.
        config: settings (defaults: ``HypothesisConfig()``).
        rng: random source (default: seeded from ``config.seed`` and the object id); Algorithm
            1's slots draw from its children 0 .. m1 - 1, each structure-aware family from its
            own keyed stream (``_structure_root``, ``structure.family_rng``).
        bounds: the space the hidden extent's rays stop in (default ``space``):
            ``prepare_hypotheses`` passes ``space`` with the other objects' observed surfaces
            (``ipr_shapes.hypotheses.neighbours``); the unary checks use ``space``.

    Returns:
        m closed convex hypotheses, each containing every observed point (but for the points'
        scatter with ``shrink_by_scatter``), none below the
        support, each labelled with its generator; see the module doc for D_max, the no-room
        rule, resampling and the timeout.
    """
    config = config or HypothesisConfig()
    if rng is None:
        rng = np.random.default_rng([config.seed, int(obj.id)])
    if config.silhouette_cut != "fallback":
        return _generate(obj, space, planes, config, rng, bounds, config.silhouette_cut == "always")
    # The same draws again, cut, for an object none of whose hypotheses is feasible.
    again = copy.deepcopy(rng)
    hypotheses = _generate(obj, space, planes, config, rng, bounds, False)
    if any(h.feasible for h in hypotheses):
        return hypotheses
    logger.info("object %d: no feasible hypothesis; made again within its silhouette", obj.id)
    return _generate(obj, space, planes, config, again, bounds, True)


def _generate(
    obj: PartialObject,
    space: SeenSpace | None,
    planes: tuple[KnownPlane, ...],
    config: HypothesisConfig,
    rng: np.random.Generator,
    bounds: SeenSpace | None,
    silhouette: bool,
) -> tuple[ShapeHypothesis, ...]:
    """``generate_hypotheses`` with the silhouette cut on or off (its doc)."""
    started = time.perf_counter()
    ctx = _prepare(obj, space, planes, config, bounds, silhouette)
    m = config.count
    makers, fits = _structure_makers(obj, ctx) if config.structure_share > 0 else ({}, {})
    structured = int(round(config.structure_share * m)) if makers else 0
    m1 = m - structured  # Algorithm 1 makes the rest
    # Stratified variates of the observed facets: column j is a shuffled set of m1 strata.
    strata = np.stack([rng.permutation(m1) for _ in ctx.observed], axis=1)
    observed_u = (strata + rng.random(strata.shape)) / max(m1, 1)
    slot_rngs = rng.spawn(m1)
    plan = (
        _structure_plan(makers, fits, structured, _structure_root(rng), ctx) if structured else []
    )
    hypotheses = []
    finished: dict[tuple, tuple] = {}  # structure-aware clouds already finished (_finished)
    timed_out = False
    for k in range(m):
        if (
            not timed_out
            and config.timeout_s is not None
            and time.perf_counter() - started > config.timeout_s
        ):
            timed_out = True
            logger.warning(
                "object %d: hypothesis timeout (%.2f s) after %d of %d; the rest are simplified",
                obj.id,
                config.timeout_s,
                k,
                m,
            )
        max_rounds = 1 if timed_out else config.max_rounds
        attempts = 1 if timed_out else config.max_attempts
        if k >= m1:
            # A structure-aware candidate's second attempt is its smallest (variates 0): a
            # shape whose family does not fit fails there too, so more halving is wasted.
            attempts = min(attempts, 2)
        best = None
        for attempt in range(attempts):
            if k < m1:
                sample = _algorithm1(ctx, observed_u[k] * 0.5**attempt, slot_rngs[k], max_rounds)
                generator = "algorithm1"
            else:
                generator, make = plan[k - m1]
                sample = make(0.0 if attempt else 1.0)
            if k < m1:
                mesh = _finish(ctx, sample.points)
                keys, free, wall, feasible = _evaluate(ctx, mesh)
            else:
                mesh, keys, free, wall, feasible = _finished(ctx, sample.points, finished)
            candidate = (free + wall, attempt, sample, mesh, keys, free, wall, feasible)
            if best is None or candidate[0] < best[0]:
                best = candidate
            if feasible:
                best = candidate
                break
        assert best is not None
        _, attempt, sample, mesh, keys, free, wall, feasible = best
        if not feasible:
            logger.info(
                "object %d hypothesis %d (%s): no feasible sample in %d attempts (%d free, %d "
                "wall voxels); kept as infeasible",
                obj.id,
                k,
                generator,
                attempts,
                free,
                wall,
            )
        vertices, faces, volume = mesh
        hypotheses.append(
            ShapeHypothesis(
                object_id=int(obj.id),
                index=k,
                vertices=vertices,
                faces=faces,
                volume_m3=volume,
                distances_m=np.array(sample.distances, dtype=float),
                facet_normals=np.array(sample.normals, dtype=float).reshape(-1, 3),
                facet_sources=tuple(sample.sources),
                rounds=sample.rounds,
                attempts=attempt + 1,
                feasible=feasible,
                free_voxels=free,
                wall_voxels=wall,
                forced_free_voxels=ctx.forced_free,
                forced_wall_voxels=ctx.forced_wall,
                voxel_keys=keys,
                voxel_pitch_m=ctx.pitch_m,
                generator=generator,
            )
        )
    if config.unary.surface_allowance_quantile is not None and not any(
        h.feasible for h in hypotheses
    ):
        hypotheses = _within_allowance(obj, ctx, hypotheses)
    logger.debug(
        "object %d: %d hypotheses in %.3f s, volumes %s",
        obj.id,
        m,
        time.perf_counter() - started,
        volume_spread(hypotheses),
    )
    return tuple(hypotheses)


def _within_allowance(
    obj: PartialObject, ctx: _Context, hypotheses: list[ShapeHypothesis]
) -> list[ShapeHypothesis]:
    """The hypotheses of an object none of which passed the seen-free check, checked again
    with the seen-free voxels within the object's surface allowance excused (``allowance``;
    ``UnaryTolerances.surface_allowance_quantile``), in the observed hull's count as in each
    hypothesis'. The same shapes; their voxel counts and ``feasible`` updated."""
    points = np.asarray(obj.points, float).reshape(-1, 3)
    points = points[np.all(np.isfinite(points), axis=1)]
    hull = _observed_hull(_observed_extremes(points))
    quantile = ctx.config.unary.surface_allowance_quantile
    if ctx.space is None or hull is None or quantile is None:
        return hypotheses
    allowed_m = allowance.surface_allowance(points, quantile, hull[0])
    excused = allowance.excused_keys(points, ctx.space, ctx.pitch_m, allowed_m)
    if excused.size == 0:
        return hypotheses
    hull_keys = voxels.scanline_voxels(hull[0], hull[1], ctx.pitch_m)
    forced_free = ctx.forced_free - voxels.intersection_count(hull_keys, excused)
    checked = []
    for h in hypotheses:
        keys = h.keys(ctx.pitch_m)
        report = unary_report(h.vertices, keys, ctx.pitch_m, ctx.space, ctx.regions)
        excused_here = voxels.intersection_count(keys, excused)
        free = max(report.free_voxels - excused_here - forced_free, 0)
        allowed = allowed_voxels(
            report.voxel_count,
            ctx.config.unary.free_space_tolerance,
            ctx.config.unary.free_space_tolerance_voxels,
        )
        checked.append(
            dataclasses.replace(
                h,
                free_voxels=free,
                forced_free_voxels=forced_free,
                excused_free_voxels=excused_here,
                feasible=free <= allowed and h.wall_voxels <= allowed,
            )
        )
    logger.info(
        "object %d: no hypothesis passed the seen-free check; with its surface allowance of "
        "%.1f mm (%d seen-free voxels excused) %d of %d do",
        obj.id,
        allowed_m * 1e3,
        excused.size,
        sum(h.feasible for h in checked),
        len(checked),
    )
    return checked


def minimum_shape(
    obj: PartialObject,
    planes: tuple[KnownPlane, ...],
    config: HypothesisConfig | None = None,
) -> ShapeHypothesis:
    """The smallest plausible solid from the observed points only.

    The convex hull of the observed points; where it is thinner than D_min along the object's
    dominant normal (the direction towards the camera, ``dominant_normal``), a copy of the
    points is added behind them so that it is D_min thick along that normal (flat or collinear
    point sets are thickened the same way). Cut at the support plane like the hypotheses.
    Index -1; no voxels.
    """
    config = config or HypothesisConfig()
    points = np.asarray(obj.points, float).reshape(-1, 3)
    points = points[np.all(np.isfinite(points), axis=1)]
    if len(points) == 0:
        raise ValueError(f"object {obj.id} has no finite observed point")
    normal = dominant_normal(obj, planes)
    base = _observed_extremes(points)
    shrink = _scatter(points, base, _observed_hull(base)) if config.shrink_by_scatter else 0.0
    extent = float(np.ptp(base @ normal))
    thickness = 0.0
    if extent < config.min_thickness_m:
        thickness = config.min_thickness_m - extent
        base = np.concatenate([base, base - thickness * normal])
    # The set-up's hull when nothing was added (``_observed_hull`` remembers it).
    mesh = _observed_hull(base) if thickness == 0.0 else convex_mesh(base)
    if mesh is None:
        logger.info("object %d: flat observed hull; minimum shape thickened", obj.id)
        base = _thicken(base, normal, config.min_thickness_m)
    regions = _plane_regions(planes, config.unary.wall_min_thickness_m)
    cuts = np.array(_support_cuts(regions, points)).reshape(-1, 4)
    ctx = _Context(
        obj.id, base, base, (), None, regions, cuts, config.max_depth_m, normal, 0, 0,
        voxels.DEFAULT_PITCH_M, config, shrink_m=shrink,
    )  # fmt: skip
    vertices, faces, volume = _finish(ctx, base, mesh)
    return ShapeHypothesis(
        object_id=int(obj.id),
        index=-1,
        vertices=vertices,
        faces=faces,
        volume_m3=volume,
        distances_m=np.array([thickness]),
        facet_normals=normal[None, :],
        facet_sources=("minimum",),
        generator="minimum",
    )
