"""How much of each object's image outline something nearer hides (issue 28).

A convex object's silhouette is where the camera's rays graze it: a ray just outside the
outline passes the object and meets something farther away (the support behind it, the
background), or the surface it stands on at the contact. So across an outline pixel pair the
outside pixel is nearer than the object's pixel only where another surface stands in front and
hides the object's continuation: an occluder (another object, the robot, a wall's rim), or the
image's end. The fraction of an object's outline that is hidden this way says how much of the
object's extent the seen part may not show; the Collision Checker's medoid weights use it
(``CollisionCheckerConfig.medoid_weights = "outline"``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ipr_shapes.perception.types import PartialObject


def hidden_outline_fractions(
    depth_m: np.ndarray, objects: Sequence[PartialObject], step_m: float
) -> dict[int, float]:
    """Per object id, the fraction of its image outline that a nearer surface or the image
    border hides, in [0, 1].

    Args:
        depth_m: (H, W) depth along the optical axis (m) of the frame the objects were
            segmented in, 0 where no reading.
        objects: the frame's partial objects; ``pixels`` (N,) flat indices into ``depth_m``
            (entries < 0, points added from other frames, are ignored).
        step_m: a depth step (m) that is not the surface running on (the segmentation's
            ``contour_gap_m``): an outside pixel nearer than the object's by more is in front.

    Each 4-neighbour pixel pair across an object's outline (inside the object, outside it) is
    hidden when the outside pixel lies beyond the image or is nearer by more than ``step_m``,
    seen when it has a reading that is not; pairs whose outside pixel has no reading say
    nothing and are left out. An object with no counted pair gets 0 (nothing says it is hidden).
    """
    depth = np.asarray(depth_m, dtype=np.float64)
    height, width = depth.shape
    labels = np.zeros(height * width, dtype=np.int64)
    for number, obj in enumerate(objects, 1):
        pixels = np.asarray(obj.pixels)
        labels[pixels[pixels >= 0]] = number
    labels = labels.reshape(height, width)
    # Pad by one pixel labelled -1: the image's end, where every outline pair is hidden.
    padded_labels = np.pad(labels, 1, constant_values=-1)
    padded_depth = np.pad(depth, 1, constant_values=0.0)
    hidden = np.zeros(len(objects) + 1)
    seen = np.zeros(len(objects) + 1)
    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        outside_labels = padded_labels[1 + dy : height + 1 + dy, 1 + dx : width + 1 + dx]
        outside_depth = padded_depth[1 + dy : height + 1 + dy, 1 + dx : width + 1 + dx]
        pair = (labels > 0) & (outside_labels != labels)
        beyond = pair & (outside_labels < 0)
        read = pair & (outside_labels >= 0) & (outside_depth > 0)
        nearer = read & (outside_depth < depth - step_m)
        hidden += np.bincount(labels[beyond | nearer], minlength=len(hidden))
        seen += np.bincount(labels[read & ~nearer], minlength=len(hidden))
    total = hidden + seen
    fractions = np.divide(hidden, total, out=np.zeros_like(hidden), where=total > 0)
    return {obj.id: float(fractions[number]) for number, obj in enumerate(objects, 1)}
