"""Candidates carved before the choice (``CarvingConfig.before_choice``): their voxels lose what
the camera saw empty, their convex meshes stay, the medoid weighs the carved shapes and the
written shape is the carved one."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ipr_shapes import voxels
from ipr_shapes.camera import look_at
from ipr_shapes.carving import (
    SurfaceView,
    carve_hypotheses,
    carve_posteriors,
    carve_voxels,
    observed_surface_depth,
)
from ipr_shapes.factor_graph import PairwiseIoU, posterior_medoid
from ipr_shapes.hypotheses import HypothesisConfig, prepare_hypotheses
from ipr_shapes.products import ObjectPosterior, ShapeHypothesis
from tests.box_scene import SUPPORT, K, box_mesh, partial_box, render_view

PITCH = voxels.DEFAULT_PITCH_M
#: A camera on -y looking along +y; its view of a wall at y = 0 (planar depth 0.5 m
#: everywhere): everything at y < 0 was seen empty, everything behind the wall is hidden.
CAMERA = look_at(np.array([0.0, -0.5, 0.02]), np.array([0.0, 0.0, 0.02]))
WALL_VIEW = SurfaceView(np.full((240, 320), 0.5), K, CAMERA, 0.0)


def _slab(front_m: float, back_m: float, index: int) -> ShapeHypothesis:
    """A candidate 8 x 4 cm across reaching ``front_m`` towards the camera (y < 0) and
    ``back_m`` behind the wall (multiples of the pitch: faces on voxel boundaries)."""
    half = np.array([0.04, (front_m + back_m) / 2, 0.02])
    vertices, faces = box_mesh(half, np.array([0.0, (back_m - front_m) / 2, 0.02]))
    return ShapeHypothesis(
        1, index, vertices, faces, float(np.prod(2 * half)), np.zeros(0), np.zeros((0, 3))
    )


def test_carving_before_the_choice_moves_the_medoid_to_the_shapes_that_are_written():
    # Two candidates that bulge 5 cm into the space the camera saw empty and end 4 / 4.5 cm
    # behind the wall, two that do not bulge and end 6 / 6.5 cm behind it.
    hyps = tuple(
        _slab(front, back, k)
        for k, (front, back) in enumerate([(0.05, 0.04), (0.05, 0.045), (0.0, 0.06), (0.0, 0.065)])
    )
    weights = np.full(len(hyps), 0.25)
    # As convex hulls the bulging pair is closest to the rest ...
    assert posterior_medoid(hyps, weights, PairwiseIoU(hyps)) == 1
    carved = carve_hypotheses(hyps, 1, [WALL_VIEW])
    # ... carved, the bulges are gone and the medoid is the one between the hidden extents.
    assert posterior_medoid(carved, weights, PairwiseIoU(carved)) == 2
    for before, after in zip(hyps, carved, strict=True):
        # The physics' convex mesh is unchanged; the voxels are the carved ones.
        assert after.vertices is before.vertices and after.faces is before.faces
        assert np.array_equal(after.keys(PITCH), carve_voxels(before.keys(PITCH), 1, [WALL_VIEW]))
    assert [h.carved for h in carved] == [True, True, False, False]
    assert carved[2] is hyps[2]  # nothing seen empty: the hypothesis as it was


def test_a_candidate_carved_before_the_choice_is_written_carved():
    hyps = carve_hypotheses((_slab(0.05, 0.04, 0), _slab(0.0, 0.06, 1)), 1, [WALL_VIEW])
    posterior = ObjectPosterior(1, hyps, np.array([0.5, 0.5]), 0, hyps[1], "independent")
    written = carve_posteriors([posterior], [WALL_VIEW])[0]
    # The views remove nothing more from the carved voxels: the written shape is those voxels
    # (a closed voxel mesh), not the convex hull the physics simulated.
    assert written.output_keys[0] is not None
    assert np.array_equal(written.output_keys[0], hyps[0].keys(PITCH))
    assert written.output_keys[0].size < voxels.scanline_voxels(*hyps[0].mesh, PITCH).size
    assert np.array_equal(voxels.occupied_voxels(written.output_mesh, PITCH), hyps[0].keys(PITCH))
    assert written.output_meshes[1] is None  # uncarved and nothing to remove: written as is


def test_prepare_hypotheses_carves_after_the_same_unary_checks():
    view = render_view([0.25, -0.3, 0.25])
    obj = partial_box(view)
    space = view.space()
    frame = type("Frame", (), {"depth_m": view.depth, "world_from_camera": view.world_from_camera,
                               "robot_mask": None})()  # fmt: skip
    surface = SurfaceView(observed_surface_depth(frame, (obj,)), K, view.world_from_camera, 0.0)
    config = HypothesisConfig(count=12)
    plain = prepare_hypotheses((obj,), space, (SUPPORT,), config, rng=np.random.default_rng(2))
    carved = prepare_hypotheses(
        (obj,), space, (SUPPORT,), config, rng=np.random.default_rng(2),
        carve=functools.partial(carve_hypotheses, views=[surface]),
    )  # fmt: skip
    assert carved.candidates == plain.candidates  # the same feasible candidates
    before, after = plain.generated[obj.id], carved.generated[obj.id]
    assert len(before) == len(after)
    assert any(h.carved for h in after)
    for b, a in zip(before, after, strict=True):
        assert np.array_equal(a.vertices, b.vertices)
        assert np.array_equal(a.keys(PITCH), carve_voxels(b.keys(PITCH), obj.id, [surface]))


def test_the_pipeline_carves_the_candidates_before_the_choice_only_when_asked(
    scene_dir, monkeypatch
):
    """``CarvingConfig.before_choice`` hands the run's carving to the hypotheses of the
    Collision Checker and of the physics methods, and the written best shape is the carved
    candidate's voxels; off (the default), no carving reaches them."""
    from ipr_shapes import pipeline
    from ipr_shapes.config import Config
    from ipr_shapes.scene import load_scene

    seen = []
    checker, prepare = pipeline.collision_checker, pipeline.prepare_hypotheses

    def checker_recording(*args, **kwargs):
        seen.append(kwargs.get("carve"))
        return checker(*args, **kwargs)

    def prepare_recording(*args, **kwargs):
        seen.append(args[9] if len(args) > 9 else kwargs.get("carve"))
        return prepare(*args, **kwargs)

    monkeypatch.setattr(pipeline, "collision_checker", checker_recording)
    monkeypatch.setattr(pipeline, "prepare_hypotheses", prepare_recording)
    scene, base = load_scene(scene_dir), Config()
    for before in (True, False):
        config = dataclasses.replace(
            base, carving=dataclasses.replace(base.carving, before_choice=before)
        )
        for method in ("collision-checker", "ipr+uniform"):
            result = pipeline.run_pipeline(scene, config, method=method, samples=2, workers=1)
            hyps = [h for p in result.posteriors for h in p.hypotheses]
            assert any(h.carved for h in hyps) == before
            for posterior in result.posteriors:
                best = posterior.hypotheses[posterior.best]
                if best.carved:  # written as its carved voxels (edge contacts joined)
                    written = posterior.written_shape(posterior.best)
                    assert np.isin(best.keys(PITCH), written).all()
                    assert written.size < voxels.scanline_voxels(*best.mesh, PITCH).size
    assert all(carve is not None for carve in seen[:2])
    assert seen[2:] == [None, None]
