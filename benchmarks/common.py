"""Shared helpers for benchmarks: machine description, medians, markdown tables."""

from __future__ import annotations

import contextlib
import os
import platform
import statistics
import subprocess
from collections.abc import Iterator, Sequence
from pathlib import Path


def machine_description() -> str:
    """One line naming the CPU, core count, memory and software versions."""
    import mujoco
    import numpy

    from ipr_shapes.gl import select_gl_backend  # the backend the benchmarks render with

    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as info:
            for line in info:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    memory = ""
    try:
        pages = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        memory = f", {pages / 2**30:.0f} GiB RAM"
    except (ValueError, OSError):
        pass
    commit = "unknown"
    with contextlib.suppress(OSError, subprocess.CalledProcessError):
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
    return (
        f"{cpu}, {os.cpu_count()} cores{memory}; Python {platform.python_version()}, "
        f"MuJoCo {mujoco.__version__}, NumPy {numpy.__version__}, "
        f"MUJOCO_GL={select_gl_backend() or '-'}; commit {commit}"
    )


def median(values: Sequence[float]) -> float:
    """Median of a non-empty sequence (nan when empty)."""
    return statistics.median(values) if values else float("nan")


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A GitHub markdown table; floats are printed with 3 decimals. ValueError when a row
    has not as many cells as the header (a table a reader would misread)."""
    for row in rows:
        if len(row) != len(header):
            raise ValueError(f"table row has {len(row)} cells for {len(header)} columns: {row}")

    def cell(value: object) -> str:
        return f"{value:.3f}" if isinstance(value, float) else str(value)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(value) for value in row) + " |" for row in rows]
    return "\n".join(lines)


#: Open containers the generator's pool rule drops (solidity), for segmentation development.
CONTAINER_OBJECTS = ("024_bowl", "025_mug", "065-a_cups", "065-d_cups", "065-g_cups", "065-j_cups")


def development_scenes(
    root: Path, seed: int, count: int, *, kind: str = "dynamic", containers: bool = False
) -> list[Path]:
    """The scene directories (sorted) of ``count`` generated development scenes of ``kind``
    from ``seed`` (never a benchmark suite's seeds), in ``root/<kind>-<seed>-<count>``
    (``root/<kind>-containers-<seed>-<count>`` with ``containers``: the pool also holds the
    bowl, the mug and four cups, each twice, ``CONTAINER_OBJECTS``): generated on first use into
    a temporary folder renamed when complete, so an interrupted run leaves no half-written set
    to be reused."""
    from ipr_shapes.synth import SynthConfig, generate_scenes

    name = f"{kind}-containers-{seed}-{count}" if containers else f"{kind}-{seed}-{count}"
    folder = Path(root) / name
    if not folder.exists():
        partial = folder.with_name(folder.name + ".part")
        if partial.exists():
            import shutil

            shutil.rmtree(partial)
        config = SynthConfig(extra_objects=CONTAINER_OBJECTS * 2) if containers else SynthConfig()
        generate_scenes(partial, kind=kind, seed=seed, count=count, config=config)
        partial.rename(folder)
    return sorted(p for p in folder.iterdir() if (p / "scene_camera.json").exists())


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """Limit BLAS/OpenMP thread pools to one thread (the one-core target), when possible."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover (the bench extra brings threadpoolctl)
        yield
        return
    with threadpool_limits(limits=1):
        yield
