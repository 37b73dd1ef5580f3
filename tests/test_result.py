"""Result directories: atomic writing, round trip, and clear rejection of malformed results."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ipr_shapes.camera import look_at
from ipr_shapes.data import ycbv_real_dir
from ipr_shapes.errors import IprError, ResultError
from ipr_shapes.ground_truth import write_ground_truth_result
from ipr_shapes.result import (
    RESULT_FORMAT,
    load_result,
    read_mesh,
    write_result,
)

WORLD_FROM_CAMERA = look_at(np.array([0.5, -0.4, 0.6]), np.zeros(3))


def _box(size: float, centre=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(size, size, size))
    box.apply_translation(centre)
    return box


def _write(path: Path, **kwargs) -> Path:
    objects = kwargs.pop("objects", None)
    if objects is None:
        objects = [
            (_box(0.05), [(_box(0.05), 0.7), (_box(0.04), 0.3)]),
            (_box(0.03, (0.1, 0, 0)), []),
        ]
    return write_result(
        path,
        kwargs.pop("method", "test-method"),
        kwargs.pop("world_from_camera", {0: WORLD_FROM_CAMERA}),
        objects,
        kwargs.pop("timing_s", {"total": 1.5}),
        **kwargs,
    )


def _edit(result_dir: Path, change) -> None:
    path = result_dir / "result.json"
    document = json.loads(path.read_text())
    change(document)
    path.write_text(json.dumps(document))


# --------------------------------------------------------------------------------------------


def test_round_trip(tmp_path):
    out = _write(tmp_path / "res", extra={"scene": "demo", "config": {"m": 16}})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]  # no staging folder left
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert files == [
        "objects/0/best.ply",
        "objects/0/hyp_000.ply",
        "objects/0/hyp_001.ply",
        "objects/1/best.ply",
        "occupancy.npz",
        "result.json",
    ]
    raw = json.loads((out / "result.json").read_text())
    assert raw["format"] == RESULT_FORMAT and raw["objects"][0]["mesh"] == "objects/0/best.ply"

    result = load_result(out)
    assert result.method == "test-method"
    assert np.allclose(result.world_from_camera[0], WORLD_FROM_CAMERA)
    assert result.timing_s == {"total": 1.5}
    assert result.extra == {"scene": "demo", "config": {"m": 16}}
    first, second = result.objects
    assert (first.id, second.id) == (0, 1)
    assert first.probability == pytest.approx(0.7)
    assert [h.probability for h in first.hypotheses] == pytest.approx([0.7, 0.3])
    assert first.hypotheses[1].mesh_path == out / "objects/0/hyp_001.ply"
    # An object written without hypotheses is its own single hypothesis, with probability 1.
    assert second.probability == 1.0
    assert [(h.mesh_path.name, h.probability) for h in second.hypotheses] == [("best.ply", 1.0)]
    # Meshes keep metres and the world frame (PLY stores float32).
    assert np.allclose(
        second.mesh.bounds, [[0.085, -0.015, -0.015], [0.115, 0.015, 0.015]], atol=1e-7
    )
    assert np.allclose(read_mesh(first.hypotheses[1].mesh_path).extents, 0.04, atol=1e-7)
    assert load_result(out / "result.json").objects[0].id == 0  # the file itself also works


def test_existing_directory_needs_overwrite_and_is_replaced_whole(tmp_path):
    out = _write(tmp_path / "res")
    with pytest.raises(ResultError, match="already exists"):
        _write(out)
    _write(out, objects=[(_box(0.02), [])], overwrite=True)
    assert len(load_result(out).objects) == 1
    assert not (out / "objects" / "1").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def test_failed_write_leaves_nothing(tmp_path, monkeypatch):
    calls = {"n": 0}
    original = trimesh.Trimesh.export

    def failing_export(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError("disk full")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(trimesh.Trimesh, "export", failing_export)
    with pytest.raises(OSError, match="disk full"):
        _write(tmp_path / "res")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("problem", "kwargs"),
    [
        ("sum to", {"objects": [(_box(0.05), [(_box(0.05), 0.5), (_box(0.04), 0.3)])]}),
        ("not in \\[0, 1\\]", {"objects": [(_box(0.05), [(_box(0.05), 1.2), (_box(0.04), -0.2)])]}),
        ("the first frame", {"world_from_camera": {}}),
        ("not a rigid", {"world_from_camera": {0: 2 * np.eye(4)}}),
        ("no faces", {"objects": [((np.zeros((3, 3)), np.zeros((0, 3), int)), [])]}),
        ("NaN", {"objects": [((np.full((3, 3), np.nan), [[0, 1, 2]]), [])]}),
        ("contract keys", {"extra": {"objects": []}}),
    ],
)
def test_write_rejects_invalid_input(tmp_path, problem, kwargs):
    with pytest.raises(ValueError, match=problem):
        _write(tmp_path / "res", **kwargs)
    assert list(tmp_path.iterdir()) == []


def _set(key, value):
    def change(document):
        document[key] = value

    return change


def _set_object(key, value, index=0):
    def change(document):
        document["objects"][index][key] = value

    return change


def _set_camera(value, key="0"):
    def change(document):
        document["world_from_camera"] = {key: value}

    return change


def _set_hypothesis_probabilities(values):
    def change(document):
        for hypothesis, value in zip(document["objects"][0]["hypotheses"], values, strict=True):
            hypothesis["probability"] = value

    return change


def _duplicate_ids(document):
    document["objects"][1]["id"] = document["objects"][0]["id"]


SCALED = (2.0 * np.eye(4)).tolist()
SCALED[3][3] = 1.0


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        (_set("format", "ipr-result/2"), "format tag 'ipr-result/2'"),
        (_set("format", None), "format tag None"),
        (_set("method", 3), "'method' must be a non-empty string"),
        (_set("objects", {}), "'objects' must be a list"),
        (_set_object("probability", 1.5), "probability is 1.5, outside \\[0, 1\\]"),
        (_set_object("probability", -0.1), "outside \\[0, 1\\]"),
        (_set_object("probability", "high"), "must be a number"),
        (_set_hypothesis_probabilities([0.5, 0.3]), "sum to 0.8, not 1"),
        (_set_hypothesis_probabilities([1.2, -0.2]), "outside \\[0, 1\\]"),
        (_set("world_from_camera", {}), "world_from_camera has no frame"),
        (_set_camera(np.eye(4).tolist(), key="\u00b2"), "is not a frame id"),
        (_set_camera(SCALED), "not a rigid transform"),
        (_set_camera(np.eye(3).tolist()), "must be a 4x4 matrix"),
        (_set_camera([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]), "not a rigid"),
        (_set_camera(np.diag([1.0, 1.0, -1.0, 1.0]).tolist()), "not a rigid"),
        (_duplicate_ids, "duplicate object id 0"),
        (_set_object("id", "a"), "'id' must be an integer"),
        (_set_object("mesh", 5), "'mesh' must be a file path"),
    ],
)
def test_malformed_result_json_is_rejected_clearly(tmp_path, change, problem):
    out = _write(tmp_path / "res")
    _edit(out, change)
    with pytest.raises(ResultError, match=problem) as error:
        load_result(out)
    assert str(out / "result.json") in str(error.value)


def test_nan_literal_and_broken_json_are_rejected(tmp_path):
    out = _write(tmp_path / "res")
    path = out / "result.json"
    text = path.read_text()
    path.write_text(text.replace('"total": 1.5', '"total": NaN'))
    with pytest.raises(ResultError, match="contains NaN") as error:
        load_result(out)
    assert str(path) in str(error.value)
    path.write_text(text.replace('"total": 1.5', '"total": 1e999'))
    with pytest.raises(ResultError, match="non-finite number 1e999"):
        load_result(out)
    path.write_text(text[:-20])
    with pytest.raises(ResultError, match="not valid JSON: .* line"):
        load_result(out)
    path.write_text("[1, 2]")
    with pytest.raises(ResultError, match="must be a JSON object"):
        load_result(out)
    path.unlink()
    with pytest.raises(ResultError, match="result.json is missing"):
        load_result(out)
    with pytest.raises(ResultError, match="not found"):
        load_result(tmp_path / "nowhere")


def test_missing_and_unreadable_meshes_are_rejected(tmp_path):
    out = _write(tmp_path / "res")
    best = out / "objects" / "1" / "best.ply"
    content = best.read_bytes()
    best.unlink()
    with pytest.raises(ResultError, match="mesh file of object 1 is missing") as error:
        load_result(out)
    assert str(best) in str(error.value) and "result.json" in str(error.value)

    best.write_bytes(b"this is not a mesh")
    with pytest.raises(ResultError, match="cannot be read|holds no triangles") as error:
        load_result(out)
    assert str(best) in str(error.value)
    with pytest.raises(ResultError, match="not a valid PLY"):  # header check without loading
        load_result(out, load_meshes=False)

    best.write_bytes(content)
    nan_mesh = trimesh.Trimesh(
        [[0, 0, 0], [1, 0, 0], [0, 1, float("nan")]], [[0, 1, 2]], process=False
    )
    nan_mesh.export(best)
    with pytest.raises(ResultError, match="NaN or inf") as error:
        load_result(out)
    assert str(best) in str(error.value)
    best.write_bytes(content)

    hypothesis = out / "objects" / "0" / "hyp_001.ply"
    hypothesis.write_bytes(b"garbage")
    with pytest.raises(ResultError, match="not a valid PLY") as error:
        load_result(out)
    assert str(hypothesis) in str(error.value)
    hypothesis.unlink()
    with pytest.raises(ResultError, match="hypothesis mesh file is missing") as error:
        load_result(out)
    assert str(hypothesis) in str(error.value)


@pytest.fixture(scope="module")
def ycbv_scene():
    root = ycbv_real_dir()
    if root is None:
        pytest.skip("shared ycbv_real data not found (set IPR_DATA or place ../shared/data)")
    return root / "ycbv_0000"


def test_ground_truth_result(ycbv_scene, tmp_path):
    from ipr_shapes.scene import load_ground_truth, load_model, load_scene

    out = write_ground_truth_result(ycbv_scene, tmp_path / "gt")
    result = load_result(out)
    assert result.method == "ground-truth"
    assert [o.probability for o in result.objects] == [1.0, 1.0, 1.0]
    assert result.extra["ground_truth"]["obj_ids"] == [8, 14, 21]
    assert result.extra["ground_truth"]["excluded_obj_ids"] == []
    scene = load_scene(ycbv_scene)
    assert np.allclose(result.world_from_camera[0], scene.frames[0].world_from_camera)
    # Each mesh is its model (mm -> m) at world_from_camera[0] @ camera_from_model.
    poses = load_ground_truth(ycbv_scene)[0]
    for obj, pose in zip(result.objects, poses, strict=True):
        model = load_model(ycbv_scene.parent / "models", pose.obj_id)
        expected = trimesh.transform_points(
            model.vertices, scene.frames[0].world_from_camera @ pose.camera_from_model
        )
        assert np.allclose(obj.mesh.vertices, expected, atol=1e-6)
        assert math.isclose(obj.mesh.volume, model.volume, rel_tol=1e-4)
    with pytest.raises(IprError, match="already exists"):
        write_ground_truth_result(ycbv_scene, out)


def test_extra_files_are_written_inside_the_result_and_checked(tmp_path):
    box = _box(0.05)
    out = write_result(
        tmp_path / "r",
        "test",
        {0: WORLD_FROM_CAMERA},
        [(box, [(box, 0.7), (_box(0.06), 0.3)], 0.7)],
        extra_files={"completion.png": b"png", "reports/summary.txt": b"ok"},
    )
    assert (out / "completion.png").read_bytes() == b"png"
    assert (out / "reports" / "summary.txt").read_bytes() == b"ok"
    assert load_result(out).objects[0].probability == pytest.approx(0.7)
    for name in ("../escape.txt", "/abs.txt", "objects/0/x.ply", "result.json"):
        with pytest.raises(ValueError, match="extra file name"):
            write_result(
                tmp_path / "bad", "test", {0: WORLD_FROM_CAMERA}, [(box, [])],
                extra_files={name: b"x"},
            )  # fmt: skip
        assert not (tmp_path / "bad").exists()
    with pytest.raises(ValueError, match="best probability"):
        write_result(tmp_path / "bad", "test", {0: WORLD_FROM_CAMERA}, [(box, [], 1.5)])


def test_a_result_mesh_in_millimetres_is_refused_with_its_file(tmp_path):
    import trimesh

    small = trimesh.creation.box(extents=(0.04, 0.03, 0.02))
    out = write_result(tmp_path / "r", "m", np.eye(4), [(small, [])])
    trimesh.creation.box(extents=(40.0, 30.0, 20.0)).export(out / "objects/0/best.ply")
    with pytest.raises(ResultError, match="millimetres") as error:
        load_result(out)
    assert "best.ply" in str(error.value)
    with pytest.raises(ValueError, match="millimetres"):
        write_result(tmp_path / "mm", "m", np.eye(4), [(small.apply_scale(1000.0), [])])
    assert not (tmp_path / "mm").exists()


def test_written_ply_reads_as_trimesh_loads_it(tmp_path):
    """``read_mesh`` parses ipr's PLY files without trimesh's scene round trip: the same
    float64 vertices and int64 faces as ``trimesh.load``; a PLY with more than positions and
    faces (vertex colours) is read by ``trimesh.load`` as before."""
    from ipr_shapes.result import _read_plain_ply

    rng = np.random.default_rng(3)
    mesh = trimesh.convex.convex_hull(rng.normal(0.0, 0.05, (40, 3)))
    plain = tmp_path / "plain.ply"
    mesh.export(plain, file_type="ply")
    read = read_mesh(plain)
    loaded = trimesh.load(plain, force="mesh", process=False)
    assert _read_plain_ply(plain) is not None
    for ours, theirs in ((read.vertices, loaded.vertices), (read.faces, loaded.faces)):
        assert ours.dtype == theirs.dtype and np.array_equal(ours, theirs)
    coloured = tmp_path / "coloured.ply"
    painted = mesh.copy()
    painted.visual.vertex_colors = np.tile([200, 10, 10, 255], (len(mesh.vertices), 1))
    painted.export(coloured, file_type="ply")
    assert _read_plain_ply(coloured) is None
    assert np.array_equal(read_mesh(coloured).faces, mesh.faces)


@pytest.mark.parametrize(
    ("meshes", "message"), [(None, "output_keys"), ((None, None), "same length")]
)
def test_object_posterior_refuses_carved_keys_without_their_meshes(meshes, message):
    """Carved voxel keys stand for carved meshes one to one; keys alone would write an
    occupancy that is not the written shapes'."""
    from ipr_shapes.products import ObjectPosterior

    with pytest.raises(ValueError, match=message):
        ObjectPosterior(
            object_id=0,
            hypotheses=(),
            probabilities=np.zeros(0),
            best=0,
            minimum=None,
            inference="exact",
            output_meshes=meshes,
            output_keys=(None,),
        )
