"""Errors that reach users: each says what is wrong, in which file, and how to fix it."""

from __future__ import annotations

from pathlib import Path


class IprError(Exception):
    """Base of every error ipr reports to a user (the CLI prints it without a traceback)."""


class SceneError(IprError):
    """A scene directory does not follow the scene contract (``SCENE_FORMAT.md``)."""

    def __init__(self, path: Path | str, problem: str, fix: str = "") -> None:
        self.path = Path(path)
        self.problem = problem
        self.fix = fix
        message = f"{self.path}: {problem}"
        if fix:
            message += f" (fix: {fix})"
        super().__init__(message)


class ResultError(SceneError):
    """A result directory does not follow the result contract."""


class ArrayInputError(SceneError, ValueError):
    """Arrays given to ``ipr_shapes.from_arrays`` do not make a valid scene (the scene contract's rules,
    applied in memory); ``path`` names the argument, such as ``depth[2]``."""

    def __init__(self, where: str, problem: str, fix: str = "") -> None:
        self.path = Path(where)
        self.problem = problem
        self.fix = fix
        message = f"ipr_shapes.from_arrays: {where}: {problem}"
        if fix:
            message += f" (fix: {fix})"
        Exception.__init__(self, message)


class BagError(SceneError):
    """A ROS bag cannot be made into a scene (``ipr-shapes import-bag``); ``path`` is the bag."""
