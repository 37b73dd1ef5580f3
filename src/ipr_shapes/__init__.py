"""ipr: complete 3D models of unknown rigid objects in clutter by inverse physics reasoning.

The method is Song & Boularias, "Inferring 3D Shapes of Unknown Rigid Objects in Clutter through
Inverse Physics Reasoning", RA-L 2018. Units are metres and radians; the world frame is z-up with
gravity along -z. Millimetres appear only at the BOP file boundary.

Importing ipr_shapes (or any of its modules) leaves the process's environment alone: the offscreen
OpenGL backend is chosen only where ipr renders (``ipr_shapes.gl``).
"""

#: The version; pyproject.toml reads it from here.
__version__ = "0.1.0"
#: The distribution's name on the package index (``pip install ipr-shapes``), also the command's;
#: "ipr" there is another project (docs/DESIGN_NOTES.md, "Distribution name").
DISTRIBUTION = "ipr-shapes"

#: The Python API's main names, imported on first use (``ipr_shapes.from_arrays``, ...) so that
#: ``import ipr_shapes`` stays light: it loads neither numpy nor MuJoCo until one is used.
_LAZY = {
    "from_arrays": "ipr_shapes.arrays",
    "load_scene": "ipr_shapes.scene",
    "write_scene": "ipr_shapes.scene",
    "Scene": "ipr_shapes.scene",
    "Frame": "ipr_shapes.scene",
    "Push": "ipr_shapes.scene",
    "Pusher": "ipr_shapes.scene",
    "Config": "ipr_shapes.config",
    "run_pipeline": "ipr_shapes.pipeline",
    "save_result": "ipr_shapes.pipeline",
    "infer": "ipr_shapes.pipeline:infer_scene",
    "load_result": "ipr_shapes.result",
}


def __getattr__(name: str):
    """The lazily imported names of ``_LAZY`` (PEP 562)."""
    if name not in _LAZY:
        raise AttributeError(f"module 'ipr_shapes' has no attribute {name!r}")
    import importlib

    module_name, _, attribute = _LAZY[name].partition(":")
    value = getattr(importlib.import_module(module_name), attribute or name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_LAZY])
