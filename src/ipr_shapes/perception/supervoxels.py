"""Supervoxels: small surface patches with a normal, the nodes of the segmentation graph.

The paper over-segments each point cloud into supervoxels before building the convexity graph;
its authors' code uses PCL's VCCS (voxel 7.5 mm, seed 2 cm, colour weight 0, spatial 1,
normal 1). This module does the same in vectorised numpy:

1. per-pixel normals from the organised cloud (``organised_normals_at``: image-space
   neighbours, one-sided at discontinuities);
2. the kept points are binned into ``supervoxels.voxel_size_m`` voxels (mean position, normal,
   colour);
3. one seed per occupied ``supervoxels.seed_size_m`` cell (the voxel nearest the cell centre);
4. a few k-means rounds assign every voxel to the nearest seed among those of the 27
   surrounding seed cells, in VCCS's distance ((distance / seed size)^2 + normal weight x
   (1 - cos of the normals' angle));
5. each supervoxel is cut into its 26-connected voxel components (so a supervoxel never spans
   a gap in 3D), and crumbs are merged into the neighbour they touch most;
6. each supervoxel's centre and normal come from its dominant face (``_dominant_faces``), so
   that patches straddling a crease do not turn into slivers between two faces.

Adjacency is the 26-neighbourhood of voxels: two supervoxels are adjacent when some of their
voxels touch, i.e. when their surfaces come within about a voxel of each other in 3D. Pixels on
either side of a depth discontinuity are centimetres apart in 3D and so never adjacent.

Why voxels rather than superpixels on the organised image: a SLIC-like superpixel pass in the
same pipeline segmented worse and took several times as long, since every foreground pixel
takes part in its k-means rounds, against one voxel per tens of pixels here
(docs/DESIGN_NOTES.md, "Supervoxels").
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig
from ipr_shapes.perception.types import Supervoxels
from ipr_shapes.scene import Frame

# The 13 "forward" offsets of the 26-neighbourhood (the other 13 are their negatives).
_FORWARD_OFFSETS = np.array(
    [
        (dx, dy, dz)
        for dx in (-1, 0, 1)
        for dy in (-1, 0, 1)
        for dz in (-1, 0, 1)
        if (dx, dy, dz) > (0, 0, 0)
    ],
    dtype=np.int64,
)


def organised_normals(
    depth_m: np.ndarray,
    K: np.ndarray,
    config: PerceptionConfig = PerceptionConfig(),  # noqa: B008 (frozen)
) -> np.ndarray:
    """Unit surface normals (H, W, 3) float32 in the camera frame, towards the camera; 0 where
    unknown (no depth, or no usable neighbour). See ``organised_normals_at``."""
    depth = np.asarray(depth_m, dtype=np.float32)
    normals = np.zeros((*depth.shape, 3), dtype=np.float32)
    pixels = np.flatnonzero(depth.reshape(-1) > 0)
    normals.reshape(-1, 3)[pixels] = organised_normals_at(depth, K, pixels, config)
    return normals


def organised_normals_at(
    depth_m: np.ndarray,
    K: np.ndarray,
    pixels: np.ndarray,
    config: PerceptionConfig = PerceptionConfig(),  # noqa: B008 (frozen)
) -> np.ndarray:
    """Unit normals (P, 3) float32, camera frame, towards the camera, of the flat ``pixels``
    (P,) of a (H, W) depth image (m) with intrinsics K; rows of 0 where unknown.

    Each pixel's normal is the cross product of the differences between its neighbours
    ``supervoxels.normal_radius_px`` pixels away horizontally and vertically (image-space
    neighbours of the organised cloud). A neighbour that has no depth, or whose depth differs
    from the pixel's by more than ``supervoxels.normal_max_jump_m`` plus
    ``supervoxels.normal_max_jump_ratio`` of the depth per pixel of offset (a discontinuity:
    another surface), is replaced by the pixel itself (a one-sided
    difference); pixels left without a difference in either direction get no normal. Only the
    requested pixels are computed (the support, most of the image, needs none).
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    height, width = depth.shape
    pixels = np.asarray(pixels, dtype=np.int64)
    r = int(config.supervoxels.normal_radius_px)
    # A border of r zero-depth pixels makes every neighbour lookup an in-bounds read: outside
    # the image reads as "no depth", which is what the bounds test gave (one gather per
    # neighbour instead of bounds masks, clamped indices and selects).
    padded = np.zeros((height + 2 * r, width + 2 * r), dtype=np.float32)
    padded[r : r + height, r : r + width] = depth
    padded_width = width + 2 * r
    flat = padded.reshape(-1)
    rows, cols = np.divmod(pixels, width)
    at = (rows + r) * padded_width + (cols + r)  # the pixels' flat indices in ``padded``
    # The per-pixel arithmetic runs compiled, in float32 as before (``kernels``).
    return kernels.organised_normals(
        flat,
        padded_width,
        at,
        rows,
        cols,
        np.asarray(K, dtype=np.float64),
        r,
        float(config.supervoxels.normal_max_jump_m),
        float(config.supervoxels.normal_max_jump_ratio),
    )


def compute_supervoxels(
    frame: Frame,
    keep: np.ndarray,
    config: PerceptionConfig = PerceptionConfig(),  # noqa: B008 (frozen)
    *,
    normals_camera: np.ndarray | None = None,
    points_world: np.ndarray | None = None,
) -> Supervoxels:
    """VCCS-like supervoxels of the pixels of ``frame`` where ``keep`` (H, W) bool is True.

    Pixels without depth are never used. ``normals_camera`` (H, W, 3) (``organised_normals``;
    only the kept pixels are read) and ``points_world`` (H, W, 3) (``frame.points_world()``)
    may be passed to avoid recomputing them.

    Supervoxel normals are the smallest principal axis of the points of their dominant face
    (``_dominant_faces``: a least-squares plane, which noise barely tilts over a 2 cm patch),
    oriented towards the camera; tiny or degenerate patches use their mean pixel normal.
    """
    height, width = frame.shape
    keep = np.asarray(keep, dtype=bool) & (frame.depth_m > 0)
    pixels = np.flatnonzero(keep.reshape(-1))
    rotation = frame.world_from_camera[:3, :3]
    camera_centre = frame.world_from_camera[:3, 3]
    labels_image = np.full((height, width), -1, dtype=np.int32)
    if pixels.size == 0:
        return _empty(labels_image)
    if points_world is None:
        points_world = frame.points_world()
    flat_points = np.asarray(points_world.reshape(-1, 3), dtype=np.float64)
    voxel = config.supervoxels.voxel_size_m
    # Compiled (``kernels``): every kept pixel's voxel key without gathering its point.
    all_keys, dims = kernels.voxel_keys(flat_points, pixels, voxel)
    # Close-up frames have tens of pixels per voxel: the statistics come from an even subset
    # of at most supervoxels.max_points pixels, and every pixel then joins its voxel's label.
    step = -(-len(pixels) // config.supervoxels.max_points)
    sample = np.arange(0, len(pixels), step)
    # Compiled row gathers (``kernels.rows_at``: numpy's fancy indexing, same values).
    points = kernels.rows_at(flat_points, pixels[sample])
    keys = all_keys[sample]
    if normals_camera is None:
        camera_normals = organised_normals_at(frame.depth_m, frame.K, pixels[sample], config)
    else:
        camera_normals = kernels.rows_at(normals_camera.reshape(-1, 3), pixels[sample])
    pixel_normals = camera_normals.astype(np.float64) @ rotation.T
    colours = kernels.rows_at(frame.rgb.reshape(-1, 3), pixels[sample]).astype(np.float64)
    colours /= 255.0

    # 1. Voxels.
    voxels = _VoxelIndex(keys, int(np.prod(dims)))
    voxel_keys, voxel_of_point = voxels.keys, voxels.of_keys
    n_voxels = len(voxel_keys)
    voxel_count = np.bincount(voxel_of_point, minlength=n_voxels).astype(np.float64)
    voxel_centre = _group_mean(voxel_of_point, points, n_voxels, voxel_count)
    voxel_normal = _normalise(_group_sum(voxel_of_point, pixel_normals, n_voxels))
    voxel_colour = _group_mean(voxel_of_point, colours, n_voxels, voxel_count)

    # 2. Voxel adjacency (26-neighbourhood) by looking up the neighbours' keys.
    strides = np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)
    edge_a, edge_b = [], []
    for offset in _FORWARD_OFFSETS:
        found = voxels.find(voxel_keys + int(offset @ strides))
        hit = found >= 0
        edge_a.append(np.flatnonzero(hit))
        edge_b.append(found[hit])
    voxel_edges = np.stack([np.concatenate(edge_a), np.concatenate(edge_b)], axis=1)

    # 3. Seeds: per occupied seed cell, the voxel nearest the cell centre.
    seed_size = config.supervoxels.seed_size_m
    seed_cells = np.floor(voxel_centre / seed_size).astype(np.int64)
    seed_cells -= seed_cells.min(axis=0) - 1
    seed_dims = seed_cells.max(axis=0) + 2
    seed_strides = np.array([seed_dims[1] * seed_dims[2], seed_dims[2], 1], dtype=np.int64)
    seed_keys_of_voxel = seed_cells @ seed_strides
    to_centre = np.linalg.norm(
        voxel_centre - (np.floor(voxel_centre / seed_size) + 0.5) * seed_size, axis=1
    )
    order = np.lexsort((to_centre, seed_keys_of_voxel))
    first = np.ones(n_voxels, dtype=bool)
    first[1:] = seed_keys_of_voxel[order[1:]] != seed_keys_of_voxel[order[:-1]]
    seed_voxels = order[first]
    seed_keys = seed_keys_of_voxel[seed_voxels]  # sorted (lexsort's primary key)
    n_seeds = len(seed_voxels)

    # Candidate seeds of each voxel: those of the 27 seed cells around its own.
    neighbour_offsets = np.array(
        [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)],
        dtype=np.int64,
    )
    wanted = seed_keys_of_voxel[:, None] + (neighbour_offsets @ seed_strides)[None, :]
    n_seed_cells = int(np.prod(seed_dims))
    if n_seed_cells <= _DENSE_CELLS_MAX:
        # A dense cell -> seed table (the seed grid is ~50 times coarser than the voxel grid):
        # one gather instead of a binary search for each of the V x 27 keys.
        seed_table = np.full(n_seed_cells, -1, dtype=np.int64)
        seed_table[seed_keys] = np.arange(n_seeds)
        candidates = seed_table[wanted]  # (V, 27)
    else:
        found = np.minimum(np.searchsorted(seed_keys, wanted), n_seeds - 1)
        candidates = np.where(seed_keys[found] == wanted, found, -1)  # (V, 27)
    has = candidates >= 0
    safe = np.where(has, candidates, 0)

    # 4. k-means rounds in VCCS's distance (compiled: the (V, 27) distances in one pass).
    assignment = kernels.supervoxel_rounds(
        voxel_centre,
        voxel_normal,
        voxel_colour,
        voxel_count,
        safe,
        has,
        voxel_centre[seed_voxels],
        voxel_normal[seed_voxels],
        voxel_colour[seed_voxels],
        config.supervoxels.iterations,
        seed_size,
        config.supervoxels.normal_weight,
        config.supervoxels.colour_weight,
    )

    # 5. Connected parts of each supervoxel (26-connectivity), then crumbs merged.
    same = assignment[voxel_edges[:, 0]] == assignment[voxel_edges[:, 1]]
    graph = coo_matrix(
        (np.ones(int(same.sum())), (voxel_edges[same, 0], voxel_edges[same, 1])),
        shape=(n_voxels, n_voxels),
    )
    _, parts = connected_components(graph, directed=False)
    parts = _merge_crumbs(parts, voxel_count * step, voxel_edges, config.supervoxels.min_points)
    _, supervoxel_of_voxel = np.unique(parts, return_inverse=True)
    n_supervoxels = int(supervoxel_of_voxel.max()) + 1

    # Per-supervoxel statistics from the (sampled) pixels.
    supervoxel_of_point = supervoxel_of_voxel[voxel_of_point]
    counts = np.bincount(supervoxel_of_point, minlength=n_supervoxels)
    centres = _group_mean(supervoxel_of_point, points, n_supervoxels, counts)
    mean_normals = _normalise(_group_sum(supervoxel_of_point, pixel_normals, n_supervoxels))
    if config.supervoxels.dominant_face_deg > 0:
        centres, normals = _dominant_faces(
            supervoxel_of_point, points, pixel_normals, mean_normals, counts, config
        )
    else:
        normals = _plane_normals(supervoxel_of_point, points, centres, counts, mean_normals)
    towards_camera = np.einsum("mc,mc->m", normals, camera_centre - centres) >= 0
    normals[~towards_camera] *= -1.0
    mean_colours = _group_mean(supervoxel_of_point, colours, n_supervoxels, counts)

    # Every kept pixel takes the label of its voxel (pixels of voxels that no sampled pixel
    # reached, a handful at most, stay unlabelled).
    if step == 1:
        supervoxel_of_pixel = supervoxel_of_point
    elif voxels.table is not None:  # compiled (``kernels``): lookup and label in one pass
        supervoxel_of_pixel = kernels.labels_of_keys(
            voxels.table, all_keys, supervoxel_of_voxel.astype(np.int64, copy=False)
        )
    else:
        position = voxels.find(all_keys)
        supervoxel_of_pixel = np.where(position >= 0, supervoxel_of_voxel[position], -1)
    sizes = np.bincount(supervoxel_of_pixel[supervoxel_of_pixel >= 0], minlength=n_supervoxels)
    labels_image.reshape(-1)[pixels] = supervoxel_of_pixel
    first, second = supervoxel_of_voxel[voxel_edges[:, 0]], supervoxel_of_voxel[voxel_edges[:, 1]]
    between = first != second
    first, second = first[between], second[between]
    # Distinct (low, high) pairs in lexicographic order, via one int64 key per pair: a 1-D
    # unique is several times faster than np.unique(axis=0) on rows, same result.
    key = np.unique(np.minimum(first, second) * n_supervoxels + np.maximum(first, second))
    pair = np.stack([key // n_supervoxels, key % n_supervoxels], axis=1)
    return Supervoxels(
        labels=labels_image,
        centres=centres,
        normals=normals,
        colours=mean_colours,
        sizes=sizes,
        adjacency=pair.astype(np.int64),
    )


#: Above this many cells in the voxel grid's bounding box, voxels are indexed by sorting their
#: keys instead of through a dense cell table (16 MB of int32 at this size; real 640x480 frames
#: need far fewer cells).
_DENSE_CELLS_MAX = 4_000_000


class _VoxelIndex:
    """The distinct voxel keys among some points, and lookups of keys among them.

    ``keys`` (V,) int64: the sorted distinct keys of the (N,) int64 point keys (each in
    [0, ``n_cells``)); ``of_keys`` (N,) int64: each point's voxel (position in ``keys``), as
    ``np.unique(point_keys, return_inverse=True)`` gives them. ``find(targets)``: the voxel of
    each key in [0, ``n_cells``), -1 where no point has that key.

    When the grid's bounding box is small enough (``_DENSE_CELLS_MAX``), a dense table from
    cell to voxel replaces the sort and the binary searches: lookups become one gather, several
    times faster on a frame's kept pixels and neighbour keys.
    """

    def __init__(self, point_keys: np.ndarray, n_cells: int) -> None:
        if n_cells > _DENSE_CELLS_MAX:
            self.keys, self.of_keys = np.unique(point_keys, return_inverse=True)
            self._table = None
            return
        occupied = np.zeros(n_cells, dtype=bool)
        occupied[point_keys] = True
        self.keys = np.flatnonzero(occupied)
        self._table = np.full(n_cells, -1, dtype=np.int32)
        self._table[self.keys] = np.arange(len(self.keys), dtype=np.int32)
        self.of_keys = self._table[point_keys].astype(np.int64)

    @property
    def table(self) -> np.ndarray | None:
        """The dense (n_cells,) int32 cell -> voxel table (-1 = empty), None for sparse grids."""
        return self._table

    def find(self, targets: np.ndarray) -> np.ndarray:
        """(T,) int64 voxel of each of the (T,) int64 keys ``targets``, -1 where none."""
        if self._table is not None:
            return self._table[targets].astype(np.int64)
        found = np.minimum(np.searchsorted(self.keys, targets), len(self.keys) - 1)
        return np.where(self.keys[found] == targets, found, -1)


def _empty(labels: np.ndarray) -> Supervoxels:
    """Supervoxels of a frame with nothing to segment."""
    return Supervoxels(
        labels=labels,
        centres=np.zeros((0, 3)),
        normals=np.zeros((0, 3)),
        colours=np.zeros((0, 3)),
        sizes=np.zeros(0, dtype=np.int64),
        adjacency=np.zeros((0, 2), dtype=np.int64),
    )


def _group_sum(groups: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """(count, C) sums of (N, C) ``values`` per group id (N,) (compiled: one pass, the same
    sums as a bincount per column)."""
    return kernels.group_sums(groups, np.asarray(values, dtype=np.float64), int(count))


def _group_mean(
    groups: np.ndarray, values: np.ndarray, count: int, sizes: np.ndarray
) -> np.ndarray:
    """(count, C) means of (N, C) ``values`` per group id, given the group sizes (count,)."""
    return _group_sum(groups, values, count) / np.maximum(sizes, 1)[:, None]


def _normalise(vectors: np.ndarray) -> np.ndarray:
    """Rows of (N, 3) scaled to unit length (zero rows stay zero)."""
    norms = np.linalg.norm(vectors, axis=1, keepdims=True)
    return np.divide(vectors, norms, out=np.zeros_like(vectors), where=norms > 1e-12)


def _merge_crumbs(
    parts: np.ndarray, voxel_count: np.ndarray, edges: np.ndarray, min_points: int
) -> np.ndarray:
    """Relabel parts (V,) with fewer than ``min_points`` points into the adjacent part they
    share the most voxel contacts with (one pass; isolated crumbs stay on their own)."""
    n_parts = int(parts.max()) + 1
    part_size = np.bincount(parts, weights=voxel_count, minlength=n_parts)
    small = part_size < min_points
    if not small.any() or len(edges) == 0:
        return parts
    a, b = parts[edges[:, 0]], parts[edges[:, 1]]
    cross = a != b
    a, b = a[cross], b[cross]
    src = np.concatenate([a, b])
    dst = np.concatenate([b, a])
    pick = small[src] & ~small[dst]
    if not pick.any():
        return parts
    src, dst = src[pick], dst[pick]
    # Count contacts per (src, dst) and keep the best dst for each small src.
    key = src * n_parts + dst
    unique_keys, counts = np.unique(key, return_counts=True)
    pair_src, pair_dst = unique_keys // n_parts, unique_keys % n_parts
    order = np.lexsort((-counts, pair_src))
    first = np.ones(len(order), dtype=bool)
    first[1:] = pair_src[order[1:]] != pair_src[order[:-1]]
    target = np.arange(n_parts)
    target[pair_src[order[first]]] = pair_dst[order[first]]
    return target[parts]


def _plane_normals(
    groups: np.ndarray,
    points: np.ndarray,
    centres: np.ndarray,
    sizes: np.ndarray,
    fallback: np.ndarray,
) -> np.ndarray:
    """(M, 3) least-squares plane normals of the points of each group (smallest principal axis
    of the covariance); groups with fewer than 6 points, or whose two smallest spreads are
    alike (a line or a blob: no plane), use ``fallback`` when it is known."""
    count = len(centres)
    # Column by column (contiguous (N,) arrays rather than strided columns of (N, 3)): the
    # same differences and products as points - centres[groups].
    local = [points[:, axis] - centres[groups, axis] for axis in range(3)]
    covariance = np.empty((count, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            value = np.bincount(groups, weights=local[i] * local[j], minlength=count)
            covariance[:, i, j] = value
            covariance[:, j, i] = value
    covariance /= np.maximum(sizes, 1)[:, None, None]
    return _normals_of_covariances(covariance, sizes, fallback)


def _normals_of_covariances(
    covariance: np.ndarray, sizes: np.ndarray, fallback: np.ndarray
) -> np.ndarray:
    """(M, 3) plane normals from (M, 3, 3) point covariances of groups of (M,) sizes: the
    smallest principal axis; ``fallback`` (M, 3) where it is known and the plane is not."""
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    normals = eigenvectors[:, :, 0]
    # The plane is defined only when the second spread clearly exceeds the thickness.
    degenerate = (sizes < 6) | (eigenvalues[:, 1] < 4.0 * np.maximum(eigenvalues[:, 0], 1e-12))
    degenerate &= np.linalg.norm(fallback, axis=1) > 0
    normals[degenerate] = fallback[degenerate]
    return normals


def _dominant_faces(
    groups: np.ndarray,
    points: np.ndarray,
    pixel_normals: np.ndarray,
    mean_normals: np.ndarray,
    sizes: np.ndarray,
    config: PerceptionConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) centres and (M, 3) plane normals of the dominant face of each group.

    A supervoxel that straddles a crease mixes two faces; its least-squares plane lies between
    them and its edges to both look concave, so it ends up alone as a sliver segment. The
    dominant face is found from the pixel normals: twice, keep the pixels whose normal is within
    ``supervoxels.dominant_face_deg`` of the group's mean normal and re-average; the centre and
    the plane fit then use those pixels only (all pixels when fewer than 6 remain).
    """
    # Compiled (``kernels``): the selections and moments in a few passes over the pixels.
    centres, covariance, sizes, normal = kernels.dominant_face_moments(
        groups,
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(pixel_normals, dtype=np.float64),
        np.ascontiguousarray(mean_normals, dtype=np.float64),
        float(np.cos(np.radians(config.supervoxels.dominant_face_deg))),
    )
    return centres, _normals_of_covariances(covariance, sizes, normal)
