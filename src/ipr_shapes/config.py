"""The configuration of a whole run: one typed object whose sections are the stages' own configs,
readable from and writable to a TOML file.

Every field has a documented default in its stage's module; ``Config()`` is what ``ipr-shapes infer``
uses. Sections, in pipeline order: ``perception`` (``ipr_shapes.perception.config``), ``fusion`` (later
views registered into frame 0 for the methods that use the pushes, ``ipr_shapes.fusion``),
``hypotheses`` (Algorithm 1, ``ipr_shapes.hypotheses.generate``), ``constraints`` (tolerances of
Constraints(X), ``ipr_shapes.hypotheses.constraints``), ``collision_checker`` (the marginals of the
uniform posterior, ``ipr_shapes.collision_checker``), ``inference`` (physics, likelihood and tree
sampling, ``ipr_shapes.inference``), ``carving`` (output shapes carved by the space the camera saw
empty, ``ipr_shapes.carving``), ``zheng2013`` (the Zheng et al. 2013 baseline, ``ipr_shapes.baselines``).

TOML: a file gives only the fields it changes, as nested tables named like the sections
(``[inference.likelihood]`` ``alpha_per_m = 8.0``); every other field keeps its default. Unknown
sections or fields, values of the wrong type and values a section's checks refuse are errors
naming the file and the field. ``None`` has no TOML spelling: a field left out keeps its
default, so a field whose default is None is set by giving a value and reset by leaving it
out.
"""

from __future__ import annotations

import dataclasses
import hashlib
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from ipr_shapes.baselines import ZhengConfig
from ipr_shapes.carving import CarvingConfig
from ipr_shapes.collision_checker import CollisionCheckerConfig
from ipr_shapes.errors import IprError
from ipr_shapes.fusion import FusionConfig
from ipr_shapes.hypotheses import ConstraintConfig, HypothesisConfig
from ipr_shapes.inference import InferenceConfig
from ipr_shapes.perception.config import PerceptionConfig


@dataclass(frozen=True)
class Config:
    """All parameters of a run, with documented defaults in each section's module."""

    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    hypotheses: HypothesisConfig = field(default_factory=HypothesisConfig)
    constraints: ConstraintConfig = field(default_factory=ConstraintConfig)
    collision_checker: CollisionCheckerConfig = field(default_factory=CollisionCheckerConfig)
    inference: InferenceConfig = field(default_factory=InferenceConfig)
    carving: CarvingConfig = field(default_factory=CarvingConfig)
    zheng2013: ZhengConfig = field(default_factory=ZhengConfig)


# --------------------------------------------------------------------------------------------
# To and from plain nested dicts (the TOML document)


def config_to_dict(config: Any) -> dict[str, Any]:
    """Nested dict of a config dataclass: every field, None fields left out (module doc)."""
    out: dict[str, Any] = {}
    for item in dataclasses.fields(config):
        value = getattr(config, item.name)
        if dataclasses.is_dataclass(value):
            out[item.name] = config_to_dict(value)
        elif value is None:
            continue
        elif isinstance(value, tuple):
            out[item.name] = [list(v) if isinstance(v, tuple) else v for v in value]
        else:
            out[item.name] = value
    return out


def _allowed(annotation: Any) -> tuple[Any, ...]:
    """The alternatives of a (possibly union or Literal) field annotation."""
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return tuple(a for alt in typing.get_args(annotation) for a in _allowed(alt))
    return (annotation,)


def _convert(value: Any, annotation: Any, where: str) -> Any:
    """``value`` read from TOML as the field's type (ints accepted for floats); ValueError."""
    alternatives = _allowed(annotation)
    for alt in alternatives:
        origin = typing.get_origin(alt)
        if origin is typing.Literal:
            if value in typing.get_args(alt) and isinstance(value, str):
                return value
        elif alt is bool:
            if isinstance(value, bool):
                return value
        elif alt is int:
            if isinstance(value, int) and not isinstance(value, bool):
                return value
        elif alt is float:
            if isinstance(value, int | float) and not isinstance(value, bool):
                return float(value)
        elif alt is str:
            if isinstance(value, str):
                return value
        elif origin is tuple and isinstance(value, list):
            args = typing.get_args(alt)
            inner = args[0] if args else Any
            if inner is Any:
                return tuple(value)
            return tuple(_convert(v, inner, f"{where}[{k}]") for k, v in enumerate(value))
        elif alt is Any:
            return value
    names = []
    for alt in alternatives:
        if typing.get_origin(alt) is typing.Literal:
            names.append(" or ".join(repr(a) for a in typing.get_args(alt)))
        elif alt is not type(None):
            names.append(getattr(alt, "__name__", str(alt)))
    raise ValueError(f"{where}: expected {' or '.join(names)}, got {value!r}")


def config_from_dict(cls: type, values: dict[str, Any], where: str = "") -> Any:
    """A ``cls`` config with ``values`` (nested dicts) over its defaults; ValueError naming
    the field when a key is unknown, a value has the wrong type or the section's checks fail."""
    if not isinstance(values, dict):
        raise ValueError(f"{where or 'the file'}: expected a table, got {values!r}")
    hints = typing.get_type_hints(cls)
    fields = {item.name: item for item in dataclasses.fields(cls)}
    default = cls()
    changes: dict[str, Any] = {}
    for key, value in values.items():
        name = f"{where}.{key}" if where else key
        if key not in fields:
            known = ", ".join(sorted(fields))
            raise ValueError(f"{name}: no such setting (the settings here: {known})")
        current = getattr(default, key)
        if dataclasses.is_dataclass(current):
            changes[key] = config_from_dict(type(current), value, name)
        else:
            changes[key] = _convert(value, hints[key], name)
    try:
        return dataclasses.replace(default, **changes)
    except (ValueError, TypeError) as error:
        raise ValueError(f"{where or 'config'}: {error}") from None


def read_config(path: Path | str) -> Config:
    """The ``Config`` a TOML file describes (its fields over the defaults); IprError naming the
    file, the field and the fix when it cannot be read or is invalid."""
    path = Path(path)
    if not path.is_file():
        raise IprError(
            f"{path}: no such config file (fix: write one with 'ipr-shapes config show')"
        )
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as error:
        raise IprError(f"{path}: cannot be read ({error})") from None
    except tomllib.TOMLDecodeError as error:
        raise IprError(
            f"{path}: not valid TOML ({error}) (fix: see 'ipr-shapes config show')"
        ) from None
    try:
        return config_from_dict(Config, document)
    except ValueError as error:
        raise IprError(
            f"{path}: {error} (fix: see 'ipr-shapes config show' for every setting)"
        ) from None


def config_to_toml(config: Config) -> str:
    """The whole configuration as a TOML document (``read_config`` reads it back equal)."""
    return tomli_w.dumps(config_to_dict(config))


def config_digest(config: Config) -> str:
    """Short hash of the whole configuration (records which settings produced a result)."""
    return hashlib.sha256(config_to_toml(config).encode()).hexdigest()[:16]
