"""Choice of MuJoCo's offscreen OpenGL backend (EGL, else OSMesa), made where ipr renders.

Importing ipr changes nothing in the host process: the backend is chosen only when ipr is about
to create an offscreen GL context (``ipr_shapes.rendering.Renderer``, the scene generator's renderer,
``check_rendering``) and by the ``ipr`` command and ``make demo`` at start-up, and only when
``MUJOCO_GL`` is not already set (a user's or host's choice always wins).

MuJoCo picks its GL context class from ``MUJOCO_GL`` when ``mujoco`` is first imported (GLFW,
which needs a display, when the variable is unset). ipr's stages import ``mujoco`` for physics
long before anything is rendered, so ``offscreen_context_class`` does not rely on that import-time
choice: it imports the chosen backend's context class itself, and points MuJoCo's own
``mujoco.Renderer`` at it when MuJoCo had picked without a ``MUJOCO_GL``. Every process chooses
for itself, so the sampling workers (started from a clean fork server) render like the parent.
"""

from __future__ import annotations

import ctypes.util
import os
import sys
from typing import Any

INSTALL_HINT = (
    "MuJoCo's offscreen rendering needs EGL or OSMesa. On Debian/Ubuntu run "
    "'sudo apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6' "
    "(or 'make setup' as root), or set MUJOCO_GL to a working backend."
)


def select_gl_backend() -> str | None:
    """Set ``MUJOCO_GL`` to ``egl`` or ``osmesa`` unless the user chose one; return the choice.

    Call it only where ipr is about to render (module doc): it changes ``os.environ``
    (``MUJOCO_GL``, and ``PYOPENGL_PLATFORM`` unless set). EGL with Mesa's software rasteriser
    is the faster headless path; OSMesa is the fallback. Returns None when neither library is
    found (rendering will then fail with ``INSTALL_HINT``).
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


def offscreen_context_class() -> Any:
    """MuJoCo's GL context class for the chosen backend (``select_gl_backend`` first), or None
    when rendering is disabled or no backend is available.

    Also makes ``mujoco.Renderer`` use that class when MuJoCo was imported before the choice
    (with no ``MUJOCO_GL``, it had picked GLFW).
    """
    backend = (select_gl_backend() or "").lower().strip()
    from mujoco.rendering.classic import gl_context

    if backend == "egl":
        from mujoco.egl import GLContext
    elif backend == "osmesa":
        from mujoco.osmesa import GLContext
    else:  # the user's own choice (glfw, disabled, ...) as MuJoCo made it at import
        return getattr(gl_context, "GLContext", None)
    if getattr(gl_context, "_MUJOCO_GL", backend) != backend:
        import mujoco

        stale = getattr(gl_context, "GLContext", None)
        gl_context.GLContext = GLContext
        if getattr(mujoco, "GLContext", None) is stale:
            mujoco.GLContext = GLContext
    return GLContext


def check_rendering() -> str:
    """Render one tiny frame offscreen; return the backend name or raise RuntimeError with a fix."""
    try:
        offscreen_context_class()
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
    return os.environ.get("MUJOCO_GL") or "default"


def main() -> int:
    """Report whether offscreen rendering works; exit status 1 with the fix when it does not."""
    try:
        print(f"ipr-shapes: offscreen rendering works (MUJOCO_GL={check_rendering()})")
    except RuntimeError as error:
        print(f"ipr-shapes: {error}", file=sys.stderr)
        return 1
    return 0
