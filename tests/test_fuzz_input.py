"""Fuzzing the entry points (issue 31, item 3): scene and result folders with mutated JSON values
and types, corrupt and oversized PNGs and odd files (FIFO, folder, empty file, symlink loop).
``ipr-shapes check``, ``ipr-shapes eval`` and ``ipr-shapes export`` must exit 0 or 2, say a failure in one line on
stderr without a traceback, leave no output behind and finish within a time bound.
Deterministic (``derandomize``): the same cases on every run."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import zlib
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from ipr_shapes.cli import main  # noqa: E402

#: Seconds one command may take on a mutated 160 x 120 scene.
TIME_BOUND_S = 20


def _settings(examples: int):
    return settings(
        max_examples=examples,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
    )


json_values = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(min_value=-(2**70), max_value=2**70),
        st.floats(allow_nan=False, allow_infinity=False),
        st.sampled_from([0, -1, 1e-300, 1e300, 1e7, "0", "1.5", "", "abc", 0.5]),
        st.text(max_size=5),
    ),
    lambda children: (
        st.lists(children, max_size=10) | st.dictionaries(st.text(max_size=3), children, max_size=3)
    ),
    max_leaves=12,
)


def _paths(document, prefix=()):
    """Every (path of keys/indices) into a JSON document, itself included."""
    yield prefix
    if isinstance(document, dict):
        for key, value in document.items():
            yield from _paths(value, (*prefix, key))
    elif isinstance(document, list):
        for index, value in enumerate(document):
            yield from _paths(value, (*prefix, index))


@st.composite
def json_mutation(draw, files: tuple[str, ...]):
    name = draw(st.sampled_from(files))
    return ("json", name, draw(st.integers(0, 10_000)), draw(json_values), draw(st.booleans()))


@st.composite
def png_mutation(draw, files: tuple[str, ...]):
    name = draw(st.sampled_from(files))
    how = draw(st.sampled_from(["truncate", "flip", "huge", "garbage"]))
    return ("png", name, how, draw(st.integers(0, 10_000)), draw(st.binary(max_size=64)))


@st.composite
def odd_file(draw, files: tuple[str, ...]):
    name = draw(st.sampled_from(files))
    return ("odd", name, draw(st.sampled_from(["fifo", "folder", "empty", "loop", "broken"])))


def _apply(root: Path, mutation) -> None:
    kind, name = mutation[0], mutation[1]
    path = root / name
    if kind in ("json", "png") and not (path.is_file() and path.stat().st_size):
        return  # an earlier mutation made it a FIFO, folder, link or empty: reading would block
    if kind == "json":
        _, _, pick, value, delete = mutation
        document = json.loads(path.read_text())
        paths = list(_paths(document))
        where = paths[pick % len(paths)]
        if not where:
            document = value
        else:
            parent = document
            for key in where[:-1]:
                parent = parent[key]
            if delete and isinstance(parent, dict):
                del parent[where[-1]]
            else:
                parent[where[-1]] = value
        path.write_text(json.dumps(document))
    elif kind == "png":
        _, _, how, offset, payload = mutation
        data = bytearray(path.read_bytes())
        if how == "truncate":
            data = data[: offset % len(data)]
        elif how == "flip":
            data[8 + offset % (len(data) - 8)] ^= 0xFF
        elif how == "huge":
            side = (offset % 200_000 + 1).to_bytes(4, "big")
            body = b"IHDR" + side + side + bytes([16, 0, 0, 0, 0])
            chunk = (13).to_bytes(4, "big") + body + zlib.crc32(body).to_bytes(4, "big")
            data = bytearray(bytes(data[:8]) + chunk + bytes(data[33:]))
        else:
            data = bytearray(bytes(data[: offset % len(data)]) + payload)
        path.write_bytes(bytes(data))
    else:
        _, _, what = mutation
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
        if what == "fifo":
            os.mkfifo(path)
        elif what == "folder":
            path.mkdir()
        elif what == "empty":
            path.write_bytes(b"")
        elif what == "loop":
            path.symlink_to(path.name)
        else:
            path.symlink_to("nowhere")


class _Timeout(Exception):
    pass


def _run(args: list[str]) -> tuple[int, str]:
    """``ipr ARGS`` in this process within TIME_BOUND_S: (exit status, stderr). Any exception
    that escapes main (a traceback for a user) fails the test."""

    def expire(signum, frame):
        raise _Timeout

    err = io.StringIO()
    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(TIME_BOUND_S)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                code = main(args)
            except SystemExit as exit_info:
                code = exit_info.code
    except _Timeout:
        pytest.fail(f"ipr {' '.join(args)} took more than {TIME_BOUND_S} s")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    return code, err.getvalue()


def _check_outcome(code: int, stderr: str) -> None:
    assert code in (0, 2), (code, stderr)
    assert "Traceback" not in stderr, stderr
    if code == 2:
        assert len(stderr.strip().splitlines()) == 1, stderr


def _listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


# ---------------------------------------------------------------------------------- scenes

SCENE_JSON = ("scene_camera.json", "actions.json")
SCENE_PNG = ("rgb/000000.png", "depth/000000.png", "depth/000001.png")
SCENE_FILES = (*SCENE_JSON, *SCENE_PNG, "rgb", "depth/000001.png")
scene_mutations = st.lists(
    st.one_of(json_mutation(SCENE_JSON), png_mutation(SCENE_PNG), odd_file(SCENE_FILES)),
    min_size=1,
    max_size=3,
)


@pytest.fixture(scope="module")
def base_scene(tmp_path_factory) -> Path:
    from ipr_shapes.scene import Push, Pusher, write_scene

    from .conftest import make_frames

    push = Push(0, 1, np.array([-0.1, 0.0, 0.08]), np.array([1.0, 0, 0]), 0.08, 0.05)
    folder = tmp_path_factory.mktemp("fuzz") / "base"
    return write_scene(folder, make_frames(2), pushes=[push], pusher=Pusher())


def _mutated_copy(base: Path, target: Path, mutations) -> Path:
    """``target``: a fresh copy of the folder ``base`` (its parent emptied first) with the
    ``mutations`` applied in turn."""
    shutil.rmtree(target.parent, ignore_errors=True)
    shutil.copytree(base, target, symlinks=True)
    for mutation in mutations:
        # An earlier mutation may have removed or broken the file (or made its folder a
        # symlink loop: OSError ELOOP).
        with contextlib.suppress(OSError, json.JSONDecodeError, UnicodeDecodeError,
                                 ZeroDivisionError, IndexError, KeyError, TypeError):  # fmt: skip
            _apply(target, mutation)
    return target


def _fuzz_check(base_scene: Path, mutations) -> None:
    work = base_scene.parent / "work"
    scene = _mutated_copy(base_scene, work / "scene", mutations)
    before = _listing(work)
    code, stderr = _run(["check", str(scene)])
    _check_outcome(code, stderr)
    assert _listing(work) == before  # check writes nothing


@_settings(3)
@given(mutations=scene_mutations)
def test_check_survives_mutated_scenes_fast(base_scene: Path, mutations):
    _fuzz_check(base_scene, mutations)


@pytest.mark.slow
@_settings(300)
@given(mutations=scene_mutations)
def test_check_survives_mutated_scenes(base_scene: Path, mutations):
    _fuzz_check(base_scene, mutations)


# ---------------------------------------------------------------------------------- results

RESULT_JSON = ("result.json",)
RESULT_FILES = ("result.json", "objects", "objects/0/best.ply", "occupancy.npz")
result_mutations = st.lists(
    st.one_of(
        json_mutation(RESULT_JSON), png_mutation(("objects/0/best.ply",)), odd_file(RESULT_FILES)
    ),  # fmt: skip
    min_size=1,
    max_size=2,
)


@pytest.fixture(scope="module")
def base_result(tmp_path_factory) -> tuple[Path, Path]:
    from ipr_shapes.ground_truth import write_ground_truth_result
    from ipr_shapes.synth import SynthConfig, generate_scene

    folder = tmp_path_factory.mktemp("fuzz-result")
    scene = generate_scene(
        folder / "scenes", kind="static", seed=3, config=SynthConfig(width=160, height=120)
    )
    result = write_ground_truth_result(scene, folder / "base")
    first = sorted((result / "objects").iterdir())[0]
    if first.name != "0":  # the mutations name objects/0
        document = json.loads((result / "result.json").read_text())
        first.rename(result / "objects" / "0")
        text = json.dumps(document).replace(f"objects/{first.name}/", "objects/0/")
        (result / "result.json").write_text(text)
    return scene, result


def _fuzz_result(base_result: tuple[Path, Path], mutations) -> None:
    scene, base = base_result
    work = base.parent / "work"
    result = _mutated_copy(base, work / "result", mutations)
    before = _listing(work)
    code, stderr = _run(["eval", str(scene), str(result), "--json", str(work / "m.json")])
    _check_outcome(code, stderr)
    assert code == 0 or not (work / "m.json").exists()
    (work / "m.json").unlink(missing_ok=True)
    code, stderr = _run(["export", str(result), "--format", "obj", "-o", str(work / "export")])
    _check_outcome(code, stderr)
    if code != 0:
        assert _listing(work) == before  # no output left behind


@pytest.mark.slow  # the base result needs a synthetic scene with ground truth (~20 s)
@_settings(3)
@given(mutations=result_mutations)
def test_eval_and_export_survive_mutated_results_fast(base_result, mutations):
    _fuzz_result(base_result, mutations)


@pytest.mark.slow
@_settings(100)
@given(mutations=result_mutations)
def test_eval_and_export_survive_mutated_results(base_result, mutations):
    _fuzz_result(base_result, mutations)
