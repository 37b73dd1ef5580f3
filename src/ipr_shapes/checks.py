"""Declarative checks of configuration fields: one table per config class, one helper.

A frozen config dataclass lists the allowed values of its fields in a class-level table and
checks them all on construction, so that a config that exists is valid::

    @dataclass(frozen=True)
    class WallsConfig:
        CHECKS: ClassVar[Checks] = {
            "min_length_m": Interval(0, None),
            ("min_height_m", "max_height_m"): Pair(Interval(0, None)),
        }
        ...

        def __post_init__(self) -> None:
            check_fields(self)

A key is a field name, or a tuple of field names whose values are checked together as one
tuple (two fields that form a range). A bad value raises ``ValueError`` naming the class, the
field, the value and what is allowed: ``WallsConfig.min_length_m must be in [0, inf), got
-0.1``. This module imports nothing from ipr, so that every stage can use it.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Literal, Protocol


class Constraint(Protocol):
    """What a table entry is: a test of one value and a description of what passes it."""

    def accepts(self, value: Any) -> bool:
        """True when ``value`` is allowed."""

    def describe(self) -> str:
        """The allowed values, completing "must be ..."."""


#: A config class's table: field name (or tuple of field names) -> constraint.
Checks = Mapping[str | tuple[str, ...], Constraint]


def _is_number(value: Any, integer: bool) -> bool:
    """A finite real number (an integer when ``integer``); bools are not numbers here."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return False
    if integer:
        return isinstance(value, numbers.Integral)
    return math.isfinite(value)


@dataclass(frozen=True)
class Interval:
    """A finite number between ``low`` and ``high`` (None: unbounded on that side).

    ``closed`` says which ends belong to the interval; ``integer`` asks for an int.
    """

    low: float | None = None
    high: float | None = None
    closed: Literal["both", "left", "right", "neither"] = "both"
    integer: bool = False

    def accepts(self, value: Any) -> bool:
        if not _is_number(value, self.integer):
            return False
        low_ok = self.low is None or (
            value >= self.low if self.closed in ("both", "left") else value > self.low
        )
        high_ok = self.high is None or (
            value <= self.high if self.closed in ("both", "right") else value < self.high
        )
        return low_ok and high_ok

    def describe(self) -> str:
        left = "[" if self.low is not None and self.closed in ("both", "left") else "("
        right = "]" if self.high is not None and self.closed in ("both", "right") else ")"
        low = "-inf" if self.low is None else f"{self.low:g}"
        high = "inf" if self.high is None else f"{self.high:g}"
        kind = "an integer" if self.integer else "a number"
        return f"{kind} in {left}{low}, {high}{right}"


class Options:
    """One of a fixed set of values (the values of a ``typing.Literal`` field)."""

    def __init__(self, *values: Any) -> None:
        self.values = values

    def accepts(self, value: Any) -> bool:
        return any(value == option and type(value) is type(option) for option in self.values)

    def describe(self) -> str:
        return "one of " + ", ".join(repr(option) for option in self.values)

    def __repr__(self) -> str:
        return f"Options({', '.join(repr(option) for option in self.values)})"


@dataclass(frozen=True)
class Pair:
    """A (low, high) tuple of two values that ``each`` accepts, with low <= high."""

    each: Interval

    def accepts(self, value: Any) -> bool:
        return (
            isinstance(value, tuple)
            and len(value) == 2
            and all(self.each.accepts(v) for v in value)
            and value[0] <= value[1]
        )

    def describe(self) -> str:
        return f"a (low, high) pair with low <= high, each {self.each.describe()}"


@dataclass(frozen=True)
class Predicate:
    """A value that ``test`` accepts; ``description`` completes "must be ..."."""

    test: Callable[[Any], bool]
    description: str

    def accepts(self, value: Any) -> bool:
        return bool(self.test(value))

    def describe(self) -> str:
        return self.description


def check_fields(instance: Any, checks: Checks | None = None) -> None:
    """Raise ValueError for the first entry of ``checks`` (default: the instance's class-level
    ``CHECKS`` table) whose field value is not allowed, naming the class, the field, the value
    and the allowed values."""
    table = type(instance).CHECKS if checks is None else checks
    owner = type(instance).__name__
    for key, constraint in table.items():
        names = key if isinstance(key, tuple) else (key,)
        values = tuple(getattr(instance, name) for name in names)
        value = values if isinstance(key, tuple) else values[0]
        if not constraint.accepts(value):
            label = f"({', '.join(names)})" if isinstance(key, tuple) else key
            raise ValueError(f"{owner}.{label} must be {constraint.describe()}, got {value!r}")


@dataclass(frozen=True)
class OrNone:
    """None, or a value that ``other`` accepts (an optional setting)."""

    other: Constraint

    def accepts(self, value: Any) -> bool:
        return value is None or self.other.accepts(value)

    def describe(self) -> str:
        return f"None or {self.other.describe()}"
