"""Packaging: the declared dependencies are the ones the code imports, the lock holds them and
what they need (nothing else), and the pinned set resolves for every supported Python."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
SUPPORTED = ("3.11", "3.12", "3.13")
#: Distribution name -> the module it is imported as, where they differ.
IMPORT_NAMES = {"pillow": "PIL", "tomli-w": "tomli_w"}


def _names(requirements: list[str]) -> list[str]:
    return [canonicalize_name(Requirement(text).name) for text in requirements]


def _lock() -> dict[str, str]:
    """Canonical name -> pinned version of requirements.lock."""
    pins = {}
    for line in (ROOT / "requirements.lock").read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, version = line.split("==")
            pins[canonicalize_name(name)] = version
    return pins


def _imported(module: str, folder: str) -> bool:
    pattern = re.compile(rf"^\s*(import|from) {re.escape(module)}\b", re.MULTILINE)
    return any(
        pattern.search(path.read_text(encoding="utf-8")) for path in (ROOT / folder).rglob("*.py")
    )


def test_the_distribution_name_is_not_the_unrelated_ipr_on_the_index():
    assert PYPROJECT["project"]["name"] == "ipr-shapes"
    assert PYPROJECT["project"]["scripts"] == {"ipr": "ipr.cli:main"}


def test_every_supported_python_is_admitted_and_no_other():
    specifier = SpecifierSet(PYPROJECT["project"]["requires-python"])
    assert all(f"{version}.0" in specifier for version in SUPPORTED)
    assert "3.10.0" not in specifier and "3.14.0" not in specifier


@pytest.mark.parametrize(
    "group, folder",
    [("runtime", "src/ipr"), ("bench", "benchmarks")],
)
def test_every_declared_dependency_is_imported(group: str, folder: str):
    project = PYPROJECT["project"]
    declared = (
        project["dependencies"] if group == "runtime" else project["optional-dependencies"][group]
    )
    unused = [
        name
        for name in _names(declared)
        if not _imported(IMPORT_NAMES.get(name, name.replace("-", "_")), folder)
    ]
    assert not unused, (
        f"declared in pyproject.toml ({group}) but never imported in {folder}: {unused}"
    )


def test_the_lock_pins_the_declared_dependencies_and_only_what_they_need():
    project = PYPROJECT["project"]
    declared = _names(project["dependencies"])
    for extra in project["optional-dependencies"].values():
        declared += _names(extra)
    pins = _lock()
    assert set(declared) <= set(pins), f"not pinned: {sorted(set(declared) - set(pins))}"
    # Everything pinned is declared or required by something pinned (installed metadata).
    needed, queue = set(), list(declared)
    while queue:
        name = queue.pop()
        if name in needed:
            continue
        needed.add(name)
        try:
            requires = metadata.requires(name) or []
        except metadata.PackageNotFoundError:
            continue
        for text in requires:
            requirement = Requirement(text)
            if requirement.marker is None or requirement.marker.evaluate({"extra": ""}):
                queue.append(canonicalize_name(requirement.name))
    assert set(pins) <= needed, f"pinned but nothing needs them: {sorted(set(pins) - needed)}"


_UNREACHABLE = re.compile(
    r"NewConnectionError|Max retries exceeded|ProxyError|Network is unreachable|"
    r"Temporary failure in name resolution|Name or service not known|ConnectTimeout",
)


@pytest.mark.slow
@pytest.mark.parametrize("python", SUPPORTED)
def test_the_lock_resolves_for_every_supported_python(python: str, tmp_path: Path):
    """pip resolves requirements.lock for ``python`` from binary wheels alone, and the set it
    would install is exactly the lock (no pin missing, none conflicting)."""
    report = tmp_path / "report.json"
    completed = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--dry-run", "--ignore-installed", "--quiet",
         "--only-binary=:all:", "--python-version", python, "--report", str(report),
         "-r", str(ROOT / "requirements.lock")],
        capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    if completed.returncode != 0 and _UNREACHABLE.search(completed.stderr):
        pytest.skip(f"the package index is unreachable: {completed.stderr.strip()[-200:]}")
    assert completed.returncode == 0, completed.stderr[-2000:]
    installed = {
        canonicalize_name(item["metadata"]["name"]): item["metadata"]["version"]
        for item in json.loads(report.read_text())["install"]
    }
    assert installed == _lock()


def test_licence_and_citation_match_the_package():
    assert PYPROJECT["project"]["license"] == "MIT"
    assert (ROOT / "LICENSE").read_text(encoding="utf-8").startswith("MIT License")
    citation = (ROOT / "CITATION.cff").read_text(encoding="utf-8")
    version = re.search(
        r'^__version__ = "([^"]+)"', (ROOT / "src/ipr/__init__.py").read_text(), re.MULTILINE
    )
    assert re.search(rf"^version: {re.escape(version.group(1))}$", citation, re.MULTILINE)
    assert re.search(r"^license: MIT$", citation, re.MULTILINE)
    assert "cff-version: 1.2.0" in citation and "Boularias" in citation
