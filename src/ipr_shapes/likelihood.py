"""The physical likelihood of a joint model (paper Eq. 2): how well depth images rendered from
its simulation match the observed ones.

    P(O | X, mu) = exp(-alpha * sum_t sum_i ||O_{i,t} - Ohat_{i,t}(X, mu_0..t)||_2)

For object i in frame t, the observed object O_{i,t} is its tracked segment (perception labels,
``ipr_shapes.perception``) with the observed depth, and the prediction Ohat_{i,t} is object i's pixels
in the depth image rendered from frame t's camera after simulating X under gravity and the pushes
before frame t (``ipr_shapes.physics``; the rendering includes the support and walls). The depth
difference is taken over the pixels either covers, and compares the observed depth with the
rendered scene's depth there, whatever the model shows at that pixel:

- covered by both, or observed only: |observed - rendered| depth. Where the model shows another
  object at the right depth the error is small: the comparison is of geometry, so pixels the
  segmentation gave to the wrong object cost nothing when the shapes explain them. Where the
  model shows nothing (no object, support or wall) the error is ``error_cap_m``.
- predicted only: if the observed depth there is nearer than the prediction by more than
  ``occlusion_margin_m``, something the camera saw (another object, the robot) hides that part
  and the pixel is no evidence: skipped; otherwise |observed - predicted| (the camera saw
  through where the model puts the object);
- missing depth (0) and robot-mask pixels are skipped (no evidence either way).

"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import ClassVar, Literal, get_args

import numpy as np

from ipr_shapes.checks import Checks, Interval, Options, check_fields
from ipr_shapes.physics import decimated_camera, decimated_pixels
from ipr_shapes.rendering import PinholeCamera
from ipr_shapes.scene import Frame

#: How the frames after the pushes enter Eq. 2's sum (``LikelihoodConfig.pushed_frames``).
PushedFrames = Literal["each", "trajectory"]
PUSHED_FRAMES: tuple[str, ...] = get_args(PushedFrames)


@dataclass(frozen=True)
class LikelihoodConfig:
    """Parameters of the physical likelihood (module doc).

    Attributes:
        alpha_per_m: alpha of Eq. 2 (1/m), the weight of the depth error norm (full-resolution
            L2 norm, m). Small, since the depth evidence is weak and noisy, so it should tilt,
            not decide: IoU fell as alpha rose on development scenes (docs/DESIGN_NOTES.md,
            "Likelihood: alpha 0.2 per metre, whole rendered scene").
        decimation: images are compared at 1/decimation of the input resolution.
        error_cap_m: largest per-pixel depth error (m).
        occlusion_margin_m: an observed surface this much nearer than the prediction hides it.
        pushed_frames: how the frames from the first push on enter the sum over frames
            (``frame_weights``): "each" (every frame its own term, Eq. 2 as written) or
            "trajectory" (their terms averaged: the replayed pushes are one observation, of
            the weight of one frame at rest). Why: a frame after a push shows the state the
            replay reached through every push before it, so its error repeats the earlier
            pushes' divergence (the replay diverges from the data by about 27 mm per moved
            object, issue 29): summed, the pushes' chaotic term counts once per later frame
            and outweighs the frame at rest, whose ranking of the candidates is the better
            one. Opt-in: it gained on the development sets at 30 and 150 samples and on
            ycb-dynamic at 50 and 100, but lost on one development set at 50 and 75 samples
            (near-tie flips either way)
            (docs/experiments/2026-11-28-push-evidence.md).
    """

    CHECKS: ClassVar[Checks] = {
        "alpha_per_m": Interval(0, None),
        "decimation": Interval(1, None, integer=True),
        "error_cap_m": Interval(0, None, closed="neither"),
        "occlusion_margin_m": Interval(0, None),
        "pushed_frames": Options(*PUSHED_FRAMES),
    }

    alpha_per_m: float = 0.2
    decimation: int = 4
    error_cap_m: float = 0.1
    occlusion_margin_m: float = 0.01
    pushed_frames: PushedFrames = "each"

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True, eq=False)
class ObservedFrames:
    """The observations the likelihood compares with, at the comparison resolution.

    Attributes:
        frames: (T,) frame indices.
        cameras: per frame, its decimated camera (``ipr_shapes.physics.decimated_camera``).
        depth_m: (T, h, w) float32 observed depth (m, 0 = no reading).
        labels: (T, h, w) int32 tracked object ids (0 = no object).
        ignore: (T, h, w) bool pixels to skip (robot mask).
        decimation: the factor between input and comparison resolution.
    """

    frames: tuple[int, ...]
    cameras: tuple[PinholeCamera, ...]
    depth_m: np.ndarray
    labels: np.ndarray
    ignore: np.ndarray
    decimation: int

    def only(self, count: int) -> ObservedFrames:
        """The first ``count`` frames."""
        return ObservedFrames(
            self.frames[:count],
            self.cameras[:count],
            self.depth_m[:count],
            self.labels[:count],
            self.ignore[:count],
            self.decimation,
        )


def observed_frames(
    frames: Sequence[Frame], labels: Sequence[np.ndarray], decimation: int
) -> ObservedFrames:
    """Decimate ``ipr_shapes.scene.Frame``s and their (H, W) tracked label images."""
    cameras, depths, ids, ignores = [], [], [], []
    for frame, label in zip(frames, labels, strict=True):
        height, width = frame.depth_m.shape
        cameras.append(
            decimated_camera(frame.K, width, height, frame.world_from_camera, decimation)
        )
        depths.append(decimated_pixels(np.asarray(frame.depth_m, np.float32), decimation))
        ids.append(decimated_pixels(np.asarray(label, np.int32), decimation))
        robot = frame.robot_mask if frame.robot_mask is not None else np.zeros_like(label, bool)
        ignores.append(decimated_pixels(np.asarray(robot, bool), decimation))
    return ObservedFrames(
        tuple(int(f.index) for f in frames),
        tuple(cameras),
        np.stack(depths),
        np.stack(ids),
        np.stack(ignores),
        decimation,
    )


def depth_error_norms(
    observed_depth: np.ndarray,
    observed_labels: np.ndarray,
    ignore: np.ndarray,
    predicted_depth: np.ndarray,
    predicted_ids: np.ndarray,
    object_ids: Sequence[int],
    config: LikelihoodConfig,
) -> np.ndarray:
    """(n,) ||O_i - Ohat_i||_2 (m) of each object of ``object_ids`` in one frame (module doc).

    Args:
        observed_depth: (h, w) m, 0 = no reading.
        observed_labels: (h, w) tracked ids, 0 = none.
        ignore: (h, w) bool pixels to skip.
        predicted_depth: (h, w) m rendered depth of the scene (objects, support, walls),
            0 = nothing drawn.
        predicted_ids: (h, w) object id of the front-most predicted object, 0 = none.
        object_ids: the objects to score.
    """
    valid = (observed_depth > 0) & ~ignore
    difference = np.minimum(np.abs(observed_depth - predicted_depth), config.error_cap_m)
    hidden = observed_depth < predicted_depth - config.occlusion_margin_m
    squared = np.zeros(len(object_ids))
    for k, object_id in enumerate(object_ids):
        observed = valid & (observed_labels == object_id)
        predicted = valid & (predicted_ids == object_id)
        both = observed & predicted
        only_predicted = predicted & ~observed & ~hidden
        only_observed = observed & ~predicted
        squared[k] = (
            float(np.sum(difference[both] ** 2))
            + float(np.sum(difference[only_predicted] ** 2))
            + float(np.sum(difference[only_observed] ** 2))
        )
    return np.sqrt(squared)


def frame_weights(
    frames: Sequence[int], pushed: Collection[int], config: LikelihoodConfig
) -> np.ndarray:
    """(T,) each compared frame's weight in Eq. 2's sum over frames
    (``LikelihoodConfig.pushed_frames``): 1 for every frame before the first push; from the
    first frame a push precedes on (``pushed``: the frame indices a push is replayed before,
    ``Push.after_frame``), 1 each ("each") or 1 / their count ("trajectory")."""
    weights = np.ones(len(frames))
    after = [p for p, frame in enumerate(frames) if frame in pushed]
    if after and config.pushed_frames == "trajectory":
        weights[after[0] :] = 1.0 / (len(frames) - after[0])
    return weights


def log_likelihood(
    norms: np.ndarray,
    decimation: int,
    config: LikelihoodConfig,
    weights: np.ndarray | None = None,
) -> float:
    """log P(O | X, mu) from the (T, n) per-frame, per-object norms at the comparison
    resolution: -alpha * decimation * sum (module doc), each frame's norms times its
    ``weights`` ((T,), ``frame_weights``; None: 1)."""
    norms = np.asarray(norms, float)
    if weights is not None:
        norms = norms * np.asarray(weights, float)[:, None]
    return -config.alpha_per_m * decimation * float(np.sum(norms))
