"""Where the shared reference data lives (YCB meshes, real YCB-Video frames, real bin-picking
frames, real unlabelled tabletop frames).

The data is read from ``$IPR_DATA`` when set, else from ``../shared/data`` beside the repository
(or the current directory). It is never copied into the repository; callers fall back to
procedural objects, and tests skip with a reason, when it is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

_REPO_ROOT = Path(__file__).resolve().parents[2]
#: Sub-folders of which any one marks a folder as the shared data.
_DATA_SETS = ("ycb", "ycbv_real", "bins_real", "real_unlabelled")


def shared_data_dir() -> Path | None:
    """The shared data folder, or None when it cannot be found."""
    candidates = []
    if os.environ.get("IPR_DATA"):
        candidates.append(Path(os.environ["IPR_DATA"]))
    candidates += [_REPO_ROOT.parent / "shared" / "data", Path.cwd().parent / "shared" / "data"]
    for candidate in candidates:
        if any((candidate / name).is_dir() for name in _DATA_SETS):
            return candidate.resolve()
    return None


def ycb_models_dir() -> Path | None:
    """Folder of YCB meshes (``<id>_<name>.ply``, metres) with ``models_info.json``, or None."""
    root = shared_data_dir()
    folder = root / "ycb" if root else None
    return folder if folder and (folder / "models").is_dir() else None


def ycbv_real_dir() -> Path | None:
    """Folder of the real YCB-Video scenes in BOP format, or None."""
    root = shared_data_dir()
    folder = root / "ycbv_real" if root else None
    return folder if folder and folder.is_dir() else None


def bins_real_dir() -> Path | None:
    """Folder of the real bin-picking scenes in BOP format (``bins_NNN/``, ``models/``; ground
    truth with ``mask_visib/``), or None."""
    root = shared_data_dir()
    folder = root / "bins_real" if root else None
    return folder if folder and folder.is_dir() else None


def real_unlabelled_dir() -> Path | None:
    """Folder of the real unlabelled tabletop scenes (BOP frames, no ground truth), or None."""
    root = shared_data_dir()
    folder = root / "real_unlabelled" if root else None
    return folder if folder and folder.is_dir() else None


def cache_dir() -> Path:
    """Cache for generated benchmark suites: ``$IPR_CACHE`` or ``~/.cache/ipr`` (outside the repo)."""
    base = os.environ.get("IPR_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "ipr"
    )
    return Path(base)
