"""Atomic output: folders and files are written to a temporary path beside the target and renamed
into place, so a failed or interrupted run never leaves half-written output."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any


def staging_directory(target: Path) -> Path:
    """A fresh, world-readable temporary folder beside ``target`` (same filesystem)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    staging.chmod(0o755)  # mkdtemp makes it private; scenes and results are meant to be shared
    return staging


def commit_directory(staging: Path, target: Path) -> None:
    """Move a fully written staging folder into place (replacing ``target`` if it exists)."""
    if target.exists():
        backup = target.with_name(f".{target.name}.old-{os.getpid()}")
        os.replace(target, backup)
        os.replace(staging, target)
        shutil.rmtree(backup, ignore_errors=True)
    else:
        os.replace(staging, target)


@contextlib.contextmanager
def staged_directory(target: Path) -> Iterator[Path]:
    """Yield a staging folder for ``target``; move it into place if the block succeeds, remove it
    if the block raises (so ``target`` is either complete or untouched)."""
    staging = staging_directory(target)
    try:
        yield staging
        commit_directory(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def write_json(path: Path, content: Any) -> None:
    """Write JSON (no NaN/inf) through a temporary file and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    staging = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        staging.write_text(json.dumps(content, indent=2, allow_nan=False) + "\n", encoding="utf-8")
        staging.replace(path)
    finally:
        staging.unlink(missing_ok=True)


def check_output_location(
    out: Path | str, inputs: Iterable[Path | str], *, overwrite: bool
) -> Path:
    """The output folder ``out``, checked before any work: it is not one of ``inputs``, inside
    one, or a folder that holds one (writing it replaces the whole folder, so each of those
    would destroy an input); it is not an existing file, nor an existing folder unless
    ``overwrite``; its nearest existing parent is a writable folder. IprError (one line: what,
    where, the fix) otherwise."""
    from ipr.errors import IprError

    out = Path(out)
    target = out.resolve()
    for item in inputs:
        source = Path(item).resolve()
        if target == source or source in target.parents or target in source.parents:
            raise IprError(
                f"{out}: the output folder would replace the input {item} (it is the input, "
                "inside it or holds it) (fix: choose an output folder outside the input)"
            )
    if out.exists() and not out.is_dir():
        raise IprError(f"{out}: exists and is not a folder (fix: choose another output path)")
    if out.exists() and not overwrite:
        raise IprError(f"{out}: already exists (fix: choose another folder or pass --overwrite)")
    parent = target.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise IprError(
            f"{out}: cannot be written ({parent} is not a writable folder) "
            "(fix: choose a writable output folder)"
        )
    return out
