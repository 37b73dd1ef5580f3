"""The known planes of a frame: the support (table) and the walls of containers and drawers.

The paper's authors find the support plane by RANSAC with a 1 cm inlier threshold and 1000
iterations (``ipr_shapes.geometry.planes.fit_plane_ransac``); vertical planes found the same way among
the points above it are kept as walls when their cues say so (``find_walls``).
"""

from __future__ import annotations

import numpy as np

from ipr_shapes.geometry import kernels as geometry_kernels
from ipr_shapes.geometry import order
from ipr_shapes.geometry.planes import Plane, fit_plane_ransac
from ipr_shapes.geometry.support import SupportChoiceConfig, choose_support
from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.types import DepthView, KnownPlane


def find_known_planes(
    points_world: np.ndarray,
    config: PerceptionConfig,
    rng: np.random.Generator | None = None,
    *,
    normals: np.ndarray | None = None,
    viewpoint: np.ndarray | None = None,
) -> tuple[KnownPlane, ...]:
    """The support plane and the walls among (N, 3) world points (m, z up).

    ``find_support_plane`` then, when ``viewpoint`` (the camera centre (3,), world, m) is given,
    ``find_walls`` with the (N, 3) unit camera-facing ``normals`` (zero = unknown, or None;
    ``supervoxels.organised_normals`` rotated to the world). Returns () when no support plane
    is found; otherwise the support first, then the walls. Points on the known planes are
    given by ``static_geometry_mask``.
    """
    points = np.asarray(points_world, dtype=np.float64)
    rng = np.random.default_rng(config.seed) if rng is None else rng
    support = find_support_plane(points, config, rng)
    if support is None:
        return ()
    if viewpoint is None:
        return (support,)
    return (
        support,
        *find_walls(points, support, config, rng, normals=normals, viewpoint=viewpoint),
    )


def find_support_plane(
    points_world: np.ndarray,
    config: PerceptionConfig,
    rng: np.random.Generator | None = None,
    *,
    grid: np.ndarray | None = None,
    usable: np.ndarray | None = None,
    viewpoint: np.ndarray | None = None,
    previous: KnownPlane | None = None,
) -> KnownPlane | None:
    """The support (table) among (N, 3) world points (m, z up), or None.

    First the largest plane: the RANSAC plane (``planes.threshold_m``, ``support.iterations``,
    scored on ``planes.sample_size`` points) with the most inliers among planes whose normal is
    within ``support.max_tilt_deg`` of world +z; it needs ``support.min_points`` inliers and
    ``support.min_fraction`` of the points. Its normal points up.

    The support is the plane the objects rest on, which the largest plane is not always: given
    the frame's organised points (``grid`` (H, W, 3) world, ``usable`` (N,) the flat pixel
    indices of ``points_world``, ``viewpoint`` the camera centre (3,)), the choice of
    ``ipr_shapes.geometry.support.choose_support`` (``support.candidates`` further planes) replaces it
    when it is the tops of packed objects or a floor seen beyond a table. With ``previous`` (the
    support of the scene's earlier frame), no choice is made again: the support does not move,
    so the largest plane is kept when it is the earlier support (refitted to this frame), and
    the earlier support otherwise. ``rng`` draws the same numbers whatever the choice (the
    choice has its own generator), so that walls found after it do not depend on it.
    """
    points = np.asarray(points_world, dtype=np.float64)
    rng = np.random.default_rng(config.seed) if rng is None else rng
    min_inliers = max(config.support.min_points, int(config.support.min_fraction * len(points)))
    plane = fit_plane_ransac(
        points,
        threshold_m=config.planes.threshold_m,
        iterations=config.support.iterations,
        min_inliers=min_inliers,
        rng=rng,
        axis=np.array([0.0, 0.0, 1.0]),
        max_tilt_deg=config.support.max_tilt_deg,
        sample_size=config.planes.sample_size,
    )
    if plane is None:
        return previous
    up, offset = plane.normal, plane.offset
    if up[2] < 0:
        up, offset = -up, -offset
    if previous is not None and not _same_plane(
        up, offset, previous, points[plane.inliers[:: max(1, len(plane.inliers) // 2000)]]
    ):
        return previous
    if previous is None and grid is not None and config.support.candidates > 0:
        chosen = choose_support(
            grid,
            usable,
            Plane(up, offset, plane.inliers),
            np.asarray(viewpoint, dtype=np.float64),
            SupportChoiceConfig(
                candidates=config.support.candidates,
                threshold_m=config.planes.threshold_m,
                see_through=config.support.see_through,
                min_fraction=config.support.min_fraction,
                seed=config.seed,
            ),
        )
        if not chosen.is_dominant:
            normal, chosen_offset = np.asarray(chosen.normal, dtype=np.float64), chosen.offset
            if normal[2] < 0:
                normal, chosen_offset = -normal, -chosen_offset
            return KnownPlane(
                "support",
                normal,
                float(chosen_offset),
                points[_subsample_indices(chosen.inliers, rng)],
            )
    # The same random subset as _subsample(points[plane.inliers], rng), without first
    # gathering all of the inliers (most of the frame).
    return KnownPlane("support", up, offset, points[_subsample_indices(plane.inliers, rng)])


def _same_plane(
    normal: np.ndarray, offset: float, support: KnownPlane, inliers: np.ndarray
) -> bool:
    """Whether the plane (normal, offset) is ``support`` again: normals within the levels'
    parallelism (``SupportChoiceConfig.level_tilt_deg``) and (M, 3) points of it (a subset of
    its inliers) at a median distance from ``support`` within the choice's ``drop_m`` (noise
    and a bent table)."""
    settings = SupportChoiceConfig()
    if float(normal @ support.normal) < np.cos(np.radians(settings.level_tilt_deg)):
        return False
    return bool(abs(order.median(support.signed_distance(inliers))) < settings.drop_m)


def static_geometry_mask(
    points_world: np.ndarray, planes: tuple[KnownPlane, ...], config: PerceptionConfig
) -> np.ndarray:
    """(N,) bool: the (N, 3) world points that belong to the known planes (static geometry).

    Support: every point less than ``support.clearance_m`` above it, and everything below it
    (table edges, the floor). Wall: points within ``planes.threshold_m`` in front of its visible
    face or up to ``thickness_m`` behind it (the wall's rim and hidden inner face), within the
    wall's extent along the support and at most ``walls.top_margin_m`` above its top there (the
    highest of its ``points`` in 2 cm columns along it, widened by one column).
    """
    points = np.asarray(points_world, dtype=np.float64)
    mask = np.zeros(len(points), dtype=bool)
    support = next((p for p in planes if p.kind == "support"), None)
    if support is None:
        return mask
    height = support.signed_distance(points)
    mask |= height < config.support.clearance_m
    margin = config.planes.threshold_m
    for wall in planes:
        if wall.kind != "wall" or len(wall.points) == 0:
            continue
        along = np.cross(support.normal, wall.normal)
        s_wall = wall.points @ along
        # The wall's top along its length (2 cm columns): a drawer's side walls are lower than
        # its front, and objects standing behind a wall rise above it.
        start = float(s_wall.min()) - margin
        columns = int((float(s_wall.max()) + margin - start) / 0.02) + 1
        column_top = np.full(columns, -np.inf)
        np.maximum.at(
            column_top,
            ((s_wall - start) / 0.02).astype(np.int64),
            wall.points @ support.normal + support.offset,
        )
        padded = np.pad(column_top, 1, constant_values=-np.inf)
        column_top = np.maximum(np.maximum(padded[:-2], padded[2:]), column_top)
        # Compiled (``kernels``): the slab, extent and column-top tests in one pass.
        kernels.mark_wall_slab(
            wall.signed_distance(points),
            points @ along,
            height,
            margin,
            -wall.thickness_m,
            start,
            start + columns * 0.02,
            column_top,
            config.walls.top_margin_m,
            mask,
        )
    return mask


#: Two walls are square to each other (parallel or perpendicular) within 5 degrees.
_SQUARE_COS = float(np.cos(np.radians(5.0)))
_SQUARE_SIN = float(np.sin(np.radians(5.0)))

#: A point belongs to a plane's face only if its normal is within 30 degrees of the plane's.
_FACING_COS = float(np.cos(np.radians(30.0)))

#: A wall's rim and the cap behind its top face up: normals within 30 degrees of up.
_UP_COS = float(np.cos(np.radians(30.0)))


def _facing(
    normals: np.ndarray, direction: np.ndarray, unknown: np.ndarray | None = None
) -> np.ndarray:
    """(N,) bool: normals (N, 3) within 30 degrees of +-direction, or unknown (zero: pixels
    seen at a grazing angle, whose neighbours all look like discontinuities).

    ``unknown`` (N,) bool, ``~normals.any(axis=1)``, may be passed when known: that row test
    costs several times the dot products (the wall search asks it about the same points two
    dozen times per frame)."""
    if unknown is None:
        unknown = ~normals.any(axis=1)
    return (np.abs(normals @ direction) > _FACING_COS) | unknown


def _subsample(points: np.ndarray, rng: np.random.Generator, count: int = 2000) -> np.ndarray:
    """At most ``count`` of (N, 3) ``points`` (a random subset, for the planes' extents)."""
    if len(points) <= count:
        return points.copy()
    return points[np.sort(rng.choice(len(points), count, replace=False))]


def _subsample_indices(
    indices: np.ndarray, rng: np.random.Generator, count: int = 2000
) -> np.ndarray:
    """At most ``count`` of the (N,) ``indices``: the entries ``_subsample`` would pick from an
    (N, 3) array (same random draws), so that ``points[_subsample_indices(indices, rng)]``
    equals ``_subsample(points[indices], rng)``."""
    if len(indices) <= count:
        return indices
    return indices[np.sort(rng.choice(len(indices), count, replace=False))]


def find_walls(
    points_world: np.ndarray,
    support: KnownPlane,
    config: PerceptionConfig,
    rng: np.random.Generator | None = None,
    *,
    normals: np.ndarray | None,
    viewpoint: np.ndarray,
    edge_on: bool = True,
    view: DepthView | None = None,
) -> tuple[KnownPlane, ...]:
    """Walls of containers and drawer fronts among (N, 3) world points (m) above ``support``.

    ``normals``: (N, 3) unit normals towards the camera (zero = unknown), or None (weaker:
    faces crossing a plane then count as its inliers); ``viewpoint``: the camera centre (3,),
    world, m. Points at or below the support are ignored, so the caller may pass only the
    points above it.

    Vertical planes are extracted one after the other by RANSAC (``walls.iterations``), at most
    ``walls.max_candidates`` of them; after each, the points of its slab (the face and a wall's
    thickness behind it) that face its way leave the pool so that the same wall is not found
    twice. Candidates are accepted by the rules of ``_select_walls``; with ``view`` (the frame's
    depth image and pose) and ``walls.hidden_bottom``, a candidate whose lowest visible points
    are above ``walls.support_gap_m`` still stands on the support when its face below them is
    hidden by nearer surfaces (``_bottom_hidden``). A wall's normal points to
    the side the camera sees; its ``thickness_m`` is the depth of the static slab behind the
    visible face (``static_geometry_mask``), estimated from its rim. Objects pressed against a
    wall or lying across its rim lose those pixels with it. A lone wall must also have a
    straight top and a solid face: without those cues, faces of objects lined up in a plane were
    taken for walls and their slabs cut the objects apart (docs/DESIGN_NOTES.md, "Lone walls
    need a straight top and a solid face").

    With ``edge_on`` (and ``walls.complete_corners``), side walls seen edge-on are then looked
    for at the open ends of the accepted walls (``_edge_on_walls``). The segmentation asks for
    them in a scene's first frame only: later frames keep the walls found before (walls do not
    move, ``temporal.consistent_walls``), and a pushed object that stopped near a container's
    side would offer its face as one.
    """
    points = np.asarray(points_world, dtype=np.float64)
    rng = np.random.default_rng(config.seed) if rng is None else rng
    viewpoint = np.asarray(viewpoint, dtype=np.float64)
    if config.walls.max_candidates <= 0:
        return ()
    up = support.normal
    height = support.signed_distance(points)
    context = np.flatnonzero(height > config.support.clearance_m)
    if len(context) > config.walls.max_points:
        # An even subset: the cues are fractions and percentiles, and a wall has thousands of
        # points, so this bounds the cost on close-up frames without changing the decisions.
        context = context[:: -(-len(context) // config.walls.max_points)]
    points, height = kernels.rows_at(points, context), height[context]
    unknown = normals_up = None
    if normals is not None:
        # Per-point quantities that every candidate's tests reuse, computed once. float64:
        # products with the float64 directions are computed in float64 anyway (same values).
        normals = np.asarray(normals[context], dtype=np.float64)
        unknown = ~normals.any(axis=1)
        normals_up = normals @ up
    above = height < config.walls.max_height_m + 0.05
    pool_mask = above.copy()
    if normals is not None:
        # Vertical surfaces only (pixel normals are noisy: a generous tilt).
        pool_mask &= np.abs(normals_up) < np.sin(np.radians(config.walls.normal_tilt_deg))
    pool = np.flatnonzero(pool_mask)
    basis = np.linalg.svd(np.eye(3) - np.outer(up, up))[0][:, :2]  # horizontal directions
    margin = config.planes.threshold_m
    candidates: list[dict] = []
    for _ in range(config.walls.max_candidates):
        if len(pool) < config.walls.min_points:
            break
        plane = _fit_vertical_plane(
            kernels.rows_at(points, pool),
            None if normals is None else kernels.rows_at(normals, pool),
            up,
            config,
            rng,
            unknown=None if unknown is None else unknown[pool],
            basis=basis,
        )
        if plane is None:
            break
        normal, offset = plane
        if normal @ viewpoint + offset < 0:  # face the camera
            normal, offset = -normal, -offset
        cues = _wall_cues(
            points,
            normals,
            height,
            normal,
            offset,
            up,
            config,
            unknown,
            normals_up,
            frame=None if view is None or not config.walls.frame_cut_tops else (view, support),
        )
        if cues is not None:
            candidates.append(cues)
        # Surfaces crossing the slab stay in the pool (compiled: ``kernels``).
        pool = kernels.outside_slab(
            points,
            points if normals is None else normals,
            np.zeros(len(points), dtype=bool) if unknown is None else unknown,
            pool,
            normal,
            float(offset),
            2 * margin,
            config.walls.max_thickness_m + 2 * margin,
            _FACING_COS,
            normals is not None,
        )
    if view is not None and config.walls.hidden_bottom:
        for cues in candidates:
            if cues["bottom"] > config.walls.support_gap_m:
                cues["bottom_hidden"] = _bottom_hidden(cues, support, view, config)
    walls = _select_walls(candidates, config)
    if edge_on and config.walls.complete_corners:
        walls += _edge_on_walls(points, normals, height, walls, up, viewpoint, config)
    return tuple(
        KnownPlane(
            "wall",
            cues["normal"],
            cues["offset"],
            _subsample(np.concatenate([cues["run_points"], cues["extra_points"]]), rng),
            cues["thickness"],
        )
        for cues in walls
    )


def _edge_on_walls(
    points: np.ndarray,
    normals: np.ndarray | None,
    height: np.ndarray,
    walls: list[dict],
    up: np.ndarray,
    viewpoint: np.ndarray,
    config: PerceptionConfig,
) -> list[dict]:
    """Side walls seen edge-on where an accepted wall's face ends without a corner partner.

    A container's side wall seen along its length shows the camera its rim and a sliver of a
    face at a grazing angle: too few points facing its way for the RANSAC search, so the rim
    stayed as thin "objects" that the physics then completed into slabs, predicted volume
    outside every object (docs/DESIGN_NOTES.md, "Edge-on side walls and walls cut by an
    occluder"). At each end of an accepted wall's face (its ``span``) with no perpendicular wall
    within ``walls.corner_gap_m``, vertical planes perpendicular to it are tried every 5 mm within
    ``walls.corner_gap_m`` of the end, with every point in their slab counted whatever its
    normal (the rim faces up). A plane is accepted as a wall when its face reaches an accepted
    wall perpendicular to it (within ``walls.corner_gap_m``: the wall it was looked for from or,
    when objects hide that corner, the opposite one), its top matches an accepted wall's top
    within ``walls.partner_top_match_m`` (a container's walls share their height), its top is
    straight (``walls.min_top_agreement``) and the scene lies on one side of it
    (``walls.max_outside_fraction``); of the planes accepted at one end, the one with the most
    points in its run. Only walls square to another accepted wall (parallel or perpendicular:
    part of a container's frame) are completed, and a plane within ``walls.corner_gap_m`` of a
    parallel known wall is not tried (that wall's own rim). The capped rule does not apply:
    seen from outside, a side wall has the container's contents behind it at its rim's height.

    ``points`` (N, 3) world (m), ``normals`` (N, 3) or None and ``height`` (N,) above the
    support: the wall search's points; ``walls``: the accepted walls' cues. Returns the added
    walls' cues.
    """
    added: list[dict] = []
    gap = config.walls.corner_gap_m
    tops = [wall["top"] for wall in walls]
    # The tests below that the cues can apply as soon as they know the top (``_wall_cues``).
    partner = (
        tops,
        config.walls.partner_top_match_m,
        config.walls.min_top_agreement,
        config.walls.min_points,
    )
    for wall in walls:
        if not any(_square(wall, other) for other in walls if other is not wall):
            continue  # a lone wall is not known to be part of a container frame
        along = wall["along"]
        s_all = points @ along
        depth_wall = points @ wall["normal"] + wall["offset"]
        for end in wall["span"]:
            present = walls + added
            if _crossed_within(present, along, end, gap):
                continue  # a corner already
            # The points near this end, off the wall's own slab, within a container's width.
            region = np.flatnonzero(
                (np.abs(s_all - end) < gap + 0.08)
                & (np.abs(depth_wall) < config.walls.partner_separation_m[1])
                & ((depth_wall > config.planes.threshold_m) | (depth_wall < -wall["thickness"]))
            )
            if len(region) < config.walls.min_points:
                continue
            best = None
            region_points, region_height = kernels.rows_at(points, region), height[region]
            region_normals = region_unknown = region_up = None
            if normals is not None:  # what every position's cues would compute again
                region_normals = normals[region]
                region_unknown, region_up = ~region_normals.any(axis=1), region_normals @ up
            for position in end + np.arange(-gap, gap + 1e-9, 0.005):
                if _crossed_within(present, along, position, gap):
                    continue  # a known wall's own face or rim
                normal, offset = along.copy(), -float(position)
                if normal @ viewpoint + offset < 0:  # face the camera
                    normal, offset = -normal, -offset
                cues = _wall_cues(
                    region_points,
                    region_normals,
                    region_height,
                    normal,
                    offset,
                    up,
                    config,
                    unknown=region_unknown,
                    normals_up=region_up,
                    edge_on=True,
                    partner=partner,
                )
                if cues is None or len(cues["run_points"]) < config.walls.min_points:
                    continue
                if (
                    _meets_wall(cues, walls, gap)
                    and min(abs(cues["top"] - top) for top in tops)
                    <= config.walls.partner_top_match_m
                    and cues["top_agreement"] >= config.walls.min_top_agreement
                    and cues["outside"] <= config.walls.max_outside_fraction
                    and (best is None or len(cues["run_points"]) > len(best["run_points"]))
                ):
                    best = cues
            if best is not None:
                # The plane is only placed to 5 mm and the rim's thickness is poorly seen
                # edge-on: remove the thickest slab a wall may have.
                best["thickness"] = config.walls.max_thickness_m
                added.append(best)
    return added


def _square(first: dict, second: dict) -> bool:
    """Whether two walls' normals are parallel or perpendicular within 5 degrees."""
    cosine = abs(float(first["normal"] @ second["normal"]))
    return cosine > _SQUARE_COS or cosine < _SQUARE_SIN


def _crossing(wall: dict, axis: np.ndarray) -> float | None:
    """Where ``wall``'s plane crosses the horizontal unit ``axis`` (m along it), when the wall is
    perpendicular to the axis (its normal within 5 degrees of it); else None."""
    cosine = float(wall["normal"] @ axis)
    return -wall["offset"] / cosine if abs(cosine) > _SQUARE_COS else None


def _crossed_within(walls: list[dict], axis: np.ndarray, position: float, gap: float) -> bool:
    """Whether one of ``walls`` crosses ``axis`` within ``gap`` (m) of ``position`` (m)."""
    crossings = (_crossing(wall, axis) for wall in walls)
    return any(c is not None and abs(c - position) <= gap for c in crossings)


def _meets_wall(cues: dict, walls: list[dict], gap: float) -> bool:
    """Whether an end of the face of ``cues``' wall (its ``span``: the run with the pieces of the
    wall beyond an occluder) is within ``gap`` (m) of the plane of one of ``walls``
    perpendicular to it (a corner; the face may stop short of its other corner, hidden behind
    the objects)."""
    return any(_crossed_within(walls, cues["along"], end, gap) for end in cues["span"])


def _select_walls(candidates: list[dict], config: PerceptionConfig) -> list[dict]:
    """The candidates (``_wall_cues``) accepted as walls of a container or a drawer.

    Walls of containers and drawer fronts must be told from the vertical faces of objects (a
    cracker box's face is 21 x 16 cm, as long as a small container's wall), so every wall must
    look like one on its own:

    - *height*: its top (the height of its rim, see ``_wall_cues``) is between
      ``walls.min_height_m`` and ``walls.max_height_m`` above the support;
    - *one-sided*: of the other points above the support near it (within its extent and
      ``walls.side_range_m``), at most ``walls.max_outside_fraction`` lie on its minority side
      (the objects are inside the container);
    - *long*: its run along the support (gaps up to ``walls.max_gap_m`` bridged) is at least
      ``walls.partner_min_length_m``;

    and then either stand alone as a wall:

    - *standing, long and thin*: its lowest inliers (2nd percentile) are within
      ``walls.support_gap_m`` of the support, or its face below them is hidden behind nearer
      surfaces (``bottom_hidden``, ``_bottom_hidden``), it is at least ``walls.min_length_m``
      long, and it is not capped: at most ``walls.max_capped_fraction`` of its length has an
      upward-facing surface at the height of its top just behind it, past a wall's thickness (a
      box has its top face there; a wall has a 1-1.5 cm rim and then nothing at that height, or
      objects at other heights); and it looks like one solid face with a straight top: its top
      edge at its top height over ``walls.min_top_agreement`` of its length and its face (bottom
      to top) ``walls.min_face_fill`` covered (the faces of a row of objects standing side by
      side line up in a plane but are of many heights, with gaps between them);

    or be part of a container frame with another candidate, at least one of the two standing:

    - *parallel partner*: normals within 5 degrees, the planes ``walls.partner_separation_m``
      apart (opposite walls), runs overlapping along the wall, the longer one at least
      ``walls.min_length_m`` long;
    - *corner partner*: normals within 5 degrees of perpendicular, the corner where the planes
      meet within ``walls.corner_gap_m`` of an end of both runs, both runs at least
      ``walls.min_length_m`` long (two faces of one box meet at a corner too, but no YCB box has
      two faces that long);

    with tops differing by at most ``walls.partner_max_top_difference_m`` (a drawer front is
    taller than the sides) or, for a partner whose bottom is hidden (the inner face of a far
    wall behind the objects), by at most ``walls.partner_top_match_m``; and at least one of the
    two not capped (seen from above, the far wall of a container has nothing on its top, while
    the faces of boxes all have the box's top behind them). Two faces of one convex object are
    never parallel and both visible, which is what makes the parallel rule safe.
    """
    basic = [
        c
        for c in candidates
        if config.walls.min_height_m <= c["top"] <= config.walls.max_height_m
        and c["outside"] <= config.walls.max_outside_fraction
        and c["length"] >= config.walls.partner_min_length_m
    ]
    for c in basic:
        c["standing"] = c["bottom"] <= config.walls.support_gap_m or c.get("bottom_hidden", False)
    accepted = {
        i
        for i, c in enumerate(basic)
        if c["standing"]
        and c["length"] >= config.walls.min_length_m
        and c["capped"] <= config.walls.max_capped_fraction
        and c["top_agreement"] >= config.walls.min_top_agreement
        and c["face_fill"] >= config.walls.min_face_fill
    }
    for i, a in enumerate(basic):
        for j in range(i + 1, len(basic)):
            if _partners(a, basic[j], config):
                accepted |= {i, j}
    return [basic[i] for i in sorted(accepted)]


def _partners(a: dict, b: dict, config: PerceptionConfig) -> bool:
    """Whether two wall candidates form part of one container (see ``_select_walls``)."""
    if not (a["standing"] or b["standing"]):
        return False
    top_tolerance = (
        config.walls.partner_max_top_difference_m
        if a["standing"] and b["standing"]
        else config.walls.partner_top_match_m
    )
    if abs(a["top"] - b["top"]) > top_tolerance:
        return False
    if min(a["capped"], b["capped"]) > config.walls.max_capped_fraction:
        return False  # two faces of boxes (their tops behind both); a container has a free rim
    cosine = float(a["normal"] @ b["normal"])
    tolerance = np.radians(5.0)
    if abs(cosine) > np.cos(tolerance):  # parallel: opposite walls
        sign = 1.0 if cosine > 0 else -1.0
        separation = abs(a["offset"] - sign * b["offset"])
        low, high = config.walls.partner_separation_m
        if not low <= separation <= high:
            return False
        if max(a["length"], b["length"]) < config.walls.min_length_m:
            return False
        # Runs overlap along the walls (b's run expressed in a's along-axis).
        b_along = b["run_points"] @ a["along"]
        return bool(b_along.max() > a["s_range"][0] and b_along.min() < a["s_range"][1])
    if abs(cosine) < np.sin(tolerance):  # perpendicular: a corner
        if min(a["length"], b["length"]) < config.walls.min_length_m:
            return False
        # Corner: the horizontal point on both planes (solve in the plane spanned by the normals).
        matrix = np.stack([a["normal"], b["normal"]])
        corner = np.linalg.lstsq(matrix, -np.array([a["offset"], b["offset"]]), rcond=None)[0]
        gap = config.walls.corner_gap_m
        for wall in (a, b):
            s_corner = float(corner @ wall["along"])
            low, high = wall["s_range"]
            if min(abs(s_corner - low), abs(s_corner - high)) > gap:
                return False
        return True
    return False


def _fit_vertical_plane(
    points: np.ndarray,
    normals: np.ndarray | None,
    up: np.ndarray,
    config: PerceptionConfig,
    rng: np.random.Generator,
    *,
    unknown: np.ndarray | None = None,
    basis: np.ndarray | None = None,
) -> tuple[np.ndarray, float] | None:
    """RANSAC plane containing the ``up`` direction (a vertical plane) through (N, 3) points.

    Hypotheses come from pairs of points (the plane through both, parallel to ``up``); with
    ``normals``, a point counts as an inlier only when its normal is within 30 degrees of the
    plane's (so that the crossing faces of other objects do not vote). Returns (unit normal,
    offset) refitted by least squares in the horizontal directions, or None. ``unknown``
    (N,) bool (``~normals.any(axis=1)``) and ``basis`` (3, 2) (two horizontal unit directions,
    from the SVD of the projection orthogonal to ``up``) may be passed when already known.
    """
    threshold = config.planes.threshold_m
    count = len(points)
    sample_index = rng.choice(count, size=min(count, config.planes.sample_size), replace=False)
    sample = points[sample_index]
    pairs = rng.integers(0, count, size=(config.walls.iterations, 2))
    along = points[pairs[:, 1]] - points[pairs[:, 0]]
    along -= np.outer(along @ up, up)
    normal = _cross_rows(up, along)
    norms = np.linalg.norm(normal, axis=1)
    valid = norms > 0.02  # pairs closer than 2 cm give unstable orientations
    if not valid.any():
        return None
    normal = normal[valid] / norms[valid, None]
    offset = -np.einsum("ij,ij->i", normal, points[pairs[valid, 0]])
    # Compiled scoring (``geometry_kernels``, ``kernels``): no (sample, hypotheses) arrays.
    if normals is None:
        votes = geometry_kernels.plane_inlier_counts(sample, normal, offset, threshold)
    else:
        sample_normals = np.ascontiguousarray(normals[sample_index], dtype=np.float64)
        sample_unknown = ~sample_normals.any(axis=1) if unknown is None else unknown[sample_index]
        votes = kernels.facing_plane_inlier_counts(
            sample, sample_normals, sample_unknown, normal, offset, threshold, _FACING_COS
        )
    best = int(np.argmax(votes))
    best_normal, best_offset = normal[best], float(offset[best])
    if basis is None:
        basis = np.linalg.svd(np.eye(3) - np.outer(up, up))[0][:, :2]  # horizontal directions
    if normals is not None and unknown is None:
        unknown = ~normals.any(axis=1)
    for _ in range(2):
        if normals is None:
            inliers = geometry_kernels.plane_inliers(points, best_normal, best_offset, threshold)
        else:
            inliers = kernels.facing_plane_inliers(
                points, normals, unknown, best_normal, best_offset, threshold, _FACING_COS
            )
        if len(inliers) < config.walls.min_points:
            return None
        # The least-squares line of the inliers seen from above: the 3D moments projected on
        # the horizontal basis (the moments of the projected points).
        centroid_3d, scatter_3d = geometry_kernels.centred_scatter(
            points, inliers[:: max(1, len(inliers) // 5000)]
        )
        centroid = basis.T @ centroid_3d
        _, vectors = np.linalg.eigh(basis.T @ scatter_3d @ basis)
        refit = basis @ vectors[:, 0]
        refit *= 1.0 if refit @ best_normal >= 0 else -1.0
        best_normal = refit / np.linalg.norm(refit)
        best_offset = -float(best_normal @ (basis @ centroid))
    return best_normal, best_offset


def _cross_rows(vector: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(N, 3) cross products of a (3,) vector with each row of (N, 3): ``np.cross(vector,
    rows)``'s formulas by columns (np.cross's set-up costs more than a few hundred rows)."""
    a0, a1, a2 = (float(c) for c in vector)
    b0, b1, b2 = rows[:, 0], rows[:, 1], rows[:, 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=1)


def _wall_cues(
    pts: np.ndarray,
    normals: np.ndarray | None,
    h: np.ndarray,
    normal: np.ndarray,
    offset: float,
    up: np.ndarray,
    config: PerceptionConfig,
    unknown: np.ndarray | None = None,
    normals_up: np.ndarray | None = None,
    edge_on: bool = False,
    frame: tuple[DepthView, KnownPlane] | None = None,
    partner: tuple[list[float], float, float, int] | None = None,
) -> dict | None:
    """Measurements of the vertical plane (normal, offset) used by ``_select_walls``.

    ``pts`` (N, 3), ``normals`` (N, 3) or None and ``h`` (N,): the points above the support and
    their heights above it; ``unknown`` (N,) bool (``~normals.any(axis=1)``) and ``normals_up``
    (N,) (``normals @ up``) may be passed when already known. Returns the plane, its run (along-axis, range and length, m), top and
    bottom (m above the support), thickness (m), capped and outside fractions and the run's face
    points, the face points of the plane's other runs with the wall's top (``extra_points``, a
    wall cut by an occluder; ``walls.max_span_m``) and the extent of both along the wall
    (``span``); None when the plane has too few inliers or cannot be a wall (a run shorter than
    ``walls.partner_min_length_m``, a top outside the wall heights or more than
    ``walls.max_outside_fraction`` of the scene near it on its minority side, which
    ``_select_walls`` and ``_edge_on_walls`` reject anyway; most candidates are faces of
    objects, and this spares their costly cues and ``_bottom_hidden``'s probes).
    ``edge_on``: every point in the plane's slab is an inlier whatever its normal (a wall seen
    along its length shows its rim, which faces up; ``_edge_on_walls``).
    ``frame``: the frame's ``DepthView`` and the support; with it, a column whose highest inlier
    is where the image ends (a point 1 cm above it on the plane projects outside the image) does
    not tell the wall's top, and the top and its agreement are measured over the other
    columns (the far wall of a bin often leaves the image at the top); and upward-facing points
    more than 2 cm below that top are not the wall's rim (the tops of objects against its face).
    ``partner``: (the accepted walls' tops (m), the top tolerance (m), the least top agreement,
    the least face points): None as soon as the plane fails one of these tests of
    ``_edge_on_walls`` (a top within the tolerance of an accepted wall's, a straight top and
    enough face points below it), which would reject it anyway: most planes tried there do,
    and this spares their remaining cues.
    """
    threshold = config.planes.threshold_m
    # up x normal by _cross_rows' formulas on scalars (the same products, without its arrays).
    (a0, a1, a2), (b0, b1, b2) = (float(c) for c in up), (float(c) for c in normal)
    along = np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])
    if normals is not None and normals_up is None:
        normals_up = normals @ up
    if normals is not None and unknown is None:
        unknown = ~normals.any(axis=1)
    # Compiled (``kernels``): depth, position along the plane and face membership in one
    # pass; surfaces crossing the plane are not part of it (unless seen edge-on).
    depth, s, on_plane = kernels.vertical_plane_coordinates(
        pts,
        pts if normals is None else normals,
        np.zeros(len(pts), dtype=bool) if unknown is None else unknown,
        h,
        normal,
        float(offset),
        along,
        threshold,
        config.walls.max_height_m + threshold,
        _FACING_COS,
        normals is not None and not edge_on,
    )
    if on_plane.sum() < config.walls.min_points:
        return None
    # The face's indices: the gathers below by index, not by chains of boolean masks.
    plane_index = np.flatnonzero(on_plane)
    s_in, h_in = s[plane_index], h[plane_index]
    # Largest run of occupied bins along the plane, bridging gaps up to walls.max_gap_m.
    bin_m = 0.01
    first = float(s_in.min())
    bins = ((s_in - first) / bin_m).astype(np.int64)
    weights = np.bincount(bins)
    occupied = np.flatnonzero(weights >= 2)
    if occupied.size == 0:
        return None
    breaks = np.flatnonzero(np.diff(occupied) * bin_m > config.walls.max_gap_m)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [occupied.size - 1]])
    cumulative = np.concatenate([[0], np.cumsum(weights)])
    mass = cumulative[occupied[ends] + 1] - cumulative[occupied[starts]]
    best = int(np.argmax(mass))
    s_lo = first + occupied[starts[best]] * bin_m
    s_hi = first + (occupied[ends[best]] + 1) * bin_m
    if s_hi - s_lo < config.walls.partner_min_length_m:
        return None  # too short for any wall rule (``_select_walls``): skip the costly cues
    in_run = (s_in >= s_lo) & (s_in <= s_hi)
    heights = h_in[in_run]
    # Top: the height of the wall's rim (upward-facing points in the slab of the wall's
    # material, which objects leaning on the wall do not reach), else the median over 2 cm bins
    # of the highest inlier.
    column = ((s_in[in_run] - s_lo) / 0.02).astype(np.int64)
    column_top = np.full(int(column.max()) + 1, -np.inf)
    np.maximum.at(column_top, column, heights)
    column_s = s_lo + 0.02 * (np.arange(column_top.size) + 0.5)
    telling = np.isfinite(column_top)  # columns whose highest inlier is the wall's top edge
    if frame is not None:
        view, support = frame
        above_top = (
            -offset * normal
            + np.outer(column_s[telling], along)
            + np.outer(column_top[telling] + 0.01 - support.offset, up)
        )
        cut = ~view.in_image(above_top)
        if not cut.all():
            telling[np.flatnonzero(telling)[cut]] = False
    top = order.median(column_top[telling])
    thickness_rim = None  # the rim points the thickness is measured on, once the top is kept
    if normals is not None:
        # Compiled (``kernels``): the rim's indices in one pass.
        rim = kernels.wall_rim_points(
            depth,
            s,
            h,
            normals_up,
            threshold,
            -(config.walls.max_thickness_m + threshold),
            s_lo,
            s_hi,
            _UP_COS,
            config.walls.min_height_m - threshold,
        )
        # The rim's occupied 2 cm bins (positions from s_lo on: non-negative), counted.
        rim_bins = np.count_nonzero(np.bincount(((s[rim] - s_lo) / 0.02).astype(np.int64)))
        # A face does not rise above its own rim: upward-facing points well below the top
        # edges of the face (objects' tops against it) are not the rim.
        if rim_bins >= max(2, 0.2 * np.isfinite(column_top).sum()) and (
            frame is None or order.median(h[rim]) >= top - 0.02
        ):
            top = order.median(h[rim])
            thickness_rim = rim
    if not config.walls.min_height_m <= top <= config.walls.max_height_m:
        return None  # no wall rule accepts this top (``_select_walls``)
    # Straight top and solid face (the lone-wall rule): the share of columns whose top edge is
    # at the wall's top, and of the face's 2 cm cells from its bottom to its top with inliers.
    top_agreement = float(np.mean(np.abs(column_top[telling] - top) < 0.02))
    below_top = heights <= top + threshold  # the face's points (``run_points``)
    if partner is not None:
        partner_tops, tolerance, min_agreement, min_points = partner
        if (
            min(abs(top - other) for other in partner_tops) > tolerance
            or top_agreement < min_agreement
            or int(below_top.sum()) < min_points
        ):
            return None  # ``_edge_on_walls`` rejects it whatever its other cues
    # The figures only an accepted plane needs, after the tests that stop most planes.
    thickness = config.walls.max_thickness_m
    if thickness_rim is not None:
        # Thickness: twice the median depth of the rim behind the face (its points spread
        # evenly over the thickness; objects just behind the wall barely move the median),
        # plus 3 mm of noise.
        rim = thickness_rim[np.abs(h[thickness_rim] - top) < 0.015]
        if rim.size >= 10:
            thickness = 2.0 * order.median(np.maximum(-depth[rim], 0.0)) + 0.003
            thickness = float(np.clip(thickness, 0.005, config.walls.max_thickness_m))
    column_bottom = np.full(column_top.size, np.inf)
    np.minimum.at(column_bottom, column, heights)
    bottom = order.percentile(heights, 2)
    floor = max(bottom, 0.0)
    rows = max(1, int(np.ceil((top - floor) / 0.02)))
    on_face = heights <= top
    face = np.zeros((rows, column_top.size), dtype=bool)
    face[
        np.clip(((heights[on_face] - floor) / 0.02).astype(np.int64), 0, rows - 1),
        column[on_face],
    ] = True
    face_fill = float(face.mean())
    # Capped: an upward-facing surface at the height of the top, just behind the face.
    # One-sided: the rest of the scene near the wall (outside its slab) lies on one side.
    # Compiled (``kernels``): both in one pass; the face's top edge is often partly hidden or
    # dropped, hence up to 3 cm above the top.
    behind, near, in_front = kernels.wall_behind_and_near(
        depth,
        s,
        h,
        h if normals_up is None else normals_up,
        normals is not None,
        threshold,
        -(config.walls.max_thickness_m + threshold),
        -config.walls.cap_depth_m,
        top - 0.015,
        top + 0.03,
        _UP_COS,
        s_lo,
        s_hi,
        config.walls.side_range_m,
        0.05,
    )
    outside = 0.0
    if near > 0:
        share_in_front = in_front / near
        outside = min(share_in_front, 1.0 - share_in_front)
    if outside > config.walls.max_outside_fraction:
        return None  # not one-sided: every wall rule rejects it (nor is its bottom probed)
    cap_bin = 0.02
    n_bins = max(1, int(np.ceil((s_hi - s_lo) / cap_bin)))
    capped_counts = np.bincount(
        np.minimum(((s[behind] - s_lo) / cap_bin).astype(np.int64), n_bins - 1), minlength=n_bins
    )
    capped = float(np.mean(capped_counts >= 3))
    # The plane's other runs whose top edge is the wall's top: the same wall, cut in two by an
    # object standing in front of it. They join the wall's extent (the static slab and the
    # physics), not the figures above, so they do not change which walls are accepted.
    extra = np.zeros(len(s_in), dtype=bool)
    for other in range(len(starts)):
        low = first + occupied[starts[other]] * bin_m
        high = first + (occupied[ends[other]] + 1) * bin_m
        if other == best or max(high, s_hi) - min(low, s_lo) > config.walls.max_span_m:
            continue
        members = (s_in >= low) & (s_in <= high)
        tops = np.full(int((high - low) / 0.02) + 1, -np.inf)
        np.maximum.at(tops, ((s_in[members] - low) / 0.02).astype(np.int64), h_in[members])
        tops = tops[np.isfinite(tops)]
        if tops.size >= 2 and np.mean(np.abs(tops - top) < 0.02) >= config.walls.min_top_agreement:
            extra |= members
    extra &= h_in <= top + threshold
    span = (float(s_in[in_run | extra].min()), float(s_in[in_run | extra].max()))
    return {
        "normal": normal,
        "offset": offset,
        "along": along,
        "s_range": (s_lo, s_hi),
        "length": s_hi - s_lo,
        "thickness": thickness,
        "top": top,
        "bottom": bottom,
        "capped": capped,
        "outside": outside,
        "top_agreement": top_agreement,
        "face_fill": face_fill,
        # The face below its top (objects leaning on the wall and rising above it excluded).
        "run_points": pts[plane_index[in_run][below_top]],
        "extra_points": pts[plane_index[extra]],
        # The extent along the wall of the run and the extra runs (m).
        "span": span,
        # The run's 2 cm columns: centres along the wall and lowest inlier heights (m; inf =
        # no inlier), for ``_bottom_hidden``.
        "column_s": column_s,
        "column_bottom": column_bottom,
        "column_top": column_top,
    }


def _bottom_hidden(
    cues: dict, support: KnownPlane, view: DepthView, config: PerceptionConfig
) -> bool:
    """Whether the face of the candidate wall ``cues`` (``_wall_cues``) below its lowest visible
    points is hidden from the camera by nearer surfaces, rather than seen through.

    The far wall of a bin shows only its upper part: the bin's contents, nearer to the camera,
    hide its foot, so its lowest visible points are the contents' top edge, not the support.
    The plane is vertical (perpendicular to the support) by construction; below each 2 cm
    column of its run, points of its face are probed every 1 cm from the column's lowest inlier
    down to the support and projected into ``view``. Where the wall goes on down, each probe's
    pixel shows the wall itself or a surface in front of it; where the face ends in the air (a
    box's face lifted by what is under it, set back), the pixel shows a surface beyond the
    plane. The bottom is hidden when at most ``walls.max_seen_through`` of the probes with a
    reading show a surface more than ``planes.threshold_m`` beyond the plane (and some probe
    has a reading). Probes outside the image or without a reading tell nothing.
    """
    bottoms = cues["column_bottom"]
    seen = np.isfinite(bottoms) & (bottoms > config.walls.support_gap_m)
    if not seen.any():
        return False
    step = 0.01
    counts = np.floor(bottoms[seen] / step).astype(np.int64)  # probes below each bottom
    column = np.repeat(np.flatnonzero(seen), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    heights = np.repeat(bottoms[seen], counts) - step * (np.arange(column.size) - first + 1)
    heights = np.maximum(heights, 0.0)
    up = support.normal
    probes = (
        -cues["offset"] * cues["normal"]
        + np.outer(cues["column_s"][column], cues["along"])
        + np.outer(heights - support.offset, up)
    )
    predicted, observed = view.depths(probes)
    known = np.isfinite(observed)
    if not known.any():
        return False
    beyond = observed[known] > predicted[known] + config.planes.threshold_m
    return bool(np.mean(beyond) <= config.walls.max_seen_through)
