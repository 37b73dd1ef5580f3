"""Output shapes carved by observed free space (ipr_shapes.carving): real renders, real voxelisation."""

from __future__ import annotations

from types import SimpleNamespace

import manifold3d
import numpy as np
import pytest
import trimesh

from ipr_shapes import voxels
from ipr_shapes.camera import look_at
from ipr_shapes.carving import (
    CarvingConfig,
    SurfaceView,
    carve_mesh,
    carve_voxels,
    observed_surface_depth,
    surface_views,
    voxel_surface,
)
from ipr_shapes.perception.types import PartialObject
from ipr_shapes.rendering import render_depth_and_ids
from tests.box_scene import box_mesh

PITCH = voxels.DEFAULT_PITCH_M
WIDTH, HEIGHT = 320, 240
K = np.array([[300.0, 0.0, WIDTH / 2 - 0.5], [0.0, 300.0, HEIGHT / 2 - 0.5], [0.0, 0.0, 1.0]])


def _mesh_arrays(solid: manifold3d.Manifold) -> tuple[np.ndarray, np.ndarray]:
    mesh = solid.to_mesh()
    return np.asarray(mesh.vert_properties, float)[:, :3], np.asarray(mesh.tri_verts, np.int64)


def _open_box() -> tuple[np.ndarray, np.ndarray]:
    """A 12 x 12 x 8 cm open-topped box (walls and floor 1 cm) standing on z = 0."""
    outer = manifold3d.Manifold.cube([0.12, 0.12, 0.08], center=True).translate([0, 0, 0.04])
    cavity = manifold3d.Manifold.cube([0.10, 0.10, 0.08], center=True).translate([0, 0, 0.05])
    return _mesh_arrays(outer - cavity)


def _view(mesh, world_from_camera, margin=0.0, motions=None, world_from_mesh=None, table=True):
    """The depth of ``mesh`` (posed by ``world_from_mesh``), on a table top at z = 0 or alone."""
    meshes, poses = [mesh], [world_from_mesh]
    if table:
        meshes.append(box_mesh(np.array([0.5, 0.5, 0.01]), np.array([0.0, 0.0, -0.01])))
        poses.append(None)
    depth, _ = render_depth_and_ids(meshes, poses, K, WIDTH, HEIGHT, world_from_camera)
    return SurfaceView(depth.astype(np.float64), K, world_from_camera, margin, motions)


def _keys(mesh) -> np.ndarray:
    vertices, faces, _ = voxels.closed_or_hull(mesh)
    return voxels.scanline_voxels(vertices, faces, PITCH)


def test_voxel_surface_is_a_closed_manifold_that_reads_back_its_voxels():
    rng = np.random.default_rng(3)
    # A random blob: many voxels touch only along an edge or at a corner.
    index = np.argwhere(rng.random((9, 8, 7)) < 0.45) + np.array([-4, 10, 2])
    keys = np.unique(voxels.pack(index))
    vertices, faces = voxel_surface(keys, PITCH)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    read_back = voxels.scanline_voxels(vertices, faces, PITCH)
    # Edge contacts are joined by added voxels, never by removing one.
    assert np.isin(keys, read_back).all()
    assert np.isclose(mesh.volume, read_back.size * PITCH**3)
    # Without edge contacts the surface is exact.
    solid = np.unique(voxels.pack(np.argwhere(np.ones((3, 4, 2), bool)) + 7))
    vertices, faces = voxel_surface(solid, PITCH)
    assert np.array_equal(voxels.scanline_voxels(vertices, faces, PITCH), solid)
    assert len(faces) == 2 * 2 * (3 * 4 + 4 * 2 + 3 * 2)


def test_voxel_surface_keys_are_the_voxels_its_mesh_reads_back():
    """The joined voxels ``voxel_surface(..., with_keys=True)`` gives are exactly what the
    result's voxelisation (``voxels.occupied_voxels``) reads back from the written mesh, so
    ``occupancy.npz`` may use them instead of voxelising the carved shapes again."""
    rng = np.random.default_rng(8)
    for share in (0.3, 0.45, 0.6, 0.8):
        index = np.argwhere(rng.random((10, 9, 8)) < share) + np.array([-30, 12, 5])
        keys = np.unique(voxels.pack(index))
        vertices, faces, joined = voxel_surface(keys, PITCH, with_keys=True)
        assert np.array_equal(voxels.occupied_voxels((vertices, faces), PITCH), joined)
        assert joined.size > keys.size and np.isin(keys, joined).all()  # edge contacts joined
        assert np.array_equal(np.sort(joined), joined)
        plain = voxel_surface(keys, PITCH)
        assert np.array_equal(plain[0], vertices) and np.array_equal(plain[1], faces)


def test_carving_hollows_an_open_box_seen_from_above():
    cup = _open_box()
    hull = voxels.convex_hull(cup[0])
    above = look_at(np.array([0.02, -0.06, 0.5]), np.array([0.0, 0.0, 0.03]))
    view = _view(cup, above)
    truth, hull_keys = _keys(cup), _keys(hull)
    carved = carve_voxels(hull_keys, 1, [view])

    def iou(a, b):
        common = voxels.intersection_count(a, b)
        return common / (a.size + b.size - common)

    assert iou(hull_keys, truth) < 0.6  # the hull fills the cavity
    assert iou(carved, truth) > 0.85  # the camera saw most of the cavity empty
    assert voxels.intersection_count(carved, truth) >= 0.98 * truth.size  # the walls stay
    # The written mesh holds exactly the carved voxels.
    vertices, faces = carve_mesh(hull, 1, [view])
    assert np.array_equal(voxels.scanline_voxels(vertices, faces, PITCH), carved)


def test_a_margin_keeps_what_lies_just_in_front_of_the_surface():
    box = box_mesh()
    camera = look_at(np.array([0.0, -0.3, 0.3]), np.array([0.0, 0.0, 0.02]))
    # A hypothesis 1.2 cm deeper towards the camera than the box.
    bulged = box_mesh(np.array([0.05, 0.042, 0.02]), np.array([0.0, -0.012, 0.02]))
    keys = _keys(bulged)
    # Alone: every ray through the hypothesis that returns ends on the box.
    tight = carve_voxels(keys, 1, [_view(box, camera, table=False)])
    loose = carve_voxels(keys, 1, [_view(box, camera, margin=0.05, table=False)])
    assert tight.size < 0.85 * keys.size
    assert loose.size == keys.size
    assert carve_mesh(bulged, 1, [_view(box, camera, margin=0.05, table=False)]) is None


def test_a_later_view_carves_through_the_objects_motion():
    box = box_mesh()
    # Hypothesis: the box plus a 3 cm slab behind it (mostly hidden from the frame-0 camera).
    hypothesis = box_mesh(np.array([0.05, 0.045, 0.02]), np.array([0.0, 0.015, 0.02]))
    keys, truth = _keys(hypothesis), _keys(box)
    first = _view(box, look_at(np.array([0.0, -0.35, 0.25]), np.array([0.0, 0.0, 0.02])))
    seen_first = carve_voxels(keys, 1, [first])
    assert voxels.intersection_count(seen_first, truth) == truth.size
    assert seen_first.size > truth.size + 0.7 * (keys.size - truth.size)  # the slab stays
    # Frame 1: the object was pushed 10 cm along x and turned -90 degrees about z; the camera
    # now looks from +x, which (through the turn) faces the box's former +y side.
    turn = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    motion = np.eye(4)
    motion[:3, :3], motion[:3, 3] = turn, [0.10, 0.0, 0.0]
    camera = look_at(np.array([0.45, 0.0, 0.25]), np.array([0.10, 0.0, 0.02]))
    later = _view(box, camera, margin=0.005, motions={1: motion}, world_from_mesh=motion)
    carved = carve_voxels(keys, 1, [first, later])
    assert voxels.intersection_count(carved, truth) >= 0.97 * truth.size
    assert carved.size < truth.size + 0.3 * (keys.size - truth.size)  # most of the slab is gone
    # Objects the view has no motion for are left alone; a wrong motion cuts into the box.
    assert carve_voxels(keys, 2, [first, later]).size == carve_voxels(keys, 2, [first]).size
    wrong = SurfaceView(later.depth_m, K, camera, 0.005, {1: np.eye(4)})
    assert voxels.intersection_count(carve_voxels(keys, 1, [wrong]), truth) < 0.9 * truth.size


def test_the_observed_surface_takes_the_objects_denoised_points_and_drops_the_robot():
    camera = np.eye(4)
    depth = np.full((6, 6), 0.8, dtype=np.float32)
    depth[:3, :3] = 0.0  # a hole, 3 x 3 pixels
    depth[0, 3] = 0.7
    robot = np.zeros((6, 6), bool)
    robot[5, 5] = True
    frame = SimpleNamespace(depth_m=depth, world_from_camera=camera, robot_mask=robot)
    points = np.array([[0.0, 0.0, 0.75], [0.0, 0.0, 0.76], [1.0, 1.0, 1.0]])
    obj = PartialObject(1, 0, np.array([15, 1, -1]), points, np.zeros((3, 3), np.uint8))
    surface = observed_surface_depth(frame, [obj])
    assert surface[2, 3] == pytest.approx(0.75)  # pixel 15 takes its denoised point
    assert surface[0, 1] == 0.0  # no reading stays no reading, even under an object's pixel
    assert surface[5, 5] == 0.0  # the robot carves nothing
    assert surface[4, 4] == pytest.approx(0.8)
    filled = observed_surface_depth(frame, [obj], hole_fill_window_px=3)
    assert filled[0, 2] == pytest.approx(0.7)  # a hole takes the nearest surface around it
    assert filled[2, 2] == pytest.approx(0.75)
    assert filled[1, 1] == 0.0  # nothing read around it
    assert filled[5, 5] == 0.0
    with pytest.raises(ValueError, match="odd"):
        CarvingConfig(hole_fill_window_px=4)


def test_surface_views_use_later_frames_only_with_motions():
    frame = SimpleNamespace(
        depth_m=np.ones((4, 5), np.float32), world_from_camera=np.eye(4), K=K, robot_mask=None
    )
    frames, objects = [frame, frame, frame], [(), (), ()]
    config = CarvingConfig()
    assert len(surface_views(frames, objects, None, config)) == 1
    motions = {3: {2: np.eye(4)}}
    views = surface_views(frames, objects, motions, config)
    assert len(views) == 2 and set(views[1].frame_from_frame0) == {3}
    assert views[1].margin_m == config.later_frame_margin_m
    assert len(surface_views(frames, objects, motions, CarvingConfig(later_frames=False))) == 1
    with pytest.raises(ValueError, match="first_frame_margin_m"):
        CarvingConfig(first_frame_margin_m=-0.001)
