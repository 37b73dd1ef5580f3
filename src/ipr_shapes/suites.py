"""Benchmark suites: scene lists generated on demand from fixed seeds, cached outside the repo.

- ``ycb-static``: 24 static piles (twice the paper's 12 static YCB scenes).
- ``ycb-dynamic``: 26 piles with 1-3 pushes each (twice the paper's 13 dynamic scenes).
- ``ycbv-real``: the real YCB-Video frames in the shared data (BOP format, static).
- ``bins-real``: the real bin-picking frames in the shared data (BOP format with ``mask_visib/``,
  one static frame each, boxes in a bin, no camera pose).

Real suites are read in place from the shared data (``ipr_shapes.data``), never copied or cached.

Generated suites live in ``<cache>/suites/<name>-<key>/`` where ``key`` hashes the generator's
source and default configuration, so a change to the generator makes a new suite instead of
silently reusing stale scenes. A suite is complete when its ``suite.json`` manifest exists;
scenes are generated in parallel, one process per core.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

from ipr_shapes.data import bins_real_dir, cache_dir, ycb_models_dir, ycbv_real_dir
from ipr_shapes.errors import IprError
from ipr_shapes.synth import ARRANGEMENTS


@dataclass(frozen=True)
class SuiteSpec:
    """A generated suite: scene kind, base seed and number of scenes."""

    kind: str
    seed: int
    count: int


GENERATED = {
    "ycb-static": SuiteSpec("static", 2018_12, 24),
    "ycb-dynamic": SuiteSpec("dynamic", 2018_13, 26),
}
#: Real suites: name -> where the shared data keeps their scenes (None when absent).
REAL: dict[str, Callable[[], Path | None]] = {
    "ycbv-real": ycbv_real_dir,
    "bins-real": bins_real_dir,
}
SUITES = [*GENERATED, *REAL]


def generator_key() -> str:
    """Short hash of the generator's source files and default configuration."""
    import ipr_shapes.synth
    from ipr_shapes.synth import SynthConfig

    digest = hashlib.sha256(repr(SynthConfig()).encode())
    for source in sorted(Path(ipr_shapes.synth.__file__).parent.glob("*.py")):
        digest.update(source.name.encode())
        digest.update(source.read_bytes())
    return digest.hexdigest()[:10]


def suite_dir(name: str) -> Path:
    """Folder of a generated suite in the cache (may not exist yet)."""
    return cache_dir() / "suites" / f"{name}-{generator_key()}"


def _generate_one(
    out_dir: str, kind: str, seed: int, arrangement: str, name: str
) -> tuple[str, float]:
    from ipr_shapes.synth import generate_scene

    started = time.perf_counter()
    path = generate_scene(
        Path(out_dir),
        kind=kind,
        seed=seed,
        arrangement=arrangement,
        name=name,
        models_dir=ycb_models_dir(),
        overwrite=True,
    )
    return str(path), time.perf_counter() - started


def suite_scenes(
    name: str,
    *,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[Path]:
    """Scene folders of a suite, generating and caching a generated suite on first use."""
    if name in REAL:
        root = REAL[name]()
        if root is None:
            raise IprError(f"suite {name} needs the shared data (../shared/data or $IPR_DATA)")
        return sorted(path for path in root.iterdir() if (path / "scene_camera.json").exists())
    if name not in GENERATED:
        raise IprError(f"unknown suite {name!r}; choose one of {', '.join(SUITES)}")
    spec = GENERATED[name]
    folder = suite_dir(name)
    manifest = folder / "suite.json"
    if manifest.exists():
        return [folder / scene for scene in json.loads(manifest.read_text())["scenes"]]

    folder.mkdir(parents=True, exist_ok=True)
    jobs = [
        (
            str(folder),
            spec.kind,
            spec.seed * 1000 + index,
            ARRANGEMENTS[index % 3],
            f"{name}-{index:03d}",
        )
        for index in range(spec.count)
    ]
    workers = workers or os.cpu_count() or 1
    timings: dict[str, float] = {}
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
        futures = [pool.submit(_generate_one, *job) for job in jobs]
        for done, future in enumerate(futures, start=1):
            path, seconds = future.result()
            timings[Path(path).name] = seconds
            if progress:
                progress(done, len(jobs))
    scenes = [job[4] for job in jobs]
    staging = folder / ".suite.json.tmp"
    staging.write_text(
        json.dumps(
            {
                "suite": name,
                "kind": spec.kind,
                "seed": spec.seed,
                "generator_key": generator_key(),
                "models": "ycb" if ycb_models_dir() else "procedural",
                "scenes": scenes,
                "generation_s": timings,
            },
            indent=1,
        )
    )
    staging.replace(manifest)
    return [folder / scene for scene in scenes]


def clear_stale_suites() -> list[Path]:
    """Remove cached suites made by other generator versions; return what was removed."""
    root = cache_dir() / "suites"
    if not root.is_dir():
        return []
    current = {suite_dir(name).name for name in GENERATED}
    removed = [path for path in root.iterdir() if path.is_dir() and path.name not in current]
    for path in removed:
        shutil.rmtree(path, ignore_errors=True)
    return removed
