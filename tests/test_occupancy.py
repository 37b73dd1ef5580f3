"""Per-voxel occupancy of a result (``occupancy.npz``): probabilities from the weighted written
shapes, the scene's from the objects', the file's layout, and clear rejection of bad files."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from ipr_shapes import voxels
from ipr_shapes.camera import look_at
from ipr_shapes.errors import ResultError
from ipr_shapes.products import ObjectPosterior, ShapeHypothesis
from ipr_shapes.result import (
    OCCUPANCY_FILE,
    load_occupancy,
    posterior_occupancy,
    write_posterior_result,
    write_result,
)

WORLD_FROM_CAMERA = look_at(np.array([0.5, -0.4, 0.6]), np.zeros(3))
PITCH = voxels.DEFAULT_PITCH_M


def _box(low, high) -> trimesh.Trimesh:
    low, high = np.asarray(low, float), np.asarray(high, float)
    box = trimesh.creation.box(extents=high - low)
    box.apply_translation((low + high) / 2)
    return box


def _probability_at(pair, point) -> float:
    """The probability of the voxel holding ``point`` (m), 0 when it is not listed."""
    indices, probability = pair
    wanted = np.floor(np.asarray(point) / PITCH).astype(np.int32)
    match = np.flatnonzero((indices == wanted).all(axis=1))
    return float(probability[match[0]]) if match.size else 0.0


SMALL = _box((0.0, 0.0, 0.0), (0.02, 0.02, 0.02))
LARGE = _box((0.0, 0.0, 0.0), (0.04, 0.02, 0.02))  # SMALL and a second cube beside it


def test_probabilities_are_the_weights_of_the_shapes_holding_each_voxel():
    occupancy = posterior_occupancy({0: [(SMALL, 0.3), (LARGE, 0.7)]})
    indices, probability = occupancy.objects[0]
    assert indices.dtype == np.int32 and indices.shape[1] == 3
    assert probability.dtype == np.float32
    assert np.all((probability >= 0) & (probability <= 1))
    assert _probability_at(occupancy.objects[0], (0.0125, 0.0075, 0.0075)) == pytest.approx(1.0)
    assert _probability_at(occupancy.objects[0], (0.0325, 0.0075, 0.0075)) == pytest.approx(0.7)
    assert _probability_at(occupancy.objects[0], (0.0525, 0.0075, 0.0075)) == 0.0
    # Every voxel of the larger cube is listed: 8 x 4 x 4, half of them at 1.
    assert len(indices) == 8 * 4 * 4
    assert np.count_nonzero(np.isclose(probability, 1.0)) == 4 * 4 * 4
    # Voxel centres are the contract's grid: (n + 1/2) * 5 mm.
    assert np.allclose(occupancy.centres_m(indices) / PITCH % 1.0, 0.5)


def test_the_scene_combines_the_objects_as_independent():
    beside = _box((0.0, 0.04, 0.0), (0.02, 0.06, 0.02))
    overlapping = _box((0.0, 0.0, 0.0), (0.02, 0.02, 0.02))
    occupancy = posterior_occupancy(
        {0: [(SMALL, 0.4), (LARGE, 0.6)], 1: [(overlapping, 0.5), (beside, 0.5)]}
    )
    scene = occupancy.scene
    # Held by both objects: 1 - (1 - 1) (1 - 0.5) = 1; by object 0 alone (0.6); by 1 alone (0.5).
    assert _probability_at(scene, (0.0075, 0.0075, 0.0075)) == pytest.approx(1.0)
    assert _probability_at(scene, (0.0325, 0.0075, 0.0075)) == pytest.approx(0.6)
    assert _probability_at(scene, (0.0075, 0.0475, 0.0075)) == pytest.approx(0.5)
    certain = posterior_occupancy({0: [(SMALL, 0.4), (LARGE, 0.6)], 1: [(LARGE, 1.0)]})
    p = _probability_at(certain.scene, (0.0325, 0.0075, 0.0075))
    assert p == pytest.approx(1.0)  # object 1 holds it surely
    two = posterior_occupancy({0: [(LARGE, 0.6), (SMALL, 0.4)], 1: [(LARGE, 0.5), (beside, 0.5)]})
    assert _probability_at(two.scene, (0.0325, 0.0075, 0.0075)) == pytest.approx(1 - 0.4 * 0.5)


def test_every_result_holds_its_occupancy_and_it_loads_back(tmp_path):
    out = write_result(
        tmp_path / "r",
        "test",
        {0: WORLD_FROM_CAMERA},
        [(LARGE, [(LARGE, 0.7), (SMALL, 0.3)], 0.7), (_box((0.1, 0, 0), (0.12, 0.02, 0.02)), [])],
    )
    with np.load(out / OCCUPANCY_FILE) as npz:
        assert set(npz.files) == {
            "format",
            "pitch_m",
            "object_ids",
            "scene_voxels",
            "scene_probability",
            "object_0_voxels",
            "object_0_probability",
            "object_1_voxels",
            "object_1_probability",
        }
        assert str(npz["format"]) == "ipr-occupancy/1" and float(npz["pitch_m"]) == PITCH
        assert npz["object_1_voxels"].dtype == np.int32
    occupancy = load_occupancy(out)
    assert occupancy.pitch_m == PITCH and sorted(occupancy.objects) == [0, 1]
    assert _probability_at(occupancy.objects[0], (0.0325, 0.0075, 0.0075)) == pytest.approx(0.7)
    # An object written without hypotheses is its best shape with probability 1.
    assert np.allclose(occupancy.objects[1][1], 1.0) and len(occupancy.objects[1][0]) == 64
    assert load_occupancy(out / OCCUPANCY_FILE).objects[0][0].shape == occupancy.objects[0][0].shape


def test_posterior_results_count_the_carved_shapes_that_were_written(tmp_path):
    """The occupancy is that of the written (carved) shapes, not of the convex hypotheses."""

    def hypothesis(box: trimesh.Trimesh, index: int) -> ShapeHypothesis:
        return ShapeHypothesis(
            0, index, np.asarray(box.vertices), np.asarray(box.faces), float(box.volume),
            np.zeros(0), np.zeros((0, 3)),
        )  # fmt: skip

    carved = SMALL.vertices.copy(), SMALL.faces.copy()  # LARGE carved down to SMALL
    posterior = ObjectPosterior(
        0,
        (hypothesis(LARGE, 0), hypothesis(SMALL, 1), hypothesis(LARGE, 2)),
        np.array([0.5, 0.5, 0.0]),
        0,
        hypothesis(SMALL, -1),
        "test",
        output_meshes=(carved, None, None),
    )
    out = write_posterior_result(tmp_path / "r", [posterior], {0: WORLD_FROM_CAMERA}, method="t")
    occupancy = load_occupancy(out)
    assert _probability_at(occupancy.objects[0], (0.0125, 0.0075, 0.0075)) == pytest.approx(1.0)
    assert _probability_at(occupancy.objects[0], (0.0325, 0.0075, 0.0075)) == 0.0


def test_posterior_occupancy_from_cached_voxels_is_that_of_the_written_meshes(tmp_path):
    """A hypothesis written as itself gives its cached voxels (not voxelised again); a carved
    one its carved mesh's: the file is the occupancy of the written meshes."""

    def hypothesis(box: trimesh.Trimesh, index: int) -> ShapeHypothesis:
        vertices, faces = np.asarray(box.vertices), np.asarray(box.faces)
        return ShapeHypothesis(
            0, index, vertices, faces, float(box.volume), np.zeros(0), np.zeros((0, 3)),
            voxel_keys=voxels.scanline_voxels(vertices, faces, PITCH),
        )  # fmt: skip

    tilted = LARGE.copy()
    tilted.apply_transform(trimesh.transformations.rotation_matrix(0.3, [0.2, 0.3, 1.0]))
    hypotheses = (hypothesis(LARGE, 0), hypothesis(SMALL, 1), hypothesis(tilted, 2))
    carved = SMALL.vertices.copy(), SMALL.faces.copy()  # LARGE carved down to SMALL
    posterior = ObjectPosterior(
        0, hypotheses, np.array([0.5, 0.2, 0.3]), 0, hypothesis(SMALL, -1), "test",
        output_meshes=(carved, None, None),
    )  # fmt: skip
    assert posterior.written_shape(0) is carved
    assert posterior.written_shape(1) is hypotheses[1].voxel_keys
    assert isinstance(posterior.written_shape(1, 2 * PITCH), tuple)  # another pitch: the mesh
    out = write_posterior_result(tmp_path / "r", [posterior], {0: WORLD_FROM_CAMERA}, method="t")
    expected = posterior_occupancy(
        {0: [(posterior.written_mesh(k), p) for k, p in enumerate(posterior.probabilities)]}
    )
    occupancy = load_occupancy(out)
    for got, wanted in (
        (occupancy.objects[0], expected.objects[0]),
        (occupancy.scene, expected.scene),
    ):
        assert np.array_equal(got[0], wanted[0]) and np.array_equal(got[1], wanted[1])
    assert _probability_at(occupancy.objects[0], (0.0325, 0.0075, 0.0075)) == 0.0


@pytest.mark.parametrize(
    "change, problem",
    [
        (lambda a: a.pop("format"), "format tag"),
        (lambda a: a.update(pitch_m=np.array(-1.0)), "pitch_m"),
        (lambda a: a.update(object_0_probability=np.full(1, 1.5, np.float32)), "outside"),
        (lambda a: a.update(object_0_voxels=np.zeros((1, 2), np.int32)), "(N, 3)"),
        (lambda a: a.pop("scene_probability"), "scene_"),
    ],
)
def test_bad_occupancy_files_are_rejected_clearly(tmp_path, change, problem):
    arrays = {
        "format": np.array("ipr-occupancy/1"),
        "pitch_m": np.array(PITCH),
        "object_ids": np.array([0]),
        "object_0_voxels": np.zeros((1, 3), np.int32),
        "object_0_probability": np.ones(1, np.float32),
        "scene_voxels": np.zeros((1, 3), np.int32),
        "scene_probability": np.ones(1, np.float32),
    }
    assert load_occupancy(_save(tmp_path / "good.npz", arrays)).objects[0][1][0] == 1.0
    change(arrays)
    with pytest.raises(ResultError, match=problem.replace("(", r"\(").replace(")", r"\)")):
        load_occupancy(_save(tmp_path / "bad.npz", arrays))
    with pytest.raises(ResultError, match="missing"):
        load_occupancy(tmp_path / "absent")


def _save(path, arrays):
    np.savez(path, **arrays)
    return path


def test_free_voxels_counted_from_keys_match_the_map_at_the_centres():
    """unary_report looks keys up in a SpaceMap of the same pitch by their integer indices: the
    same states as ``state_at`` at the voxel centres, grid edges and outside included."""
    from ipr_shapes import voxels as vox
    from ipr_shapes.perception.free_space import FREE, SpaceMap, VoxelGrid
    from ipr_shapes.perception.occupancy import unary_report

    rng = np.random.default_rng(0)
    grid = VoxelGrid.around(np.array([-0.3, -0.2, -0.05]), np.array([0.25, 0.3, 0.3]), 0.005)
    space = SpaceMap(grid, rng.integers(0, 3, grid.shape).astype(np.uint8))
    keys = np.unique(vox.pack(rng.integers(-80, 80, (20000, 3))))
    expected = np.count_nonzero(space.state_at(vox.centres(keys, 0.005)) == FREE)
    report = unary_report(np.zeros((1, 3)), keys, 0.005, space, ())
    assert report.free_voxels == expected
    # Another pitch than the map's: looked up at the centres.
    coarse = unary_report(np.zeros((1, 3)), keys, 0.01, space, ())
    assert coarse.free_voxels == np.count_nonzero(space.state_at(vox.centres(keys, 0.01)) == FREE)
