"""The configuration of a whole run: one typed object whose sections are the stages' own configs.

Every field has a documented default in its stage's module; ``Config()`` is what ``ipr infer``
uses. Sections: ``perception`` (``ipr.perception.config``), ``fusion`` (later views registered
into frame 0 for the methods that use the pushes, ``ipr.fusion``), ``collision_checker`` (hypotheses,
constraints and the Collision Checker, ``ipr.collision_checker``), ``inference`` (physics,
likelihood and tree sampling, ``ipr.inference``), ``carving`` (output shapes carved by the space the
camera saw empty, ``ipr.carving``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ipr.carving import CarvingConfig
from ipr.collision_checker import CollisionCheckerConfig
from ipr.fusion import FusionConfig
from ipr.inference import InferenceConfig
from ipr.perception.config import PerceptionConfig


@dataclass(frozen=True)
class Config:
    """All parameters of a run, with documented defaults in each section."""

    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    collision_checker: CollisionCheckerConfig = field(default_factory=CollisionCheckerConfig)
    inference: InferenceConfig = field(default_factory=InferenceConfig)
    carving: CarvingConfig = field(default_factory=CarvingConfig)
