"""Superquadric candidates: a smooth generic family with fitted shape exponents (issue 28).

The structure-aware families (``ipr_shapes.hypotheses.structure``) are exact shapes: a box's
sharp edges, a cylinder's flat lid, a sphere. Most household objects are between them (a box
with rounded edges, a can's rounded rim, a fruit's flattened sphere), and the ceiling-gap
experiment found the best candidates off by a voxel or two over large areas for that reason
(docs/experiments/2026-11-26-ceiling-gap.md). A superquadric (Barr 1981; fitted to range data
as in Solina & Bajcsy 1990, to the visible part of unknown objects for grasping as in Vezzani
et al. 2017 and Makhal et al. 2018) covers them with two exponents: in a frame (a, b, up) about
a centre c, with semi-axes (s1, s2, s3) and exponents e1 (profile along ``up``) and e2 (the
cross-section), its inside-outside function is

    F(x, y, z) = (|x/s1|^(2/e2) + |y/s2|^(2/e2))^(e2/e1) + |z/s3|^(2/e1)

(F < 1 inside, = 1 on the surface). Exponents near 0 give a box, e2 = 1 a round cross-section
(e1 near 0: a cylinder), e1 = e2 = 1 an ellipsoid; exponents in [``min_exponent``, 1] keep it
convex and between those.

Fit (``fit``): in a frame of the object (the upright frame on the support; the object's own
frame from its faces too, for a box leaning or an object lying on its side, when the upright
fit fails or its residual is above half the gate), the parameters are the six extents along
+-a, +-b, +-up and e1, e2;
bounded least squares (``scipy.optimize.least_squares``) of

- each observed point's radial distance from the surface, |p - c| (1 - F(p)^(-e1/2)) (Jaklic
  et al. 2000: a metric approximation of the distance, unlike the raw F - 1 which weighs
  points by the shape's size);
- for seen-free voxel centres near the object (the frame's free-space map), how deep inside
  the superquadric they lie (the same distance, 0 outside): the camera saw that space empty,
  so the hidden side may not grow into it;

with each extent bounded below by the observed points' extent and above by the observed
extent plus the direction's reach (rays from the extreme points through the free space,
support and walls: ``structure.reaches``), so the bottom is never below the support, and
plus at most the points' largest extent (``extrapolation``). The fit
applies when the points' RMS distance is at most ``residual`` of the mean semi-axis.

Candidates (``surface_points``): the fit, then variants whose extension beyond the observed
extent in each direction is the fit's moved by (2t - 1) * max(half of it, ``spread_m``)
within [0, reach], and whose exponents are the fit's moved by (2t - 1) * ``exponent_spread``
within the bounds, t in [0, 1] per parameter (``structure.variates``, stratified; 0.5 is the
fit). The surface is sampled on a grid of the parametric angles and the candidate is the
convex hull of those points and the observed hull's vertices, so every observed point stays
inside (``ipr_shapes.hypotheses.generate`` finishes and checks it like every hypothesis).
Deterministic: no random draw in the fit, a fixed count of function evaluations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ipr_shapes.hypotheses.kernels import superquadric_residuals
from ipr_shapes.hypotheses.structure import UprightFrame
from ipr_shapes.perception.free_space import FREE, SeenSpace

#: Variates per candidate: the six extents (+a, -a, +b, -b, +up, -up), then e1, e2.
PARAMETERS = 8


@dataclass(frozen=True)
class SuperquadricSettings:
    """Settings of the superquadric fit (metres, shares); module defaults like
    ``structure.StructureSettings`` (``HypothesisConfig.superquadric_count`` turns it on).

    Attributes:
        min_exponent: smallest exponent (a box with edges rounded at about this share of its
            size); the largest is 1 (round), so every candidate is convex.
        residual: RMS radial distance of the points from the fitted surface, as a share of
            the mean semi-axis, above which the family does not apply (like the sphere's and
            the circles' gates).
        fit_points: observed points in the fit at most (taken evenly).
        free_points: seen-free voxel centres in the fit at most (a sixth beyond each side of
            the points' box, the nearest first).
        free_weight: weight of a free voxel's depth inside against a point's distance.
        max_evaluations: function evaluations of the least-squares fit at most (a count, not
            a time: results do not depend on the machine).
        tolerance: relative change of the cost and of the parameters at which the fit stops
            (``least_squares``' ftol and xtol).
        spread_m: the smallest move of a hidden extension between candidates.
        exponent_spread: the largest move of an exponent between candidates.
        rings: samples of the profile angle of the tessellation (the cross-section has twice).
        extrapolation: a direction's extent grows beyond the observed points' by at most
            this share of their largest extent (the shadow behind a small patch is no bound).
        room_quantile: the quantile of a direction's rays that bounds the fit's extent along
            it (``structure.reaches``; the other families use 0.1): the hidden part of a
            curved side reaches past the rays from its silhouette, which end in seen-free
            space at once, so the bound is loose and the seen-free voxels in the fit decide.
    """

    min_exponent: float = 0.1
    residual: float = 0.1
    fit_points: int = 100
    free_points: int = 240
    free_weight: float = 2.0
    max_evaluations: int = 50
    tolerance: float = 1e-6
    spread_m: float = 0.01
    exponent_spread: float = 0.1
    rings: int = 8
    room_quantile: float = 0.9
    extrapolation: float = 1.0


@dataclass(frozen=True, eq=False)
class SuperquadricFit:
    """A fitted superquadric in ``frame``: ``lo``, ``hi`` (3,) its extents (local coordinates:
    along a, along b, height), ``exponents`` (e1, e2), the observed points' extents ``seen_lo``,
    ``seen_hi`` (3,), the reach (6,) of each direction, and the RMS residual as a share of the
    mean semi-axis."""

    frame: UprightFrame
    lo: np.ndarray
    hi: np.ndarray
    exponents: np.ndarray
    seen_lo: np.ndarray
    seen_hi: np.ndarray
    room: np.ndarray
    residual: float


def _radial(local: np.ndarray, lo: np.ndarray, hi: np.ndarray, e1, e2) -> np.ndarray:
    """Signed radial distance of local points (N, 3) from the superquadric spanning [lo, hi]
    with exponents e1, e2: positive outside, negative inside (module doc). Several
    superquadrics at once: ``lo``, ``hi`` (P, 3) and ``e1``, ``e2`` (P,) give (P, N)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    e1, e2 = np.asarray(e1, float)[..., None], np.asarray(e2, float)[..., None]
    centre = 0.5 * (lo + hi)
    semi = np.maximum(0.5 * (hi - lo), 1e-6)
    p = local - centre[..., None, :]
    # In logs: the powers 2/e reach 20 for e = 0.1.
    logs = np.log(np.abs(p) / semi[..., None, :] + 1e-12)
    xy = np.logaddexp(2.0 / e2 * logs[..., 0], 2.0 / e2 * logs[..., 1]) * (e2 / e1)
    log_f = np.logaddexp(xy, 2.0 / e1 * logs[..., 2])
    scale = np.exp(np.clip(-0.5 * e1 * log_f, -50.0, 50.0))
    return np.sqrt(np.einsum("...i,...i->...", p, p)) * (1.0 - scale)


def _free_near(
    space: SeenSpace | None, frame: UprightFrame, lo: np.ndarray, hi: np.ndarray,
    local: np.ndarray, count: int,
) -> np.ndarray:  # fmt: skip
    """Local centres (F, 3) of at most ``count`` seen-free voxels in the box [lo, hi] (local),
    up to a sixth of them beyond each side of the box of the points ``local``, the nearest to
    the box first."""
    if space is None or count <= 0:
        return np.zeros((0, 3))
    # The voxels' centres, on a coarser lattice when the box is large (20 000 queries at most).
    pitch = float(space.grid.voxel_size_m)
    volume = float(np.prod(np.maximum(hi - lo, pitch)))
    pitch = max(pitch, (volume / 20_000) ** (1 / 3))
    axes = [np.arange(lo[i] + 0.5 * pitch, hi[i], pitch) for i in range(3)]
    if any(len(a) == 0 for a in axes):
        return np.zeros((0, 3))
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    free = grid[space.state_at(frame.world(grid)) == FREE]
    if len(free) <= count:
        return free
    # Each side of the points' box gets its share, the nearest to the box first: the nearest
    # overall are all on the seen side (in front of the camera), not behind the hidden ones.
    seen_lo, seen_hi = local.min(axis=0), local.max(axis=0)
    excess = np.empty((len(free), 6))
    excess[:, 0::2] = free - seen_hi
    excess[:, 1::2] = seen_lo - free
    side = np.argmax(excess, axis=1)
    outside = np.maximum(excess, 0.0)
    distance = np.einsum("ij,ij->i", outside, outside)
    # Ties (a whole shell of the lattice is equally near) broken by a fixed permutation, so
    # that the share spreads over the side instead of filling one corner in grid order.
    spread = np.random.default_rng(0).permutation(len(free))
    order = np.lexsort((spread, np.round(distance, 12), side))
    rank = np.arange(len(free)) - np.searchsorted(side[order], side[order])
    return free[order[rank < max(count // 6, 1)]]


def fit(
    frame: UprightFrame,
    points: np.ndarray,
    room: np.ndarray,
    space: SeenSpace | None,
    s: SuperquadricSettings,
) -> SuperquadricFit | None:
    """The superquadric of the observed points (N, 3) (world) in ``frame``, each extent within
    the observed one plus the (6,) ``room`` (+a, -a, +b, -b, +up, -up), seen-free voxels of
    ``space`` kept out (module doc); None when fewer than 10 points or the residual is above
    ``s.residual``."""
    if len(points) < 10:
        return None
    if len(points) > s.fit_points:
        points = points[np.linspace(0, len(points) - 1, s.fit_points).round().astype(np.int64)]
    local = frame.local(points)
    seen_lo, seen_hi = local.min(axis=0), local.max(axis=0)
    # No direction extrapolates further than the points' largest extent times
    # ``extrapolation``: the reach of a hidden side is mostly the object's shadow, and a fit to
    # a small patch would otherwise fill it.
    largest = float(np.ptp(local, axis=0).max())
    cap = max(s.extrapolation * largest, s.spread_m)
    room = np.minimum(np.maximum(np.asarray(room, float), 0.0), cap)
    max_lo, max_hi = seen_lo - room[1::2], seen_hi + room[0::2]
    free = _free_near(space, frame, max_lo - 0.01, max_hi + 0.01, local, s.free_points)
    # Start: the observed extents, each hidden side grown to half its room (at most the
    # observed size across it), exponents in the middle.
    size = np.maximum(seen_hi - seen_lo, 1e-3)
    grow = np.minimum(0.5 * room, float(size.max()))
    x0 = np.concatenate([seen_lo - grow[1::2], seen_hi + grow[0::2], [0.5, 0.5]])
    lower = np.concatenate([max_lo, seen_hi, [s.min_exponent] * 2])
    upper = np.concatenate([seen_lo, max_hi, [1.0, 1.0]])
    # least_squares needs lower < upper: a side with no room gets a hair of it.
    upper = np.maximum(upper, lower + 1e-6)
    x0 = np.clip(x0, lower, upper)
    weight = s.free_weight
    local_c, free_c = np.ascontiguousarray(local), np.ascontiguousarray(free, dtype=float)
    # The residuals and their exact Jacobian in one compiled pass (``kernels``):
    # least_squares asks for the Jacobian at the point whose residuals it just took.
    last: dict[str, np.ndarray] = {}

    def residuals(x: np.ndarray) -> np.ndarray:
        res, jac = superquadric_residuals(local_c, free_c, np.asarray(x, float), weight)
        last["x"], last["jac"] = x.copy(), jac
        return res

    def jacobian(x: np.ndarray, *_) -> np.ndarray:
        if "x" not in last or not np.array_equal(last["x"], x):
            residuals(x)
        return last["jac"]

    try:
        result = least_squares(
            residuals,
            x0,
            jac=jacobian,
            bounds=(lower, upper),
            x_scale="jac",
            ftol=s.tolerance,
            xtol=s.tolerance,
            max_nfev=s.max_evaluations,
        )
    except (ValueError, np.linalg.LinAlgError):
        return None
    x = result.x
    lo, hi, exponents = x[:3], x[3:6], x[6:8]
    distance = _radial(local, lo, hi, *exponents)
    rms = float(np.sqrt(np.mean(distance**2)))
    share = rms / max(float(np.mean(0.5 * (hi - lo))), 1e-6)
    if not np.isfinite(share) or share > s.residual:
        return None
    return SuperquadricFit(frame, lo, hi, exponents, seen_lo, seen_hi, room, share)


def _signed_power(value: np.ndarray, exponent: float) -> np.ndarray:
    return np.sign(value) * np.abs(value) ** exponent


def surface_points(
    found: SuperquadricFit, t: np.ndarray, extreme: np.ndarray, s: SuperquadricSettings
) -> np.ndarray:
    """World points of the candidate of variates ``t`` (8,) in [0, 1] (0.5: the fit; module
    doc): its surface sampled on the parametric angles, with ``extreme`` (K, 3), the observed
    hull's vertices (world), so that every observed point stays inside."""
    t = np.asarray(t, float)
    move = 2.0 * t - 1.0
    grow_fit = np.empty(6)
    grow_fit[0::2] = found.hi - found.seen_hi
    grow_fit[1::2] = found.seen_lo - found.lo
    grow_fit = np.maximum(grow_fit, 0.0)
    grow = grow_fit + move[:6] * np.maximum(0.5 * grow_fit, s.spread_m)
    grow = np.clip(grow, 0.0, np.maximum(found.room, grow_fit))
    lo, hi = found.seen_lo - grow[1::2], found.seen_hi + grow[0::2]
    exponents = np.clip(found.exponents + move[6:8] * s.exponent_spread, s.min_exponent, 1.0)
    e1, e2 = float(exponents[0]), float(exponents[1])
    centre, semi = 0.5 * (lo + hi), 0.5 * (hi - lo)
    eta = np.linspace(-np.pi / 2, np.pi / 2, s.rings + 1)
    omega = np.linspace(-np.pi, np.pi, 2 * s.rings, endpoint=False)
    ce, se = np.cos(eta)[:, None], np.sin(eta)[:, None]
    cw, sw = np.cos(omega)[None, :], np.sin(omega)[None, :]
    x = semi[0] * _signed_power(ce, e1) * _signed_power(cw, e2)
    y = semi[1] * _signed_power(ce, e1) * _signed_power(sw, e2)
    z = semi[2] * _signed_power(se, e1) * np.ones_like(cw)
    local = np.column_stack([x.ravel(), y.ravel(), z.ravel()]) + centre
    # Small exponents crowd the samples at the corners, microns apart: merged on a 0.1 mm
    # lattice, else qhull's facets among near-coincident points tilt (1e-8 of the size).
    local = np.unique(np.round(local, 4), axis=0)
    return np.concatenate([found.frame.world(local), extreme])
