"""Offscreen depth and object-id images of posed triangle meshes, rendered by MuJoCo.

Two layers, so that later stages (the physics likelihood) reuse the same GL code:

- ``Renderer`` holds one offscreen GL context and renders any compiled ``mujoco.MjModel`` from
  one of its cameras into a planar depth image (metres, 0 where no geom) and a geom-id image
  (-1 where no geom). The context is kept across models; the per-model MuJoCo render context
  (which uploads the meshes) is rebuilt only when the model changes.
- ``render_depth_and_ids`` builds a small static model from meshes, their world poses and a
  pinhole camera (``add_pinhole_camera``, ``add_visual_mesh``, ``configure_visual`` work on any
  ``mujoco.MjSpec``) and renders it.

Conventions (``ipr_shapes.camera``): OpenCV camera frames, ``K`` in pixels with pixel centres at integer
coordinates, ``world_from_camera`` a 4x4 rigid transform in metres. Depth is the z coordinate in
the camera frame (not the distance along the ray). MuJoCo draws every real triangle (not a hull),
with face culling off so that open or inconsistently oriented meshes show their nearest surface.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ipr_shapes.camera import mujoco_camera_attributes, mujoco_camera_pose
from ipr_shapes.gl import INSTALL_HINT, offscreen_context_class

#: Near and far clipping distances (m) of the models built here.
DEFAULT_ZNEAR_M = 0.01
DEFAULT_ZFAR_M = 20.0
CAMERA_NAME = "ipr_camera"


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """A pinhole camera: (3, 3) intrinsics ``K`` in pixels, image ``width`` x ``height`` in
    pixels, and its (4, 4) OpenCV ``world_from_camera`` pose in metres."""

    K: np.ndarray
    width: int
    height: int
    world_from_camera: np.ndarray


# --------------------------------------------------------------------------------------------
# Model building on any MjSpec


def configure_visual(
    spec: Any,
    width: int,
    height: int,
    *,
    znear_m: float = DEFAULT_ZNEAR_M,
    zfar_m: float = DEFAULT_ZFAR_M,
) -> None:
    """Make ``spec`` renderable offscreen at ``width`` x ``height`` with exact depth and ids.

    Sets the offscreen buffer size (never shrinking it), turns multisampling off (blended
    edge pixels would corrupt ids), fixes the model extent to 1 m with the centre at the origin
    and sets the clipping planes to ``znear_m`` and ``zfar_m`` (MuJoCo scales both by the
    extent).
    """
    spec.visual.global_.offwidth = max(int(spec.visual.global_.offwidth), int(width))
    spec.visual.global_.offheight = max(int(spec.visual.global_.offheight), int(height))
    spec.visual.quality.offsamples = 0
    spec.visual.quality.shadowsize = 0
    spec.stat.extent = 1.0
    spec.stat.center = [0.0, 0.0, 0.0]
    spec.visual.map.znear = float(znear_m)
    spec.visual.map.zfar = float(zfar_m)


def add_pinhole_camera(spec: Any, camera: PinholeCamera, name: str = CAMERA_NAME) -> Any:
    """Add a fixed world camera reproducing ``camera`` (intrinsics and pose) to ``spec``."""
    attributes = mujoco_camera_attributes(np.asarray(camera.K, float), camera.width, camera.height)
    position, quaternion = mujoco_camera_pose(np.asarray(camera.world_from_camera, float))

    def numbers(key: str) -> list[float]:
        return [float(value) for value in attributes[key].split()]

    element = spec.worldbody.add_camera(name=name)
    element.pos = position
    element.quat = quaternion
    element.resolution = numbers("resolution")
    element.sensor_size = numbers("sensorsize")
    element.focal_pixel = numbers("focalpixel")
    element.principal_pixel = numbers("principalpixel")
    return element


def add_visual_mesh(
    spec: Any,
    name: str,
    vertices: np.ndarray,
    faces: np.ndarray,
    world_from_mesh: np.ndarray | None = None,
    *,
    body: Any = None,
    rgba: Sequence[float] = (0.7, 0.7, 0.7, 1.0),
) -> Any | None:
    """Add a mesh geom that is drawn but never collides; return the geom, or None when the mesh
    has nothing to draw (no face, fewer than three distinct vertices).

    ``vertices`` (V, 3) metres are placed by ``world_from_mesh`` (4x4, None = identity; any
    affine transform is applied to the vertices) in ``body`` (default: the world body).
    Inertia is computed as a shell so that open and flat meshes compile.
    """
    import mujoco

    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if world_from_mesh is not None:
        transform = np.asarray(world_from_mesh, dtype=np.float64)
        vertices = vertices @ transform[:3, :3].T + transform[:3, 3]
    if len(faces) == 0 or len(np.unique(vertices, axis=0)) < 3:
        return None
    used = np.unique(faces)
    if len(used) < 4:  # MuJoCo wants 4 vertices: add an unused copy of the first one
        vertices = np.vstack([vertices[used], vertices[used[:1]]])
        faces = np.searchsorted(used, faces)
    mesh = spec.add_mesh(name=name)
    mesh.uservert = vertices.ravel()
    mesh.userface = faces.astype(np.int32).ravel()
    mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
    parent = body if body is not None else spec.worldbody
    return parent.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname=name,
        contype=0,
        conaffinity=0,
        rgba=list(rgba),
    )


def _mesh_arrays(mesh: Any) -> tuple[np.ndarray, np.ndarray]:
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    vertices, faces = mesh
    return np.asarray(vertices, float), np.asarray(faces, np.int64)


def build_mesh_model(
    meshes: Sequence[Any],
    world_from_mesh: Sequence[np.ndarray | None],
    camera: PinholeCamera,
    *,
    znear_m: float = DEFAULT_ZNEAR_M,
    zfar_m: float = DEFAULT_ZFAR_M,
) -> tuple[Any, np.ndarray]:
    """Compile a static model of posed meshes and the camera ``CAMERA_NAME``.

    Returns the ``mujoco.MjModel`` and ``object_of_geom`` (ngeom,) int32: the index into
    ``meshes`` of every geom (meshes with nothing to draw get no geom).
    """
    import mujoco

    if len(meshes) != len(world_from_mesh):
        raise ValueError(f"{len(meshes)} meshes but {len(world_from_mesh)} poses")
    spec = mujoco.MjSpec()
    spec.modelname = "ipr_render"
    configure_visual(spec, camera.width, camera.height, znear_m=znear_m, zfar_m=zfar_m)
    object_of_geom = []
    for index, (mesh, pose) in enumerate(zip(meshes, world_from_mesh, strict=True)):
        vertices, faces = _mesh_arrays(mesh)
        if add_visual_mesh(spec, f"object_{index}", vertices, faces, pose) is not None:
            object_of_geom.append(index)
    add_pinhole_camera(spec, camera)
    model = spec.compile()
    return model, np.asarray(object_of_geom, dtype=np.int32)


# --------------------------------------------------------------------------------------------
# Rendering


@dataclass(frozen=True, eq=False)
class RenderedImages:
    """Depth (H, W) float32 metres along the optical axis, 0 where no geom; ``geom_id`` (H, W)
    int32 model geom index of the front-most geom, -1 where none."""

    depth_m: np.ndarray
    geom_id: np.ndarray


class Renderer:
    """One offscreen GL context that renders MuJoCo models at a fixed ``width`` x ``height``.

    Reuse it for many renders (of the same model or of different models) and ``close()`` it,
    or use it as a context manager. Not thread-safe: one renderer per thread or process.
    """

    def __init__(self, width: int, height: int) -> None:
        import mujoco

        context_class = offscreen_context_class()  # chooses the backend unless MUJOCO_GL is set
        self._mujoco = mujoco
        self.width = int(width)
        self.height = int(height)
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {width}x{height}")
        self._gl = None
        self._model = None
        self._context = None
        self._scene = None
        if context_class is None:
            raise RuntimeError(f"no offscreen GL backend available. {INSTALL_HINT}")
        try:
            self._gl = context_class(self.width, self.height)
            self._gl.make_current()
        except Exception as error:  # any backend failure gets the same actionable message
            raise RuntimeError(f"offscreen rendering failed ({error}). {INSTALL_HINT}") from error
        self._option = mujoco.MjvOption()
        for group in ("sitegroup", "jointgroup", "tendongroup", "actuatorgroup", "skingroup"):
            getattr(self._option, group)[:] = 0
        self._rect = mujoco.MjrRect(0, 0, self.width, self.height)
        self._rgb = np.empty((self.height, self.width, 3), dtype=np.uint8)
        self._depth = np.empty((self.height, self.width), dtype=np.float32)

    def _bind(self, model: Any) -> None:
        """Make ``model`` the current one: upload its meshes into a new render context."""
        mujoco = self._mujoco
        if model is self._model:
            return
        if model.vis.global_.offwidth < self.width or model.vis.global_.offheight < self.height:
            raise ValueError(
                f"the model's offscreen buffer ({model.vis.global_.offwidth}x"
                f"{model.vis.global_.offheight}) is smaller than the renderer "
                f"({self.width}x{self.height}); call configure_visual(spec, width, height)"
            )
        self._free_context()
        self._gl.make_current()
        self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_50.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._context)
        self._context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=max(16, 2 * model.ngeom + 16))
        self._model = model

    def render(self, model: Any, data: Any, camera: int | str = CAMERA_NAME) -> RenderedImages:
        """Render ``model`` in state ``data`` (kinematics computed) from a fixed model camera.

        Returns the planar depth (metres, 0 where no geom) and the front-most geom id (-1 where
        none). Only geoms are drawn (sites, joints, tendons hidden).
        """
        mujoco = self._mujoco
        if self._gl is None:
            raise RuntimeError("render called after close()")
        camera_id = (
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
            if isinstance(camera, str)
            else int(camera)
        )
        if not 0 <= camera_id < model.ncam:
            raise ValueError(f"camera {camera!r} is not in the model")
        self._bind(model)
        self._gl.make_current()
        view = mujoco.MjvCamera()
        view.type = mujoco.mjtCamera.mjCAMERA_FIXED
        view.fixedcamid = camera_id
        scene = self._scene
        mujoco.mjv_updateScene(
            model, data, self._option, None, view, mujoco.mjtCatBit.mjCAT_ALL.value, scene
        )
        flags = mujoco.mjtRndFlag
        scene.flags[flags.mjRND_SEGMENT] = True
        scene.flags[flags.mjRND_IDCOLOR] = True
        scene.flags[flags.mjRND_CULL_FACE] = False
        for flag in (flags.mjRND_SHADOW, flags.mjRND_REFLECTION, flags.mjRND_SKYBOX):
            scene.flags[flag] = False
        mujoco.mjr_render(self._rect, scene, self._context)
        mujoco.mjr_readPixels(self._rgb, self._depth, self._rect, self._context)

        # Segment colour -> scene geom (segid + 1; 0 = background) -> model geom id.
        colour = self._rgb[::-1].astype(np.int32)
        segment = colour[..., 0] | (colour[..., 1] << 8) | (colour[..., 2] << 16)
        lookup = np.full(scene.ngeom + 2, -1, dtype=np.int32)
        for index in range(scene.ngeom):
            geom = scene.geoms[index]
            if geom.segid >= 0 and geom.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                lookup[geom.segid + 1] = geom.objid
        geom_id = lookup[np.minimum(segment, lookup.size - 1)]

        # Reversed-Z depth buffer -> metric planar depth (as mujoco's own Renderer does).
        extent = float(model.stat.extent)
        znear = np.float32(model.vis.map.znear * extent)
        zfar = np.float32(model.vis.map.zfar * extent)
        c_coef = np.float32(-0.5) * (-(zfar + znear) / (zfar - znear)) - np.float32(0.5)
        d_coef = np.float32(-0.5) * (-(np.float32(2) * zfar * znear) / (zfar - znear))
        buffer = self._depth[::-1].astype(np.float64)
        with np.errstate(divide="ignore"):
            depth = (d_coef / (buffer + c_coef)).astype(np.float32)
        depth[geom_id < 0] = 0.0
        return RenderedImages(depth, geom_id)

    def _free_context(self) -> None:
        if self._context is not None and self._gl is not None:
            self._gl.make_current()
            self._context.free()
        self._context = None
        self._scene = None
        self._model = None

    def close(self) -> None:
        """Free the GL resources; the renderer cannot be used afterwards."""
        self._free_context()
        if self._gl is not None:
            self._gl.free()
        self._gl = None

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __del__(self) -> None:  # best effort; prefer close()
        with contextlib.suppress(Exception):  # interpreter shutdown may have torn GL down
            self.close()


def render_depth_and_ids(
    meshes: Sequence[Any],
    world_from_mesh: Sequence[np.ndarray | None],
    K: np.ndarray,
    width: int,
    height: int,
    world_from_camera: np.ndarray,
    *,
    renderer: Renderer | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Depth and object-index images of posed meshes seen by a pinhole camera.

    Args:
        meshes: trimesh meshes or (vertices (V, 3) metres, faces (F, 3)) pairs, mesh frame.
        world_from_mesh: a 4x4 pose (or None = identity) per mesh, metres.
        K: (3, 3) intrinsics in pixels (OpenCV).
        width, height: image size in pixels.
        world_from_camera: (4, 4) OpenCV camera pose in the world, metres.
        renderer: a ``Renderer`` of the same size to reuse (one is created and closed if None).

    Returns:
        depth_m (H, W) float32, camera-frame z in metres, 0 where nothing is seen;
        object_index (H, W) int32, index into ``meshes`` of the front-most mesh, -1 for
        background.
    """
    import mujoco

    camera = PinholeCamera(np.asarray(K, float), int(width), int(height), world_from_camera)
    model, object_of_geom = build_mesh_model(meshes, world_from_mesh, camera)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_camlight(model, data)
    own = renderer is None
    if renderer is not None and (renderer.width, renderer.height) != (camera.width, camera.height):
        raise ValueError(
            f"renderer is {renderer.width}x{renderer.height}, image is {width}x{height}"
        )
    active = Renderer(camera.width, camera.height) if own else renderer
    try:
        images = active.render(model, data, CAMERA_NAME)
    finally:
        if own:
            active.close()
    lookup = np.append(object_of_geom, -1).astype(np.int32)  # geom -1 -> last entry -> -1
    object_index = lookup[images.geom_id]
    return images.depth_m, object_index
