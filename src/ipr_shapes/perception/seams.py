"""Cutting segments along straight colour seams where the geometry is silent.

Packed boxes of one height show coplanar tops: the convexity graph (``segmentation``) sees one
flat surface, and a real depth sensor shows no groove between them. What tells them apart is in
the colour image: the boxes' outlines are straight lines that cross the merged segment from one
side of its outline to the other. A seam here is such a line, with five checks that keep an
object's own lines whole:

- **straight and long**: edge pixels (non-maximum-suppressed colour gradient above
  ``seams.edge_factor`` times the frame's median, and their faint continuations above half
  that, ``seams.hysteresis``) vote in a Hough transform for lines along
  their own edge direction; a candidate is the longest stretch of the line inside the segment
  whose pixels lie on edges at least ``seams.coverage`` of the time, and it must be at least
  ``seams.min_length_m`` long in 3D;
- **geometry silent**: the surfaces on both sides of it have the same normal (within
  ``seams.max_normal_deg``) and no step (``seams.max_step_m``): a colour edge along a crease is
  an object's own edge, a step is already the graph's to cut;
- **straight in 3D**: its points lie within ``seams.max_bend_m`` of one 3D line (a straight
  image line on a ball, a can or a bottle is a curve in 3D);
- **a cut**: removing it splits the segment into pieces of at least ``seams.min_area_m2`` and
  ``seams.min_width_m`` across;
- **flat and repeated**: once the segment is cut, the strips on both sides of each seam must
  lie on its plane (a crease shows over a strip, not always in the side bands), and the seam
  must lie midway between a bound on each side (a parallel seam on the same surface, or the
  segment's outline), within ``seams.strip_tolerance``, or at one spacing with two parallel
  seams beside it (``seams.rows_of_three``: a row's end strips to the outline are off by side
  faces and occluders): packed boxes of one size repeat at one spacing, a printed border (a
  box's end panel) lies where the print puts it. Cuts that fail are undone;
- **or a shadow line where packed boxes are seen**: in a frame where the strip tests kept a
  cut, a flat seam that is a dark line darker than both sides in every channel alike (the gap
  between two touching boxes, which the light does not reach) is kept whatever its strips
  measure: a printed border is a step between two colours, coloured ink darkens some channels
  more than others; black or grey ink is told apart only by the frame (``seams.shadow_lines``);
- **supported when alone**: a seam midway between the outline on both sides (two boxes, or
  one box with a printed line through its middle) is kept only where it meets a seam that
  lies between seams (a grid of boxes) or its strips have the size of a flat rectangular
  face seen elsewhere in the frame (packed boxes repeat; ``seams.pair_needs_grid``,
  ``seams.pair_sizes``);
- **decided once per unmoved surface**: in frames after the first, a segment that is an
  unmoved segment of the previous frame (``seams.settled``,
  ``segmentation.settled_segments``) is not searched: the previous frame decided its seams;
- **planes across the other faces**: a seam between two boxes goes on as a plane (its 3D line
  and the surface normal) across the boxes' other faces, where the colour edge bends over a
  crease or fades; a piece facing several pieces across a seam, with kept seams between them,
  is cut along their planes when its parts are as wide as the pieces they face and its own
  seams do not lie between the planes (``seams.extend_planes``).

The best seam (most edge pixels) is cut and both pieces are searched again, up to
``seams.max_cuts`` cuts per segment; every segment is searched before any cut is judged, so
that the frame's faces are known. Text and logos do not qualify: their edges are short or do
not line up across the segment. What no check here tells apart: a printed line through the
middle of one box from a seam between two boxes of half its size when no box of that size is
seen alone (docs/experiments/2026-11-26-colour-seams.md, 2026-11-26-packed-boxes.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull

from ipr_shapes.perception import kernels
from ipr_shapes.perception.config import PerceptionConfig

#: Hough resolution: line directions per half turn, and the candidates tried per search.
_DIRECTIONS = 180
_CANDIDATES = 40
#: The compiled screen of a part's candidate seams (``_best_cut``) drops a candidate only this far
#: (relative length, degrees) beyond the exact checks' thresholds: far above the rounding of
#: its float64 norms against numpy's float32 and BLAS ones, so that it drops only what those
#: checks drop.
_SCREEN_MARGIN = 1e-6
#: The Hough's line directions' cosines and sines.
_COS = np.cos(np.linspace(0.0, np.pi, _DIRECTIONS, endpoint=False))
_SIN = np.sin(np.linspace(0.0, np.pi, _DIRECTIONS, endpoint=False))
#: An edge pixel votes for line directions within this of its own edge direction (deg).
_VOTE_SPREAD_DEG = 10.0
#: Pixels either side of a seam whose normals and points are compared (near, far; px).
_SIDE_BAND_PX = (2, 10)
#: Margin (px) around a segment's bounding box, enough for the side bands.
_MARGIN_PX = 12
#: Seams within this of one direction (deg) are parallel: neighbours in one row of boxes.
_PARALLEL_DEG = 10.0
#: How a seam is bounded (``_repeated``).
_UNBOUNDED, _BY_OUTLINE, _BY_SEAM = 0, 1, 2
#: Most points of a face whose size is measured (``_face_size``): larger faces are subsampled.
_FACE_POINTS = 4096
#: Most points of a segment's cloud for the strip tests (``_flat_strips``, ``_repeated``).
_CLOUD_POINTS = 4096
#: A segment's flat face (``_has_flat_face``) is found among this many of its pixels, and its
#: normal among this many of theirs.
_GATE_POINTS = 1024
_FACE_CANDIDATES = 32
#: The edge noise scale's sample: every this many rows and columns (``_edge_noise``).
_NOISE_STEP_PX = 16
#: How far (px) the colour gradient reads around a pixel: the Gaussian's 4 and Sobel's 1.
_GRADIENT_REACH_PX = 5
#: A gradient's 45 degree sector (``_thin``) is read from its components unless its angle lies
#: within this (rad) of a sector's boundary (22.5 or 67.5 deg from an axis), where the float32
#: arctangent is measured: far above that arctangent's rounding (about 1e-7 rad) and the
#: float32 division by 45 degrees, far below the share of gradients it sends to be measured.
_SECTOR_MARGIN_RAD = 1e-4
_SECTOR_TANGENTS = np.tan(
    np.radians([22.5, 22.5, 67.5, 67.5]) + np.array([-1.0, 1.0, -1.0, 1.0]) * _SECTOR_MARGIN_RAD
)
#: Row and column offsets of a pixel's 3 x 3 neighbourhood.
_NEIGHBOURS = np.mgrid[-1:2, -1:2].reshape(2, -1)
#: The colour gradient's smoothing: scipy's Gaussian of sigma 1 px (truncated at 4 sigma) as
#: weights, its response to a unit impulse.
_GAUSSIAN = ndimage.gaussian_filter1d(np.eye(1, 9, 4)[0], 1.0, truncate=4.0, mode="constant")


@dataclass(frozen=True)
class _Seam:
    """One cut: its pixels in the crop (in order along it), its image line's unit normal
    (cos_a, sin_a), and in 3D (world frame, m) its middle, unit direction, the unit direction
    across it in the surface, the surface's unit normal, and half its length."""

    rows: np.ndarray
    cols: np.ndarray
    cos_a: float
    sin_a: float
    middle: np.ndarray
    direction: np.ndarray
    across: np.ndarray
    normal: np.ndarray
    half_length_m: float
    shadow: bool = False


class Normals:
    """World unit normals (H, W, 3) float32 of a frame's labelled pixels with depth, computed
    on demand: the pass reads them in a sample of each segment (``_has_flat_face``), then in
    the searched segments, and in every segment only when a strip test asks for the frame's
    face sizes (``_pairs_by_size``); most tabletop segments are never searched.

    Args:
        compute: maps (P,) flat pixel indices to their (P, 3) float32 normals (rows of 0
            where unknown); each pixel's normal depends on its own neighbours only, so the
            values do not depend on which pixels are asked together.
        labelled: (H, W) bool, the pixels that have a normal at all (labelled, with depth);
            0 elsewhere.
    """

    def __init__(self, compute, labelled: np.ndarray) -> None:
        self._compute = compute
        self._labelled = labelled
        self._values = np.zeros((*labelled.shape, 3), dtype=np.float32)
        self._done = np.zeros(labelled.shape, dtype=bool)

    @classmethod
    def of(cls, normals: np.ndarray) -> Normals:
        """Already computed (H, W, 3) normals."""
        known = cls(None, np.ones(normals.shape[:2], dtype=bool))
        known._values = normals
        known._done[:] = True
        return known

    def at(self, flat: np.ndarray) -> np.ndarray:
        """(P, 3) normals of the (P,) flat pixel indices."""
        self._fill(flat)
        return self._values.reshape(-1, 3)[flat]

    def within(self, crop: tuple[slice, slice], mask: np.ndarray) -> np.ndarray:
        """(h, w, 3) normals of ``crop`` filled at least at ``mask`` ((h, w) bool)."""
        rows, cols = np.nonzero(mask)
        self._fill((rows + crop[0].start) * self._labelled.shape[1] + cols + crop[1].start)
        return self._values[crop]

    def everywhere(self) -> np.ndarray:
        """The (H, W, 3) normals of every pixel."""
        if not self._done.all():
            self._fill(np.flatnonzero(~self._done))
        return self._values

    def _fill(self, flat: np.ndarray) -> None:
        flat = flat[~self._done.reshape(-1)[flat]]
        if len(flat) == 0:
            return
        self._done.reshape(-1)[flat] = True
        flat = flat[self._labelled.reshape(-1)[flat]]
        if len(flat):
            self._values.reshape(-1, 3)[flat] = self._compute(flat)


def cut_colour_seams(
    labels: np.ndarray,
    rgb: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray | Normals,
    depth_m: np.ndarray,
    K: np.ndarray,
    config: PerceptionConfig,
    settled: np.ndarray | None = None,
) -> np.ndarray:
    """Labels (H, W) int32 with segments cut along colour seams (module doc); new pieces take
    new ids above the largest one (renumbering is the caller's).

    Args:
        labels: (H, W) int segment labels, 0 = none; rgb: (H, W, 3) uint8;
        points: (H, W, 3) world points (m); normals: (H, W, 3) unit normals in the world frame,
            0 where unknown, or ``Normals`` that computes them where the pass reads; depth_m: (H, W) depth (m, 0 = none); K: (3, 3) intrinsics.
        settled: (labels.max() + 1,) bool, segments not searched (kept whole: unmoved since
            the previous frame, which decided their seams; ``segmentation.settled_segments``),
            or None (all searched). They still count as faces for ``seams.pair_sizes``.
    """
    seams = config.seams
    out = labels.astype(np.int32, copy=True)
    segment_pixels = labels > 0
    if not seams.enabled or not segment_pixels.any():
        return out
    if not isinstance(normals, Normals):
        normals = Normals.of(normals)
    focal_px = float(K[0, 0])
    # The segments to search: not settled, and with room for two pieces of the smallest area
    # (``_search_segment``'s own first test). A frame with none needs no edges at all.
    segments = []
    for segment, box in enumerate(ndimage.find_objects(labels), start=1):
        if box is None:
            continue
        top = max(box[0].start - _MARGIN_PX, 0)
        bottom = min(box[0].stop + _MARGIN_PX, labels.shape[0])
        left = max(box[1].start - _MARGIN_PX, 0)
        right = min(box[1].stop + _MARGIN_PX, labels.shape[1])
        crop = (slice(top, bottom), slice(left, right))
        mask = labels[crop] == segment
        search = not (settled is not None and segment < len(settled) and settled[segment])
        if search and not _has_area(mask, depth_m[crop], focal_px, 2 * seams.min_area_m2):
            search = False
        segments.append((crop, mask, search))
    if seams.flat_face_gate:
        # Every gate's sample of normals in one request (one pass of the normals' kernel).
        samples = [_gate_sample(mask, crop, labels.shape[1]) if search else None
                   for crop, mask, search in segments]  # fmt: skip
        if any(sample is not None for sample in samples):
            normals.at(np.concatenate([sample for sample in samples if sample is not None]))
        segments = [
            (crop, mask, search and _has_flat_face(mask, crop, points, normals, config, sample))
            for (crop, mask, search), sample in zip(segments, samples, strict=True)
        ]
    if not any(search for *_, search in segments):
        return out
    # And the searched segments' normals in one request.
    normals.at(np.concatenate([_gate_sample(mask, crop, labels.shape[1], everything=True)
                               for crop, mask, search in segments if search]))  # fmt: skip
    # The gradient where edges are read: the searched segments' crops and a 1 px ring (the
    # edges' thinning reads a pixel's neighbours), 0 elsewhere; or the frame's.
    magnitude, gx, gy, whole = _colour_gradient_in(
        rgb, [crop for crop, _, search in segments if search]
    )
    # The frame's own scale, over every pixel with depth: not over the segments, whose share
    # of smooth surfaces depends on what the earlier steps removed (a bin's walls). Without the
    # frame's gradient, from a sample of the frame.
    if whole:
        measured = depth_m > 0
        noise = _masked_median(magnitude, measured if measured.any() else segment_pixels)
    else:
        noise = _edge_noise(rgb, depth_m, segment_pixels)
    # The edges are read only in the searched segments' crops: found in the box around them
    # and a 1 px ring (the thinning reads a pixel's neighbours; the faint edges lie within 3 px
    # of a searched segment, at least ``_MARGIN_PX`` inside its crop unless at the frame's
    # border), the same edges there as the frame's.
    crops = [crop for crop, _, search in segments if search]
    box = (
        slice(max(min(crop[0].start for crop in crops) - 1, 0),
              min(max(crop[0].stop for crop in crops) + 1, labels.shape[0])),
        slice(max(min(crop[1].start for crop in crops) - 1, 0),
              min(max(crop[1].stop for crop in crops) + 1, labels.shape[1])),
    )  # fmt: skip
    magnitude, gx, gy = (np.ascontiguousarray(array[box]) for array in (magnitude, gx, gy))
    strong = np.flatnonzero(magnitude > seams.edge_factor * max(noise, 1e-6))
    # The gradient's direction is read at edge pixels only (the search's votes), and its
    # 45 degree sector for the thinning: that from the components, measured only near a
    # sector's boundary (``_thin``), the direction once the edges are known.
    direction = np.zeros(magnitude.shape, dtype=magnitude.dtype)
    edges = _thin(magnitude, direction, strong, gx, gy)
    # With the faint stretches that continue a strong edge (Canny's hysteresis): the edge
    # between two boxes of one colour fades along its length.
    if seams.hysteresis:
        # Only where seams are searched: the searched segments and a ring around them.
        searched_pixels = np.zeros(magnitude.shape, dtype=bool)
        for crop, mask, search in segments:
            if search:
                searched_pixels[_within(crop, box)] |= mask
        near = kernels.dilate_diamond(searched_pixels, 3)  # binary_dilation, iterations=3
        low = 0.5 * seams.edge_factor * max(noise, 1e-6)
        edges = _linked_edges(magnitude, gx, gy, direction, edges, low, near)
    at = np.flatnonzero(edges)
    direction.flat[at] = np.arctan2(gy.flat[at], gx.flat[at])
    searched = []
    for crop, mask, search in segments:
        if not search:
            # Kept whole; still a face for the pairs' sizes (``_pairs_by_size``).
            searched.append((crop, mask, mask.astype(np.int32), [], np.empty((0, 3)), []))
            continue
        cut, found = _search_segment(mask, edges[_within(crop, box)],
                                     direction[_within(crop, box)], points[crop],
                                     normals.within(crop, mask), depth_m[crop], focal_px,
                                     config)  # fmt: skip
        # The segment's points with depth, and which seams have flat strips: measured once,
        # asked by every strip test below.
        cloud = np.empty((0, 3))
        if found:
            cloud = points[crop][mask & (depth_m[crop] > 0)].astype(np.float64)
            # Every k-th point of a large segment: the strip tests take medians and 98th
            # percentiles of it, which move by far less than their tolerances.
            cloud = cloud[:: -(-len(cloud) // _CLOUD_POINTS)]
        flat = [_flat_strips(seam, cloud, config) for seam in found]
        searched.append((crop, mask, cut, found, cloud, flat))
    asked = [_Sizes() for _ in searched]
    with_depth = depth_m > 0
    decided = [_decide(cut, found, cloud, flat, config, sizes, points[crop], with_depth[crop])
               for (crop, _, cut, found, cloud, flat), sizes
               in zip(searched, asked, strict=True)]  # fmt: skip
    if seams.pair_needs_grid and seams.pair_sizes:
        decided = _pairs_by_size(searched, decided, asked, points, normals, depth_m,
                                 config)  # fmt: skip
    if seams.shadow_lines:
        decided = _with_shadow_lines(searched, decided, rgb, points, normals, depth_m, config)
    next_id = int(labels.max()) + 1
    for (crop, *_), pieces in zip(searched, decided, strict=True):
        view = out[crop]  # writes go to out
        for piece in range(2, int(pieces.max()) + 1):
            view[pieces == piece] = next_id
            next_id += 1
    return out


def _within(crop: tuple[slice, slice], box: tuple[slice, slice]) -> tuple[slice, slice]:
    """``crop`` of the frame in the coordinates of ``box`` (a box of the frame holding it)."""
    return (
        slice(crop[0].start - box[0].start, crop[0].stop - box[0].start),
        slice(crop[1].start - box[1].start, crop[1].stop - box[1].start),
    )


def _decide(
    cut: np.ndarray,
    found: list[_Seam],
    cloud: np.ndarray,
    flat: list[bool],
    config: PerceptionConfig,
    sizes: _Sizes | None = None,
    points: np.ndarray | None = None,
    measured: np.ndarray | None = None,
) -> np.ndarray:
    """(h, w) int pieces of one segment's crop with the cuts that fail the strip tests undone
    (``_unrepeated``: ``cloud``, ``flat`` and ``sizes`` see there); with
    ``seams.extend_planes``, ``points`` ((h, w, 3) world, m) and ``measured`` ((h, w) bool,
    pixels with depth) of the crop, a piece that faces several pieces across an undone or a
    kept seam is cut along the kept seams' planes between them (``_cut_by_planes``)."""
    if config.seams.strip_tolerance >= 1.0:
        return cut
    pieces = cut
    dropped = _unrepeated(found, cloud, flat, config, sizes)
    kept = [seam for seam in found if not any(seam is other for other in dropped)]
    if not config.seams.extend_planes:
        points = measured = None
    for seam in dropped:
        pieces = _undo(pieces, seam, kept, points, measured, config)
    # And across the kept seams: a row of boxes cut apart on one side of a seam goes on
    # across it (the second row of a grid, whose seams bend over the boxes' front faces).
    if points is not None and measured is not None:
        for seam in kept:
            others = [other for other in kept if other is not seam]
            if others:
                pieces = _cut_by_planes(pieces, seam, others, points, measured, config)
    return pieces


class _Sizes:
    """The face sizes (longer, shorter; m) of boxes seen elsewhere in the frame ((M, 2), or an
    iterable of such arrays read only as far as needed: ``_FacesElsewhere``) and the
    (P, 2, 2) sizes of the two strips of each lone seam elsewhere (``_lone_strips``), made by
    ``make`` on first use (None: no sizes), and whether they were asked for: a segment whose
    strip tests never asked is decided without them (``_pairs_by_size``)."""

    def __init__(self, make=None) -> None:
        self._make = make
        self._sizes: tuple[np.ndarray, np.ndarray] | None = None
        self.asked = False

    def get(self) -> tuple[np.ndarray, np.ndarray] | None:
        self.asked = True
        if self._make is not None and self._sizes is None:
            self._sizes = self._make()
        return self._sizes


def _pairs_by_size(
    searched: list,
    decided: list[np.ndarray],
    asked: list[_Sizes],
    points: np.ndarray,
    normals: Normals,
    depth_m: np.ndarray,
    config: PerceptionConfig,
) -> list[np.ndarray]:
    """``decided`` with each segment's strip tests run again, a lone midway seam now also kept
    when its strips have the size of a box seen elsewhere in the frame (another segment or
    piece, ``_face_size``, or the strips of a lone seam of another segment, ``_lone_strips``):
    packed boxes repeat across the frame, a printed line through one box's middle makes halves
    that nothing else in the frame matches. Only segments whose first tests asked for sizes
    (``asked``) are run again (the others' tests go the same way), and the frame's faces are
    measured segment by segment only until both strips of the seam asking have a match
    (``_FrameFaces``)."""
    pairs: list[tuple[int, tuple[tuple[float, float], tuple[float, float]]]] = []
    done = []
    faces = _FrameFaces(searched, decided, points, normals, depth_m, config)
    result = []
    for index, ((crop, _, cut, found, cloud, flat), pieces) in enumerate(
        zip(searched, decided, strict=True)
    ):
        if len(found) == 0 or not asked[index].asked:
            result.append(pieces)
            continue

        def others(index: int = index) -> tuple[_FacesElsewhere, np.ndarray]:
            if not done:  # the lone seams' strips of every segment, once
                done.append(True)
                for owner, (_, _, _, seams_of, cloud_of, flat_of) in enumerate(searched):
                    pairs.extend((owner, pair) for pair in _lone_strips(seams_of, cloud_of,
                                                                         flat_of, config))  # fmt: skip
            pairs_elsewhere = [pair for owner, pair in pairs if owner != index]
            return _FacesElsewhere(faces, index), np.array(pairs_elsewhere).reshape(-1, 2, 2)

        result.append(_decide(cut, found, cloud, flat, config, _Sizes(others), points[crop],
                              depth_m[crop] > 0))  # fmt: skip
    return result


class _FrameFaces:
    """The face sizes (``_face_size``; (longer, shorter), m) of every piece of every segment of
    the frame (``searched``, as first ``decided``), each measured when first asked and kept: a
    strip test stops asking once both strips have a match (``_covered``), and skips a piece
    whose points span less than any face it needs (``reach``), so that most of the frame's
    faces are never measured. The normals are computed only in the segments measured."""

    def __init__(self, searched, decided, points, normals, depth_m, config) -> None:
        self._searched, self._decided = searched, decided
        self._points, self._normals, self._depth_m, self._config = points, normals, depth_m, config
        self._reach: dict[int, np.ndarray] = {}
        self._inputs: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._sizes: dict[tuple[int, int], tuple[float, float] | None] = {}

    def __len__(self) -> int:
        return len(self._searched)

    def reach(self, index: int) -> np.ndarray:
        """(k + 1,) upper bounds (m) on the longer extent of the face of each piece 1..k of
        segment ``index`` (entry 0 unused): the diagonal of the box around the piece's points
        with depth (a face's extents are percentiles of some of those points' projections on
        a line, within their range). Cheaper than the faces, and it proves that no face of a
        small piece matches a long strip."""
        if index not in self._reach:
            crop = self._searched[index][0]
            pieces = self._decided[index]
            spans = kernels.piece_spans(self._points[crop], pieces, self._depth_m[crop] > 0,
                                        int(pieces.max()))  # fmt: skip
            self._reach[index] = np.sqrt(np.einsum("ij,ij->i", spans, spans))
        return self._reach[index]

    def size(self, index: int, piece: int) -> tuple[float, float] | None:
        """The face size of piece ``piece`` (1..k) of segment ``index``, or None."""
        if (index, piece) not in self._sizes:
            if index not in self._inputs:
                crop, mask = self._searched[index][:2]
                normals = np.ascontiguousarray(self._normals.within(crop, mask))
                measured = (self._depth_m[crop] > 0) & _known(normals)
                # Contiguous once: each piece reads it flat (a crop's reshape copies it).
                self._inputs[index] = (measured, np.ascontiguousarray(self._points[crop]), normals)
            measured, points, normals = self._inputs[index]
            self._sizes[index, piece] = _face_size(self._decided[index] == piece, measured, points,
                                                   normals, self._config)  # fmt: skip
        return self._sizes[index, piece]

    def of(self, index: int) -> np.ndarray:
        """The (k, 2) face sizes of segment ``index``'s pieces."""
        sizes = [self.size(index, piece) for piece in range(1, int(self._decided[index].max()) + 1)]
        return np.array([size for size in sizes if size is not None]).reshape(-1, 2)


class _FacesElsewhere:
    """The ``faces`` of every segment but ``owner``: an iterable of (k, 2) arrays, segment by
    segment, measured as they are read; or, by ``reaching``, only the pieces that may have a
    face of a given length."""

    def __init__(self, faces: _FrameFaces, owner: int) -> None:
        self._faces, self._owner = faces, owner

    def __iter__(self):
        return (self._faces.of(index) for index in range(len(self._faces)) if index != self._owner)

    def reaching(self, least):
        """(1, 2) face sizes of the pieces whose ``_FrameFaces.reach`` is at least ``least()``
        (m, asked again before each piece: it grows as strips find their match), in the
        order of ``__iter__``; the others' faces are all shorter, and are not measured."""
        for index in range(len(self._faces)):
            if index == self._owner:
                continue
            for piece, reach in enumerate(self._faces.reach(index)[1:], start=1):
                # A relative margin far above the float rounding of the bound and the sizes.
                if reach * (1.0 + 1e-6) + 1e-9 < least():
                    continue
                size = self._faces.size(index, piece)
                if size is not None:
                    yield np.array([size])


def _lone_strips(
    found: list[_Seam], cloud: np.ndarray, flat: list[bool], config: PerceptionConfig
) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The (longer, shorter) sizes (m) of the two strips beside each seam of one segment that
    has flat strips (``flat``, per seam) and lies midway between its outline on both sides
    (``_repeated`` among no other seams; ``cloud``: the segment's points): two pairs of one
    size in two segments are two boxes each."""
    sizes = []
    for seam, is_flat in zip(found, flat, strict=True):
        if not is_flat:
            continue
        by, widths = _repeated(seam, [], cloud, config)
        if by == _BY_OUTLINE:
            length = 2.0 * seam.half_length_m
            sizes.append(tuple((max(length, width), min(length, width)) for width in widths))
    return sizes


def _face_size(
    piece: np.ndarray, measured: np.ndarray, points: np.ndarray, normals: np.ndarray,
    config: PerceptionConfig,
) -> tuple[float, float] | None:  # fmt: skip
    """(longer, shorter) extent (m) of the dominant face of ``piece`` ((h, w) bool; ``measured``
    (h, w) bool: pixels with depth and a normal): its points
    whose normals lie within ``seams.max_normal_deg`` of their median normal, 2nd to 98th
    percentile along the axes of its smallest enclosing rectangle (a hull edge's direction);
    None for fewer than 50 such points, or a face
    that is not a flat rectangle (90 % of the points within ``seams.max_bend_m`` of its plane;
    its extent across each axis at 10, 50 and 90 % along it at least 1 -
    ``seams.strip_tolerance`` of the whole). A face of more than ``_FACE_POINTS`` pixels is
    measured on every k-th of them."""
    usable = np.flatnonzero(piece & measured)
    if len(usable) < 50:
        return None
    # A large face's every k-th pixel: its percentiles move by far less than the sizes'
    # tolerance, and the time of the rectangle search goes with the points.
    usable = usable[:: -(-len(usable) // _FACE_POINTS)]
    face_normals = normals.reshape(-1, 3)[usable].astype(np.float64)
    normal = np.median(face_normals, axis=0)
    normal /= max(float(np.linalg.norm(normal)), 1e-12)
    on_face = face_normals @ normal >= np.cos(np.radians(config.seams.max_normal_deg))
    if on_face.sum() < 50:
        return None
    cloud = points.reshape(-1, 3)[usable][on_face].astype(np.float64)
    centred = cloud - cloud.mean(axis=0)
    # A box's face is flat: a can's side or a bottle's is not.
    if _percentiles(np.abs(centred @ normal), (90.0,))[0] > config.seams.max_bend_m:
        return None
    flat = centred - np.outer(centred @ normal, normal)
    basis = np.linalg.svd(flat, full_matrices=False)[2][:2]
    plane = flat @ basis.T
    # The rectangle's axes: the hull edge direction whose extents enclose the least area (a
    # square's principal axes are any two).
    hull = plane[ConvexHull(plane).vertices]
    edges = np.roll(hull, -1, axis=0) - hull
    angles = np.unique(np.round(np.arctan2(edges[:, 1], edges[:, 0]) % (np.pi / 2), 3))
    coords = [
        plane @ np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]]).T
        for angle in angles
    ]
    # Every direction's percentiles in one call (column by column, as one call each), on the
    # columns laid out as rows: the same order statistics, read from contiguous memory.
    lows, highs = _row_percentiles(np.concatenate(coords, axis=1).T, (2.0, 98.0))
    best = None
    for index in range(len(angles)):
        low, high = lows[2 * index : 2 * index + 2], highs[2 * index : 2 * index + 2]
        area = float(np.prod(high - low))
        if best is None or area < best[0]:
            best = (area, coords[index], low, high)
    _, coords, low, high = best
    extent = high - low
    # And a rectangle: as wide near its ends as in its middle (a can's top is a disc).
    tolerance = config.seams.strip_tolerance
    for axis in (0, 1):
        other = 1 - axis
        for share in (0.1, 0.5, 0.9):
            at = low[axis] + share * extent[axis]
            near = np.abs(coords[:, axis] - at) <= 0.05 * extent[axis]
            if near.sum() < 5:
                return None
            span = np.ptp(coords[near, other])
            if span < (1.0 - tolerance) * extent[other]:
                return None
    return float(extent.max()), float(extent.min())


def _percentiles(values: np.ndarray, percents: tuple[float, ...]) -> list[float]:
    """``np.percentile(values, percents)`` of the (N,) ``values`` (N > 0) as floats, the same
    values: from a sorted row (``_row_percentiles``) for float64 values, N >= 2; numpy's
    otherwise (its float32 interpolation stays float32)."""
    if values.dtype == np.float64 and values.ndim == 1 and len(values) >= 2:
        return [float(value) for value in _row_percentiles(values[None, :], percents)[:, 0]]
    return [float(value) for value in np.percentile(values, percents)]


def _row_percentiles(rows: np.ndarray, percents: tuple[float, ...]) -> np.ndarray:
    """(len(percents), R) percentiles of each of the R rows of ``rows`` ((R, N) float64, N
    >= 2, finite): ``np.percentile(rows, percents, axis=1)``, the same bits (numpy's linear
    method and its interpolation, on the rows sorted). numpy partitions a strided copy for
    several order statistics at once, which takes about four times a sort of the rows."""
    ordered = np.sort(rows, axis=1)
    count = ordered.shape[1]
    virtual = (count - 1) * np.true_divide(np.asarray(percents, dtype=np.float64), 100)
    previous = np.floor(virtual)
    at = previous.astype(np.intp)
    # numpy's bounds: at the last value, both neighbours are the last value.
    last = virtual >= count - 1
    at[last] = count - 1
    following = np.where(last, count - 1, at + 1)
    gamma = (virtual - previous)[:, None]
    below, above = ordered[:, at].T, ordered[:, following].T
    # numpy's _lerp: from the nearer end.
    step = above - below
    result = below + step * gamma
    return np.where(gamma >= 0.5, above - step * (1 - gamma), result)


def _gate_sample(
    mask: np.ndarray, crop: tuple[slice, slice], width: int, everything: bool = False
) -> np.ndarray:
    """The flat frame indices (frame ``width`` px wide) of about ``_GATE_POINTS`` pixels of the
    segment ``mask`` ((h, w) bool in ``crop``): every k-th of its pixels, row-major (all of
    them with ``everything``)."""
    rows, cols = np.nonzero(mask)
    step = 1 if everything else -(-len(rows) // _GATE_POINTS)
    return (rows[::step] + crop[0].start) * width + cols[::step] + crop[1].start


def _has_flat_face(
    mask: np.ndarray,
    crop: tuple[slice, slice],
    points: np.ndarray,
    normals: Normals,
    config: PerceptionConfig,
    sample: np.ndarray | None = None,
) -> bool:
    """Whether the segment ``mask`` ((h, w) bool in ``crop`` of the frame; ``points`` (H, W, 3)
    world, m; ``normals`` the frame's, read at ``sample`` only: ``_gate_sample``'s flat
    indices, given when already asked for) holds a flat face with room for a seam and the two
    strips beside it: its pixels whose normals lie within ``seams.max_normal_deg`` of one normal span at least
    ``seams.min_length_m`` (the seam) by twice ``seams.min_width_m`` (a strip each side), 2nd to
    98th percentile along the face's principal axes. A seam's two sides must share a normal and
    its strips lie on its plane (``_coplanar_sides``, ``_flat_strips``): a can's, a bottle's or a
    bowl's faces within that angle are narrower (2 R sin 15 deg: 1.7 cm on a 3.3 cm soup can),
    and small objects have no such face. The up to three best-supported normals of a sample of
    about ``_GATE_POINTS`` pixels are tried (a box seen over an edge shows two faces)."""
    seams = config.seams
    usable = _gate_sample(mask, crop, points.shape[1]) if sample is None else sample
    sample_normals = normals.at(usable).astype(np.float64)
    known = _known(sample_normals)
    if known.sum() < 50:
        return False
    usable, sample_normals = usable[known], sample_normals[known]
    sample_points = points.reshape(-1, 3)[usable].astype(np.float64)
    cos_limit = np.cos(np.radians(seams.max_normal_deg))
    candidates = sample_normals[:: max(1, len(sample_normals) // _FACE_CANDIDATES)]
    support = (candidates @ sample_normals.T >= cos_limit).sum(axis=1)
    tried: list[np.ndarray] = []
    long_side, short_side = seams.min_length_m, 2.0 * seams.min_width_m
    for index in np.argsort(-support, kind="stable"):
        if len(tried) == 3 or support[index] < 50:
            break
        normal = candidates[index]
        if any(float(normal @ other) >= cos_limit for other in tried):
            continue
        tried.append(normal)
        face = sample_points[sample_normals @ normal >= cos_limit]
        centred = face - face.mean(axis=0)
        flat = centred - np.outer(centred @ normal, normal)
        axes = np.linalg.svd(flat, full_matrices=False)[2][:2]
        # ``np.percentile(flat @ axes.T, [2, 98], axis=0)``, the same bits, from sorted rows.
        low, high = _row_percentiles(np.ascontiguousarray((flat @ axes.T).T), (2.0, 98.0))
        extent = np.sort(high - low)
        if extent[1] >= max(long_side, short_side) and extent[0] >= min(long_side, short_side):
            return True
    return False


def _masked_median(values: np.ndarray, mask: np.ndarray | None = None, dtype=None) -> float:
    """``float(np.median(values[mask].astype(dtype)))`` of ``values`` >= 0 (any shape, no NaN)
    at the bool ``mask`` of their shape (None: all; none: NaN, as numpy), ``dtype`` the
    values' own when None: the same value. For float32 values the middle order statistics
    are compiled (``kernels.middle_values``; a conversion to float64 keeps their order) and
    their mean is numpy's, as its median takes it; other dtypes take numpy's median."""
    if values.dtype != np.float32:  # (the compiled selection reads float32 bits)
        chosen_values = values if mask is None else values[mask]
        return float(np.median(chosen_values if dtype is None else chosen_values.astype(dtype)))
    flat = values.reshape(-1)
    chosen = np.ones(flat.shape, dtype=bool) if mask is None else mask.reshape(-1)
    count = np.count_nonzero(chosen)
    if count == 0:
        return float("nan")  # numpy's median of nothing
    low, high = kernels.middle_values(flat, chosen)
    middle = [low] if count % 2 else [low, high]
    return float(np.median(np.array(middle, dtype=values.dtype if dtype is None else dtype)))


def _edge_noise(rgb: np.ndarray, depth_m: np.ndarray, segment_pixels: np.ndarray) -> float:
    """The median colour gradient magnitude (``_colour_gradient``) over the pixels with depth
    (``depth_m`` > 0; none: over ``segment_pixels``, (H, W) bool) of a grid of every
    ``_NOISE_STEP_PX``-th row and column: the frame's noise scale for the edge threshold,
    without the frame's gradient (a median of thousands of samples moves by about a percent)."""
    height, width = depth_m.shape
    offset = _NOISE_STEP_PX // 2
    rows, cols = np.mgrid[offset:height:_NOISE_STEP_PX, offset:width:_NOISE_STEP_PX]
    rows, cols = rows.ravel(), cols.ravel()
    for usable in (depth_m[rows, cols] > 0, segment_pixels[rows, cols]):
        if usable.any():
            rows, cols = rows[usable], cols[usable]
            break
    if len(rows) == 0 or min(height, width) <= len(_GAUSSIAN) // 2:
        return float(np.median(_colour_gradient(rgb)[0][segment_pixels]))
    return float(np.median(kernels.colour_gradient_at(rgb, _GAUSSIAN, rows.astype(np.int64),
                                                      cols.astype(np.int64))))  # fmt: skip


def _colour_gradient_in(
    rgb: np.ndarray, crops: list[tuple[slice, slice]]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """``_colour_gradient`` of ``rgb`` (H, W, 3) within the ``crops`` and a 1 px ring, 0
    elsewhere: each crop's gradient from the crop and a ring of ``_GRADIENT_REACH_PX`` (the
    filters' reach), the same numbers as the frame's gradient there; or of the one box around
    all crops when it has fewer pixels than the crops one by one (they overlap in a cluttered
    frame); the frame's when that covers more than half of it. And whether it is the frame's."""
    height, width = rgb.shape[:2]
    reach = _GRADIENT_REACH_PX + 1
    boxes = [
        (max(crop[0].start - reach, 0), min(crop[0].stop + reach, height),
         max(crop[1].start - reach, 0), min(crop[1].stop + reach, width))
        for crop in crops
    ]  # fmt: skip
    # The fewest pixels: the boxes one by one (they overlap in a cluttered frame), or the one
    # box around them all; the frame's when either covers more than half of it.
    one_by_one = sum((b - t) * (r - lf) for t, b, lf, r in boxes)
    if boxes:
        around = (min(b[0] for b in boxes), max(b[1] for b in boxes),
                  min(b[2] for b in boxes), max(b[3] for b in boxes))  # fmt: skip
        if (around[1] - around[0]) * (around[3] - around[2]) < one_by_one:
            top, bottom, left, right = around
            crops = [
                (slice(min(c[0].start for c in crops), max(c[0].stop for c in crops)),
                 slice(min(c[1].start for c in crops), max(c[1].stop for c in crops)))
            ]  # fmt: skip
            boxes = [around]
            one_by_one = (bottom - top) * (right - left)
    if one_by_one > 0.5 * height * width:
        return (*_colour_gradient(rgb), True)
    magnitude = np.zeros((height, width), dtype=np.float32)
    gx = np.zeros((height, width), dtype=np.float32)
    gy = np.zeros((height, width), dtype=np.float32)
    for (top, bottom, left, right), crop in zip(boxes, crops, strict=True):
        part_m, part_x, part_y = _colour_gradient(rgb[top:bottom, left:right])
        # Valid where the filters did not reach the box's cut sides: the crop and a 1 px ring.
        inner = (
            slice(max(crop[0].start - 1, 0), min(crop[0].stop + 1, height)),
            slice(max(crop[1].start - 1, 0), min(crop[1].stop + 1, width)),
        )
        local = (slice(inner[0].start - top, inner[0].stop - top),
                 slice(inner[1].start - left, inner[1].stop - left))  # fmt: skip
        magnitude[inner] = part_m[local]
        gx[inner] = part_x[local]
        gy[inner] = part_y[local]
    return magnitude, gx, gy, False


def _colour_gradient(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(H, W) float32 gradient magnitude and its x and y components (Sobel, per pixel of
    RGB in [0, 1] smoothed by a Gaussian of sigma 1 px) of the colour channel that changes
    most at each pixel (the first of equals). Compiled (``kernels.colour_gradient``, the same
    numbers as the scipy filters below, which remain for images narrower than the kernel)."""
    if min(rgb.shape[0], rgb.shape[1]) > len(_GAUSSIAN) // 2:
        gx, gy = kernels.colour_gradient(rgb, _GAUSSIAN)
        return np.hypot(gx, gy), gx, gy
    image = ndimage.gaussian_filter(rgb.astype(np.float32) / 255.0, sigma=(1.0, 1.0, 0.0))
    # ndimage.sobel per channel, all three channels in one pass along each axis.
    gx = ndimage.correlate1d(image, [-1, 0, 1], axis=1, output=np.float32)
    ndimage.correlate1d(gx, [1, 2, 1], axis=0, output=gx)
    gy = ndimage.correlate1d(image, [-1, 0, 1], axis=0, output=np.float32)
    ndimage.correlate1d(gy, [1, 2, 1], axis=1, output=gy)
    square = gx**2 + gy**2
    best_x, best_y, best = gx[..., 0], gy[..., 0], square[..., 0]
    for channel in (1, 2):
        larger = square[..., channel] > best  # argmax: the first of equals
        best = np.where(larger, square[..., channel], best)
        best_x = np.where(larger, gx[..., channel], best_x)
        best_y = np.where(larger, gy[..., channel], best_y)
    return np.hypot(best_x, best_y), best_x, best_y


def _linked_edges(
    magnitude: np.ndarray,
    gx: np.ndarray,
    gy: np.ndarray,
    direction: np.ndarray,
    edges: np.ndarray,
    low: float,
    near: np.ndarray,
) -> np.ndarray:
    """(H, W) bool: the thinned pixels (``_thin``) of gradient ``magnitude`` above ``low``
    within ``near`` ((H, W) bool) that are 8-connected through such pixels to a pixel of
    ``edges`` ((H, W) bool, the thinned strong edges): Canny's hysteresis, the faint stretches
    of an edge that is strong somewhere. The faint pixels are thinned in the sectors of
    ``gx``, ``gy`` (``_thin``; ``direction`` ((H, W), rad) filled in where it is measured)."""
    weak = np.flatnonzero((magnitude > low) & near)
    # The 8-connected components of the thinned faint pixels that hold a strong one (compiled:
    # a flood fill from the strong pixels, not a label image of the frame).
    return kernels.linked_to(_thin(magnitude, direction, weak, gx, gy), edges) | edges


def _with_shadow_lines(
    searched: list,
    decided: list[np.ndarray],
    rgb: np.ndarray,
    points: np.ndarray,
    normals: Normals,
    depth_m: np.ndarray,
    config: PerceptionConfig,
) -> list[np.ndarray]:
    """``decided`` (each searched segment's pieces, ``searched`` as in ``cut_colour_seams``)
    with the segments whose seams found hold a shadow line (``_is_shadow``) decided again,
    those seams kept whatever their strips measure, when the strip tests kept a cut somewhere
    in the frame; else as it is. The other segments keep their pieces (the faces that the
    segments decided again compare their strips with).

    Why the frame's kept cut: a shadow line is the gap between two touching boxes, but black
    or grey ink darkens every channel alike too (a printed line on a white box). A cut that
    the strip tests kept (a row or grid of boxes of one size, or a pair with a twin) says that
    the frame holds packed boxes, where a dark line between flat strips is a gap; a tabletop
    frame with no such cut keeps its printed lines whole."""
    if not any(int(pieces.max()) > 1 for pieces in decided):
        return decided
    marked = [(crop, mask, cut, _with_shadows(found, rgb[crop]), cloud, flat)
              for crop, mask, cut, found, cloud, flat in searched]  # fmt: skip
    again = [any(seam.shadow for seam in entry[3]) for entry in marked]
    if not any(again):
        return decided
    # Only those segments ask for sizes (``_pairs_by_size`` decides again the ones that asked).
    asked = [_Sizes() for _ in marked]
    with_depth = depth_m > 0
    decided = [
        _decide(cut, found, cloud, flat, config, sizes, points[crop], with_depth[crop])
        if redo else pieces
        for (crop, _, cut, found, cloud, flat), sizes, redo, pieces
        in zip(marked, asked, again, decided, strict=True)
    ]  # fmt: skip
    if config.seams.pair_needs_grid and config.seams.pair_sizes:
        decided = _pairs_by_size(marked, decided, asked, points, normals, depth_m, config)
    return decided


def _with_shadows(found: list[_Seam], rgb: np.ndarray) -> list[_Seam]:
    """The seams ``found`` (pixels in the crop of ``rgb``, (h, w, 3) uint8), each marked
    ``shadow`` when it is a shadow line (``_is_shadow``)."""
    return [replace(seam, shadow=_is_shadow(seam, rgb)) for seam in found]


def _is_shadow(seam: _Seam, rgb: np.ndarray) -> bool:
    """Whether ``seam`` is a shadow line: across it, in every channel of ``rgb`` ((h, w, 3)
    uint8, the crop's), each offset's median along the seam is darker within a pixel of the seam
    than both side bands (``_SIDE_BAND_PX``, their mean) by more than the two bands differ,
    and the channels darken alike: the ratios of the line's channels to the darker band's
    differ by less than the light lost (one minus their mean).

    Why: two touching boxes leave a gap that the light does not reach, a line darker than
    both tops in every channel (less light, whatever the colour); one box with a printed
    border through its middle shows a step between two colours, and ink or a coloured side
    face darkens the channels it absorbs more than the others."""
    height, width = rgb.shape[:2]
    near, far = _SIDE_BAND_PX
    offsets = np.arange(-far, far + 1)
    rows = np.rint(seam.rows[:, None] + offsets[None, :] * seam.sin_a).astype(np.int64)
    cols = np.rint(seam.cols[:, None] + offsets[None, :] * seam.cos_a).astype(np.int64)
    np.clip(rows, 0, height - 1, out=rows)
    np.clip(cols, 0, width - 1, out=cols)
    profile = np.median(rgb[rows, cols].astype(np.float64), axis=0)  # (offsets, 3)
    middle = profile[far - 1 : far + 2].min(axis=0)
    before = profile[: far - near + 1].mean(axis=0)
    after = profile[far + near :].mean(axis=0)
    darker = np.minimum(before, after)
    if not np.all(darker - middle > np.abs(before - after)):
        return False
    # Less light scales every channel by one factor; their ratios differ by less than the
    # light lost.
    ratios = middle / np.maximum(darker, 1.0)
    return float(np.ptp(ratios)) < 1.0 - float(ratios.mean())


def _thin(
    magnitude: np.ndarray,
    direction: np.ndarray,
    at: np.ndarray,
    gx: np.ndarray | None = None,
    gy: np.ndarray | None = None,
) -> np.ndarray:
    """(H, W) bool: of the pixels ``at`` (flat indices), those whose gradient magnitude is a
    maximum across the edge (Canny's non-maximum suppression, directions quantised to 45
    degrees). Compiled (``kernels.thin_edges``; ``_thin_numpy`` is its reference).

    With the gradient's components ``gx``, ``gy`` ((H, W) float32), ``direction`` need not
    be known: each pixel's sector is read from them (``kernels.gradient_sectors``), and only
    within ``_SECTOR_MARGIN_RAD`` of a sector's boundary is the direction measured
    (``np.arctan2`` in float32, written into ``direction``): the same sectors, without an
    arctangent per pixel."""
    at = np.asarray(at, dtype=np.int64)
    if gx is None or gy is None:
        return kernels.thin_edges(magnitude, direction, at)
    sectors = kernels.gradient_sectors(gx, gy, at, _SECTOR_TANGENTS)
    unsure = at[sectors < 0]
    direction.flat[unsure] = np.arctan2(gy.flat[unsure], gx.flat[unsure])
    return kernels.thin_edges_in_sectors(magnitude, direction, at, sectors)


def _thin_numpy(magnitude: np.ndarray, direction: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``_thin`` in numpy: the compiled kernel's reference (``tests/test_seams.py``)."""
    height, width = magnitude.shape
    sector = (np.round(direction.flat[at] / (np.pi / 4)) % 4).astype(np.int8)
    padded = np.pad(magnitude, 1)
    rows, cols = np.divmod(at, width)
    rows, cols = rows + 1, cols + 1
    value = magnitude.flat[at]
    keep = np.zeros(len(at), dtype=bool)
    for index, (dy, dx) in enumerate(((0, 1), (1, 1), (1, 0), (1, -1))):
        ahead = padded[rows + dy, cols + dx]
        behind = padded[rows - dy, cols - dx]
        keep |= (sector == index) & (value >= ahead) & (value >= behind)
    edges = np.zeros(magnitude.shape, dtype=bool)
    edges.flat[at[keep]] = True
    return edges


def _search_segment(
    mask: np.ndarray,
    edges: np.ndarray,
    direction: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    depth_m: np.ndarray,
    focal_px: float,
    config: PerceptionConfig,
) -> tuple[np.ndarray, list[_Seam]]:
    """(h, w) int pieces of one segment's crop cut at every seam found (0 outside, 1 the first
    piece, 2.. the cut-off pieces), and the seams in the order cut (best first, then the
    pieces searched again). Each piece needs room for two pieces of ``seams.min_area_m2``
    (the whole segment's is the caller's first test; ``_split`` judges every cut anyway)."""
    pieces = mask.astype(np.int32)
    near_edge = _dilate_square(edges)  # ndimage.binary_dilation(edges, np.ones((3, 3)))
    has_normal = _known(normals)
    queue = [1]
    found: list[_Seam] = []
    while queue and len(found) < config.seams.max_cuts:
        piece = queue.pop()
        part = pieces == piece
        # (The whole segment's area was the caller's first test.)
        if found and not _has_area(part, depth_m, focal_px, 2 * config.seams.min_area_m2):
            continue
        cut = _best_cut(part, edges, near_edge, direction, points, normals, has_normal,
                        depth_m, focal_px, config)  # fmt: skip
        if cut is None:
            continue
        side, seam = cut
        new = int(pieces.max()) + 1
        pieces[side] = new
        found.append(seam)
        queue.extend((piece, new))
    return pieces, found


def _known(normals: np.ndarray) -> np.ndarray:
    """(...) bool: the (..., 3) ``normals`` that are known (not all 0): ``np.any(normals != 0,
    axis=-1)``, by three comparisons (numpy's reduction over a last axis of 3 is slow)."""
    return (normals[..., 0] != 0) | (normals[..., 1] != 0) | (normals[..., 2] != 0)


def _dilate_square(mask: np.ndarray) -> np.ndarray:
    """(h, w) bool: the pixels whose 3 x 3 neighbourhood holds a pixel of ``mask`` ((h, w)
    bool; ``ndimage.binary_dilation`` by a 3 x 3 square, border 0), by shifted ORs."""
    height, width = mask.shape
    padded = np.pad(mask, 1)
    out = np.zeros((height, width), dtype=bool)
    for dr in range(3):
        for dc in range(3):
            out |= padded[dr : dr + height, dc : dc + width]
    return out


def _unrepeated(
    found: list[_Seam],
    cloud: np.ndarray,
    flat: list[bool],
    config: PerceptionConfig,
    sizes: _Sizes | None = None,
) -> list[_Seam]:
    """The seams of one segment whose strips are not flat (``_flat_strips``) or that do not
    repeat (``_repeated``). Repetition is judged among the seams still kept, until no more
    drop out: a seam dropped is no bound for its neighbours. With ``seams.pair_needs_grid``
    a seam bounded only by the outline on both sides (one seam midway across the segment:
    two boxes, or one box with a printed line through its middle) is kept only when it meets
    a seam that repeats between seams (a grid of packed boxes), or when both its strips have
    one of the (longer, shorter) face sizes ``sizes`` ((M, 2), m) of boxes seen elsewhere in
    the frame, within ``seams.size_tolerance_m``. A seam marked a shadow line
    (``_Seam.shadow``; ``_with_shadow_lines``) with flat strips is kept whatever it repeats: a
    gap between two boxes. ``cloud`` (N, 3): the segment's points with
    depth (world, m); ``flat``: whether each seam's strips are flat (``_flat_strips``)."""
    kept = [seam for seam, is_flat in zip(found, flat, strict=True) if is_flat]
    while True:
        bound = [_repeated(seam, kept, cloud, config) for seam in kept]
        in_row = [seam for seam, (by, _) in zip(kept, bound, strict=True) if by == _BY_SEAM]
        still = [
            seam
            for seam, (by, widths) in zip(kept, bound, strict=True)
            if by == _BY_SEAM
            or seam.shadow
            or (
                by == _BY_OUTLINE
                and (
                    not config.seams.pair_needs_grid
                    or _meets_any(seam, in_row, config)
                    or _sized_like(seam, widths, sizes, config)
                )
            )
        ]
        if len(still) == len(kept):
            break
        kept = still
    return [seam for seam in found if not any(seam is other for other in kept)]


def _sized_like(
    seam: _Seam, widths: tuple[float, float], sizes: _Sizes | None, config: PerceptionConfig
) -> bool:
    """Whether both strips beside ``seam`` (its length by each of ``widths``, m) match a face
    size of ``sizes`` (each extent within ``seams.size_tolerance_m``), or match the two strips
    of one lone seam elsewhere both ways: each strip here matches one there and each there
    one here (two pairs of one product; a strip of any pair alone would let a can's straight
    line along its axis match one half of a printed box)."""
    if sizes is None:
        return False
    known = sizes.get()
    if known is None:
        return False
    faces, pairs = known
    length = 2.0 * seam.half_length_m
    strips = np.array([[max(length, width), min(length, width)] for width in widths])
    tolerance = config.seams.size_tolerance_m
    # (P, 2, 2): this seam's strip i against strip j of lone pair p.
    alike = np.all(np.abs(strips[None, :, None, :] - pairs[:, None, :, :]) <= tolerance, axis=3)
    if np.any(alike.any(axis=2).all(axis=1) & alike.any(axis=1).all(axis=1)):
        return True
    return _covered(strips, [faces] if isinstance(faces, np.ndarray) else faces, tolerance)


def _covered(strips: np.ndarray, faces, tolerance: float) -> bool:
    """Whether each of the (2, 2) ``strips`` sizes (m) is within ``tolerance`` of some face size
    in both extents; ``faces``: an iterable of (k, 2) arrays, read only until both match."""
    matched = np.zeros(len(strips), dtype=bool)
    if isinstance(faces, _FacesElsewhere):
        # A face within the tolerance of a strip is at least its longer extent less the
        # tolerance long: segments that cannot hold one for a strip still unmatched are skipped.
        faces = faces.reaching(lambda: float(strips[~matched, 0].min()) - tolerance)
    for sizes in faces:
        # (2, k): strip i within the tolerance of face j in both extents.
        on = np.all(np.abs(strips[:, None, :] - sizes[None, :, :]) <= tolerance, axis=2)
        matched |= on.any(axis=1)
        if matched.all():
            return True
    return False


def _flat_strips(seam: _Seam, cloud: np.ndarray, config: PerceptionConfig) -> bool:
    """Whether the segment's points ``cloud`` ((N, 3), m) on each side of ``seam``, within its
    length, lie on its surface: their median height over the seam's plane is at most
    tan(``seams.max_normal_deg``) times their median distance across the seam. The side bands
    of ``_coplanar_sides`` are narrow; over a whole strip a crease shows (a box's top and front
    face, whose colour edge at the crease runs straight from outline to outline)."""
    relative = cloud - seam.middle
    near = np.abs(relative @ seam.direction) <= seam.half_length_m
    across = relative[near] @ seam.across
    height = relative[near] @ seam.normal
    slope = np.tan(np.radians(config.seams.max_normal_deg))
    for side in (across > 0, across < 0):
        if not side.any():
            return False
        if abs(float(np.median(height[side]))) > slope * float(np.median(np.abs(across[side]))):
            return False
    return True


def _repeated(
    seam: _Seam, found: list[_Seam], cloud: np.ndarray, config: PerceptionConfig
) -> tuple[int, tuple[float, float]]:
    """How ``seam`` lies midway between two bounds, one on each side: a parallel seam on the
    same surface (``_neighbours``, at least ``seams.min_width_m`` away) or the segment's far
    outline (its points ``cloud`` (N, 3), m, within the seam's length, 98th percentile),
    measured in 3D across the seam; the narrower strip is at least 1 - ``seams.strip_tolerance``
    of the wider. Packed boxes of one size repeat at one spacing, a printed border lies where
    the print puts it; a bound may lie beyond a nearer seam (a printed line on a box in the
    row). With ``seams.rows_of_three`` two parallel seams on one side at one spacing with it
    (``_equally_spaced``) bound it too, whatever the outline. Returns ``_BY_SEAM`` when a pair
    of bounds that passes includes a seam, or such a row,
    ``_BY_OUTLINE`` when only the outline on both sides passes, else ``_UNBOUNDED``, and the
    distances (m) from the seam to the outline on its two sides."""
    relative = cloud - seam.middle
    along = relative @ seam.direction
    across = (relative @ seam.across)[np.abs(along) <= seam.half_length_m]
    offsets = [
        float((other.middle - seam.middle) @ seam.across) for other in _neighbours(seam, found)
    ]
    bounds = []
    for sign in (1.0, -1.0):
        side = sign * across[sign * across > 0]
        widest = _percentiles(side, (98.0,))[0] if side.size else 0.0
        nearer = [sign * offset for offset in offsets if sign * offset >= config.seams.min_width_m]
        bounds.append(np.array([widest, *nearer]))
    ratio = np.minimum.outer(*bounds) / np.maximum(np.maximum.outer(*bounds), 1e-9)
    passes = ratio >= 1.0 - config.seams.strip_tolerance
    widths = (float(bounds[0][0]), float(bounds[1][0]))
    if config.seams.rows_of_three and any(
        _equally_spaced(np.sort(side[1:]), config) for side in bounds
    ):
        return _BY_SEAM, widths
    if not passes.any():
        return _UNBOUNDED, widths
    passes[0, 0] = False  # the outline on both sides
    return (_BY_SEAM if passes.any() else _BY_OUTLINE), widths


def _equally_spaced(offsets: np.ndarray, config: PerceptionConfig) -> bool:
    """Whether two of the parallel seams at ``offsets`` (sorted, m, on one side of a seam)
    lie at one spacing with it (the nearer at x, the farther at y: x and y - x within
    ``seams.strip_tolerance`` of each other): three seams of one row of boxes of one size,
    which the row's end strips (to an outline that shows side faces, or is cut by an
    occluder) need not confirm."""
    for index, near in enumerate(offsets):
        for far in offsets[index + 1 :]:
            gap = far - near
            if gap >= config.seams.min_width_m and min(near, gap) >= (
                1.0 - config.seams.strip_tolerance
            ) * max(near, gap):
                return True
    return False


def _meets_any(seam: _Seam, others: list[_Seam], config: PerceptionConfig) -> bool:
    """Whether ``seam`` meets one of ``others`` on one surface at an angle, as the seams of a
    grid of packed boxes do: normals within ``_PARALLEL_DEG``, directions more than 45 deg
    apart, and the crossing of their 3D lines within each seam's half length plus
    ``seams.min_width_m`` (a seam found in a piece ends at the seam that cut it off)."""
    parallel = np.cos(np.radians(_PARALLEL_DEG))
    for other in others:
        if other is seam or float(other.normal @ seam.normal) < parallel:
            continue
        if abs(float(other.direction @ seam.direction)) > np.cos(np.radians(45.0)):
            continue
        # middle + t direction = other.middle + u other.direction, least squares (skew lines).
        system = np.stack([seam.direction, -other.direction], axis=1)
        (t, u), *_ = np.linalg.lstsq(system, other.middle - seam.middle, rcond=None)
        margin = config.seams.min_width_m
        if abs(t) <= seam.half_length_m + margin and abs(u) <= other.half_length_m + margin:
            return True
    return False


def _neighbours(seam: _Seam, found: list[_Seam]) -> list[_Seam]:
    """The seams of ``found`` in one row of boxes with ``seam``: parallel to it (within
    ``_PARALLEL_DEG``), on one surface (normals within ``_PARALLEL_DEG``) and beside it along
    its length."""
    parallel = np.cos(np.radians(_PARALLEL_DEG))
    return [
        other
        for other in found
        if other is not seam
        and abs(float(other.direction @ seam.direction)) >= parallel
        and float(other.normal @ seam.normal) >= parallel
        and abs(float((other.middle - seam.middle) @ seam.direction))
        <= seam.half_length_m + other.half_length_m
    ]


def _undo(
    pieces: np.ndarray,
    seam: _Seam,
    kept: list[_Seam] | None = None,
    points: np.ndarray | None = None,
    measured: np.ndarray | None = None,
    config: PerceptionConfig | None = None,
) -> np.ndarray:
    """``pieces`` with the pieces that face each other across ``seam`` (3-5 px either side of
    it, along its length) merged back, one to one: each piece joins at most one piece across
    it, the one it faces along most of the seam. A piece that faces several pieces across it
    was cut by kept seams after this one (a printed line across a row of boxes cut first,
    then the seams between the boxes): joining it to all of them would undo those cuts too.

    With the ``kept`` seams and the crop's ``points`` ((h, w, 3) world, m; ``measured`` (h, w)
    bool: pixels with depth), such a piece is first cut along the 3D planes of the kept seams
    between the pieces it faces (``_cut_by_planes``), each part then joining the piece it faces:
    a seam between two boxes goes on across the rest of the boxes (their barcode ends and end
    faces beyond a printed line across the row), where no colour edge of its own was found."""
    if kept and points is not None and measured is not None and config is not None:
        pieces = _cut_by_planes(pieces, seam, kept, points, measured, config)
    counts = _facing(pieces, seam)
    if not counts:
        return pieces
    relabel = np.arange(int(pieces.max()) + 1)
    joined: set[int] = set()
    for (a, b), _ in sorted(counts.items(), key=lambda item: (-item[1], item[0])):
        if a in joined or b in joined:
            continue
        joined.update((a, b))
        root_a, root_b = relabel[a], relabel[b]
        low, high = min(root_a, root_b), max(root_a, root_b)
        relabel[relabel == high] = low
    return relabel[pieces].astype(np.int32)


def _facing(pieces: np.ndarray, seam: _Seam) -> dict[tuple[int, int], int]:
    """How often (samples 3-5 px either side of ``seam``, along its length) each pair
    (smaller id, larger id) of different pieces faces each other across it."""
    height, width = pieces.shape
    k = np.array([3.0, 4.0, 5.0])[:, None]
    rows_a = np.clip(np.round(seam.rows + k * seam.sin_a).astype(np.int64), 0, height - 1)
    cols_a = np.clip(np.round(seam.cols + k * seam.cos_a).astype(np.int64), 0, width - 1)
    rows_b = np.clip(np.round(seam.rows - k * seam.sin_a).astype(np.int64), 0, height - 1)
    cols_b = np.clip(np.round(seam.cols - k * seam.cos_a).astype(np.int64), 0, width - 1)
    a, b = pieces[rows_a, cols_a].ravel(), pieces[rows_b, cols_b].ravel()
    keep = (a > 0) & (b > 0) & (a != b)
    low = np.minimum(a[keep], b[keep]).astype(np.int64)
    high = np.maximum(a[keep], b[keep]).astype(np.int64)
    keys, counts = np.unique(low * (int(pieces.max()) + 1) + high, return_counts=True)
    low, high = np.divmod(keys, int(pieces.max()) + 1)
    return {
        (int(pa), int(pb)): int(count)
        for pa, pb, count in zip(low.tolist(), high.tolist(), counts.tolist(), strict=True)
    }


def _cut_by_planes(
    pieces: np.ndarray,
    seam: _Seam,
    kept: list[_Seam],
    points: np.ndarray,
    measured: np.ndarray,
    config: PerceptionConfig,
) -> np.ndarray:
    """``pieces`` with each piece that faces two or more pieces across ``seam`` (a seam undone,
    or a kept seam that ends a row of boxes cut apart on its other side) cut along the planes
    of the ``kept`` seams that lie between two of those pieces (each kept seam's plane holds
    its 3D line and the surface's normal: the plane between two packed boxes, which goes on
    across the boxes' other faces and across the seam where the colour edge bends or fades).
    Each of the piece's pixels with depth (``measured``; ``points`` (h, w, 3), m) takes the
    side of every plane; a facing piece's sides are those of its median point; the pixels on
    the sides of one facing piece form a part (new id), the rest of the piece (and its pixels
    without depth) go to the nearest part. A part must span the width of the piece it faces
    along ``seam`` (within ``seams.strip_tolerance``; one that does not goes to its
    neighbours), and at least two parts must. Nothing changes when no kept seam lies between
    two facing pieces, two facing pieces lie on the same sides, or the piece's own seams
    along the planes lie off them (``_on_any_plane``: its rows are offset from the faced
    ones)."""
    tolerance = config.seams.strip_tolerance
    counts = _facing(pieces, seam)
    across: dict[int, set[int]] = {}
    for a, b in counts:
        across.setdefault(a, set()).add(b)
        across.setdefault(b, set()).add(a)
    between = {}
    for other in kept:
        pairs = _facing(pieces, other)
        if pairs:
            between[id(other)] = max(pairs, key=lambda pair: (pairs[pair], pair))
    out = pieces
    next_id = int(pieces.max()) + 1
    for piece, faced in sorted(across.items()):
        if len(faced) < 2:
            continue
        planes = [other for other in kept if id(other) in between
                  and set(between[id(other)]) <= faced]  # fmt: skip
        if not planes:
            continue
        # The piece's own seams across the same direction must continue the planes (an
        # aligned grid): where they lie between them, its boxes are offset from the faced
        # ones (rows laid like bricks) and the planes are not their boundaries.
        if any(
            _parallel_to_any(other, planes) and not _on_any_plane(other, planes, config)
            for other in kept
            if all(other is not plane for plane in planes)
            and any(piece in pair for pair in _facing(pieces, other))
        ):
            continue
        normals = np.array([other.across for other in planes])
        offsets = np.array([float(other.across @ other.middle) for other in planes])
        signs = {}
        for other_piece in sorted(faced):
            cloud = points[(pieces == other_piece) & measured].astype(np.float64)
            if len(cloud) == 0:
                break
            signs[other_piece] = tuple(np.median(cloud, axis=0) @ normals.T > offsets)
        if len(signs) < len(faced) or len(set(signs.values())) < len(signs):
            continue
        inside = pieces == piece
        own = inside & measured
        side = points[own].astype(np.float64) @ normals.T > offsets
        assigned = np.zeros(pieces.shape, dtype=np.int32)
        values = np.zeros(int(own.sum()), dtype=np.int32)
        for part, other_piece in enumerate(sorted(faced), start=1):
            values[np.all(side == np.array(signs[other_piece]), axis=1)] = part
        # A part is as wide along the undone seam as the piece it faces (within
        # ``seams.strip_tolerance``): the same boxes go on beyond a printed line across them;
        # another box beyond the line (lying across the row's end) does not end at their
        # seams. A part that is not goes to its neighbours (below), as the pixels without depth.
        along = points[own].astype(np.float64) @ seam.direction
        for part, other_piece in enumerate(sorted(faced), start=1):
            if not _alike_widths(along[values == part], pieces == other_piece, points, measured,
                                 seam.direction, tolerance):  # fmt: skip
                values[values == part] = 0
        if len(np.unique(values[values > 0])) < 2:
            continue
        assigned[own] = values
        # The rest of the piece (its pixels without depth, off every facing piece's sides):
        # the nearest part's.
        nearest = ndimage.distance_transform_edt(
            assigned == 0, return_distances=False, return_indices=True
        )
        parts = np.where(inside, assigned[nearest[0], nearest[1]], 0)
        if out is pieces:
            out = pieces.copy()
        for part in range(2, len(faced) + 1):
            out[parts == part] = next_id
            next_id += 1
    return out


def _parallel_to_any(seam: _Seam, planes: list[_Seam]) -> bool:
    """Whether ``seam`` runs along one of ``planes``' seams (within ``_PARALLEL_DEG``)."""
    parallel = np.cos(np.radians(_PARALLEL_DEG))
    return any(abs(float(seam.direction @ plane.direction)) >= parallel for plane in planes)


def _on_any_plane(seam: _Seam, planes: list[_Seam], config: PerceptionConfig) -> bool:
    """Whether ``seam`` continues one of ``planes``' seams: parallel to it and its middle
    within ``seams.min_width_m`` of its plane (the line and the surface normal)."""
    parallel = np.cos(np.radians(_PARALLEL_DEG))
    return any(
        abs(float(seam.direction @ plane.direction)) >= parallel
        and abs(float(plane.across @ (seam.middle - plane.middle))) <= config.seams.min_width_m
        for plane in planes
    )


def _alike_widths(
    along: np.ndarray,
    other: np.ndarray,
    points: np.ndarray,
    measured: np.ndarray,
    direction: np.ndarray,
    tolerance: float,
) -> bool:
    """Whether a part's points' coordinates ``along`` (m) a direction and the points of the
    piece ``other`` ((h, w) bool; ``points`` (h, w, 3) m, ``measured`` (h, w) bool) along
    ``direction`` (3,) span one width (2nd-98th percentile) within ``tolerance`` of the wider."""
    theirs = points[other & measured].astype(np.float64) @ direction
    if len(along) < 2 or len(theirs) < 2:
        return False
    mine = float(np.subtract(*_percentiles(along, (98.0, 2.0))))
    width = float(np.subtract(*_percentiles(theirs, (98.0, 2.0))))
    return min(mine, width) >= (1.0 - tolerance) * max(mine, width, 1e-9)


def _best_cut(
    part: np.ndarray,
    edges: np.ndarray,
    near_edge: np.ndarray,
    direction: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    has_normal: np.ndarray,
    depth_m: np.ndarray,
    focal_px: float,
    config: PerceptionConfig,
) -> tuple[np.ndarray, _Seam] | None:
    """(h, w) bool: the smaller side of the best seam of ``part`` and the seam, or None
    (module doc; ``has_normal`` (h, w) bool: pixels whose normal is known)."""
    seams = config.seams
    # The part's box and a ring: its erosion, edge pixels and chords lie there (coordinates
    # stay the crop's, so that the votes are the crop's).
    window = _window(part, part.shape)
    top_px, left_px = window[0].start, window[1].start
    # Compiled: ``ndimage.binary_erosion(part[window], iterations=2)``.
    inner = kernels.erode_diamond(part[window], 2)
    rows, cols = np.nonzero(edges[window] & inner)
    if len(rows) < 20:
        return None
    rows += top_px
    cols += left_px
    height, width = part.shape
    cos_a, sin_a = _COS, _SIN
    reach = int(np.ceil(np.hypot(height, width)))
    own = np.round((direction[rows, cols] % np.pi) / np.pi * _DIRECTIONS).astype(np.int64)
    spread = int(np.ceil(_VOTE_SPREAD_DEG / 180.0 * _DIRECTIONS))
    # Every pixel's votes for its own direction +- spread.
    # (And those lines with at least 20 votes, in the order of (direction, offset).)
    lines, votes = kernels.hough_lines(rows, cols, own, spread, cos_a, sin_a, reach, 20)
    # Each candidate's densest stretch first (cheap), then the checks from the longest down:
    # the first that passes them all is the best.
    # The _CANDIDATES lines with most votes, at least 20; equal votes in the order of
    # (direction, offset).
    lines = lines[np.argsort(-votes, kind="stable")][:_CANDIDATES]
    line_a, line_rho = np.divmod(lines, 2 * reach + 1)
    line_rho -= reach
    # Each line's chord through the part, its densest stretch and whether that reaches the
    # outline at both ends (one compiled pass over all lines).
    lengths, reaches, stretch_rows, stretch_cols, bounds = kernels.line_stretches(
        part,
        near_edge,
        np.array([window[0].start, window[0].stop, window[1].start, window[1].stop]),
        cos_a[line_a],
        sin_a[line_a],
        line_rho.astype(np.float64),
        float(seams.coverage),
        20,
    )
    stretches = [
        (int(lengths[k]), int(line_a[k]), int(line_rho[k]), bool(reaches[k]),
         stretch_rows[bounds[k] : bounds[k + 1]], stretch_cols[bounds[k] : bounds[k + 1]], k)
        for k in np.flatnonzero(lengths)
    ]  # fmt: skip
    stretches.sort(key=lambda item: -item[0])  # stable: ties keep the vote order
    # Only a stretch that reaches the outline at both ends can cut.
    stretches = [stretch for stretch in stretches if stretch[3]]
    if not stretches:
        return None
    # A compiled screen first: every candidate's 3D length (``kernels.stretch_lengths``), then
    # the next one with room for two pieces and side bands of one normal
    # (``kernels.seam_screen``). It drops only candidates that the checks below drop (its
    # margins exceed its rounding), and the one it finds takes those checks as before, in the
    # same order: the first candidate that passes them all is the same.
    which = np.array([stretch[6] for stretch in stretches], dtype=np.int64)
    long_enough = kernels.stretch_lengths(stretch_rows, stretch_cols, bounds, which, depth_m,
                                          points) >= seams.min_length_m * (1.0 - _SCREEN_MARGIN)  # fmt: skip
    if not long_enough.any():
        return None
    stretches = [stretch for stretch, keep in zip(stretches, long_enough, strict=True) if keep]
    # The part's pixels with a normal, row-major (the side bands' pixels are among them).
    part_rows, part_cols = np.nonzero(part[window] & has_normal[window])
    part_pixels = (part_rows + top_px, part_cols + left_px)
    room = _Room(part, window, depth_m, focal_px)
    near, far = _SIDE_BAND_PX
    candidates = np.array([stretch[6] for stretch in stretches], dtype=np.int64)
    line_cos, line_sin = cos_a[line_a], sin_a[line_a]
    line_offsets = line_rho.astype(np.float64)
    found = -1
    while True:
        # The next candidate that passes the screen (compiled), then the checks as before.
        found = kernels.seam_screen(
            candidates, line_cos, line_sin, line_offsets, stretch_rows, stretch_cols, bounds,
            room.rows, room.cols, room.foot, room.size,
            float(seams.min_area_m2), float(seams.min_width_m),
            part_pixels[0], part_pixels[1], height, width, float(near), float(far),
            normals, float(seams.max_normal_deg) + _SCREEN_MARGIN, found + 1,
        )  # fmt: skip
        if found < 0:
            return None
        _, a, rho, _, line_rows, line_cols, _ = stretches[found]
        # Its length between its outermost pixels with depth (label images fill dropouts).
        measured = np.flatnonzero(depth_m[line_rows, line_cols] > 0)
        if measured.size < 2:
            continue
        ends = measured[[0, -1]]
        ends_3d = points[line_rows[ends], line_cols[ends]]
        if np.linalg.norm(ends_3d[0] - ends_3d[1]) < seams.min_length_m:
            continue
        # (Room for a piece of the smallest area and width on each side of the line: the
        # screen's ``_Room.fits``, the same numbers.)
        normal = _coplanar_sides(part_pixels, part.shape, line_rows, line_cols, cos_a[a],
                                 sin_a[a], rho, points, normals, config)  # fmt: skip
        if normal is None:
            continue
        seam = _straight_seam(line_rows[measured], line_cols[measured], points, normal,
                              cos_a[a], sin_a[a], config)  # fmt: skip
        if seam is None:
            continue
        side = _split(part, line_rows, line_cols, depth_m, focal_px, config)
        if side is not None:
            return side, seam


class _Room:
    """A part's pixels in its window with their footprints (m^2) and sizes (m per px; pixels
    without depth take the median depth of the others, as ``_area_m2``), for ``fits``."""

    def __init__(self, part: np.ndarray, window: tuple[slice, slice], depth_m: np.ndarray,
                 focal_px: float) -> None:  # fmt: skip
        if depth_m.dtype == np.float32:  # compiled, the same numbers
            self.rows, self.cols, self.size, self.foot = kernels.room_pixels(
                part[window], depth_m[window], window[0].start, window[1].start, float(focal_px)
            )
            return
        rows, cols = np.nonzero(part[window])
        measured = depth_m[window][rows, cols]
        depths = measured.astype(np.float64)
        known = depths > 0
        if not known.all():
            fill = _masked_median(measured, known, np.float64) if known.any() else 0.0
            depths = np.where(known, depths, fill)
        self.rows = rows + window[0].start
        self.cols = cols + window[1].start
        self.size = depths / focal_px
        self.foot = self.size**2

    def fits(self, cos_a: float, sin_a: float, rho: float, config: PerceptionConfig) -> bool:
        """Whether each side of the line x cos a + y sin a = rho holds pixels enough for a piece
        of ``seams.min_area_m2`` and ``seams.min_width_m`` (the search's compiled screen,
        ``kernels.seam_screen``, computes the same; ``kernels.line_sides``: upper bounds;
        a trial cut that fails them fails ``_split``, which judges the pieces, for any part whose
        pieces lie within the line's two half-planes: every convex part)."""
        sides = kernels.line_sides(self.rows, self.cols, self.foot, self.size, float(cos_a),
                                   float(sin_a), float(rho))  # fmt: skip
        seams = config.seams
        return bool(
            np.all(sides[:, 0] >= seams.min_area_m2)
            and np.all(np.minimum(sides[:, 1], sides[:, 2]) >= seams.min_width_m)
        )


def _straight_seam(
    rows: np.ndarray,
    cols: np.ndarray,
    points: np.ndarray,
    normal: np.ndarray,
    cos_a: float,
    sin_a: float,
    config: PerceptionConfig,
) -> _Seam | None:
    """The seam through the pixels (rows, cols) with depth, or None when its 3D points bend:
    a straight image line on a plane is a straight 3D line, on a ball, a can or a bottle it is
    a curve. Its middle 80 % (its ends may run onto the boxes' sides) must lie within
    ``seams.max_bend_m`` of one 3D line at the 90th percentile (depth noise and ripples)."""
    seam_points = points[rows, cols].astype(np.float64)
    count = len(seam_points)
    middle = seam_points[int(0.1 * count) : int(np.ceil(0.9 * count))]
    if len(middle) < 2:
        return None
    centre = middle.mean(axis=0)
    direction = np.linalg.svd(middle - centre, full_matrices=False)[2][0]
    offsets = middle - centre
    bend = np.linalg.norm(offsets - np.outer(offsets @ direction, direction), axis=1)
    if _percentiles(bend, (90.0,))[0] > config.seams.max_bend_m:
        return None
    across = np.cross(normal, direction)
    across_norm = float(np.linalg.norm(across))
    if across_norm < 1e-9:
        return None
    extent = (seam_points - centre) @ direction
    return _Seam(
        rows=rows,
        cols=cols,
        cos_a=float(cos_a),
        sin_a=float(sin_a),
        middle=centre,
        direction=direction,
        across=across / across_norm,
        normal=normal,
        half_length_m=float(extent.max() - extent.min()) / 2.0,
    )


def _coplanar_sides(
    part_pixels: tuple[np.ndarray, np.ndarray],
    shape: tuple[int, int],
    rows: np.ndarray,
    cols: np.ndarray,
    cos_a: float,
    sin_a: float,
    rho: float,
    points: np.ndarray,
    normals: np.ndarray,
    config: PerceptionConfig,
) -> np.ndarray | None:
    """The surfaces' unit normal (3,) when the surfaces along both sides of the seam
    (``_SIDE_BAND_PX`` away, within its extent) have one normal (``seams.max_normal_deg``) and
    no step (``seams.max_step_m``), else None. ``part_pixels``: the (rows, cols) (int64, in
    the crop of ``shape``) of the part's pixels with a normal, row-major: the bands are chosen
    among them (``kernels.seam_side_bands``), not among every pixel of the seam's box."""
    near, far = _SIDE_BAND_PX
    top, bottom = max(rows.min() - far, 0), min(rows.max() + far + 1, shape[0])
    left, right = max(cols.min() - far, 0), min(cols.max() + far + 1, shape[1])
    yy, xx = part_pixels
    seam_along = -cols * sin_a + rows * cos_a
    bands = kernels.seam_side_bands(
        yy,
        xx,
        np.array([top, bottom, left, right], dtype=np.int64),
        float(cos_a),
        float(sin_a),
        float(rho),
        np.array([seam_along.min(), seam_along.max()]),
        float(near),
        float(far),
    )
    if len(bands[0]) < 20 or len(bands[1]) < 20:
        return None
    normal_a, normal_b = (kernels.mean_at(normals, yy[chosen], xx[chosen]) for chosen in bands)
    normal_a /= max(np.linalg.norm(normal_a), 1e-12)
    normal_b /= max(np.linalg.norm(normal_b), 1e-12)
    cos_angle = float(np.clip(normal_a @ normal_b, -1.0, 1.0))
    if np.degrees(np.arccos(cos_angle)) > config.seams.max_normal_deg:
        return None
    normal = normal_a + normal_b
    normal /= max(np.linalg.norm(normal), 1e-12)
    points_a, points_b = (points[yy[chosen], xx[chosen]] for chosen in bands)
    step = abs(float(np.median(points_a @ normal) - np.median(points_b @ normal)))
    return normal if step <= config.seams.max_step_m else None


def _split(
    part: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    depth_m: np.ndarray,
    focal_px: float,
    config: PerceptionConfig,
) -> np.ndarray | None:
    """(h, w) bool: the second-largest piece left when the seam (3 px wide) is removed from
    ``part``, with the seam and crumbs given to the nearest of the two largest pieces; None
    when the seam does not cut ``part`` into two pieces large and wide enough.

    All of it is computed inside ``part``'s bounding box and a 1 px ring around it, each
    piece's inscribed radius inside its own box and ring (``_window``): the nearest pixel
    outside a 4-connected piece lies there (straight along a row or a column from any of its
    pixels), so the figures are those of the whole crop at a fraction of the pixels."""
    height, width = part.shape
    window = _window(part, part.shape)
    top, left = window[0].start, window[1].start
    sub = part[window]
    sub_depth = depth_m[window]
    seam = np.zeros(sub.shape, dtype=bool)
    # The seam's 3 x 3 neighbourhood, clipped to the crop as a whole, kept inside the window.
    r = np.clip(rows[:, None] + _NEIGHBOURS[0], 0, height - 1) - top
    c = np.clip(cols[:, None] + _NEIGHBOURS[1], 0, width - 1) - left
    inside = (r >= 0) & (r < sub.shape[0]) & (c >= 0) & (c < sub.shape[1])
    seam[r[inside], c[inside]] = True
    seam &= sub
    # Compiled: ``ndimage.label(sub & ~seam)``'s labels and count (4-connected).
    pieces, count = kernels.label_four_connected(sub & ~seam)
    if count < 2:
        return None
    sizes = np.bincount(pieces.ravel())[1:]
    largest = np.argsort(sizes)[::-1][:2] + 1
    masks = [pieces == piece for piece in largest]
    # Areas first, then the widths, the smaller piece first each time: cheaper, and the one
    # that fails when either does (a sliver cut off the outline); either failing is a None.
    for inside in masks[::-1]:
        if not _has_area(inside, sub_depth, focal_px, config.seams.min_area_m2):
            return None
    for inside in masks[::-1]:
        box = _window(inside, sub.shape)
        # Each piece's largest inscribed radius: the seam and the outside bound every piece
        # (``distance_transform_edt(pieces > 0)[inside].max()``, the root of an integer).
        squared = kernels.largest_inscribed_squared(inside[box], pieces[box] > 0)
        if squared < 0:
            squared = ndimage.distance_transform_edt(pieces[box] > 0)[inside[box]].max() ** 2
        depths = sub_depth[inside]
        depths = depths[depths > 0]
        radius_px = float(np.sqrt(float(squared)))
        if 2.0 * radius_px * _masked_median(depths) / focal_px < config.seams.min_width_m:
            return None
    two = np.where(masks[0], 1, np.where(masks[1], 2, 0))
    nearest = ndimage.distance_transform_edt(two == 0, return_distances=False, return_indices=True)
    side = np.zeros(part.shape, dtype=bool)
    side[window] = sub & (two[nearest[0], nearest[1]] == 2)
    return side


def _window(mask: np.ndarray, shape: tuple[int, int]) -> tuple[slice, slice]:
    """The bounding box of ``mask`` ((h, w) bool, not empty) and a 1 px ring, within
    ``shape``."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    return (
        slice(max(int(rows[0]) - 1, 0), min(int(rows[-1]) + 2, shape[0])),
        slice(max(int(cols[0]) - 1, 0), min(int(cols[-1]) + 2, shape[1])),
    )


#: Relative margin of ``_has_area``'s bounds: well above the float32 rounding of ``_area_m2``'s
#: sum (about 1e-6 relative for a million pixels), so that a bound decides only what
#: ``_area_m2`` would decide the same way.
_AREA_ROUNDING = 1e-4


def _has_area(part: np.ndarray, depth_m: np.ndarray, focal_px: float, area_m2: float) -> bool:
    """Whether ``_area_m2(part, depth_m, focal_px) >= area_m2``, without the median of its
    pixels with depth where it cannot decide: the pixels without depth take that median,
    which lies between their smallest and largest depth, so the area lies between the bounds
    with either; only when ``area_m2`` lies between them is the area itself computed."""
    depths = depth_m[part]
    has_depth = depths > 0
    if has_depth.all():
        return float(np.sum(depths**2)) / focal_px**2 >= area_m2
    known = depths[has_depth]
    if known.size == 0:
        return area_m2 <= 0.0
    missing = depths.size - known.size
    base = float(np.sum(known.astype(np.float64) ** 2))
    low = (base + missing * float(known.min()) ** 2) / focal_px**2
    high = (base + missing * float(known.max()) ** 2) / focal_px**2
    if low * (1.0 - _AREA_ROUNDING) >= area_m2:
        return True
    if high * (1.0 + _AREA_ROUNDING) < area_m2:
        return False
    return _area_m2(part, depth_m, focal_px) >= area_m2


def _area_m2(part: np.ndarray, depth_m: np.ndarray, focal_px: float) -> float:
    """Area (m^2) of the pixels of ``part``, each a (depth / focal)^2 square (pixels without
    depth take the median depth of the others)."""
    depths = depth_m[part]
    has_depth = depths > 0
    if has_depth.all():  # nothing to fill: the median would not be used
        return float(np.sum(depths**2)) / focal_px**2
    known = depths[has_depth]
    if known.size == 0:
        return 0.0
    filled = np.where(has_depth, depths, _masked_median(depths, has_depth))
    return float(np.sum(filled**2)) / focal_px**2
