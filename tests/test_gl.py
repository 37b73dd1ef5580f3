"""Importing ipr leaves the host's environment alone; ipr still renders offscreen wherever it
renders (this process, MuJoCo's own Renderer, a fork-server worker), choosing the backend then."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Imports every module of ipr, then renders in a fork-server worker, in this process through
#: ipr_shapes.rendering, and through MuJoCo's own Renderer; prints what changed in os.environ.
SCRIPT = """
import importlib, json, multiprocessing, os, pkgutil
before = dict(os.environ)
import ipr_shapes
for module in pkgutil.walk_packages(ipr_shapes.__path__, "ipr_shapes."):
    if module.name != "ipr_shapes.__main__":  # runs the command
        importlib.import_module(module.name)
import mujoco  # imported before any choice: MuJoCo picked its GL context with no MUJOCO_GL
after_import = {k: v for k, v in os.environ.items() if before.get(k) != v}
after_import.update({k: None for k in before if k not in os.environ})

import numpy as np
from ipr_shapes.camera import look_at
from ipr_shapes.rendering import render_depth_and_ids

box = (np.array([[x, y, z] for x in (-.05, .05) for y in (-.05, .05) for z in (0, .1)]),
       np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                 [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]))
K = np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]])
args = ([box], [None], K, 64, 48, look_at(np.array([0.3, -0.3, 0.4]), np.zeros(3)))
context = multiprocessing.get_context("forkserver")
context.set_forkserver_preload(["ipr_shapes.inference.pool"])  # as the sampling pool does
with context.Pool(1) as pool:
    worker_depth, _ = pool.apply(render_depth_and_ids, args)
    worker_gl = pool.apply(os.getenv, ("MUJOCO_GL",))
depth, index = render_depth_and_ids(*args)
import ipr_shapes.gl
backend = ipr_shapes.gl.check_rendering()
print(json.dumps({
    "changed_by_import": after_import,
    "worker_sees_box": bool((worker_depth > 0).any()),
    "worker_gl": worker_gl,
    "sees_box": bool((index == 0).any()),
    "gl": os.environ.get("MUJOCO_GL"),
    "backend": backend,
}))
"""


def _run(env_changes: dict[str, str | None]) -> dict:
    env = dict(os.environ)
    for key, value in env_changes.items():
        if value is None:
            env.pop(key, None)
        else:
            env[key] = value
    completed = subprocess.run(
        [sys.executable, "-c", SCRIPT],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=300,
    )
    assert completed.returncode == 0, completed.stderr[-3000:]
    return json.loads(completed.stdout.strip().splitlines()[-1])


@pytest.mark.slow  # several seconds: keeps `make test` under 3 minutes on 2 cores
def test_importing_ipr_leaves_the_environment_alone_and_rendering_still_works():
    outcome = _run({"MUJOCO_GL": None, "PYOPENGL_PLATFORM": None})
    assert outcome["changed_by_import"] == {}
    assert outcome["sees_box"] and outcome["worker_sees_box"]
    # Chosen where ipr rendered, in each process for itself.
    assert outcome["gl"] in ("egl", "osmesa") and outcome["worker_gl"] == outcome["gl"]
    assert outcome["backend"] == outcome["gl"]


@pytest.mark.slow
def test_a_backend_the_user_chose_is_kept():
    from ctypes.util import find_library

    if not find_library("OSMesa"):
        pytest.skip("OSMesa is not installed")
    outcome = _run({"MUJOCO_GL": "osmesa", "PYOPENGL_PLATFORM": None})
    assert outcome["sees_box"] and outcome["worker_sees_box"]
    assert outcome["gl"] == outcome["worker_gl"] == outcome["backend"] == "osmesa"
