"""Voxel occupancy: exact on boxes, right volume on YCB meshes, agrees with an independent
inside test (generalised winding number),
consistent on degenerate (grid-aligned) geometry, convex hull for open meshes."""

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from ipr_shapes import voxels
from ipr_shapes.data import ycb_models_dir

P = voxels.DEFAULT_PITCH_M


def _box(lower, upper) -> trimesh.Trimesh:
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    box = trimesh.creation.box(extents=upper - lower)
    box.apply_translation((lower + upper) / 2)
    return box


def _pose(seed: int, translation=(0.0123, -0.2, 0.3)) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3] = Rotation.random(random_state=seed).as_matrix()
    transform[:3, 3] = translation
    return transform


def _winding_inside(mesh: trimesh.Trimesh, points: np.ndarray, chunk: int = 32) -> np.ndarray:
    """Inside test by the generalised winding number (solid angles, Van Oosterom-Strackee)."""
    triangles = mesh.vertices[mesh.faces]
    winding = np.empty(len(points))
    for start in range(0, len(points), chunk):
        p = points[start : start + chunk, None, None, :]
        a, b, c = (triangles[None, :, i, :] - p[:, :, 0, :] for i in range(3))
        la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
        numerator = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        denominator = (
            la * lb * lc
            + np.einsum("ijk,ijk->ij", a, b) * lc
            + np.einsum("ijk,ijk->ij", a, c) * lb
            + np.einsum("ijk,ijk->ij", b, c) * la
        )
        winding[start : start + chunk] = np.arctan2(numerator, denominator).sum(1) / (2 * np.pi)
    return np.abs(winding) > 0.5


def _ycb(name: str) -> trimesh.Trimesh:
    folder = ycb_models_dir()
    if folder is None:
        pytest.skip("shared YCB meshes not found (set IPR_DATA or place ../shared/data)")
    return trimesh.load(folder / "models" / f"{name}.ply", process=False)


def _sample_centres(keys_mesh: trimesh.Trimesh, count: int, seed: int) -> np.ndarray:
    """Integer voxel indices in the mesh's bounding box (margin of one voxel)."""
    low = np.floor(keys_mesh.bounds[0] / P).astype(int) - 1
    high = np.ceil(keys_mesh.bounds[1] / P).astype(int) + 1
    rng = np.random.default_rng(seed)
    return np.unique(rng.integers(low, high, size=(count, 3)), axis=0)


# --------------------------------------------------------------------------------------------


def test_pack_unpack_round_trip_and_order():
    rng = np.random.default_rng(0)
    indices = rng.integers(-(2**20), 2**20, size=(1000, 3))
    keys = voxels.pack(indices)
    assert np.array_equal(voxels.unpack(keys), indices)
    order = np.lexsort(indices.T[::-1])
    assert np.all(np.diff(keys[order]) >= 0)  # keys sort like (i, j, k) tuples
    with pytest.raises(ValueError, match="out of range"):
        voxels.pack([[2**20, 0, 0]])


def test_set_helpers_match_numpy():
    rng = np.random.default_rng(1)
    a = np.unique(rng.integers(0, 500, 200)).astype(np.int64)
    b = np.unique(rng.integers(0, 500, 300)).astype(np.int64)
    assert voxels.intersection_count(a, b) == np.intersect1d(a, b).size
    assert np.array_equal(voxels.intersection(a, b), np.intersect1d(a, b))
    assert np.array_equal(voxels.union(a, b), np.union1d(a, b))
    assert voxels.intersection_count(a, voxels.EMPTY) == 0
    assert voxels.union().size == 0


@pytest.mark.parametrize(
    ("lower", "upper", "expected"),
    [
        ((0, 0, 0), (0.1, 0.1, 0.1), 20 * 20 * 20),
        ((0.0012, -0.0488, 0.0301), (0.1012, 0.0012, 0.0501), 20 * 10 * 4),
        ((-0.3, 0.2, -0.01), (-0.2, 0.25, 0.0), 20 * 10 * 2),
    ],
)
def test_axis_aligned_box_is_exact(lower, upper, expected):
    keys = voxels.occupied_voxels(_box(lower, upper))
    assert keys.dtype == np.int64
    assert keys.size == expected
    assert np.all(np.diff(keys) > 0)  # sorted, unique
    centres = voxels.centres(keys)
    assert np.all(centres > np.asarray(lower)) and np.all(centres < np.asarray(upper))


def test_box_shifted_by_a_tenth_has_iou_nine_elevenths():
    box = voxels.occupied_voxels(_box((0, 0, 0), (0.1, 0.1, 0.1)))
    shift = np.eye(4)
    shift[0, 3] = 0.01
    moved = voxels.occupied_voxels(_box((0, 0, 0), (0.1, 0.1, 0.1)), P, shift)
    inter = voxels.intersection_count(box, moved)
    assert inter / voxels.union(box, moved).size == pytest.approx(9 / 11, abs=1e-12)


def test_faces_and_diagonals_on_column_centres_are_counted_once():
    # A binary pitch makes the centres (n + 1/2) p exact floats, so the box faces x, y, z = 1.5 p
    # and 11.5 p pass exactly through voxel centres, and the top/bottom diagonals through the
    # columns i == j. The displaced-column rule (and half-open z) counts [1.5, 11.5) per axis.
    pitch = 1.0 / 256
    lower, upper = 1.5 * pitch, 11.5 * pitch
    vertices = np.array(
        [[x, y, z] for x in (lower, upper) for y in (lower, upper) for z in (lower, upper)]
    )
    box = trimesh.Trimesh(vertices, trimesh.creation.box().faces, process=False)
    box.fix_normals()
    assert box.is_watertight and box.volume == pytest.approx((10 * pitch) ** 3)
    assert voxels.occupied_voxels(box, pitch).size == 10 * 10 * 10
    # A diamond prism (square turned by 45 degrees) with its corners on voxel centres.
    corners = (np.array([[6, 1], [11, 6], [6, 11], [1, 6]]) + 0.5) * pitch
    prism = trimesh.convex.convex_hull(
        np.vstack([np.column_stack([corners, np.full(4, z)]) for z in (1.5 * pitch, 5.5 * pitch)])
    )
    displaced = prism.copy()
    displaced.apply_translation([-1e-9, -1e-12, -1e-7])  # the tie rule, made explicit
    assert np.array_equal(
        voxels.occupied_voxels(prism, pitch), voxels.occupied_voxels(displaced, pitch)
    )
    # Area 2 x 5^2 voxels per layer: 50 columns (half-open diamond), 4 layers [1.5, 5.5).
    assert voxels.occupied_voxels(prism, pitch).size == 50 * 4


@pytest.mark.parametrize(("subdivisions", "radius"), [(1, 0.03), (2, 0.04)])
def test_grid_snapped_mesh_has_exact_parity(subdivisions, radius):
    # Vertices snapped to voxel centres: many columns run through vertices and edges, and many
    # centres lie on faces. Every centre off the surface (integer winding number) must be
    # decided exactly; centres on the surface (fractional winding number) may go either way.
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    sphere.vertices = (np.round(sphere.vertices / P - 0.5) + 0.5) * P
    keys = voxels.occupied_voxels(sphere)
    low = np.floor(sphere.bounds[0] / P).astype(int) - 1
    high = np.ceil(sphere.bounds[1] / P).astype(int) + 1
    grid = np.stack(
        np.meshgrid(*[np.arange(a, b) for a, b in zip(low, high, strict=True)], indexing="ij"),
        axis=-1,
    ).reshape(-1, 3)
    centres = (grid + 0.5) * P
    occupied = np.isin(voxels.pack(grid), keys)
    inside = _winding_inside(sphere, centres)
    disagree = np.flatnonzero(occupied != inside)
    # Only centres lying exactly on the surface (vertex, edge or face) may go either way.
    for index in disagree:
        point = np.repeat(centres[index][None], len(sphere.faces), axis=0)
        closest = trimesh.triangles.closest_point(sphere.triangles, point)
        distance = np.linalg.norm(closest - point, axis=1).min()
        assert distance < 1e-9, f"centre {grid[index]} is {distance:.2e} m off the surface"
    assert len(disagree) < 0.02 * len(grid)


def test_orientation_and_unshared_vertices_do_not_matter():
    mesh = trimesh.creation.capsule(height=0.08, radius=0.03)
    pose = _pose(2, (0.01, 0.02, 0.03))
    reference = voxels.occupied_voxels(mesh, P, pose)
    inverted = trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False)
    assert np.array_equal(voxels.occupied_voxels(inverted, P, pose), reference)
    # Every face with its own three vertices (as some PLY exporters write): still closed.
    soup = trimesh.Trimesh(
        mesh.vertices[mesh.faces].reshape(-1, 3),
        np.arange(3 * len(mesh.faces)).reshape(-1, 3),
        process=False,
    )
    vertices, faces, closed = voxels.closed_or_hull(soup)
    assert closed
    assert np.array_equal(voxels.occupied_voxels(soup, P, pose), reference)
    assert np.array_equal(voxels.occupied_voxels((mesh.vertices, mesh.faces), P, pose), reference)


def test_open_mesh_is_scored_as_its_convex_hull():
    mug = _ycb("025_mug")  # concave: the hull is much larger
    pose = _pose(4)
    closed_keys = voxels.occupied_voxels(mug, P, pose)
    opened = trimesh.Trimesh(mug.vertices, mug.faces[:-5], process=False)
    _, _, closed = voxels.closed_or_hull(opened)
    assert not closed
    open_keys = voxels.occupied_voxels(opened, P, pose)
    hull_keys = voxels.occupied_voxels(mug.convex_hull, P, pose)
    assert np.array_equal(open_keys, hull_keys)
    assert open_keys.size > 1.3 * closed_keys.size
    # Two vertical walls only: parity would fill nothing, the hull fills the box.
    box = _box((0, 0, 0), (0.1, 0.1, 0.1))
    walls = box.faces[
        np.all(np.isclose(box.vertices[box.faces][:, :, 0], 0.0), axis=1)
        | np.all(np.isclose(box.vertices[box.faces][:, :, 0], 0.1), axis=1)
    ]
    assert len(walls) == 4
    assert voxels.occupied_voxels((box.vertices, walls)).size == 8000
    # A flat mesh has no interior.
    flat = (np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0.0]]), np.array([[0, 1, 2]]))
    assert voxels.occupied_voxels(flat).size == 0


@pytest.mark.parametrize("name", ["006_mustard_bottle", "003_cracker_box", "011_banana"])
def test_ycb_volume_and_speed(name):
    mesh = _ycb(name)
    assert mesh.is_watertight
    pose = _pose(7)
    voxels.occupied_voxels(mesh, P, pose)  # warm-up
    keys = voxels.occupied_voxels(mesh, P, pose)
    assert np.all(np.diff(keys) > 0)
    assert voxels.volume_m3(keys) == pytest.approx(mesh.volume, rel=0.03)
    fine = voxels.occupied_voxels(mesh, 0.001, pose)
    assert voxels.volume_m3(fine, 0.001) == pytest.approx(mesh.volume, rel=0.003)


def test_ycb_occupancy_matches_winding_number_at_voxel_centres():
    mesh = _ycb("006_mustard_bottle")
    pose = _pose(3)
    keys = voxels.occupied_voxels(mesh, P, pose)
    placed = mesh.copy()
    placed.apply_transform(pose)
    # Half random centres in the bounding box, half centres next to the surface.
    indices = _sample_centres(placed, 250, seed=0)
    near = voxels.unpack(keys[np.random.default_rng(1).choice(keys.size, 150, replace=False)])
    near = near + np.random.default_rng(2).integers(-1, 2, size=near.shape)
    indices = np.unique(np.vstack([indices, near]), axis=0)
    inside = _winding_inside(placed, (indices + 0.5) * P)
    assert 0 < inside.sum() < len(indices)
    assert np.array_equal(np.isin(voxels.pack(indices), keys), inside)
