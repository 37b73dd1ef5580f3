"""Atomic output: folders and files are written to a temporary path beside the target and renamed
into place, so a failed or interrupted run never leaves half-written output."""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import socket
import tempfile
import uuid
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

#: Marks the temporary folders ipr makes beside an output: ``.<name>.ipr-staging.<host>.<pid>.
#: <random>`` (and ``.ipr-old.`` for the replaced output during a swap). A killed run leaves
#: one behind; ``staging_directory`` removes those of dead processes of this host.
STAGING_TAG = "ipr-staging"
OLD_TAG = "ipr-old"


def _owner_tag() -> str:
    return f"{socket.gethostname().replace('.', '_')}.{os.getpid()}"


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def remove_stale_staging(target: Path) -> list[Path]:
    """Remove the staging folders ipr left beside ``target`` when a run was killed: only names
    ipr makes (``STAGING_TAG``/``OLD_TAG``), of this host, whose process is gone (a live run's
    folder, or another host's on a shared disk, is never touched). Returns what was removed."""
    host = socket.gethostname().replace(".", "_")
    pattern = re.compile(
        rf"^\.{re.escape(target.name)}\.(?:{STAGING_TAG}|{OLD_TAG})\.{re.escape(host)}\.(\d+)\."
    )
    removed = []
    try:
        entries = list(target.parent.iterdir())
    except OSError:
        return removed
    for entry in entries:
        match = pattern.match(entry.name)
        if match and not _process_alive(int(match.group(1))) and not entry.is_symlink():
            if entry.is_dir():
                shutil.rmtree(entry, ignore_errors=True)
            else:
                entry.unlink(missing_ok=True)
            removed.append(entry)
    return removed


def staging_directory(target: Path) -> Path:
    """A fresh, world-readable temporary folder beside ``target`` (same filesystem), named for
    this host and process; stale ones of killed runs are removed first."""
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(target)
    staging = Path(
        tempfile.mkdtemp(prefix=f".{target.name}.{STAGING_TAG}.{_owner_tag()}.", dir=target.parent)
    )
    staging.chmod(0o755)  # mkdtemp makes it private; scenes and results are meant to be shared
    return staging


def commit_directory(staging: Path, target: Path) -> None:
    """Move a fully written staging folder into place (replacing ``target`` if it exists)."""
    if target.exists():
        backup = target.with_name(f".{target.name}.{OLD_TAG}.{_owner_tag()}.{uuid.uuid4().hex[:8]}")
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
    write_text(path, json.dumps(content, indent=2, allow_nan=False) + "\n")


def write_text(path: Path, text: str) -> None:
    """Write UTF-8 text through a temporary file (named as ``STAGING_TAG`` says) and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(path)
    staging = path.with_name(f".{path.name}.{STAGING_TAG}.{_owner_tag()}.tmp")
    try:
        staging.write_text(text, encoding="utf-8")
        staging.replace(path)
    finally:
        staging.unlink(missing_ok=True)


#: Free space an output needs before a run starts (bytes): results and segmentations of
#: ordinary scenes are a few to tens of megabytes.
MIN_FREE_BYTES = 64 * 2**20


def check_output_location(
    out: Path | str, inputs: Iterable[Path | str], *, overwrite: bool
) -> Path:
    """The output folder ``out``, checked before any work: it is not one of ``inputs``, inside
    one, or a folder that holds one (writing it replaces the whole folder, so each of those
    would destroy an input), nor the current folder or one holding it; it is not an existing file, nor an existing folder unless
    ``overwrite``; its nearest existing parent is a writable folder with ``MIN_FREE_BYTES``
    free. IprError (one line: what,
    where, the fix) otherwise."""
    from ipr_shapes.errors import IprError

    out = Path(out)
    target = out.resolve()
    here = Path.cwd().resolve()
    if target == here or target in here.parents:
        raise IprError(
            f"{out}: the output folder is the current folder or holds it, and writing it "
            "replaces the whole folder (fix: name a new folder, e.g. -o result)"
        )
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
    try:
        free = shutil.disk_usage(parent).free
    except OSError:
        free = None
    if free is not None and free < MIN_FREE_BYTES:
        raise IprError(
            f"{out}: only {free / 2**20:.0f} MiB free on the disk of {parent} (at least "
            f"{MIN_FREE_BYTES // 2**20} MiB needed) (fix: free space or choose another disk)"
        )
    return out
