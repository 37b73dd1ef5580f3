"""Superquadric candidates (ipr_shapes.hypotheses.superquadric): the fit of the family to
partial points with the seen-free space kept out, and its candidates on rendered shapes that
the exact families (box, sphere) miss: a box with rounded edges, a flattened ellipsoid."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from ipr_shapes.hypotheses import (
    HypothesisConfig,
    generate_hypotheses,
    kernels,
    structure,
    superquadric,
)
from ipr_shapes.perception.free_space import FREE, UNKNOWN, VoxelGrid

from .box_scene import SUPPORT
from .test_hypotheses import assert_valid
from .test_structure import best_by_generator, rendered

CONFIG = HypothesisConfig(count=16, superquadric_count=4)
SETTINGS = superquadric.SuperquadricSettings()
UP = np.array([0.0, 0.0, 1.0])


def rounded_box(extents, radius: float) -> trimesh.Trimesh:
    """A box of ``extents`` (3,) m with edges rounded at ``radius``, bottom on z = 0."""
    core = trimesh.creation.box(extents=np.asarray(extents, float) - 2 * radius)
    ball = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    points = (core.vertices[:, None, :] + ball.vertices[None]).reshape(-1, 3)
    mesh = trimesh.convex.convex_hull(points)
    mesh.apply_translation([0.0, 0.0, extents[2] / 2])
    return mesh


def ellipsoid(semi) -> trimesh.Trimesh:
    """An ellipsoid of semi-axes ``semi`` (3,) m resting on z = 0."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    mesh.apply_scale(semi)
    mesh.apply_translation([0.0, 0.0, semi[2]])
    return mesh


def superquadric_points(lo, hi, e1, e2, count, rng):
    """Points on the surface of the superquadric spanning [lo, hi] (z up) with exponents e1, e2
    (the module's parametrisation), angles uniform."""
    eta, omega = rng.uniform(-np.pi / 2, np.pi / 2, count), rng.uniform(-np.pi, np.pi, count)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    centre, semi = (lo + hi) / 2, (hi - lo) / 2

    def power(v, e):
        return np.sign(v) * np.abs(v) ** e

    x = semi[0] * power(np.cos(eta), e1) * power(np.cos(omega), e2)
    y = semi[1] * power(np.cos(eta), e1) * power(np.sin(omega), e2)
    z = semi[2] * power(np.sin(eta), e1)
    return np.column_stack([x, y, z]) + centre


class HalfFree:
    """A seen space that is FREE where y > ``y0`` (the camera saw it empty), else unknown."""

    def __init__(self, y0: float):
        self.y0 = y0
        self.grid = VoxelGrid.around(
            np.array([-0.2, -0.2, -0.05]), np.array([0.2, 0.2, 0.2]), 0.005
        )

    def state_at(self, points: np.ndarray) -> np.ndarray:
        return np.where(points[:, 1] > self.y0, FREE, UNKNOWN).astype(np.uint8)


def upright(points: np.ndarray, towards) -> structure.UprightFrame:
    return structure.upright_frame(points, [], UP, 0.0, np.asarray(towards, float))


def test_the_fit_recovers_extents_and_exponents_of_a_seen_half():
    """Points on the front half (y < 0.01) of a rounded box: extents within 3 mm (the hidden
    back from the curvature of the sides), exponents within 0.1."""
    rng = np.random.default_rng(0)
    lo, hi = np.array([-0.05, -0.03, 0.0]), np.array([0.05, 0.03, 0.08])
    points = superquadric_points(lo, hi, 0.3, 0.6, 6000, rng)
    points = points[points[:, 1] < 0.01] + rng.normal(0, 0.0003, (1, 3))
    frame = upright(points, (0.0, -1.0, 0.0))
    room = np.full(6, 0.1)
    found = superquadric.fit(frame, points, room, None, SETTINGS)
    assert found is not None and found.residual < 0.02
    world_lo = frame.world(found.lo[None])[0]
    world_hi = frame.world(found.hi[None])[0]
    span = np.sort(np.stack([world_lo, world_hi]), axis=0)
    assert np.abs(span[0] - lo).max() < 0.003 and np.abs(span[1] - hi).max() < 0.003
    assert found.exponents == pytest.approx([0.3, 0.6], abs=0.1)


def test_seen_free_space_keeps_the_hidden_side_out():
    """A third of a cylinder's side (facing -y, y <= -0.0175) curves away from the camera; the
    fit alone closes it behind y = 0; with the space from y = -0.01 on seen free, the fitted
    back stays within one step of the free voxels' lattice (5-6 mm here) and 1 mm of y = -0.01."""
    rng = np.random.default_rng(1)
    angle = np.radians(rng.uniform(-150, -30, 3000))
    side = np.column_stack(
        [0.035 * np.cos(angle), 0.035 * np.sin(angle), rng.uniform(0.0, 0.1, 3000)]
    )
    frame = upright(side, (0.0, -1.0, 0.0))
    room = np.full(6, 0.04)
    loose = superquadric.fit(frame, side, room, None, SETTINGS)
    assert loose is not None
    assert frame.world(np.array([loose.lo, loose.hi]))[:, 1].max() > 0.0
    found = superquadric.fit(frame, side, room, HalfFree(-0.01), SETTINGS)
    assert found is not None
    assert frame.world(np.array([found.lo, found.hi]))[:, 1].max() <= -0.01 + 0.007


def test_points_off_the_family_do_not_apply():
    """A tetrahedron's corner region is no superquadric in the upright frame: the residual
    gate refuses it (no candidates), as the sphere's and the circles' gates do."""
    rng = np.random.default_rng(2)
    corner = np.array([0.0, 0.0, 0.0])
    tips = np.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]])
    faces = []
    for i in range(3):
        u, v = rng.uniform(0, 1, (2, 1500))
        keep = u + v <= 1
        a, b = tips[i], tips[(i + 1) % 3]
        faces.append(corner + u[keep, None] * (a - corner) + v[keep, None] * (b - corner))
    tilted = np.concatenate(faces) + rng.normal(0, 0.0003, (1, 3))
    rotation = trimesh.transformations.rotation_matrix(np.radians(35), [1, 1, 0])[:3, :3]
    tilted = tilted @ rotation.T
    tilted[:, 2] -= tilted[:, 2].min()
    frame = upright(tilted, (0.0, -1.0, 0.0))
    assert superquadric.fit(frame, tilted, np.full(6, 0.05), None, SETTINGS) is None


@pytest.mark.parametrize(
    ("mesh", "eye", "rival", "floor"),
    [
        (rounded_box([0.1, 0.06, 0.08], 0.012), (0.3, -0.3, 0.2), "box", 0.95),
        (ellipsoid([0.04, 0.035, 0.03]), (0.0, -0.45, 0.4), "sphere", 0.86),
        (ellipsoid([0.04, 0.035, 0.03]), (0.3, -0.3, 0.2), "sphere", 0.82),
    ],
)
def test_rounded_shapes_get_a_superquadric_the_exact_families_miss(mesh, eye, rival, floor):
    obj, space, truth = rendered(mesh, eye, (0.0, 0.0, 0.04))
    hypotheses = generate_hypotheses(obj, space, (SUPPORT,), CONFIG, np.random.default_rng(0))
    assert sum(h.generator == "superquadric" for h in hypotheses) == CONFIG.superquadric_count
    for h in hypotheses:
        assert_valid(h, obj.points, convex_tolerance=1e-8)
    best = best_by_generator(hypotheses, truth)
    assert best["superquadric"] >= floor
    assert best["superquadric"] > best[rival] + 0.04
    # Feasible superquadrics respect the seen-free space within the unary tolerance.
    tolerance = CONFIG.unary
    for h in hypotheses:
        if h.generator == "superquadric" and h.feasible:
            allowed = max(tolerance.free_space_tolerance * h.keys().size,
                          tolerance.free_space_tolerance_voxels)  # fmt: skip
            assert h.free_voxels <= allowed
    # The fit first, then variants: the volumes differ.
    volumes = [h.volume_m3 for h in hypotheses if h.generator == "superquadric"]
    assert len(set(np.round(volumes, 9))) > 1


def test_candidates_are_deterministic_and_can_be_turned_off():
    mesh = rounded_box([0.1, 0.06, 0.08], 0.012)
    obj, space, _ = rendered(mesh, (0.3, -0.3, 0.2), (0.0, 0.0, 0.04))
    first = generate_hypotheses(obj, space, (SUPPORT,), CONFIG, np.random.default_rng(0))
    again = generate_hypotheses(obj, space, (SUPPORT,), CONFIG, np.random.default_rng(0))
    for a, b in zip(first, again, strict=True):
        assert a.generator == b.generator
        np.testing.assert_array_equal(a.vertices, b.vertices)
    default = dataclasses.replace(CONFIG, superquadric_count=0)
    plain = generate_hypotheses(obj, space, (SUPPORT,), default, np.random.default_rng(0))
    assert "superquadric" not in {h.generator for h in plain}
    assert sum(h.generator == "algorithm1" for h in plain) == CONFIG.count // 2


def test_the_tessellation_lies_on_the_fitted_surface():
    """The candidate's surface samples are on the superquadric the fit's inside-outside
    function describes (within the 0.1 mm lattice they are merged on), for the fit's variates
    (0.5) and, with other exponents, for a variant."""
    frame = upright(np.array([[0.0, 0.0, 0.0], [0.1, 0.06, 0.0]]), (0.0, -1.0, 0.0))
    lo, hi = np.array([-0.05, -0.03, 0.0]), np.array([0.05, 0.03, 0.08])
    found = superquadric.SuperquadricFit(
        frame, lo, hi, np.array([0.3, 0.7]), lo, hi, np.zeros(6), 0.0
    )
    move = SETTINGS.exponent_spread
    for t, exponents in [(0.5, (0.3, 0.7)), (1.0, (0.3 + move, 0.7 + move))]:
        world = superquadric.surface_points(found, np.full(8, t), np.zeros((0, 3)), SETTINGS)
        distance = superquadric._radial(frame.local(world), lo, hi, *exponents)
        assert np.abs(distance).max() < 2e-4


def test_compiled_residuals_and_jacobian_match_numpy_and_finite_differences():
    """``kernels.superquadric_residuals`` gives the fit's numpy residuals (``_radial`` on the
    points, the weighted depth of the free voxels inside) and, as its Jacobian, their central
    finite differences: shapes from boxes to ellipsoids, points inside and outside, on the
    axes' planes (q_i = 0) and free voxels both inside and outside."""
    rng = np.random.default_rng(3)
    weight = SETTINGS.free_weight
    inside_free = 0
    for trial in range(60):
        lo, hi = -rng.uniform(0.02, 0.08, 3), rng.uniform(0.02, 0.08, 3)
        e1, e2 = rng.uniform(SETTINGS.min_exponent, 1.0, 2)
        x = np.concatenate([lo, hi, [e1, e2]])
        points = superquadric_points(lo, hi, e1, e2, 40, rng) + rng.normal(0, 0.004, (40, 3))
        points[:4, trial % 3] = (lo + hi)[trial % 3] / 2  # on a plane of the centre
        free = rng.uniform(-0.09, 0.09, (30, 3))

        def numpy_residuals(x, points=points, free=free):
            lo, hi, e1, e2 = x[:3], x[3:6], x[6], x[7]
            depth = np.maximum(-superquadric._radial(free, lo, hi, e1, e2), 0.0)
            return np.concatenate([superquadric._radial(points, lo, hi, e1, e2), weight * depth])

        res, jac = kernels.superquadric_residuals(points, free, x, weight)
        np.testing.assert_allclose(res, numpy_residuals(x), rtol=0, atol=1e-15)
        step = 1e-7
        differences = np.stack(
            [
                (numpy_residuals(x + step * unit) - numpy_residuals(x - step * unit)) / (2 * step)
                for unit in np.eye(8)
            ],
            axis=1,
        )
        # Away from the free term's kink at the surface (|depth| within the step).
        smooth = np.abs(res) > 1e-5
        np.testing.assert_allclose(jac[smooth], differences[smooth], rtol=1e-5, atol=1e-6)
        inside_free += int((res[40:] > 0).sum())
    assert inside_free > 100


def test_the_hypotheses_stage_fits_on_one_blas_thread_and_restores_the_callers(monkeypatch):
    """The stage's linear algebra is small (the fits' SVDs of about 100 x 8 Jacobians): OpenBLAS
    threads over every core spin for nothing and make a fit's last bits depend on the core
    count. ``prepare_hypotheses`` fits on one BLAS thread whatever its caller set, and leaves
    the caller's setting as it was."""
    from threadpoolctl import ThreadpoolController, threadpool_info

    from ipr_shapes.hypotheses import prepare_hypotheses

    def blas_threads() -> int:
        return max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")

    seen: list[int] = []
    real = superquadric.least_squares

    def counted(*args, **kwargs):
        seen.append(blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(superquadric, "least_squares", counted)
    mesh = rounded_box([0.1, 0.06, 0.08], 0.012)
    obj, space, _ = rendered(mesh, (0.3, -0.3, 0.2), (0.0, 0.0, 0.04))
    with ThreadpoolController().limit(limits=2, user_api="blas"):
        if blas_threads() < 2:
            pytest.skip("this machine's BLAS runs one thread at most")
        prepare_hypotheses((obj,), space, (SUPPORT,), CONFIG)
        assert blas_threads() == 2
    assert seen and set(seen) == {1}
