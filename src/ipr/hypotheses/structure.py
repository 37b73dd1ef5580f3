"""Structure-aware shape candidates beside Algorithm 1's mirrored facets (issue 28).

Most household objects stand on their support and have structure Algorithm 1 cannot see:
reflective symmetry planes through their middle, rotational symmetry about the support normal
(cans, cups, bowls, bottles), or the shape of a box, a cylinder or a sphere. Each generator
here turns the observed points (world frame, m) and one hidden-extent variate per hidden
direction into the points of a candidate; ``ipr.hypotheses.generate`` then takes their convex
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
box seen from above) has reach near 0, a hidden side the depth of the hidden space.

- ``symmetry`` (Thrun & Wegbreit 2005; Bohg et al. 2011): vertical symmetry planes normal to
  ``a`` and to ``b``. Along each axis the plane sits in the middle of the extent the variates
  give (observed extent plus the extension of the side with more reach), and the observed
  points are mirrored about it (both planes in turn, or one: variants cycle through
  {a and b, a, b}). The candidate is their hull: the object's own profile completed by its
  symmetry.
- ``revolution``: a surface of revolution about a vertical axis. The axis is the common
  centre of circles fitted to 1 cm height slices of the points (one linear least-squares
  problem: |p|^2 = 2 c.p + k_slice), the points of near-horizontal facets (a lid seen from
  above) left out; each slice's radius is its points' largest distance from the axis. The
  candidate is the rings of the profile (circumscribed polygons). Variants move the axis
  along the hidden horizontal direction by up to two standard errors of the fitted centre (at
  least one voxel) either way.
- ``cylinder``: the same axis, one radius (the largest of all points), from the lowest to the
  highest point.
- ``box``: the frame-aligned box of the points extended by the variates.
- ``sphere``: a least-squares sphere through the points, radius the largest distance of a
  point from its centre, variants moved like the revolution's axis.

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

#: Structure-aware generators, in the order their candidates are made (round robin).
STRUCTURE_GENERATORS = ("symmetry", "revolution", "box", "cylinder", "sphere")

#: Directions of the upright frame whose reach bounds the hidden extent: +a, -a, +b, -b, +up,
#: -up (indices into a variate vector).
DIRECTIONS = 6

#: reach(origins (R, 3), direction (3,)) -> (R,) free distance along the direction (m).
Reach = Callable[[np.ndarray, np.ndarray], np.ndarray]


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
    """

    rim_m: float = 0.01
    max_rays: int = 48
    quantile: float = 0.1
    slice_m: float = 0.01
    ring_sides: int = 24
    circle_residual: float = 0.1
    sphere_residual: float = 0.05
    pitch_m: float = 0.005


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
    e1 = np.cross(up, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    vertical = [(n, area) for n, area in facets if abs(float(n @ up)) < 0.5]
    if vertical:
        normal = max(vertical, key=lambda item: item[1])[0]
        side = np.array([normal @ e1, normal @ e2])
    else:
        side = _min_area_axis(np.column_stack([points @ e1, points @ e2]))
    side = side / max(np.linalg.norm(side), 1e-12)
    a = side[0] * e1 + side[1] * e2
    b = np.cross(up, a)
    hidden = -np.array([towards_camera @ a, towards_camera @ b])
    norm = float(np.linalg.norm(hidden))
    hidden = hidden / norm if norm > 0.2 else np.zeros(2)
    return UprightFrame(a, b, up, float(offset), hidden)


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
    """The points (world) and their mirror images about vertical symmetry planes normal to the
    frame's ``axes`` (0: a, 1: b), each in the middle of the extent along it that the
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


def fit_axis(local: np.ndarray, keep: np.ndarray, s: StructureSettings) -> AxisFit | None:
    """The common centre of circles fitted to height slices of the points ``keep`` selects
    (module doc); None when fewer than 8 points or 3 unknowns' worth of slices."""
    pts = local[keep]
    if len(pts) < 8:
        return None
    slices = np.floor((pts[:, 2] - pts[:, 2].min()) / s.slice_m).astype(np.int64)
    labels, slices = np.unique(slices, return_inverse=True)
    counts = np.bincount(slices)
    ok = counts[slices] >= 4
    pts, slices = pts[ok], np.unique(slices[ok], return_inverse=True)[1]
    if len(pts) < 8:
        return None
    columns = slices.max() + 1
    design = np.zeros((len(pts), 2 + columns))
    design[:, 0], design[:, 1] = 2.0 * pts[:, 0], 2.0 * pts[:, 1]
    design[np.arange(len(pts)), 2 + slices] = 1.0
    target = pts[:, 0] ** 2 + pts[:, 1] ** 2
    solution, *_ = np.linalg.lstsq(design, target, rcond=None)
    centre = solution[:2]
    radius = np.linalg.norm(pts[:, :2] - centre, axis=1)
    slice_radius = np.bincount(slices, weights=radius) / np.bincount(slices)
    mean_radius = float(np.mean(radius))
    if not np.isfinite(mean_radius) or mean_radius <= 0:
        return None
    rms = float(np.sqrt(np.mean((radius - slice_radius[slices]) ** 2)))
    dof = max(len(pts) - design.shape[1], 1)
    try:
        covariance = np.linalg.inv(design.T @ design) * (
            np.sum((design @ solution - target) ** 2) / dof
        )
        error = float(np.sqrt(max(np.max(np.diag(covariance)[:2]), 0.0)))
    except np.linalg.LinAlgError:
        error = 0.0
    return AxisFit(centre, error, rms / mean_radius, mean_radius)


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


def revolution_points(
    frame: UprightFrame,
    local: np.ndarray,
    fit: AxisFit,
    t: float,
    s: StructureSettings,
    constant: bool = False,
) -> np.ndarray:
    """World points of the surface of revolution (or, ``constant``, the cylinder) about the
    fitted axis moved by variate ``t`` (module doc), with the observed points."""
    centre = _shifted(fit.centre, frame, fit.error_m, t, s.pitch_m)
    radius = np.linalg.norm(local[:, :2] - centre, axis=1)
    low, high = float(local[:, 2].min()), float(local[:, 2].max())
    if constant:
        heights = np.array([low, high])
        radii = np.full(2, radius.max())
    else:
        slices = np.floor((local[:, 2] - low) / s.slice_m).astype(np.int64)
        count = int(slices.max()) + 1
        per_slice = np.zeros(count)
        np.maximum.at(per_slice, slices, radius)
        bottoms = low + np.arange(count) * s.slice_m
        tops = np.minimum(bottoms + s.slice_m, high)
        occupied = np.bincount(slices, minlength=count) > 0
        heights = np.concatenate([bottoms[occupied], tops[occupied]])
        radii = np.concatenate([per_slice[occupied], per_slice[occupied]])
    return np.concatenate([frame.world(_rings(centre, heights, radii, s.ring_sides)),
                           frame.world(local)])  # fmt: skip


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
    points: np.ndarray, fit: SphereFit, t: float, s: StructureSettings, towards_camera: np.ndarray
) -> np.ndarray:
    """World points of the sphere about the fitted centre moved by variate ``t`` away from the
    camera (radius: the farthest observed point), with the observed points."""
    shift = max(2.0 * fit.error_m, s.pitch_m) * (2.0 * t - 1.0)
    centre = fit.centre - shift * towards_camera
    radius = float(np.linalg.norm(points - centre, axis=1).max())
    # A geodesic-like cover: latitude rings circumscribed so the polytope holds the sphere.
    rings = max(s.ring_sides // 2, 4)
    polar = (np.arange(rings) + 0.5) * np.pi / rings
    lat_scale = 1.0 / np.cos(np.pi / (2 * rings))
    heights = radius * lat_scale * np.cos(polar)
    radii = radius * lat_scale * np.sin(polar)
    local = _rings(np.zeros(2), heights, radii, s.ring_sides)
    local = np.concatenate([local, [[0, 0, radius * lat_scale], [0, 0, -radius * lat_scale]]])
    return np.concatenate([centre + local, points])
