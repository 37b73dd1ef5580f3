"""Choice of MuJoCo's offscreen OpenGL backend (EGL, else OSMesa), made before MuJoCo is imported."""

from __future__ import annotations

import ctypes.util
import os
import sys

INSTALL_HINT = (
    "MuJoCo's offscreen rendering needs EGL or OSMesa. On Debian/Ubuntu run "
    "'sudo apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6' "
    "(or 'make setup' as root), or set MUJOCO_GL to a working backend."
)


def select_gl_backend() -> str | None:
    """Set ``MUJOCO_GL`` to ``egl`` or ``osmesa`` unless the user chose one; return the choice.

    EGL with Mesa's software rasteriser is the faster headless path; OSMesa is the fallback.
    Returns None when neither library is found (rendering will then fail with ``INSTALL_HINT``).
    """
    chosen = os.environ.get("MUJOCO_GL")
    if chosen:
        os.environ.setdefault("PYOPENGL_PLATFORM", chosen if chosen != "glfw" else "")
        return chosen
    for backend, library in (("egl", "EGL"), ("osmesa", "OSMesa")):
        if ctypes.util.find_library(library):
            os.environ["MUJOCO_GL"] = backend
            os.environ.setdefault("PYOPENGL_PLATFORM", backend)
            return backend
    return None


def check_rendering() -> str:
    """Render one tiny frame offscreen; return the backend name or raise RuntimeError with a fix."""
    backend = select_gl_backend()
    try:
        import mujoco

        model = mujoco.MjModel.from_xml_string(
            "<mujoco><worldbody><geom type='sphere' size='0.1'/></worldbody></mujoco>"
        )
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        with mujoco.Renderer(model, 32, 32) as renderer:
            renderer.update_scene(data)
            renderer.render()
    except Exception as error:  # any GL failure gets the same actionable message
        raise RuntimeError(f"offscreen rendering failed ({error}). {INSTALL_HINT}") from error
    return backend or "default"


def main() -> int:
    """Report whether offscreen rendering works; exit status 1 with the fix when it does not."""
    try:
        print(f"ipr: offscreen rendering works (MUJOCO_GL={check_rendering()})")
    except RuntimeError as error:
        print(f"ipr: {error}", file=sys.stderr)
        return 1
    return 0
