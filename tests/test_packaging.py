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


#: Extras pinned in a lock of their own (requirements-<extra>.lock, over requirements.lock), kept
#: out of requirements.lock so that ``make test`` does not install them.
SEPARATE_LOCKS = ("ray", "pybullet")


def _lock(name: str = "requirements.lock") -> dict[str, str]:
    """Canonical name -> pinned version of a lock file (its own lines; ``-r`` includes skipped)."""
    pins = {}
    for line in (ROOT / name).read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].split(";", 1)[0].strip()  # no comment, no marker
        if line and not line.startswith("-r"):
            name_, version = line.split("==")
            pins[canonicalize_name(name_)] = version
    return pins


def _closure(roots: list[Requirement]) -> set[str]:
    """Canonical names of ``roots`` and everything they require (installed metadata)."""
    needed, seen = set(), set()
    queue = [(canonicalize_name(r.name), tuple(sorted(r.extras))) for r in roots]
    while queue:
        name, extras = queue.pop()
        if (name, extras) in seen:
            continue
        seen.add((name, extras))
        needed.add(name)
        try:
            requires = metadata.requires(name) or []
        except metadata.PackageNotFoundError:
            continue
        for text in requires:
            requirement = Requirement(text)
            markers = [{"extra": extra} for extra in ("", *extras)]
            if requirement.marker is None or any(requirement.marker.evaluate(m) for m in markers):
                queue.append(
                    (canonicalize_name(requirement.name), tuple(sorted(requirement.extras)))
                )
    return needed


def _imported(module: str, folder: str) -> bool:
    pattern = re.compile(rf"^\s*(import|from) {re.escape(module)}\b", re.MULTILINE)
    return any(
        pattern.search(path.read_text(encoding="utf-8")) for path in (ROOT / folder).rglob("*.py")
    )


def test_the_names_are_not_the_unrelated_ipr_on_the_index():
    """On the package index "ipr" is another project with the import package and command "ipr":
    the distribution, the command and the import package all carry another name."""
    assert PYPROJECT["project"]["name"] == "ipr-shapes"
    assert PYPROJECT["project"]["scripts"] == {"ipr-shapes": "ipr_shapes.cli:main"}
    packages = [p.name for p in (ROOT / "src").iterdir() if (p / "__init__.py").is_file()]
    assert packages == ["ipr_shapes"]


def test_every_supported_python_is_admitted_and_no_other():
    specifier = SpecifierSet(PYPROJECT["project"]["requires-python"])
    assert all(f"{version}.0" in specifier for version in SUPPORTED)
    assert "3.10.0" not in specifier and "3.14.0" not in specifier


@pytest.mark.parametrize(
    "group, folder",
    [("runtime", "src/ipr_shapes"), ("bench", "benchmarks")],
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
    for extra, requirements in project["optional-dependencies"].items():
        if extra not in SEPARATE_LOCKS:
            declared += _names(requirements)
    pins = _lock()
    assert set(declared) <= set(pins), f"not pinned: {sorted(set(declared) - set(pins))}"
    # Everything pinned is declared or required by something pinned (installed metadata).
    needed = _closure([Requirement(name) for name in declared])
    assert set(pins) <= needed, f"pinned but nothing needs them: {sorted(set(pins) - needed)}"


@pytest.mark.parametrize("extra", SEPARATE_LOCKS)
def test_a_separately_locked_extra_pins_what_it_adds_and_only_that(extra: str):
    """requirements-<extra>.lock includes requirements.lock and pins the extra's packages (and,
    where they are installed, what they need) that requirements.lock does not."""
    lock = ROOT / f"requirements-{extra}.lock"
    assert "-r requirements.lock" in lock.read_text(encoding="utf-8").splitlines()
    roots = [Requirement(t) for t in PYPROJECT["project"]["optional-dependencies"][extra]]
    pins, base = _lock(lock.name), _lock()
    assert not set(pins) & set(base), f"pinned twice: {sorted(set(pins) & set(base))}"
    assert {canonicalize_name(r.name) for r in roots} <= set(pins)
    for root in roots:
        assert pins[canonicalize_name(root.name)] in root.specifier
    if all(_installed(r.name) for r in roots):
        needed = _closure(roots) - set(base)
        assert set(pins) == needed, f"lock {sorted(set(pins))} != needed {sorted(needed)}"


def _installed(name: str) -> bool:
    try:
        metadata.version(name)
    except metadata.PackageNotFoundError:
        return False
    return True


_UNREACHABLE = re.compile(
    r"NewConnectionError|Max retries exceeded|ProxyError|Network is unreachable|"
    r"Temporary failure in name resolution|Name or service not known|ConnectTimeout",
)


@pytest.mark.slow
@pytest.mark.parametrize(
    "lock", ["requirements.lock", *(f"requirements-{e}.lock" for e in SEPARATE_LOCKS)]
)
@pytest.mark.parametrize("python", SUPPORTED)
def test_the_lock_resolves_for_every_supported_python(python: str, lock: str, tmp_path: Path):
    """pip resolves each lock for ``python`` from binary wheels alone, and the set it would
    install is exactly the lock (no pin missing, none conflicting)."""
    if lock == "requirements-pybullet.lock" and python != "3.11":
        # Its one pin is for 3.11 only (a marker), and pip's --python-version does not apply
        # markers for the target version: it would look for a 3.12 wheel that does not exist.
        pytest.skip("pybullet has wheels for Python 3.11 only")
    report = tmp_path / "report.json"
    completed = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--dry-run", "--ignore-installed", "--quiet",
         "--only-binary=:all:", "--python-version", python, "--report", str(report),
         "-r", str(ROOT / lock)],
        capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    if completed.returncode != 0 and _UNREACHABLE.search(completed.stderr):
        pytest.skip(f"the package index is unreachable: {completed.stderr.strip()[-200:]}")
    assert completed.returncode == 0, completed.stderr[-2000:]
    installed = {
        canonicalize_name(item["metadata"]["name"]): item["metadata"]["version"]
        for item in json.loads(report.read_text())["install"]
    }
    expected = _lock() if lock == "requirements.lock" else {**_lock(), **_lock(lock)}
    assert installed == expected


def test_licence_and_citation_match_the_package():
    assert PYPROJECT["project"]["license"] == "MIT"
    assert (ROOT / "LICENSE").read_text(encoding="utf-8").startswith("MIT License")
    citation = (ROOT / "CITATION.cff").read_text(encoding="utf-8")
    version = re.search(
        r'^__version__ = "([^"]+)"', (ROOT / "src/ipr_shapes/__init__.py").read_text(), re.MULTILINE
    )
    assert re.search(rf"^version: {re.escape(version.group(1))}$", citation, re.MULTILINE)
    assert re.search(r"^license: MIT$", citation, re.MULTILINE)
    assert "cff-version: 1.2.0" in citation and "Boularias" in citation
