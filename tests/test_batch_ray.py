"""``ipr-shapes batch --ray ADDRESS``: scenes on an existing Ray cluster (a local head started here, on
127.0.0.1 only), with the local pool's semantics; and every way ``--ray`` can be refused."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from ipr_shapes.batch import (
    SceneOutcome,
    _run_all,
    _Runner,
    run_scene_detached,
    write_result_files,
)
from ipr_shapes.cli import EXIT_INPUT_ERROR, main
from ipr_shapes.cluster import RAY_INSTALL, _deadline, check_reachable, parse_address
from ipr_shapes.errors import IprError

#: result.json keys that hold wall-clock times or the time of writing: the only keys that may
#: differ between two runs of one scene with one seed.
CLOCK_KEYS = {"timing_s", "created_utc", "generation_s"}


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_ray_addresses_are_validated():
    assert parse_address("auto").host is None
    head = parse_address("127.0.0.1:6379")
    assert (head.host, head.port, head.client) == ("127.0.0.1", 6379, False)
    client = parse_address("ray://head-node.lab:10001")
    assert (client.host, client.port, client.client) == ("head-node.lab", 10001, True)
    assert parse_address("[::1]:6379").host == "::1"
    for bad in ["", "127.0.0.1", "127.0.0.1:0", "127.0.0.1:70000", "http://h:1", "h:p", "a b:1"]:
        with pytest.raises(IprError, match="not a Ray cluster address"):
            parse_address(bad)


def test_an_unreachable_head_is_refused_quickly():
    port = _free_port()  # closed again: nothing listens there
    started = time.monotonic()
    with pytest.raises(IprError, match="cannot reach the Ray cluster"):
        check_reachable(parse_address(f"127.0.0.1:{port}"), timeout_s=5)
    assert time.monotonic() - started < 5


def test_a_connection_that_hangs_is_cut_at_its_deadline():
    """Also through a retry loop that catches Exception, as Ray's connection attempts do."""
    started = time.monotonic()
    with pytest.raises(IprError, match="too slow"), _deadline(0.3, "too slow"):
        while time.monotonic() - started < 5:
            try:
                time.sleep(0.1)
            except Exception:  # noqa: BLE001, S112 - the retry loop the deadline must get through
                continue
    assert time.monotonic() - started < 2


def test_batch_with_ray_missing_says_how_to_install_it_and_writes_nothing(
    scene_dir: Path, tmp_path: Path, monkeypatch, capsys
):
    monkeypatch.setitem(sys.modules, "ray", None)  # as if not installed: import ray fails
    out = tmp_path / "out"
    assert main(["batch", str(scene_dir), "-o", str(out), "--ray", "auto"]) == EXIT_INPUT_ERROR
    error = capsys.readouterr().err.strip()
    assert RAY_INSTALL in error and len(error.splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize("address", ["nonsense", "127.0.0.1:{closed}"])
def test_batch_with_a_bad_or_unreachable_address_fails_before_any_output(
    scene_dir: Path, tmp_path: Path, address: str, capsys
):
    pytest.importorskip("ray", reason=f"Ray is not installed ({RAY_INSTALL})")
    out = tmp_path / "out"
    run = ["batch", str(scene_dir), "-o", str(out), "--ray", address.format(closed=_free_port())]
    assert main(run) == EXIT_INPUT_ERROR
    error = capsys.readouterr().err
    assert "not a Ray cluster address" in error or "cannot reach the Ray cluster" in error
    assert not out.exists()


def test_a_scene_missing_on_a_node_fails_with_the_fix(tmp_path: Path):
    outcome, files = run_scene_detached(str(tmp_path / "not-mounted-here"), None)
    assert outcome.status == "failed" and files == {}
    assert "not found on the cluster node" in outcome.error and "same path" in outcome.error


def test_returned_result_files_are_written_whole_or_not_at_all(tmp_path: Path):
    target = tmp_path / "out" / "scene"
    write_result_files({"result.json": b"{}", "objects/1/best.ply": b"ply"}, target)
    assert (target / "objects/1/best.ply").read_bytes() == b"ply"
    with pytest.raises(IprError, match="leaves the folder"):
        write_result_files({"result.json": b"new", "../escape": b"x"}, target)
    assert (target / "result.json").read_bytes() == b"{}"  # the earlier result stays
    assert not (tmp_path / "out" / "escape").exists()
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["scene"]  # no staging left


def test_a_lost_worker_fails_its_scenes_and_the_others_are_kept(tmp_path: Path):
    """The loop both backends share: a worker process that dies (here: it exits mid-task) is
    a failed outcome, not an exception, and scenes that finished before keep their outcome."""
    scenes = [tmp_path / "a", tmp_path / "b"]
    outcomes: dict[int, SceneOutcome] = {}
    with ProcessPoolExecutor(max_workers=1) as pool:

        def submit(scene: Path, result_dir: Path):
            if scene.name == "a":
                return pool.submit(str, "fine")
            return pool.submit(os._exit, 3)

        def settle(value, scene: Path, result_dir: Path) -> SceneOutcome:
            return SceneOutcome(str(scene), str(result_dir), "done", objects=len(value))

        runner = _Runner(submit=submit, settle=settle, window=1)
        _run_all(scenes, tmp_path / "out", runner, outcomes.__setitem__, range(2))
    assert outcomes[0].status == "done" and outcomes[0].objects == 4
    assert outcomes[1].status == "failed" and outcomes[1].error.startswith("worker died:")


# --- A real Ray cluster on this machine ---------------------------------------------------------

#: Keeps Ray's addresses on the loopback: without it Ray turns 127.0.0.1 into the machine's
#: network address (ray._private.services.resolve_ip_for_localhost).
LOOPBACK_ENV = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}


@pytest.fixture(scope="module")
def ray_head() -> Iterator[tuple[str, str]]:
    """A Ray head on 127.0.0.1 with 2 CPUs, started for these tests and stopped after them;
    yields its addresses (HOST:PORT, and ray://HOST:PORT of its Ray Client server)."""
    if not _ray_installed():
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must run the Ray test: Ray is not installed ({RAY_INSTALL})")
        pytest.skip(f"Ray is not installed ({RAY_INSTALL}; make test-slow installs it)")
    port, client_port = _free_port(), _free_port()
    temp = Path(tempfile.mkdtemp(prefix="ipr-ray-", dir="/tmp"))  # short: Ray's socket paths
    ray = Path(sys.executable).with_name("ray")
    command = [
        str(ray) if ray.exists() else "ray", "start", "--head", "--block",
        f"--port={port}", "--node-ip-address=127.0.0.1", f"--ray-client-server-port={client_port}",
        "--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats",
        "--object-store-memory=200000000", f"--temp-dir={temp}",
    ]  # fmt: skip
    log = (temp / "head.log").open("w")
    head = subprocess.Popen(
        command,
        stdout=log,
        stderr=subprocess.STDOUT,
        env={**os.environ, **LOOPBACK_ENV},
        start_new_session=True,  # its own process group: stopped as a whole at the end
    )
    try:
        deadline = time.monotonic() + 180
        while "Ray runtime started" not in (temp / "head.log").read_text():
            if head.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"the Ray head did not start: {(temp / 'head.log').read_text()}")
            time.sleep(0.5)
        # "Ray runtime started" comes before the Ray Client server can serve: its first
        # connection starts a server process per client, which on a fresh venv's cold start can
        # fail ("Initialization failure from server"). Connect until one succeeds.
        client = f"ray://127.0.0.1:{client_port}"
        probe = f"import ray; ray.init({client!r}); ray.shutdown()"
        while True:
            connected = subprocess.run(
                [sys.executable, "-c", probe],
                capture_output=True,
                text=True,
                timeout=300,
                env={**os.environ, **LOOPBACK_ENV},
            )
            if connected.returncode == 0:
                break
            if head.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"the Ray Client server did not serve: {connected.stderr[-2000:]}")
            time.sleep(1.0)
        yield f"127.0.0.1:{port}", client
    finally:
        head.send_signal(signal.SIGTERM)  # ray start --block stops what it started
        with contextlib.suppress(subprocess.TimeoutExpired):
            head.wait(timeout=60)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(head.pid, signal.SIGKILL)  # anything of this head's group left over
        log.close()
        shutil.rmtree(temp, ignore_errors=True)


def _ray_installed() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def _ipr(*args: str) -> subprocess.CompletedProcess:
    """``ipr ARGS`` in a process of its own (a Ray driver), with the loopback setting."""
    return subprocess.run(
        [sys.executable, "-m", "ipr_shapes", *args],
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, **LOOPBACK_ENV},
    )


def _without_clocks(value):
    if isinstance(value, dict):
        return {k: _without_clocks(v) for k, v in value.items() if k not in CLOCK_KEYS}
    if isinstance(value, list):
        return [_without_clocks(v) for v in value]
    return value


def _files(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()
    }


@pytest.mark.slow
def test_a_batch_on_a_ray_cluster_matches_the_local_pool(ray_head: tuple[str, str], tmp_path: Path):
    """Through Ray Client first (ray://), then through the head's address (the rerun)."""
    head, client = ray_head
    scenes = tmp_path / "scenes"
    synth = ["synth", str(scenes), "--kind", "static", "--seed", "5", "--count", "2"]
    assert main([*synth, "--width", "320", "--height", "240"]) == 0
    broken = scenes / "static_broken"
    broken.mkdir()
    (broken / "scene_camera.json").write_text("{not json")
    names = ["static_000000", "static_000001"]
    common = ["--method", "collision-checker", "--seed", "3"]
    on_ray = tmp_path / "on-ray"
    run = ["batch", str(scenes), "-o", str(on_ray), *common, "--ray"]

    completed = _ipr(*run, client)
    assert completed.returncode == 1, completed.stderr  # one scene failed, the others ran
    assert "2 run, 0 kept, 1 failed" in completed.stdout
    summary = json.loads((on_ray / "summary.json").read_text())
    status = {Path(o["scene"]).name: o for o in summary["outcomes"]}
    assert [status[n]["status"] for n in names] == ["done", "done"]
    assert all(status[n]["result"] == str(on_ray / n) for n in names)  # here, not the worker's
    assert status["static_broken"]["status"] == "failed"
    assert "scene_camera.json" in status["static_broken"]["error"]
    assert not (on_ray / "static_broken").exists()  # nothing half-written
    assert "static_broken" in (on_ray / "summary.md").read_text()
    assert not [p for p in on_ray.iterdir() if p.name.startswith(".")]  # no staging left

    # The same scenes in the local pool: the same result files (clock readings aside).
    local = tmp_path / "local"
    assert main(["batch", str(scenes), "-o", str(local), *common, "--jobs", "1"]) == 1
    local_summary = json.loads((local / "summary.json").read_text())
    for name, row in zip(names, local_summary["outcomes"][:2], strict=True):
        assert row["object_iou"] == status[name]["object_iou"] and row["objects"] >= 1
        ray_files, local_files = _files(on_ray / name), _files(local / name)
        assert sorted(ray_files) == sorted(local_files) and "objects/1/best.ply" in ray_files
        for file in ray_files:
            if file == "result.json":
                ray_json, local_json = (json.loads(f[file]) for f in (ray_files, local_files))
                assert _without_clocks(ray_json) == _without_clocks(local_json)
            elif file == "report.html":  # shows result.json's timings: only its presence
                assert ray_files[file].startswith(b"<!DOCTYPE html>")
                assert local_files[file].startswith(b"<!DOCTYPE html>")
            else:
                assert ray_files[file] == local_files[file], file

    # Rerun on the cluster: the finished results are kept (scored here), the fixed scene runs.
    broken.rename(tmp_path / "set-aside")
    stamp = (on_ray / names[0] / "result.json").stat().st_mtime_ns
    completed = _ipr(*run, head)
    assert completed.returncode == 0, completed.stderr
    assert "0 run, 2 kept, 0 failed" in completed.stdout
    summary = json.loads((on_ray / "summary.json").read_text())
    assert {o["status"] for o in summary["outcomes"]} == {"kept"}
    assert [o["object_iou"] for o in summary["outcomes"]] == [
        status[n]["object_iou"] for n in names
    ]
    assert (on_ray / names[0] / "result.json").stat().st_mtime_ns == stamp
