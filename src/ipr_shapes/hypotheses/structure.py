"""Structure-aware shape candidates beside Algorithm 1's mirrored facets (issue 28).

Most household objects stand on their support and have structure Algorithm 1 cannot see:
reflective symmetry planes through their middle, rotational symmetry about the support normal
(cans, cups, bowls, bottles), or the shape of a box, a cylinder or a sphere. Each generator
here turns the observed points (world frame, m) and one hidden-extent variate per hidden
direction into the points of a candidate; ``ipr_shapes.hypotheses.generate`` then takes their convex
hull, snaps it to the support, cuts it and checks it against the free space like every
hypothesis. Nothing here reads a model or a shape list: the generators are fits of generic
families to what was seen.

The upright frame: ``up`` the support normal, ``a`` and ``b`` horizontal. ``a`` is the
horizontal part of the normal of the largest near-vertical observed facet (the face of a box),
else the side of the minimum-area rectangle around the points' footprint. Heights are measured
from the support plane.

Hidden extent (Thrun & Wegbreit 2005 and Bohg et al. 2011 bound it by visibility; here by the
frame's free-space map, as Algorithm 1 does): for each of the six directions of the frame
(+-a, +-b, +-up), rays are cast from the observed points within ``rim_m`` of the points'
extreme along it; the largest extension that at most a ``quantile`` share of them block
(free voxel, support, wall) is that direction's reach. A candidate's variate t in [0, 1] per
direction extends the observed extent by t times the reach: a face seen whole (the top of a
box seen from above) has reach near 0, a hidden side the depth of the hidden space. That depth
is an upper bound, and usually a loose one: the unseen space behind and under an object is
mostly its own shadow, far deeper than the object (a box leaning on another has the whole
shadow under it). So each generator's first candidate is its own fit with no hidden
extension at all, and the others draw t = u^2 (u stratified): small extensions more often.

- ``symmetry`` (Thrun & Wegbreit 2005; Bohg et al. 2011): symmetry planes normal to the axes
  of a frame: the upright frame's vertical planes (normal to ``a``, to ``b``), and, when it
  differs by more than 10 degrees, the object's own frame from its faces (``facet_frame``: a
  box leaning on another), whose planes may be tilted, the one parallel to its largest face
  included. Along each axis the plane sits in the middle of the extent the variates give
  (observed extent plus the extension of the side with more reach), and the observed points
  are mirrored about it (the planes in turn; variants cycle through the frames and through
  subsets of the planes). The candidate is their hull: the object's own profile completed by
  its symmetry.
- ``revolution``: a surface of revolution about the support normal (the issue's rotational
  symmetry), or about a horizontal axis when that fits better (a can or a bottle lying on its
  side; 12 directions tried). For a direction, the axis is the common centre of circles
  fitted to 1 cm slices of the points along it (one linear least-squares problem:
  |p|^2 = 2 c.p + k_slice), for the vertical axis without the points of near-horizontal
  facets (a lid seen from above); the direction with the smallest RMS residual wins. Each
  slice's radius is its points' largest distance from the axis (or, opt-in, its side wall's
  mean distance: ``StructureSettings.mean_radius``). The
  candidate is the rings of the profile (circumscribed polygons). Variants move the axis
  along the hidden horizontal direction by up to two standard errors of the fitted centre (at
  least one voxel) either way.
- ``cylinder``: the same axis, one radius (the largest of all points), from the lowest to the
  highest point.
- ``box``: the frame-aligned box of the points extended by the variates (variants cycle
  through the frames as the symmetry's do).
- ``sphere``: a least-squares sphere through the points, radius the 95th percentile of the
  points' distances from its centre (the hull of the observed points is added, so every
  point stays inside), variants moved like the revolution's axis.

A fit applies only when its family describes the points: the revolution and cylinder when the
circles' RMS residual is at most ``circle_residual`` of the mean radius, the sphere when its
RMS residual is at most ``sphere_residual`` of its radius, and either only when its radius is
at most the points' horizontal (sphere: largest) extent, i.e. the points span an arc of at
least 60 degrees (a flat face fits a huge circle with a tiny residual); the upright generators
only when there is a support.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

#: Structure-aware generators, in the order their candidates are made (round robin; the
#: superquadric, ``ipr_shapes.hypotheses.superquadric``, takes its own count of the slots first).
STRUCTURE_GENERATORS = ("symmetry", "revolution", "box", "cylinder", "sphere", "superquadric")

#: Stable keys of the generators' random streams (``family_rng``): each family draws its
#: variates from its own stream, so a change in one family's draws (its count of fits, its
#: presence) leaves another's candidates of the same count bit-identical. Constants, not
#: positions in ``STRUCTURE_GENERATORS`` nor Python's salted ``hash``: a new family takes a new
#: number and the others keep theirs.
STREAM_KEYS = {
    "symmetry": 1,
    "revolution": 2,
    "box": 3,
    "cylinder": 4,
    "sphere": 5,
    "superquadric": 6,
}

#: Directions of the upright frame whose reach bounds the hidden extent: +a, -a, +b, -b, +up,
#: -up (indices into a variate vector).
DIRECTIONS = 6

#: reach(origins (R, 3), direction (3,)) -> (R,) free distance along the direction (m).
Reach = Callable[[np.ndarray, np.ndarray], np.ndarray]


#: Generators whose variate 0.5 is their fit (the others' smallest member is at 0).
CENTRED = ("revolution", "cylinder", "sphere", "superquadric")


def family_rng(root: np.random.SeedSequence, generator: str) -> np.random.Generator:
    """The generator's own random stream: the child of ``root`` with spawn key
    ``root.spawn_key + (STREAM_KEYS[generator],)``, made without advancing ``root``'s spawn
    counter, so it depends on ``root`` and the generator's name alone (not on which other
    families applied or how many variates they drew)."""
    return np.random.default_rng(
        np.random.SeedSequence(
            root.entropy,
            spawn_key=(*root.spawn_key, STREAM_KEYS[generator]),
            pool_size=root.pool_size,
        )
    )


def variates(
    generator: str, count: int, rng: np.random.Generator, fits: int = 1, width: int = DIRECTIONS
) -> np.ndarray:
    """(count, width) variates in [0, 1] of a generator's candidates (module doc): the first
    ``fits`` (one per frame the generator cycles through) are the family's own fit (0 for
    every direction: the observed extent; 0.5 for the centred generators: the fitted axis or
    centre), the others stratified per direction (shuffled independently); for the extents
    (symmetry, box) squared, so that small hidden extents are drawn more often."""
    out = np.full((count, width), 0.5 if generator in CENTRED else 0.0)
    rest = count - min(fits, count)
    if rest > 0:
        strata = np.stack([rng.permutation(rest) for _ in range(width)], axis=1)
        u = (strata + rng.random((rest, width))) / rest
        out[count - rest :] = u if generator in CENTRED else u**2
    return out


@dataclass(frozen=True)
class StructureSettings:
    """Settings of the structure-aware generators (metres; shares).

    Attributes:
        rim_m: ray origins are the points within this of the extreme along a direction.
        max_rays: rays per direction at most (taken evenly).
        quantile: share of a direction's rays its reach may cross blocked space on.
        slice_m: height of the revolution's slices.
        ring_sides: sides of the polygons of revolved shapes.
        circle_residual: RMS residual of the circle fit, as a share of the radius, above which
            the revolution and the cylinder do not apply.
        sphere_residual: the same for the sphere fit.
        pitch_m: the free-space grid's pitch (the smallest axis shift of the variants).
        mean_radius: the revolved shapes' radii are their side wall's mean distance from the
            axis (``revolution_points``), not the largest of any point's (default).
    """

    rim_m: float = 0.01
    max_rays: int = 48
    quantile: float = 0.1
    slice_m: float = 0.01
    ring_sides: int = 24
    circle_residual: float = 0.1
    sphere_residual: float = 0.05
    pitch_m: float = 0.005
    mean_radius: bool = False


@dataclass(frozen=True, eq=False)
class UprightFrame:
    """The object's frame on its support: unit ``a``, ``b`` (horizontal), ``up``; heights from
    the support plane {x : up . x + offset = 0}; ``hidden`` (2,) the horizontal direction (in
    a, b) away from the camera (zeros when unknown)."""

    a: np.ndarray
    b: np.ndarray
    up: np.ndarray
    offset: float
    hidden: np.ndarray

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) rows a, b, up."""
        return np.stack([self.a, self.b, self.up])

    def local(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) coordinates (along a, along b, height above the support)."""
        out = points @ self.rotation.T
        out[:, 2] += self.offset
        return out

    def world(self, local: np.ndarray) -> np.ndarray:
        """Inverse of ``local``."""
        shifted = np.array(local, dtype=float, copy=True)
        shifted[:, 2] -= self.offset
        return shifted @ self.rotation

    def direction(self, index: int) -> np.ndarray:
        """World direction (3,) of direction ``index`` (+a, -a, +b, -b, +up, -up)."""
        return (1.0 - 2.0 * (index % 2)) * self.rotation[index // 2]


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """u x v of (3,) vectors: ``np.cross``'s arithmetic (each product rounded, then their
    difference: the same bits) without its per-call overhead."""
    return np.array(
        [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    )


def _min_area_axis(flat: np.ndarray) -> np.ndarray:
    """Unit (2,) side direction of the minimum-area rectangle around 2-D points."""
    try:
        hull = flat[ConvexHull(flat).vertices]
    except (QhullError, ValueError):
        return np.array([1.0, 0.0])
    edges = np.roll(hull, -1, axis=0) - hull
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2))
    best, best_area = 0.0, np.inf
    for angle in angles:
        c, s = np.cos(angle), np.sin(angle)
        rotated = hull @ np.array([[c, -s], [s, c]])
        area = float(np.prod(np.ptp(rotated, axis=0)))
        if area < best_area:
            best, best_area = float(angle), area
    return np.array([np.cos(best), np.sin(best)])


def upright_frame(
    points: np.ndarray,
    facets: list[tuple[np.ndarray, float]],
    up: np.ndarray,
    offset: float,
    towards_camera: np.ndarray,
) -> UprightFrame:
    """The upright frame of an object resting on the support {up . x + offset = 0} (module
    doc); ``facets`` are (unit normal, area m^2) pairs, ``towards_camera`` (3,) the object's
    dominant normal."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    helper = np.eye(3)[int(np.argmin(np.abs(up)))]
    e1 = _cross(up, helper)
    e1 /= np.linalg.norm(e1)
    e2 = _cross(up, e1)
    vertical = [(n, area) for n, area in facets if abs(float(n @ up)) < 0.5]
    if vertical:
        normal = max(vertical, key=lambda item: item[1])[0]
        side = np.array([normal @ e1, normal @ e2])
    else:
        side = _min_area_axis(np.column_stack([points @ e1, points @ e2]))
    side = side / max(np.linalg.norm(side), 1e-12)
    a = side[0] * e1 + side[1] * e2
    b = _cross(up, a)
    hidden = -np.array([towards_camera @ a, towards_camera @ b])
    norm = float(np.linalg.norm(hidden))
    hidden = hidden / norm if norm > 0.2 else np.zeros(2)
    return UprightFrame(a, b, up, float(offset), hidden)


def facet_frame(
    points: np.ndarray, facets: list[tuple[np.ndarray, float]], towards_camera: np.ndarray
) -> UprightFrame | None:
    """The object's own frame from its observed faces, for objects that do not stand upright
    (a box leaning on another): ``up`` the largest facet's normal, ``a`` the largest facet's
    normal at least 60 degrees from it (made orthogonal), else the side of the minimum-area
    rectangle around the points projected along ``up``; None without a facet."""
    if not facets:
        return None
    ordered = sorted(facets, key=lambda item: -item[1])
    up = np.asarray(ordered[0][0], float)
    up = up / np.linalg.norm(up)
    helper = np.eye(3)[int(np.argmin(np.abs(up)))]
    e1 = _cross(up, helper)
    e1 /= np.linalg.norm(e1)
    e2 = _cross(up, e1)
    side = None
    for normal, _ in ordered[1:]:
        if abs(float(normal @ up)) < 0.5:
            side = np.array([normal @ e1, normal @ e2])
            break
    if side is None:
        side = _min_area_axis(np.column_stack([points @ e1, points @ e2]))
    side = side / max(np.linalg.norm(side), 1e-12)
    a = side[0] * e1 + side[1] * e2
    b = _cross(up, a)
    hidden = -np.array([towards_camera @ a, towards_camera @ b])
    norm = float(np.linalg.norm(hidden))
    hidden = hidden / norm if norm > 0.2 else np.zeros(2)
    return UprightFrame(a, b, up, 0.0, hidden)


def same_frame(first: UprightFrame, second: UprightFrame, degrees: float = 10.0) -> bool:
    """Whether two frames' axes agree up to order and sign within ``degrees``."""
    products = np.abs(first.rotation @ second.rotation.T)
    return bool(np.all(products.max(axis=1) >= np.cos(np.radians(degrees))))


def reaches(
    frame: UprightFrame, local: np.ndarray, points: np.ndarray, reach: Reach, s: StructureSettings
) -> np.ndarray:
    """(6,) reach (m) of each direction of the frame (module doc)."""
    out = np.zeros(DIRECTIONS)
    for index in range(DIRECTIONS):
        coordinate = local[:, index // 2] * (1.0 - 2.0 * (index % 2))
        origins = points[coordinate >= coordinate.max() - s.rim_m]
        if len(origins) > s.max_rays:
            origins = origins[np.linspace(0, len(origins) - 1, s.max_rays).round().astype(int)]
        limits = reach(origins, frame.direction(index))
        out[index] = max(float(np.quantile(limits, s.quantile)), 0.0)
    return out


def extents(local: np.ndarray, extension: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)) of the points' local extent grown by the (6,) extensions."""
    return local.min(axis=0) - extension[1::2], local.max(axis=0) + extension[0::2]


def box_points(frame: UprightFrame, local: np.ndarray, extension: np.ndarray) -> np.ndarray:
    """The 8 corners (world) of the frame-aligned box of the points grown by ``extension``."""
    lo, hi = extents(local, extension)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])  # fmt: skip
    return frame.world(corners)


def symmetry_points(
    frame: UprightFrame, local: np.ndarray, extension: np.ndarray, axes: tuple[int, ...]
) -> np.ndarray:
    """The points (world) and their mirror images about symmetry planes normal to the frame's
    ``axes`` (0: a, 1: b, 2: up), each in the middle of the extent along it that the
    extension of its side with more reach gives (module doc)."""
    cloud = local
    for axis in axes:
        lo, hi = float(local[:, axis].min()), float(local[:, axis].max())
        grow_up, grow_down = extension[2 * axis], extension[2 * axis + 1]
        middle = 0.5 * (lo + hi + grow_up) if grow_up >= grow_down else 0.5 * (lo + hi - grow_down)
        mirrored = cloud.copy()
        mirrored[:, axis] = 2.0 * middle - mirrored[:, axis]
        cloud = np.concatenate([cloud, mirrored])
    return frame.world(cloud)


@dataclass(frozen=True)
class AxisFit:
    """A vertical axis through ``centre`` (2,) (in a, b), the standard error of the centre
    (m), the RMS residual as a share of the mean radius, and that mean radius (m)."""

    centre: np.ndarray
    error_m: float
    residual: float
    radius_m: float


def _circle_centre(pts: np.ndarray, slices: np.ndarray):
    """Least-squares common centre (2,) of circles through each slice's points, the points'
    distances (N,) from it, the slices' mean distances, and the centre's standard error (m).

    The slice constants k_s of |p|^2 = 2 c.p + k_s are eliminated (k_s = the slice's mean of
    |p|^2 - 2 c.p), so c solves a 2 x 2 least-squares problem in slice-centred coordinates."""
    counts = np.bincount(slices).astype(float)
    target = pts[:, 0] ** 2 + pts[:, 1] ** 2
    xy = pts[:, :2]
    mean_xy = np.stack([np.bincount(slices, weights=xy[:, k]) for k in range(2)], axis=1)
    design = 2.0 * (xy - (mean_xy / counts[:, None])[slices])
    rhs = target - (np.bincount(slices, weights=target) / counts)[slices]
    normal = design.T @ design
    if abs(np.linalg.det(normal)) < 1e-18:
        return None
    centre = np.linalg.solve(normal, design.T @ rhs)
    radius = np.linalg.norm(xy - centre, axis=1)
    slice_radius = np.bincount(slices, weights=radius) / counts
    dof = max(len(pts) - 2 - len(counts), 1)
    variance = float(np.sum((design @ centre - rhs) ** 2)) / dof
    error = float(np.sqrt(max(np.max(np.diag(np.linalg.inv(normal))) * variance, 0.0)))
    return centre, radius, slice_radius, error


def _slices(pts: np.ndarray, s: StructureSettings) -> tuple[np.ndarray, np.ndarray]:
    """The points in slices of at least 4 points, and their slice numbers (0, 1, ...)."""
    if len(pts) == 0:
        return pts, np.zeros(0, dtype=np.int64)
    slices = np.floor((pts[:, 2] - pts[:, 2].min()) / s.slice_m).astype(np.int64)
    slices = _ranks(slices)
    ok = np.bincount(slices)[slices] >= 4
    return pts[ok], _ranks(slices[ok])


def _ranks(values: np.ndarray) -> np.ndarray:
    """``np.unique(values, return_inverse=True)[1]`` of non-negative ints (N,): each value's
    rank among the distinct values, by counting instead of sorting (the same integers); a
    range far wider than the count (an outlier kilometres off) sorts, like numpy."""
    if values.size == 0 or int(values.max()) > 4 * values.size + 1024:
        return np.unique(values, return_inverse=True)[1]
    present = np.zeros(int(values.max()) + 1, dtype=np.int64)
    present[values] = 1
    return (np.cumsum(present) - 1)[values]


#: The share of a slice's largest distance from the axis at and beyond which a point counts
#: as the side wall's (``_wall``): points well inside are a lid seen from above or a cup's
#: inner wall, not the circle.
WALL_SHARE = 0.85


def _wall(radius: np.ndarray, slices: np.ndarray) -> np.ndarray:
    """Which points (N,) of distances ``radius`` (N,) from the axis, in ``slices`` (N,)
    (0, 1, ...), are on their slice's side wall: at least ``WALL_SHARE`` of the slice's
    largest distance."""
    outer = np.zeros(int(slices.max()) + 1)
    np.maximum.at(outer, slices, radius)
    return radius >= WALL_SHARE * outer[slices]


def fit_axis(local: np.ndarray, keep: np.ndarray, s: StructureSettings) -> AxisFit | None:
    """The common centre of circles fitted to height slices of the points ``keep`` selects
    (module doc); None when fewer than 8 points remain.

    Fitted twice: the second time only on each slice's outer points (``_wall``), since points well inside a slice's circle are not on the side
    wall (a lid seen from above, a cup's inner wall), the residual is that fit's; None when
    fewer than 70 % of the points are outer ones (a box's faces: only the corners and the ends
    are near a circle through them). None too when
    a straight line per slice explains the points within twice the circles' RMS residual (a
    flat face is a circle of any large radius)."""
    pts, slices = _slices(local[keep], s)
    if len(pts) < 8:
        return None
    first = _circle_centre(pts, slices)
    if first is None:
        return None
    wall = _wall(first[1], slices)
    if wall.mean() < 0.7:
        return None  # most points are not on one circle per slice (a polygon's corners are)
    pts, slices = _slices(pts[wall], s)
    if len(pts) < 8:
        return None
    second = _circle_centre(pts, slices)
    if second is None:
        return None
    centre, radius, slice_radius, error = second
    mean_radius = float(np.mean(radius))
    if not np.isfinite(mean_radius) or mean_radius <= 0:
        return None
    rms = float(np.sqrt(np.mean((radius - slice_radius[slices]) ** 2)))
    # A straight face is a circle of any large radius: the points must be curved, i.e. far
    # worse explained by a line (per slice) than by the circles.
    counts = np.bincount(slices).astype(float)
    spread = (
        pts[:, :2]
        - (
            np.stack([np.bincount(slices, weights=pts[:, k]) for k in range(2)], axis=1)
            / counts[:, None]
        )[slices]
    )
    line_rms = float(np.sqrt(max(np.linalg.eigvalsh(spread.T @ spread / len(pts))[0], 0.0)))
    if line_rms < 2.0 * rms:
        return None
    return AxisFit(centre, error, rms / mean_radius, mean_radius)


def axis_frame(axis: np.ndarray, towards_camera: np.ndarray) -> UprightFrame:
    """A frame whose third direction is the unit ``axis`` (no support offset): for a surface of
    revolution about a direction other than the support normal (a can lying on its side)."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    a = _cross(axis, helper)
    a /= np.linalg.norm(a)
    b = _cross(axis, a)
    hidden = -np.array([towards_camera @ a, towards_camera @ b])
    norm = float(np.linalg.norm(hidden))
    hidden = hidden / norm if norm > 0.2 else np.zeros(2)
    return UprightFrame(a, b, axis, 0.0, hidden)


def surface_normals(points: np.ndarray, neighbours: int = 16) -> np.ndarray:
    """Unit surface normals (N, 3) of (N, 3) points (sign arbitrary): the least-spread axis
    of each point's ``neighbours`` nearest points (zeros with fewer than 4 points)."""
    from scipy.spatial import cKDTree

    n = len(points)
    if n < 4:
        return np.zeros((n, 3))
    _, index = cKDTree(points).query(points, k=min(neighbours, n))
    near = points[index]
    near = near - near.mean(axis=1, keepdims=True)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", near, near))
    return vectors[:, :, 0]


def revolution_axis(
    points: np.ndarray, normals: np.ndarray, trim: float = 0.2
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The axis (unit direction (3,), a point on it (3,)) of the surface of revolution that
    best explains points (N, 3) with unit surface normals (N, 3), and how far the normals
    miss it (RMS angle, radians); None when degenerate.

    Every normal line of a surface of revolution meets its axis (a lid's and an end cap's are
    parallel to it, which counts as meeting), so with the axis direction a and moment
    m = c x a (c on the axis) each point satisfies (p x n) . a + n . m = 0 (Pottmann and
    Randrup 1998, the linear line complex of rotational surfaces); the left side is
    (a x n) . (p - c), the point's distance from the axis times the sine of the angle by
    which its normal leaves the plane through the axis and the point. The axis is the
    least-squares solution with |a| = 1: m eliminated, a is the smallest eigenvector of the
    3 x 3 Schur complement. Refitted once without the ``trim`` share of the points that fit
    worst (other surfaces in the segment, noisy normals at edges); the angle is that of the
    points kept. A sphere or a plane fits many axes (the caller's circle fit decides whether
    the axis is any good); a shape that is no surface of revolution (a bottle with a flat
    cross-section) leaves its normals off every axis by a large angle."""
    if len(points) < 10:
        return None
    origin = points.mean(axis=0)
    p = points - origin
    lines = np.concatenate([np.cross(p, normals), normals], axis=1)
    weights = np.ones(len(p))
    axis = moment = None
    for _ in range(2):
        matrix = (lines * weights[:, None]).T @ lines
        a_block, b_block, c_block = matrix[:3, :3], matrix[:3, 3:], matrix[3:, 3:]
        c_inverse = np.linalg.pinv(c_block, rcond=1e-9)
        schur = a_block - b_block @ c_inverse @ b_block.T
        values, vectors = np.linalg.eigh(0.5 * (schur + schur.T))
        if not np.all(np.isfinite(values)):
            return None
        axis = vectors[:, 0]
        moment = -c_inverse @ b_block.T @ axis
        residual = np.abs(lines @ np.concatenate([axis, moment]))
        weights = (residual <= np.quantile(residual, 1.0 - trim)).astype(float)
    assert axis is not None and moment is not None
    # m = c x a, so a x m is the axis' point nearest the origin (|a| = 1).
    centre = _cross(axis, moment)
    across = p - centre
    across -= np.outer(across @ axis, axis)
    sines = residual / np.maximum(np.linalg.norm(across, axis=1), 1e-3)
    angle = float(np.sqrt(np.mean(sines[weights > 0] ** 2)))
    return axis, origin + centre, angle


def best_axis(
    upright: UprightFrame,
    points: np.ndarray,
    point_normals: np.ndarray,
    towards_camera: np.ndarray,
    s: StructureSettings,
    horizontal: int = 12,
    fitted_axis: bool = False,
) -> tuple[UprightFrame, np.ndarray, AxisFit] | None:
    """The axis of revolution that fits the points best: the support normal, or one of
    ``horizontal`` directions in the support plane (every 180/horizontal degrees, objects
    lying on their side), each fitted by ``fit_axis`` without the points whose facet normal
    (``point_normals`` (N, 3), zero for none) is within 37 degrees of the axis (a lid or an
    end cap lies inside the circles of the sides); (frame, local points, fit) of the smallest
    residual among the fits that apply (module doc), None when none does.

    With ``fitted_axis``, also the axis the points' own surface normals meet
    (``surface_normals``, ``revolution_axis``: a can leaning on another, at any tilt), its
    lids left out by those normals rather than by the facets' (a perceived facet may span a
    can's lid and side); only when the normals miss it by at most the circles' own share
    (``circle_residual``) as an angle in radians."""
    frames = [(upright, point_normals)]
    for angle in np.arange(horizontal) * np.pi / horizontal:
        axis = np.cos(angle) * upright.a + np.sin(angle) * upright.b
        frames.append((axis_frame(axis, towards_camera), point_normals))
    if fitted_axis:
        surface = surface_normals(points)
        found = revolution_axis(points, surface)
        if found is not None and found[2] <= s.circle_residual:
            frames.append((axis_frame(found[0], towards_camera), surface))
    return _best_fit(frames, points, s)


def _best_fit(
    frames: list[tuple[UprightFrame, np.ndarray]], points: np.ndarray, s: StructureSettings
) -> tuple[UprightFrame, np.ndarray, AxisFit] | None:
    """(frame, local points, fit) of the smallest circle residual among ``frames`` (each with
    the points' normals (N, 3) that leave out lids along its axis) whose fit applies."""
    best = None
    for frame, normals in frames:
        local = frame.local(points)
        keep = np.abs(normals @ frame.up) <= 0.8
        fit = fit_axis(local, keep, s)
        if fit is None or fit.residual > s.circle_residual:
            continue
        if fit.radius_m > float(np.ptp(local[:, :2], axis=0).max()):
            continue
        if best is None or fit.residual < best[2].residual:
            best = (frame, local, fit)
    return best


def _shifted(fit_centre: np.ndarray, frame: UprightFrame, error_m: float, t: float, pitch: float):
    """The centre moved along the hidden direction by (2t - 1) * max(2 error, pitch)."""
    return fit_centre + (2.0 * t - 1.0) * max(2.0 * error_m, pitch) * frame.hidden


def _rings(centre: np.ndarray, heights: np.ndarray, radii: np.ndarray, sides: int) -> np.ndarray:
    """Local points (len(heights) * sides, 3) of circumscribed polygons (radius / cos(pi/sides)),
    one per (height, radius)."""
    angles = 2 * np.pi * np.arange(sides) / sides
    scale = radii / np.cos(np.pi / sides)
    ring = np.column_stack([np.cos(angles), np.sin(angles)])
    xy = centre + scale[:, None, None] * ring[None, :, :]
    z = np.broadcast_to(heights[:, None, None], (len(heights), sides, 1))
    return np.concatenate([xy, z], axis=2).reshape(-1, 3)


def constant_radius(local: np.ndarray, fit: AxisFit, s: StructureSettings) -> bool:
    """Whether the points' ``local`` (N, 3) coordinates in the fit's frame lie on one
    cylinder: the side wall's mean distance from the axis per slice (``_wall``; slices of at
    least 4 wall points, as the circle fit's) varies about the slices' mean by an RMS of at
    most ``circle_residual`` of it, the share the circles themselves may miss by. A ball, a pear or a bottle's shoulder
    are surfaces of revolution but no cylinder: a cylinder of their mean radius is no shape
    of theirs and only moves the choice among the candidates."""
    radius = np.linalg.norm(local[:, :2] - fit.centre, axis=1)
    slices = _ranks(np.floor((local[:, 2] - local[:, 2].min()) / s.slice_m).astype(np.int64))
    wall = _wall(radius, slices)
    counts = np.bincount(slices[wall]).astype(float)
    used = counts >= 4  # a circle's slice (``_slices``)
    if not used.any():
        return False
    per_slice = np.bincount(slices[wall], weights=radius[wall])[used] / counts[used]
    mean = float(per_slice.mean())
    return mean > 0 and float(per_slice.std()) <= s.circle_residual * mean


def revolution_points(
    frame: UprightFrame,
    local: np.ndarray,
    extreme: np.ndarray,
    fit: AxisFit,
    t: float,
    s: StructureSettings,
    constant: bool = False,
) -> np.ndarray:
    """World points of the surface of revolution (or, ``constant``, the cylinder) about the
    fitted axis moved by variate ``t`` (module doc): its rings from the points' ``local``
    coordinates in ``frame``, with ``extreme`` (K, 3), the observed hull's vertices (world),
    so that every observed point stays inside."""
    centre = _shifted(fit.centre, frame, fit.error_m, t, s.pitch_m)
    radius = np.linalg.norm(local[:, :2] - centre, axis=1)
    low, high = float(local[:, 2].min()), float(local[:, 2].max())
    slices = np.floor((local[:, 2] - low) / s.slice_m).astype(np.int64)
    count = int(slices.max()) + 1
    wall = _wall(radius, slices) if s.mean_radius else np.ones(len(radius), bool)
    if constant:
        heights = np.array([low, high])
        radii = np.full(2, radius[wall].mean() if s.mean_radius else radius.max())
    else:
        if s.mean_radius:
            per_slice = np.bincount(slices[wall], weights=radius[wall], minlength=count)
            per_slice /= np.maximum(np.bincount(slices[wall], minlength=count), 1)
        else:
            per_slice = np.zeros(count)
            np.maximum.at(per_slice, slices, radius)
        bottoms = low + np.arange(count) * s.slice_m
        tops = np.minimum(bottoms + s.slice_m, high)
        occupied = np.bincount(slices, minlength=count) > 0
        heights = np.concatenate([bottoms[occupied], tops[occupied]])
        radii = np.concatenate([per_slice[occupied], per_slice[occupied]])
    return np.concatenate([frame.world(_rings(centre, heights, radii, s.ring_sides)), extreme])


@dataclass(frozen=True)
class SphereFit:
    """A sphere (centre (3,), world; radius m) and its RMS residual as a share of the radius."""

    centre: np.ndarray
    radius: float
    error_m: float
    residual: float


def fit_sphere(points: np.ndarray) -> SphereFit | None:
    """Least-squares sphere through (N, 3) points (|p|^2 = 2 c.p + k); None when degenerate."""
    if len(points) < 10:
        return None
    design = np.column_stack([2.0 * points, np.ones(len(points))])
    target = np.einsum("ij,ij->i", points, points)
    solution, *_ = np.linalg.lstsq(design, target, rcond=None)
    centre = solution[:3]
    squared = solution[3] + centre @ centre
    if not np.isfinite(squared) or squared <= 0:
        return None
    radius = float(np.sqrt(squared))
    distances = np.linalg.norm(points - centre, axis=1)
    rms = float(np.sqrt(np.mean((distances - radius) ** 2)))
    dof = max(len(points) - 4, 1)
    try:
        covariance = np.linalg.inv(design.T @ design) * (
            np.sum((design @ solution - target) ** 2) / dof
        )
        error = float(np.sqrt(max(np.max(np.diag(covariance)[:3]), 0.0)))
    except np.linalg.LinAlgError:
        error = 0.0
    return SphereFit(centre, radius, error, rms / radius)


def sphere_points(
    extreme: np.ndarray,
    points: np.ndarray,
    fit: SphereFit,
    t: float,
    s: StructureSettings,
    towards_camera: np.ndarray,
) -> np.ndarray:
    """World points of the sphere about the fitted centre moved by variate ``t`` away from the
    camera, with ``extreme`` (the observed hull's vertices). Radius: the 95th percentile of
    the distances of ``points`` (the observed points) from the centre, so that a few stray
    points (segmentation bleeding onto the table) add a bump to the hull, not a shell."""
    shift = max(2.0 * fit.error_m, s.pitch_m) * (2.0 * t - 1.0)
    centre = fit.centre - shift * towards_camera
    radius = float(np.quantile(np.linalg.norm(points - centre, axis=1), 0.95))
    # A geodesic-like cover: latitude rings circumscribed so the polytope holds the sphere.
    rings = max(s.ring_sides // 2, 4)
    polar = (np.arange(rings) + 0.5) * np.pi / rings
    lat_scale = 1.0 / np.cos(np.pi / (2 * rings))
    heights = radius * lat_scale * np.cos(polar)
    radii = radius * lat_scale * np.sin(polar)
    local = _rings(np.zeros(2), heights, radii, s.ring_sides)
    local = np.concatenate([local, [[0, 0, radius * lat_scale], [0, 0, -radius * lat_scale]]])
    return np.concatenate([centre + local, extreme])
