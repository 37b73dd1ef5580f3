"""Camera conventions: MuJoCo renders a point where the OpenCV pinhole model projects it."""

import numpy as np
import pytest

from ipr_shapes.camera import (
    apply_transform,
    backproject,
    invert_transform,
    look_at,
    mujoco_camera_attributes,
    mujoco_camera_pose,
    project,
    view_halfspaces,
)
from ipr_shapes.gl import offscreen_context_class

mujoco = pytest.importorskip("mujoco")


def _render_sphere(K, world_from_camera, centre, width=160, height=120):
    pos, quat = mujoco_camera_pose(world_from_camera)
    attrs = " ".join(f'{k}="{v}"' for k, v in mujoco_camera_attributes(K, width, height).items())
    xml = f"""<mujoco><statistic extent="2" center="0 0 0"/>
      <visual><global offwidth="{width}" offheight="{height}"/><map znear="0.01" zfar="20"/></visual>
      <worldbody><geom type="sphere" size="0.004" pos="{centre[0]} {centre[1]} {centre[2]}"/>
      <camera name="c" pos="{pos[0]} {pos[1]} {pos[2]}"
              quat="{quat[0]} {quat[1]} {quat[2]} {quat[3]}" {attrs}/></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    offscreen_context_class()  # MuJoCo's own Renderer, on ipr's choice of backend
    with mujoco.Renderer(model, height, width) as renderer:
        renderer.enable_segmentation_rendering()
        renderer.update_scene(data, "c")
        seg = renderer.render()[..., 0]
        renderer.disable_segmentation_rendering()
        renderer.enable_depth_rendering()
        renderer.update_scene(data, "c")
        depth = renderer.render()
    return seg, depth


@pytest.mark.parametrize(
    ("cx", "cy", "offset"),
    [(79.5, 59.5, (0.0, 0.0)), (70.0, 66.0, (0.05, -0.03)), (90.0, 50.0, (-0.04, 0.02))],
)
def test_mujoco_camera_matches_opencv_projection(cx, cy, offset):
    K = np.array([[150.0, 0, cx], [0, 140.0, cy], [0, 0, 1]])
    world_from_camera = look_at(np.array([0.3, -0.4, 0.5]), np.zeros(3))
    camera_from_world = invert_transform(world_from_camera)
    # A point off the optical axis so that any sign error in the principal point shows.
    right, down = world_from_camera[:3, 0], world_from_camera[:3, 1]
    centre = offset[0] * right + offset[1] * down
    seg, depth = _render_sphere(K, world_from_camera, centre)
    rows, cols = np.nonzero(seg >= 0)
    assert rows.size > 0, "sphere not rendered"
    expected = project(apply_transform(camera_from_world, centre[None]), K)[0]
    assert abs(cols.mean() - expected[0]) < 0.35
    assert abs(rows.mean() - expected[1]) < 0.35
    # Depth is planar z in metres: the sphere's nearest surface is about its centre's z minus r.
    z_centre = apply_transform(camera_from_world, centre[None])[0, 2]
    assert abs(depth[rows, cols].min() - (z_centre - 0.004)) < 2.5e-3


def test_backproject_inverts_project():
    K = np.array([[500.0, 0, 320], [0, 510.0, 240], [0, 0, 1]])
    depth = np.full((480, 640), 0.7)
    points = backproject(depth, K)
    pixels = project(points.reshape(-1, 3), K).reshape(480, 640, 2)
    assert np.allclose(pixels[123, 456], [456, 123])


def test_look_at_is_right_handed_and_faces_target():
    world_from_camera = look_at(np.array([1.0, 0, 1.0]), np.zeros(3))
    rotation = world_from_camera[:3, :3]
    assert np.isclose(np.linalg.det(rotation), 1.0)
    assert np.allclose(rotation[:, 2], -np.array([1.0, 0, 1.0]) / np.sqrt(2))
    assert rotation[2, 1] < 0  # image "down" points down in the world


def test_the_view_halfspaces_hold_what_projects_inside_the_image():
    K = np.array([[500.0, 0, 300.5], [0, 510.0, 250.0], [0, 0, 1]])
    world_from_camera = look_at(np.array([0.2, -0.6, 0.5]), np.array([0.0, 0.1, 0.0]))
    height, width = 480, 640
    view = view_halfspaces(K, world_from_camera, (height, width))
    rng = np.random.default_rng(3)
    # Camera-frame points in front of the camera, projecting inside and outside the image.
    z = rng.uniform(0.2, 2.0, 5000)
    u, v = rng.uniform(-200, width + 200, 5000), rng.uniform(-200, height + 200, 5000)
    camera = np.column_stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z])
    world = apply_transform(world_from_camera, camera)
    distance = world @ view[:, :3].T + view[:, 3]
    assert np.allclose(np.linalg.norm(view[:, :3], axis=1), 1.0)
    inside = (u >= -0.5) & (u <= width - 0.5) & (v >= -0.5) & (v <= height - 0.5)
    assert np.array_equal(np.all(distance >= 0, axis=1), inside)
    # Each row is the distance (m) from its border's plane: left, right, top, bottom.
    left = world_from_camera[:3, 3] + world_from_camera[:3, :3] @ np.array(
        [(-0.5 - K[0, 2]) / K[0, 0], 0.0, 1.0]
    )
    assert abs(left @ view[0, :3] + view[0, 3]) < 1e-12
    step = world_from_camera[:3, :3] @ np.array([0.01, 0.0, 0.0])  # 1 cm to the right
    assert (left + step) @ view[0, :3] + view[0, 3] == pytest.approx(
        0.01 * view[0, :3] @ world_from_camera[:3, 0]
    )
    assert view[0, :3] @ world_from_camera[:3, 0] > 0.8  # into the view, about the x axis
