"""Result directories (``SCENE_FORMAT.md``, "Result directory"): write atomically, read, validate.

A result holds, per reconstructed object, its most probable complete shape (``best.ply``) and
optionally its weighted shape hypotheses (``hyp_NNN.ply``), all in metres in the world frame at
the object's frame-0 pose, plus the world-from-camera transforms the method used (so that ground
truth given in camera frames can be placed in the result's world frame), the method name and
timings. ``write_posterior_result`` writes a method's per-object posteriors; the oracle result
built from ground truth is ``ipr_shapes.ground_truth``'s (evaluation only).

Every result written here also holds ``occupancy.npz``: per object, the posterior probability
that each 5 mm voxel of the contract's world grid is occupied, and the same for the scene
(``posterior_occupancy``, ``load_occupancy``; layout in docs/FORMATS.md).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ipr_shapes import voxels
from ipr_shapes.atomic import staged_directory
from ipr_shapes.errors import ResultError
from ipr_shapes.products import ObjectPosterior, volume_spread

RESULT_FORMAT = "ipr-result/1"
RESULT_FILE = "result.json"
#: Tolerance on a sum of hypothesis probabilities being 1.
PROBABILITY_TOLERANCE = 1e-3
#: Tolerance on a rotation being orthonormal (|R R^T - I|) with determinant +1.
RIGID_TOLERANCE = 1e-3
#: Keys of result.json defined by the contract; any other top-level key is kept in ``extra``.
RESERVED_KEYS = ("format", "method", "world_from_camera", "objects", "timing_s")
#: Method name of the oracle result built from ground truth.
GROUND_TRUTH_METHOD = "ground-truth"
#: The per-voxel occupancy file of a result, and its format tag.
OCCUPANCY_FILE = "occupancy.npz"
OCCUPANCY_FORMAT = "ipr-occupancy/1"


@dataclass(frozen=True)
class HypothesisResult:
    """One weighted shape hypothesis of an object: mesh file (absolute path) and probability."""

    mesh_path: Path
    probability: float


@dataclass(frozen=True)
class ObjectResult:
    """One reconstructed object.

    Attributes:
        id: the object's id in the result (unique, any integer).
        mesh_path: absolute path of its most probable shape (world frame, metres, frame-0 pose).
        probability: marginal posterior of its best hypothesis, in [0, 1].
        hypotheses: its weighted hypotheses (probabilities sum to 1), possibly empty.
        mesh: the loaded best mesh (a ``trimesh.Trimesh``) when ``load_result`` read it.
    """

    id: int
    mesh_path: Path
    probability: float
    hypotheses: tuple[HypothesisResult, ...] = ()
    mesh: Any = field(default=None, compare=False, repr=False)

    def load_mesh(self) -> Any:
        """The best mesh as a trimesh (the cached one when available); ResultError if unreadable."""
        if self.mesh is not None:
            return self.mesh
        return read_mesh(self.mesh_path)


@dataclass(frozen=True, eq=False)
class Result:
    """A validated result directory.

    Attributes:
        path: the result directory.
        method: name of the method that produced it (e.g. ``"ipr+action+uniform"``).
        world_from_camera: frame id -> (4, 4) float64 rigid transform (OpenCV camera to world,
            metres); frame 0 is always present.
        objects: the reconstructed objects, in file order.
        timing_s: named durations in seconds.
        extra: any further top-level keys of result.json, as parsed JSON.
    """

    path: Path
    method: str
    world_from_camera: dict[int, np.ndarray]
    objects: tuple[ObjectResult, ...]
    timing_s: dict[str, float] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------------------------
# Meshes


def _to_trimesh(mesh: Any) -> Any:
    """A trimesh of a trimesh or a (vertices (V, 3), faces (F, 3)) pair (not processed)."""
    import trimesh

    if isinstance(mesh, trimesh.Trimesh):
        return mesh
    if isinstance(mesh, tuple | list) and len(mesh) == 2:
        vertices, faces = mesh
        return trimesh.Trimesh(
            np.asarray(vertices, float).reshape(-1, 3),
            np.asarray(faces, np.int64).reshape(-1, 3),
            process=False,
        )
    raise TypeError(f"expected a trimesh.Trimesh or a (vertices, faces) pair, got {type(mesh)}")


def read_mesh(path: Path | str) -> Any:
    """Load a triangle mesh file (any trimesh format) with finite vertices and at least one face;
    ResultError naming the file otherwise."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise ResultError(
            path, "mesh file is missing", "write the mesh or fix its path in result.json"
        )
    try:
        mesh = _read_plain_ply(path)
        if mesh is None:
            mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as error:  # trimesh raises many types on corrupt files
        raise ResultError(
            path,
            f"mesh file cannot be read ({type(error).__name__}: {error})",
            "write a valid triangle mesh (binary PLY)",
        ) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ResultError(path, "mesh file holds no triangles", "write a triangle mesh")
    if not np.all(np.isfinite(mesh.vertices)):
        raise ResultError(path, "mesh vertices contain NaN or inf", "write finite coordinates")
    extent = float(np.max(mesh.extents))
    if extent > voxels.MAX_MESH_EXTENT_M:
        raise ResultError(
            path,
            f"mesh spans {extent:.4g} m, more than the {voxels.MAX_MESH_EXTENT_M:g} m an object may",
            "write the mesh in metres (are its coordinates in millimetres?)",
        )
    distance = float(np.abs(mesh.vertices).max())
    if distance > voxels.MAX_DISTANCE_M:
        raise ResultError(
            path,
            f"mesh lies {distance:.4g} m from the world origin, more than the "
            f"{voxels.MAX_DISTANCE_M:g} m a scene may span",
            "write the mesh in metres in the result's world frame",
        )
    return mesh


def _read_plain_ply(path: Path) -> Any:
    """The trimesh of a PLY file holding only vertex positions and faces (as ipr writes them),
    read by trimesh's PLY parser without ``trimesh.load``'s scene round trip (a fifth of the
    time; the same float64 vertices and int64 faces); None for any other file (colours,
    normals, another format), which ``trimesh.load`` reads."""
    import trimesh
    from trimesh.exchange.ply import load_ply

    if path.suffix.lower() != ".ply":
        return None
    with path.open("rb") as handle:
        loaded = load_ply(handle)
    extra = {key for key, value in loaded.items() if value is not None}
    if extra != {"vertices", "faces", "metadata"} or len(loaded["faces"]) == 0:
        return None
    return trimesh.Trimesh(loaded["vertices"], loaded["faces"], process=False)


def _check_ply_header(path: Path) -> None:
    """Cheap readability check of a hypothesis file: exists and, for PLY, has a sane header."""
    if not path.is_file():
        raise ResultError(
            path, "hypothesis mesh file is missing", "write the mesh or fix its path in result.json"
        )
    if path.suffix.lower() != ".ply":
        return
    with path.open("rb") as handle:
        head = handle.read(4096)
    if not head.startswith(b"ply") or b"end_header" not in head or b"element vertex" not in head:
        raise ResultError(
            path,
            "hypothesis mesh is not a valid PLY file (bad header)",
            "write a valid triangle mesh (binary PLY)",
        )


# --------------------------------------------------------------------------------------------
# Reading


def _read_result_json(path: Path) -> Any:
    """Parse result.json, rejecting NaN, Infinity and numbers that overflow to inf."""
    if not path.is_file():
        raise ResultError(
            path,
            "result.json is missing",
            "pass a result directory written by ipr (it holds result.json)",
        )

    def reject_constant(name: str) -> Any:
        raise ResultError(path, f"result.json contains {name}", "write finite numbers only")

    def finite_float(text: str) -> float:
        value = float(text)
        if not math.isfinite(value):
            raise ResultError(
                path,
                f"result.json contains the non-finite number {text}",
                "write finite numbers only",
            )
        return value

    try:
        return json.loads(
            path.read_text(encoding="utf-8"),
            parse_constant=reject_constant,
            parse_float=finite_float,
        )
    except json.JSONDecodeError as error:
        raise ResultError(
            path,
            f"result.json is not valid JSON: {error.msg} at line {error.lineno} column {error.colno}",
            "correct the JSON syntax",
        ) from None
    except UnicodeDecodeError:
        raise ResultError(path, "result.json is not UTF-8 text", "save it as UTF-8 JSON") from None


def _number(value: Any, path: Path, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ResultError(path, f"{where} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ResultError(path, f"{where} is not finite", "write finite numbers only")
    return float(value)


def _probability(value: Any, path: Path, where: str) -> float:
    number = _number(value, path, where)
    if not 0.0 <= number <= 1.0:
        raise ResultError(
            path, f"{where} is {number}, outside [0, 1]", "write probabilities in [0, 1]"
        )
    return number


def check_rigid(matrix: Any, path: Path, where: str) -> np.ndarray:
    """A (4, 4) float64 rigid transform from nested lists; ResultError naming ``where`` if not."""
    try:
        array = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError):
        raise ResultError(path, f"{where} must be a 4x4 matrix of numbers") from None
    if array.shape != (4, 4):
        raise ResultError(
            path,
            f"{where} must be a 4x4 matrix, got shape {array.shape}",
            "write [[r r r t], [r r r t], [r r r t], [0 0 0 1]] in metres",
        )
    if not np.all(np.isfinite(array)):
        raise ResultError(path, f"{where} contains NaN or inf", "write finite numbers only")
    rotation = array[:3, :3]
    if (
        np.abs(array[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-6
        or np.abs(rotation @ rotation.T - np.eye(3)).max() > RIGID_TOLERANCE
        or np.linalg.det(rotation) < 0
    ):
        raise ResultError(
            path,
            f"{where} is not a rigid transform",
            "give an orthonormal rotation (det +1) and last row [0, 0, 0, 1]",
        )
    return array


def _mesh_path(value: Any, root: Path, json_path: Path, where: str) -> Path:
    if not isinstance(value, str) or not value:
        raise ResultError(json_path, f"{where} must be a file path string, got {value!r}")
    candidate = Path(value)
    return candidate if candidate.is_absolute() else root / candidate


def load_result(path: Path | str, *, load_meshes: bool = True) -> Result:
    """Read and validate a result directory (or its result.json); ResultError on any problem.

    Checks: result.json exists and parses (no NaN/inf), ``format`` is ``"ipr-result/1"``,
    ``method`` is a string, ``world_from_camera`` has frame ``"0"`` and only rigid 4x4 matrices,
    object ids are unique integers, every mesh file exists, probabilities are in [0, 1] and each
    object's hypotheses sum to 1 (within 1e-3). With ``load_meshes`` the best meshes are read
    (unreadable or non-finite meshes are errors) and kept in ``ObjectResult.mesh``; hypothesis
    files are checked for existence and, for PLY, a valid header (they are not fully parsed).
    """
    root = Path(path)
    if root.is_file() and root.name == RESULT_FILE:
        root = root.parent
    if not root.is_dir():
        raise ResultError(root, "result directory not found", "pass the folder holding result.json")
    json_path = root / RESULT_FILE
    raw = _read_result_json(json_path)
    if not isinstance(raw, dict):
        raise ResultError(json_path, "result.json must be a JSON object")
    tag = raw.get("format")
    if tag != RESULT_FORMAT:
        raise ResultError(
            json_path, f"unknown or missing format tag {tag!r}", f'set "format": "{RESULT_FORMAT}"'
        )
    method = raw.get("method")
    if not isinstance(method, str) or not method:
        raise ResultError(json_path, f"'method' must be a non-empty string, got {method!r}")

    cameras = raw.get("world_from_camera")
    if not isinstance(cameras, dict):
        raise ResultError(
            json_path,
            "'world_from_camera' must map frame ids to 4x4 matrices",
            'add "world_from_camera": {"0": [[...4x4...]]}',
        )
    world_from_camera: dict[int, np.ndarray] = {}
    for key, matrix in cameras.items():
        if not (str(key).isascii() and str(key).isdigit() and len(str(key)) <= 6):
            raise ResultError(
                json_path,
                f"world_from_camera key {key!r} is not a frame id",
                'use frame ids such as "0"',
            )
        world_from_camera[int(key)] = check_rigid(matrix, json_path, f"world_from_camera[{key!r}]")
    if not world_from_camera:
        raise ResultError(
            json_path,
            "world_from_camera has no frame",
            "record the world-from-camera transform of the first frame (frame 0)",
        )

    timing_raw = raw.get("timing_s", {})
    if not isinstance(timing_raw, dict):
        raise ResultError(json_path, "'timing_s' must map names to seconds")
    timing = {
        str(name): _number(value, json_path, f"timing_s[{name!r}]")
        for name, value in timing_raw.items()
    }

    objects_raw = raw.get("objects")
    if not isinstance(objects_raw, list):
        raise ResultError(json_path, "'objects' must be a list", 'write "objects": [] if none')
    objects = []
    seen: set[int] = set()
    for number, item in enumerate(objects_raw):
        where = f"objects[{number}]"
        if not isinstance(item, dict):
            raise ResultError(json_path, f"{where} must be an object with id, mesh, probability")
        object_id = item.get("id")
        if isinstance(object_id, bool) or not isinstance(object_id, int):
            raise ResultError(json_path, f"{where}: 'id' must be an integer, got {object_id!r}")
        if object_id in seen:
            raise ResultError(
                json_path,
                f"{where}: duplicate object id {object_id}",
                "give every object a unique id",
            )
        seen.add(object_id)
        where = f"object {object_id}"
        mesh_path = _mesh_path(item.get("mesh"), root, json_path, f"{where}: 'mesh'")
        if not mesh_path.is_file():
            raise ResultError(
                mesh_path,
                f"mesh file of {where} is missing (named in {json_path})",
                "write the mesh or fix its path in result.json",
            )
        if "probability" not in item:
            raise ResultError(json_path, f"{where}: 'probability' is missing")
        probability = _probability(item["probability"], json_path, f"{where}: probability")
        mesh = None
        if load_meshes:
            try:
                mesh = read_mesh(mesh_path)
            except ResultError as error:
                raise ResultError(
                    error.path, f"{error.problem} ({where}, named in {json_path})", error.fix
                ) from None
        hypotheses_raw = item.get("hypotheses", [])
        if not isinstance(hypotheses_raw, list):
            raise ResultError(json_path, f"{where}: 'hypotheses' must be a list")
        hypotheses = []
        for index, hypothesis in enumerate(hypotheses_raw):
            label = f"{where} hypothesis {index}"
            if not isinstance(hypothesis, dict):
                raise ResultError(json_path, f"{label} must be an object with mesh, probability")
            hyp_path = _mesh_path(hypothesis.get("mesh"), root, json_path, f"{label}: 'mesh'")
            if "probability" not in hypothesis:
                raise ResultError(json_path, f"{label}: 'probability' is missing")
            hyp_probability = _probability(
                hypothesis["probability"], json_path, f"{label}: probability"
            )
            try:
                _check_ply_header(hyp_path)
            except ResultError as error:
                raise ResultError(
                    error.path, f"{error.problem} ({label}, named in {json_path})", error.fix
                ) from None
            hypotheses.append(HypothesisResult(hyp_path, hyp_probability))
        if hypotheses:
            total = sum(h.probability for h in hypotheses)
            if abs(total - 1.0) > PROBABILITY_TOLERANCE:
                raise ResultError(
                    json_path,
                    f"{where}: hypothesis probabilities sum to {total:.6g}, not 1",
                    f"normalise them (tolerance {PROBABILITY_TOLERANCE})",
                )
        objects.append(ObjectResult(object_id, mesh_path, probability, tuple(hypotheses), mesh))

    extra = {key: value for key, value in raw.items() if key not in RESERVED_KEYS}
    return Result(root, method, world_from_camera, tuple(objects), timing, extra)


# --------------------------------------------------------------------------------------------
# Occupancy


@dataclass(frozen=True, eq=False)
class Occupancy:
    """Posterior probability of occupancy of the world grid's voxels (``occupancy.npz``).

    Voxel (i, j, k) is the cube of edge ``pitch_m`` centred at ((i, j, k) + 1/2) * pitch_m
    (metres, world frame; the metric's grid, ``ipr_shapes.voxels``). Only voxels with a non-zero
    probability are listed, in lexicographic (i, j, k) order.

    Attributes:
        pitch_m: the voxel edge (m).
        objects: result object id -> (voxels (N, 3) int32, probability (N,) float32): the
            probability that the object occupies each voxel, i.e. the sum of the probabilities
            of the object's written hypotheses whose shape holds the voxel's centre.
        scene: (voxels (M, 3) int32, probability (M,) float32): the probability that any
            object occupies each voxel, 1 - prod over objects of (1 - p_object), which
            treats the objects as independent given their marginals.
    """

    pitch_m: float
    objects: dict[int, tuple[np.ndarray, np.ndarray]]
    scene: tuple[np.ndarray, np.ndarray]

    def centres_m(self, voxel_indices: np.ndarray) -> np.ndarray:
        """(N, 3) float64 world-frame centres (m) of (N, 3) voxel indices."""
        return (np.asarray(voxel_indices, np.float64) + 0.5) * self.pitch_m


def _weighted_voxels(
    shapes: Sequence[tuple[np.ndarray, float]],
) -> tuple[np.ndarray, np.ndarray]:
    """Sorted keys (N,) int64 and their summed weights (N,) float64 of weighted voxel sets."""
    keys = [k for k, w in shapes if k.size and w > 0]
    if not keys:
        return voxels.EMPTY.copy(), np.zeros(0)
    weights = [np.full(k.size, w) for k, w in shapes if k.size and w > 0]
    unique, inverse = np.unique(np.concatenate(keys), return_inverse=True)
    return unique, np.bincount(inverse, weights=np.concatenate(weights), minlength=unique.size)


def posterior_occupancy(
    objects: Mapping[int, Sequence[tuple[Any, float]]],
    pitch_m: float = voxels.DEFAULT_PITCH_M,
) -> Occupancy:
    """The per-voxel occupancy of weighted shapes (``Occupancy``).

    Args:
        objects: result object id -> its written shapes as (shape, probability) pairs whose
            probabilities sum to 1; a shape is a mesh (trimesh or (vertices, faces), world
            frame, m; a mesh that is not closed counts as its convex hull, as the metric
            reads it) or already its sorted unique ``ipr_shapes.voxels`` keys at ``pitch_m``.
        pitch_m: the grid's voxel edge (m).
    """
    per_object: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    scene_keys, scene_logs = [], []
    for object_id, shapes in objects.items():
        sets = []
        for shape, probability in shapes:
            is_keys = isinstance(shape, np.ndarray) and shape.ndim == 1
            keys = shape if is_keys else voxels.occupied_voxels(shape, pitch_m)
            sets.append((np.asarray(keys, np.int64), float(probability)))
        keys, weights = _weighted_voxels(sets)
        probability = np.clip(weights, 0.0, 1.0)
        listed = probability.astype(np.float32) > 0  # what float32 cannot tell from 0 is left out
        per_object[int(object_id)] = (
            voxels.unpack(keys[listed]).astype(np.int32),
            probability[listed].astype(np.float32),
        )
        scene_keys.append(keys)
        scene_logs.append(np.log1p(-np.minimum(probability, 1.0 - 1e-12)))
    if scene_keys:
        unique, inverse = np.unique(np.concatenate(scene_keys), return_inverse=True)
        log_empty = np.bincount(inverse, weights=np.concatenate(scene_logs), minlength=unique.size)
        scene_probability = np.clip(-np.expm1(log_empty), 0.0, 1.0)
        listed = scene_probability.astype(np.float32) > 0
        unique, scene_probability = unique[listed], scene_probability[listed]
    else:
        unique, scene_probability = voxels.EMPTY.copy(), np.zeros(0)
    scene = (voxels.unpack(unique).astype(np.int32), scene_probability.astype(np.float32))
    return Occupancy(float(pitch_m), per_object, scene)


def _occupancy_arrays(occupancy: Occupancy) -> dict[str, np.ndarray]:
    """The arrays of ``occupancy.npz`` (docs/FORMATS.md)."""
    arrays = {
        "format": np.array(OCCUPANCY_FORMAT),
        "pitch_m": np.array(occupancy.pitch_m, dtype=np.float64),
        "object_ids": np.array(sorted(occupancy.objects), dtype=np.int64),
        "scene_voxels": occupancy.scene[0].reshape(-1, 3).astype(np.int32),
        "scene_probability": occupancy.scene[1].astype(np.float32),
    }
    for object_id, (indices, probability) in occupancy.objects.items():
        arrays[f"object_{object_id}_voxels"] = indices.reshape(-1, 3).astype(np.int32)
        arrays[f"object_{object_id}_probability"] = probability.astype(np.float32)
    return arrays


def load_occupancy(path: Path | str) -> Occupancy:
    """Read and check a result's ``occupancy.npz`` (the result directory or the file itself);
    ResultError naming the file and the problem otherwise."""
    path = Path(path)
    if path.is_dir():
        path = path / OCCUPANCY_FILE
    if not path.is_file():
        raise ResultError(
            path,
            "occupancy file is missing",
            "pass a result written by ipr 0.1.0 or later (it holds occupancy.npz)",
        )
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {name: npz[name] for name in npz.files}
    except Exception as error:  # zip and npy errors come in many types
        raise ResultError(
            path, f"occupancy file cannot be read ({type(error).__name__}: {error})"
        ) from None
    tag = arrays.get("format")
    if tag is None or str(tag) != OCCUPANCY_FORMAT:
        raise ResultError(
            path, f"unknown or missing format tag {tag!r}", f"expected {OCCUPANCY_FORMAT}"
        )
    pitch = float(arrays.get("pitch_m", np.nan))
    if not (math.isfinite(pitch) and pitch > 0):
        raise ResultError(path, f"pitch_m must be a positive number, got {pitch}")

    def pair(prefix: str) -> tuple[np.ndarray, np.ndarray]:
        indices = arrays.get(f"{prefix}_voxels")
        probability = arrays.get(f"{prefix}_probability")
        if indices is None or probability is None:
            raise ResultError(path, f"{prefix}_voxels or {prefix}_probability is missing")
        if indices.ndim != 2 or indices.shape[1] != 3 or indices.dtype.kind not in "iu":
            raise ResultError(
                path,
                f"{prefix}_voxels must be (N, 3) integers, got {indices.dtype} {indices.shape}",
            )
        if probability.shape != (len(indices),) or probability.dtype.kind != "f":
            raise ResultError(
                path, f"{prefix}_probability must be (N,) floats matching {prefix}_voxels"
            )
        if not np.all(np.isfinite(probability)) or np.any((probability < 0) | (probability > 1)):
            raise ResultError(path, f"{prefix}_probability has values outside [0, 1]")
        return indices.astype(np.int32), probability.astype(np.float32)

    ids = arrays.get("object_ids", np.zeros(0, np.int64))
    if ids.ndim != 1 or ids.dtype.kind not in "iu" or len(set(ids.tolist())) != len(ids):
        raise ResultError(path, "object_ids must be distinct integers")
    objects = {int(object_id): pair(f"object_{int(object_id)}") for object_id in ids}
    return Occupancy(pitch, objects, pair("scene"))


# --------------------------------------------------------------------------------------------
# Writing

#: (best mesh, [(hypothesis mesh, probability), ...]) or the same with the best mesh's
#: marginal probability as a third element.
ObjectToWrite = (
    tuple[Any, Sequence[tuple[Any, float]]] | tuple[Any, Sequence[tuple[Any, float]], float]
)


def write_result(
    out_dir: Path | str,
    method: str,
    world_from_camera: Mapping[int, np.ndarray] | np.ndarray,
    objects: Sequence[ObjectToWrite],
    timing_s: Mapping[str, float] | None = None,
    extra: Mapping[str, Any] | None = None,
    *,
    extra_files: Mapping[str, bytes] | None = None,
    overwrite: bool = False,
    occupancy: Occupancy | None = None,
    ids: Sequence[int] | None = None,
    finish: Callable[[Path], None] | None = None,
) -> Path:
    """Write a result directory atomically (staged beside ``out_dir``, then renamed into place).

    Args:
        out_dir: the result directory to create (replaced only when ``overwrite``).
        method: method name recorded in result.json.
        world_from_camera: frame id -> (4, 4) rigid OpenCV-camera-to-world transform (metres);
            frame 0 is required. A single (4, 4) array means frame 0.
        objects: per object k (its id), ``(best_mesh, hypotheses)`` where meshes are trimesh
            meshes or (vertices, faces) pairs in metres, world frame, frame-0 pose, and
            ``hypotheses`` is a sequence of ``(mesh, probability)`` summing to 1 (the best
            included). The object's probability (the contract: the marginal posterior of its
            best hypothesis) is the optional third element, else its largest hypothesis
            probability. With no hypotheses the best mesh is the only hypothesis, with
            probability 1.
        timing_s: named durations in seconds.
        extra: further JSON-serialisable top-level keys (not those of the contract).
        extra_files: further files, relative name -> content (reports, images); names must stay
            inside the directory and not collide with the contract's files.

    Writes ``result.json``, ``objects/<k>/best.ply`` (+ ``hyp_NNN.ply``) as binary PLY and
    ``occupancy.npz`` (``posterior_occupancy`` of the hypotheses; ``occupancy`` gives it
    precomputed, e.g. from cached voxels of the same shapes, keyed by the objects' ids).
    ``ids``: the objects' ids (distinct integers, e.g. the perception's, so that the result's
    ids are those of the segmentation; default 0, 1, ...); object k's files go to
    ``objects/<id>/``. ``finish``: called with the staging folder once everything else is
    written, to add files made from the written result (``report.html``), so that they are
    part of the same atomic step.
    Raises ValueError on invalid inputs and ResultError if ``out_dir`` exists without
    ``overwrite``. Returns ``out_dir``.
    """
    target = Path(out_dir)
    if isinstance(world_from_camera, np.ndarray):
        world_from_camera = {0: world_from_camera}
    cameras = {}
    for key, matrix in world_from_camera.items():
        try:
            cameras[str(int(key))] = check_rigid(matrix, target, f"world_from_camera[{key}]")
        except ResultError as error:
            raise ValueError(error.problem) from None
    if not cameras:
        raise ValueError("world_from_camera must contain the first frame")
    if not isinstance(method, str) or not method:
        raise ValueError("method must be a non-empty string")
    timing = {str(name): float(value) for name, value in (timing_s or {}).items()}
    if not all(math.isfinite(value) for value in timing.values()):
        raise ValueError("timing_s values must be finite")
    extra = dict(extra or {})
    clash = set(extra) & set(RESERVED_KEYS)
    if clash:
        raise ValueError(f"extra must not redefine contract keys {sorted(clash)}")

    files = {}
    for name, content in (extra_files or {}).items():
        relative = Path(name)
        if relative.is_absolute() or ".." in relative.parts or not relative.parts:
            raise ValueError(f"extra file name {name!r} must be a relative path inside the result")
        if relative.parts[0] in ("objects", RESULT_FILE, OCCUPANCY_FILE):
            raise ValueError(f"extra file name {name!r} collides with the result's own files")
        files[relative] = bytes(content)
    ids = list(range(len(objects))) if ids is None else [int(i) for i in ids]
    if len(ids) != len(objects) or len(set(ids)) != len(ids):
        raise ValueError(f"ids must be {len(objects)} distinct integers, one per object")
    prepared = []
    for k, entry in zip(ids, objects, strict=True):
        best, hypotheses = entry[0], entry[1]
        stated = float(entry[2]) if len(entry) > 2 else None
        if stated is not None and not (math.isfinite(stated) and 0.0 <= stated <= 1.0):
            raise ValueError(f"object {k}: best probability {stated} not in [0, 1]")
        best_mesh = _to_trimesh(best)
        _check_mesh_for_writing(best_mesh, f"object {k} best mesh")
        hyps = [(_to_trimesh(mesh), float(p)) for mesh, p in hypotheses]
        for index, (mesh, p) in enumerate(hyps):
            _check_mesh_for_writing(mesh, f"object {k} hypothesis {index}")
            if not (math.isfinite(p) and 0.0 <= p <= 1.0):
                raise ValueError(f"object {k} hypothesis {index}: probability {p} not in [0, 1]")
        if hyps and abs(sum(p for _, p in hyps) - 1.0) > PROBABILITY_TOLERANCE:
            raise ValueError(
                f"object {k}: hypothesis probabilities sum to {sum(p for _, p in hyps):.6g}, not 1"
            )
        prepared.append((best_mesh, hyps, stated))

    if target.exists() and not overwrite:
        raise ResultError(target, "already exists", "choose another folder or allow overwriting")
    if occupancy is None:
        occupancy = posterior_occupancy(
            {
                k: hyps if hyps else [(best, 1.0)]
                for k, (best, hyps, _) in zip(ids, prepared, strict=True)
            }
        )
    elif sorted(occupancy.objects) != sorted(ids):
        raise ValueError("occupancy must list exactly the objects written, by their ids")
    with staged_directory(target) as staging:
        np.savez_compressed(staging / OCCUPANCY_FILE, **_occupancy_arrays(occupancy))
        entries = []
        for relative, content in files.items():
            (staging / relative).parent.mkdir(parents=True, exist_ok=True)
            (staging / relative).write_bytes(content)
        for k, (best_mesh, hyps, stated) in zip(ids, prepared, strict=True):
            folder = staging / "objects" / str(k)
            folder.mkdir(parents=True)
            best_mesh.export(folder / "best.ply", file_type="ply")
            best_name = f"objects/{k}/best.ply"
            if hyps:
                hyp_entries = []
                for index, (mesh, p) in enumerate(hyps):
                    name = f"hyp_{index:03d}.ply"
                    mesh.export(folder / name, file_type="ply")
                    hyp_entries.append({"mesh": f"objects/{k}/{name}", "probability": p})
                probability = stated if stated is not None else max(p for _, p in hyps)
            else:
                hyp_entries = [{"mesh": best_name, "probability": 1.0}]
                probability = 1.0
            entries.append(
                {"id": k, "mesh": best_name, "probability": probability, "hypotheses": hyp_entries}
            )
        document = {
            "format": RESULT_FORMAT,
            "method": method,
            "world_from_camera": {
                key: matrix.tolist()
                for key, matrix in sorted(cameras.items(), key=lambda item: int(item[0]))
            },
            "objects": entries,
            "timing_s": timing,
            **extra,
        }
        text = json.dumps(document, indent=1, allow_nan=False)
        (staging / RESULT_FILE).write_text(text + "\n", encoding="utf-8")
        if finish is not None:
            finish(staging)
    return target


def _check_mesh_for_writing(mesh: Any, what: str) -> None:
    if len(mesh.faces) == 0:
        raise ValueError(f"{what} has no faces")
    vertices = np.asarray(mesh.vertices)
    if not np.all(np.isfinite(vertices)):
        raise ValueError(f"{what} has NaN or inf vertices")
    # trimesh's extents (the sides of the box of the vertices the faces use) without its
    # cache's hashing.
    used = np.zeros(len(vertices), dtype=bool)
    used[np.asarray(mesh.faces).ravel()] = True
    corners = vertices[used]
    extent = float(np.max(corners.max(axis=0) - corners.min(axis=0))) if len(corners) else 0.0
    if extent > voxels.MAX_MESH_EXTENT_M:
        raise ValueError(
            f"{what} spans {extent:.4g} m, more than the {voxels.MAX_MESH_EXTENT_M:g} m an object "
            "may (are its coordinates in millimetres? results are in metres)"
        )


def write_posterior_result(
    out_dir: Path | str,
    posteriors: Sequence[ObjectPosterior],
    world_from_camera: Mapping[int, np.ndarray],
    timing_s: Mapping[str, float] | None = None,
    *,
    method: str,
    extra: Mapping | None = None,
    extra_files: Mapping[str, bytes] | None = None,
    overwrite: bool = False,
    finish: Callable[[Path], None] | None = None,
) -> Path:
    """Write a result directory (``ipr_shapes.result.write_result``) from per-object posteriors: per
    object its output shape as ``best.ply`` and its hypotheses with non-zero probability
    (renormalised against rounding) as weighted hypotheses. Each object's id in the result is
    its posterior's ``object_id`` (the perception's id: the ids ``ipr-shapes segment`` shows).

    ``world_from_camera``: frame id -> (4, 4) OpenCV camera-to-world (frame 0 required).
    ``extra["objects_summary"]`` records each object's id, inference mode and volumes;
    ``extra`` adds further keys and ``extra_files`` further files (name -> bytes);
    ``finish`` as for ``write_result``.
    """
    objects, summary, shapes = [], [], {}
    for posterior in posteriors:
        keep = np.flatnonzero(posterior.probabilities > 0)
        weights = posterior.probabilities[keep] / posterior.probabilities[keep].sum()
        hypotheses = [
            (posterior.written_mesh(k), float(w)) for k, w in zip(keep, weights, strict=True)
        ]
        # occupancy.npz from the voxels the hypotheses already have (not voxelised again).
        shapes[posterior.object_id] = [
            (posterior.written_shape(k), float(w)) for k, w in zip(keep, weights, strict=True)
        ]
        best_probability = float(posterior.probabilities[posterior.best])
        objects.append((posterior.output_mesh, hypotheses, best_probability))
        summary.append(
            {
                "object_id": posterior.object_id,
                "inference": posterior.inference,
                "hypotheses": len(posterior.hypotheses),
                "nonzero": int(keep.size),
                "best_volume_m3": posterior.best_hypothesis.volume_m3,
                "carved": posterior.output_meshes is not None
                and posterior.output_meshes[posterior.best] is not None,
                "volumes_m3": volume_spread(posterior.hypotheses),
                "best_generator": posterior.best_hypothesis.generator,
                "hypothesis_generators": [posterior.hypotheses[k].generator for k in keep],
                "generation_s": posterior.generation_s,
            }
        )
    return write_result(
        out_dir,
        method,
        dict(world_from_camera),
        objects,
        timing_s,
        {"objects_summary": summary, **dict(extra or {})},
        extra_files=extra_files,
        overwrite=overwrite,
        ids=[posterior.object_id for posterior in posteriors],
        finish=finish,
        occupancy=posterior_occupancy(shapes),
    )
