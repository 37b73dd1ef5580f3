"""The package's layering: stages import one way (pyproject's import-linter contracts)."""

from __future__ import annotations

from pathlib import Path

from importlinter.cli import lint_imports

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def test_the_stages_import_one_way(tmp_path):
    assert lint_imports(config_filename=str(PYPROJECT), cache_dir=str(tmp_path)) == 0
