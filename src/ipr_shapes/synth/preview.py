"""A picture of a generated scene to check at a glance: one row per frame with the RGB image,
the colour-mapped depth, and the ground-truth object outlines and ids over the RGB image; each
push is drawn as an arrow (start to end of the capsule centre) on the frame before it."""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from ipr_shapes.camera import apply_transform, invert_transform, project
from ipr_shapes.scene import Frame, Push

# Anchor colours of a perceptual colour map (viridis-like), dark = near.
_COLOUR_MAP = np.array(
    [
        [68, 1, 84],
        [59, 82, 139],
        [33, 145, 140],
        [94, 201, 98],
        [253, 231, 37],
    ],
    dtype=np.float64,
)

_OBJECT_COLOURS = np.array(
    [
        [255, 64, 64],
        [64, 220, 64],
        [80, 140, 255],
        [255, 210, 0],
        [255, 0, 255],
        [0, 230, 230],
        [255, 140, 0],
        [180, 100, 255],
        [255, 255, 255],
        [140, 255, 140],
    ],
    dtype=np.uint8,
)


def colour_map_depth(depth_m: np.ndarray, focus: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 3) uint8 colour-mapped depth; 0 (no reading) is black.

    The colour range spans the valid depths of the ``focus`` pixels (H, W) bool (the objects)
    with a margin, or the 2nd to 98th percentile of the whole image without focus.
    """
    valid = depth_m > 0
    result = np.zeros((*depth_m.shape, 3), dtype=np.uint8)
    if not valid.any():
        return result
    if focus is not None and (focus & valid).sum() > 10:
        low, high = np.percentile(depth_m[focus & valid], [1, 99])
        low, high = low - 0.02, high + 0.08
    else:
        low, high = np.percentile(depth_m[valid], [2, 98])
    scaled = np.clip((depth_m - low) / max(high - low, 1e-6), 0, 1) * (len(_COLOUR_MAP) - 1)
    index = np.minimum(scaled.astype(int), len(_COLOUR_MAP) - 2)
    fraction = (scaled - index)[..., None]
    colours = _COLOUR_MAP[index] * (1 - fraction) + _COLOUR_MAP[index + 1] * fraction
    result[valid] = np.round(colours[valid]).astype(np.uint8)
    return result


def _outlines(rgb: np.ndarray, labels: np.ndarray, obj_ids: Sequence[int]) -> Image.Image:
    """RGB (dimmed) with each visible object's boundary coloured and its BOP id written."""
    image = (rgb.astype(np.float32) * 0.6).astype(np.uint8)
    border = np.zeros(labels.shape, dtype=bool)
    border[:-1] |= labels[:-1] != labels[1:]
    border[1:] |= labels[:-1] != labels[1:]
    border[:, :-1] |= labels[:, :-1] != labels[:, 1:]
    border[:, 1:] |= labels[:, :-1] != labels[:, 1:]
    for index in range(len(obj_ids)):
        mask = border & (labels == index)
        image[mask] = _OBJECT_COLOURS[index % len(_OBJECT_COLOURS)]
    return Image.fromarray(image)


def _label_ids(
    draw: ImageDraw.ImageDraw,
    labels: np.ndarray,
    obj_ids: Sequence[int],
    scale: float,
    font: ImageFont.ImageFont,
) -> None:
    for index, obj_id in enumerate(obj_ids):
        rows, cols = np.nonzero(labels == index)
        if rows.size == 0:
            continue
        x, y = float(np.median(cols)) * scale, float(np.median(rows)) * scale
        colour = tuple(int(c) for c in _OBJECT_COLOURS[index % len(_OBJECT_COLOURS)])
        draw.text(
            (x - 6, y - 6),
            str(obj_id),
            fill=colour,
            font=font,
            stroke_width=2,
            stroke_fill=(0, 0, 0),
        )


def _arrow(
    draw: ImageDraw.ImageDraw, push: Push, frame: Frame, scale: float, drop_m: float
) -> None:
    """Arrow of the capsule's path ``drop_m`` below its centre (near its lower tip)."""
    camera_from_world = invert_transform(frame.world_from_camera)
    ends = np.stack([push.start_m, push.end_m]) - [0.0, 0.0, drop_m]
    ends = apply_transform(camera_from_world, ends)
    if np.any(ends[:, 2] <= 0.01):
        return
    (x0, y0), (x1, y1) = project(ends, frame.K) * scale
    draw.line([(x0, y0), (x1, y1)], fill=(255, 40, 40), width=3)
    angle = np.arctan2(y1 - y0, x1 - x0)
    for side in (-1, 1):
        tip = angle + np.pi + side * 0.45
        draw.line(
            [(x1, y1), (x1 + 10 * np.cos(tip), y1 + 10 * np.sin(tip))], fill=(255, 40, 40), width=3
        )
    radius = 4
    draw.ellipse(
        [x0 - radius, y0 - radius, x0 + radius, y0 + radius], outline=(255, 40, 40), width=2
    )


def preview_png(
    frames: Sequence[Frame],
    labels: Sequence[np.ndarray],
    obj_ids: Sequence[int],
    pushes: Sequence[Push],
    panel_width: int,
    title: str,
    pusher_drop_m: float = 0.0,
) -> bytes:
    """PNG bytes of the preview; ``labels[k]`` is frame k's (H, W) object-index image.

    Push arrows are drawn ``pusher_drop_m`` below the capsule centre (the generator passes the
    height of the capsule's lower cap centre, where it meets the pile).
    """
    height, width = frames[0].depth_m.shape
    scale = panel_width / width
    panel = (panel_width, max(1, int(round(height * scale))))
    header = 18
    canvas = Image.new(
        "RGB", (3 * panel[0], header + len(frames) * (panel[1] + header)), (24, 24, 24)
    )
    draw = ImageDraw.Draw(canvas)
    font = ImageFont.load_default()
    draw.text((4, 3), title, fill=(230, 230, 230), font=font)
    for row, (frame, label) in enumerate(zip(frames, labels, strict=True)):
        top = header + row * (panel[1] + header)
        push = next((p for p in pushes if p.before_frame == frame.index), None)
        caption = f"frame {frame.index}: RGB | depth | ground truth (obj ids)"
        if push is not None:
            caption += f"   push -> frame {push.after_frame}: {push.distance_m * 100:.1f} cm"
        draw.text((4, top + 3), caption, fill=(230, 230, 230), font=font)
        tiles = [
            Image.fromarray(frame.rgb),
            Image.fromarray(colour_map_depth(frame.depth_m, label >= 0)),
            _outlines(frame.rgb, label, obj_ids),
        ]
        for column, tile in enumerate(tiles):
            tile = tile.resize(panel, Image.Resampling.BILINEAR)
            tile_draw = ImageDraw.Draw(tile)
            if column == 2:
                _label_ids(tile_draw, label, obj_ids, scale, font)
            if push is not None and column in (0, 2):
                _arrow(tile_draw, push, frame, scale, pusher_drop_m)
            canvas.paste(tile, (column * panel[0], top + header))
    buffer = io.BytesIO()
    canvas.save(buffer, format="PNG", optimize=False)
    return buffer.getvalue()
