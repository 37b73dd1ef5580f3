"""The declarative field checks (``ipr_shapes.checks``) and the perception config's tables."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
import pytest

from ipr_shapes.checks import Checks, Interval, Options, Pair, Predicate, check_fields
from ipr_shapes.perception.config import (
    DenoiseConfig,
    PerceptionConfig,
    PlanesConfig,
    TrackingConfig,
    WallsConfig,
)


def test_interval_ends_and_integers():
    positive = Interval(0, None, closed="neither")
    assert positive.accepts(1e-9) and not positive.accepts(0) and not positive.accepts(-1)
    assert positive.describe() == "a number in (0, inf)"
    share = Interval(0, 1)
    assert share.accepts(0) and share.accepts(1.0) and not share.accepts(1.5)
    assert Interval(0, 1, closed="left").describe() == "a number in [0, 1)"
    assert not Interval(0, 1, closed="left").accepts(1)
    assert not Interval(0, 1, closed="right").accepts(0)
    count = Interval(1, None, integer=True)
    assert count.accepts(3) and count.accepts(np.int64(3))
    assert not count.accepts(3.0) and not count.accepts(0) and not count.accepts(True)
    assert count.describe() == "an integer in [1, inf)"
    anything = Interval()
    assert anything.accepts(-5.5) and not anything.accepts(float("nan"))
    assert not anything.accepts(float("inf")) and not anything.accepts("1")


def test_options_pairs_and_predicates():
    mode = Options("fast", "exact")
    assert mode.accepts("exact") and not mode.accepts("Exact")
    assert mode.describe() == "one of 'fast', 'exact'"
    assert not Options(1, 2).accepts(True)  # True == 1, but a flag is not an option here
    pair = Pair(Interval(0, None))
    assert pair.accepts((0.1, 0.2)) and pair.accepts((0.1, 0.1))
    assert not pair.accepts((0.2, 0.1)) and not pair.accepts([0.1, 0.2])
    assert not pair.accepts((-0.1, 0.2)) and not pair.accepts((0.1, 0.2, 0.3))
    even = Predicate(lambda v: v % 2 == 0, "even")
    assert even.accepts(4) and not even.accepts(3) and even.describe() == "even"


@dataclass(frozen=True)
class _Example:
    CHECKS: ClassVar[Checks] = {
        "mode": Options("a", "b"),
        ("low", "high"): Pair(Interval(0, None)),
    }

    mode: str = "a"
    low: float = 0.0
    high: float = 1.0

    def __post_init__(self) -> None:
        check_fields(self)


def test_check_fields_names_the_field_the_value_and_the_range():
    _Example()
    with pytest.raises(ValueError) as error:
        _Example(mode="c")
    assert str(error.value) == "_Example.mode must be one of 'a', 'b', got 'c'"
    with pytest.raises(ValueError, match=r"_Example\.\(low, high\) must be a \(low, high\) pair"):
        _Example(low=2.0)
    with pytest.raises(ValueError, match=r"got \(2.0, 1.0\)"):
        _Example(low=2.0)
    # An explicit table overrides the class's.
    with pytest.raises(ValueError, match="_Example.high must be a number in"):
        check_fields(_Example(), {"high": Interval(2, None)})


def _groups(config) -> list:
    """The config and every nested config dataclass in it."""
    found = [config]
    for item in dataclasses.fields(config):
        value = getattr(config, item.name)
        if dataclasses.is_dataclass(value):
            found += _groups(value)
    return found


def test_every_perception_field_is_declared_and_the_defaults_pass():
    groups = _groups(PerceptionConfig())
    assert len(groups) == 16
    for group in groups:
        check_fields(group)
        names = {item.name for item in dataclasses.fields(group)}
        declared = set()
        for key in type(group).CHECKS:
            declared |= set(key) if isinstance(key, tuple) else {key}
        assert declared <= names, type(group).__name__
        # Every field is checked except flags and the nested groups.
        unchecked = {
            item.name
            for item in dataclasses.fields(group)
            if item.name not in declared
            and not isinstance(getattr(group, item.name), bool)
            and not dataclasses.is_dataclass(getattr(group, item.name))
        }
        assert not unchecked, (type(group).__name__, unchecked)


def test_bad_perception_values_are_refused_with_the_range():
    with pytest.raises(ValueError) as error:
        WallsConfig(min_length_m=-0.1)
    assert str(error.value) == "WallsConfig.min_length_m must be a number in [0, inf), got -0.1"
    with pytest.raises(ValueError, match=r"PlanesConfig\.threshold_m .* \(0, inf\), got 0"):
        PlanesConfig(threshold_m=0)
    with pytest.raises(ValueError, match=r"WallsConfig\.\(min_height_m, max_height_m\)"):
        WallsConfig(min_height_m=0.3)
    with pytest.raises(ValueError, match="partner_separation_m"):
        WallsConfig(partner_separation_m=(0.5, 0.1))
    with pytest.raises(ValueError, match="TrackingConfig.max_sightings must be an integer"):
        TrackingConfig(max_sightings=0)
    with pytest.raises(ValueError, match="PerceptionConfig.seed"):
        PerceptionConfig(seed=-1)
    with pytest.raises(ValueError, match="DenoiseConfig.window_px must be odd"):
        replace(DenoiseConfig(), window_px=6)
    assert DenoiseConfig(window_px=1).window_px == 1
    assert DenoiseConfig(window_px=7).window_px == 7


def test_every_field_of_the_whole_configuration_is_declared():
    from ipr_shapes.config import Config

    groups = _groups(Config())[1:]  # the sections and their nested groups
    assert {type(g).__name__ for g in groups} >= {
        "InferenceConfig", "HypothesisConfig", "UnaryTolerances", "ConstraintConfig",
        "CollisionCheckerConfig", "PhysicsConfig", "LikelihoodConfig", "FusionConfig",
        "CarvingConfig", "PerceptionConfig",
    }  # fmt: skip
    for group in groups:
        declared = set()
        for key in type(group).CHECKS:
            declared |= set(key) if isinstance(key, tuple) else {key}
        fields = {
            item.name
            for item in dataclasses.fields(group)
            if not dataclasses.is_dataclass(getattr(group, item.name))
            and not isinstance(getattr(group, item.name), bool)
        }
        assert fields <= declared, (type(group).__name__, fields - declared)


@pytest.mark.parametrize(
    ("section", "changes", "message"),
    [
        ("inference", {"weighting": "mean"}, "InferenceConfig.weighting must be one of"),
        ("inference", {"stability_measure": "fall"}, "InferenceConfig.stability_measure"),
        ("inference", {"workers": 0}, "InferenceConfig.workers must be None or an integer"),
        ("hypotheses", {"min_room_m": 0.05}, "ordered: min_room_m <= min_thickness_m"),
        ("fusion", {"fine_gate_m": 0.1}, r"FusionConfig.\(fine_gate_m, coarse_gate_m\)"),
        ("carving", {"hole_fill_window_px": 4}, "a positive odd number of pixels"),
        ("collision_checker", {"gibbs_chains": 0}, "CollisionCheckerConfig.gibbs_chains"),
    ],
)
def test_bad_values_anywhere_are_refused_with_the_range(section, changes, message):
    from ipr_shapes.config import Config

    with pytest.raises(ValueError, match=message):
        replace(getattr(Config(), section), **changes)
