"""Benchmark scene generator: piles of YCB (or procedural) objects simulated in MuJoCo, RGB-D
frames with a realistic depth-sensor model, robot pushes, and BOP ground truth.

Public API: ``SynthConfig``, ``generate_scene``, ``generate_scenes`` (see ``generate.py`` for
the retry rules, ``catalogue.py`` for the object pool rule, ``sensor.py`` for the noise model,
``render.py`` for the colour method, ``pushes.py`` for push planning). Scenes follow
``SCENE_FORMAT.md``; each scene folder also holds ``synth.json`` (generation parameters: camera
target, objects with mass and friction, walls, attempts) and ``preview.png``.
"""

from ipr_shapes.synth.config import ARRANGEMENTS, KINDS, OBJECT_SOURCES, SynthConfig
from ipr_shapes.synth.generate import (
    GenerationError,
    generate_scene,
    generate_scenes,
    object_pool,
    scene_seed,
)

__all__ = [
    "ARRANGEMENTS",
    "KINDS",
    "OBJECT_SOURCES",
    "GenerationError",
    "SynthConfig",
    "generate_scene",
    "generate_scenes",
    "object_pool",
    "scene_seed",
]
