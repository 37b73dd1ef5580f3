"""Rendering of a pile world: clean depth, segmentation, shading and realistic object colours.

MuJoCo cannot render per-vertex colours, so objects are rendered white (lit, with shadows) and
the colour of each object pixel is the colour of the nearest model vertex to the pixel's 3D
point (a KD-tree per object in its model frame) times the rendered shading. Table and walls keep
their rendered colours and textures.

Images are (H, W) or (H, W, 3) arrays; depth is planar z (along the optical axis) in metres; the
camera is the OpenCV camera ``world_from_camera`` with intrinsics ``K``.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial import cKDTree

from ipr_shapes.camera import (
    backproject,
    invert_transform,
    mujoco_camera_attributes,
    mujoco_camera_pose,
)
from ipr_shapes.gl import offscreen_context_class
from ipr_shapes.synth.piles import (
    GROUP_OBJECTS,
    GROUP_TABLE,
    GROUP_WALLS,
    LABEL_BACKGROUND,
    PileWorld,
)

#: Geom groups used to render one object alone.
_GROUP_SOLO, _GROUP_HIDDEN = 4, 5


@dataclass(frozen=True, eq=False)
class RenderedFrame:
    """Noise-free renders of one state.

    Attributes:
        depth_m: (H, W) float32 planar depth in metres (every pixel sees some surface).
        labels: (H, W) int32 object index per pixel, or a negative ``LABEL_*`` code.
        rgb: (H, W, 3) uint8 colour image with object albedo applied.
        poses: (n, 4, 4) world-from-model of the objects.
    """

    depth_m: np.ndarray
    labels: np.ndarray
    rgb: np.ndarray
    poses: np.ndarray


class SceneRenderer:
    """One offscreen renderer for a ``PileWorld`` and a fixed camera; use as a context manager."""

    def __init__(self, world: PileWorld, K: np.ndarray, world_from_camera: np.ndarray) -> None:
        self.world = world
        self.K = K
        self.world_from_camera = world_from_camera
        config = world.config
        self.width, self.height = config.width, config.height
        _set_camera(world.model, K, world_from_camera, self.width, self.height)
        self.data = mujoco.MjData(world.model)
        offscreen_context_class()  # the GL backend, unless MUJOCO_GL is set (ipr_shapes.gl)
        self.renderer = mujoco.Renderer(world.model, self.height, self.width)
        self.trees = [cKDTree(item.vertices) for item in world.objects]
        self.options = mujoco.MjvOption()
        self.options.geomgroup[:] = 0
        self.options.geomgroup[[GROUP_OBJECTS, GROUP_TABLE, GROUP_WALLS]] = 1

    def __enter__(self) -> SceneRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Free the GL context."""
        self.renderer.close()

    # ----------------------------------------------------------------------------------------

    def _update(self, qpos: np.ndarray, options: mujoco.MjvOption) -> None:
        self.data.qpos[:] = qpos
        self.data.mocap_pos[:] = self.world.data.mocap_pos
        mujoco.mj_kinematics(self.world.model, self.data)
        mujoco.mj_camlight(self.world.model, self.data)
        self.renderer.update_scene(self.data, "camera", scene_option=options)

    def _labels(self) -> np.ndarray:
        self.renderer.enable_segmentation_rendering()
        try:
            ids = self.renderer.render()
        finally:
            self.renderer.disable_segmentation_rendering()
        geom = ids[..., 0]
        is_geom = (ids[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)) & (geom >= 0)
        labels = np.full(geom.shape, LABEL_BACKGROUND, dtype=np.int32)
        labels[is_geom] = self.world.labels[geom[is_geom]]
        return labels

    def _depth(self) -> np.ndarray:
        self.renderer.enable_depth_rendering()
        try:
            return np.asarray(self.renderer.render(), dtype=np.float32).copy()
        finally:
            self.renderer.disable_depth_rendering()

    def render(self, qpos: np.ndarray) -> RenderedFrame:
        """Depth, labels and coloured RGB of the state ``qpos`` (pusher withdrawn)."""
        self._update(qpos, self.options)
        depth = self._depth()
        labels = self._labels()
        shading = self.renderer.render().copy()
        poses = self.world.poses(self.data)
        rgb = self._colourise(shading, depth, labels, poses)
        return RenderedFrame(depth, labels, rgb, poses)

    def objects_only_labels(self, qpos: np.ndarray) -> np.ndarray:
        """(H, W) labels with table and walls hidden (objects occlude only each other)."""
        options = mujoco.MjvOption()
        options.geomgroup[:] = 0
        options.geomgroup[GROUP_OBJECTS] = 1
        self._update(qpos, options)
        return self._labels()

    def solo_masks(self, qpos: np.ndarray) -> np.ndarray:
        """(n, H, W) bool silhouettes of each object rendered alone."""
        model, geoms = self.world.model, self.world.geom_ids
        saved = model.geom_group[geoms].copy()
        options = mujoco.MjvOption()
        options.geomgroup[:] = 0
        options.geomgroup[_GROUP_SOLO] = 1
        masks = np.zeros((len(geoms), self.height, self.width), dtype=bool)
        try:
            for index, geom in enumerate(geoms):
                model.geom_group[geoms] = _GROUP_HIDDEN
                model.geom_group[geom] = _GROUP_SOLO
                self._update(qpos, options)
                masks[index] = self._labels() == index
        finally:
            model.geom_group[geoms] = saved
        return masks

    # ----------------------------------------------------------------------------------------

    def _colourise(
        self, shading: np.ndarray, depth: np.ndarray, labels: np.ndarray, poses: np.ndarray
    ) -> np.ndarray:
        """Object pixels: nearest-vertex albedo x white-object shading; others unchanged."""
        rgb = shading.astype(np.float32)
        points_camera = backproject(depth, self.K)
        for index, item in enumerate(self.world.objects):
            rows, cols = np.nonzero(labels == index)
            if rows.size == 0:
                continue
            model_from_camera = invert_transform(poses[index]) @ self.world_from_camera
            points = points_camera[rows, cols] @ model_from_camera[:3, :3].T
            points += model_from_camera[:3, 3]
            _, nearest = self.trees[index].query(points, workers=1)
            albedo = item.colors[nearest].astype(np.float32) / 255.0
            rgb[rows, cols] = shading[rows, cols].astype(np.float32) * albedo * _OBJECT_GAIN
        return np.clip(np.round(rgb), 0, 255).astype(np.uint8)


#: White objects render slightly below full brightness; this gain maps the brightest lit
#: surfaces back to their albedo.
_OBJECT_GAIN = 1.1


def _set_camera(
    model: mujoco.MjModel, K: np.ndarray, world_from_camera: np.ndarray, width: int, height: int
) -> None:
    """Copy the camera that ``ipr_shapes.camera`` defines for ``K`` and the pose into ``model``'s
    camera 0 (compiling a one-camera model, so MuJoCo applies its own attribute rules)."""
    position, quaternion = mujoco_camera_pose(world_from_camera)
    attributes = " ".join(
        f'{key}="{value}"' for key, value in mujoco_camera_attributes(K, width, height).items()
    )
    camera_xml = (
        f'<mujoco><worldbody><camera name="camera" pos="{_numbers(position)}" '
        f'quat="{_numbers(quaternion)}" {attributes}/></worldbody></mujoco>'
    )
    reference = mujoco.MjModel.from_xml_string(camera_xml)
    for name in (
        "cam_pos",
        "cam_quat",
        "cam_fovy",
        "cam_resolution",
        "cam_sensorsize",
        "cam_intrinsic",
        "cam_orthographic",
        "cam_pos0",
        "cam_mat0",
        "cam_poscom0",
    ):
        if hasattr(model, name):
            getattr(model, name)[0] = getattr(reference, name)[0]


def _numbers(values: np.ndarray) -> str:
    return " ".join(f"{float(value):.17g}" for value in values)
