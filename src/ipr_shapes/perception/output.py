"""``ipr-shapes segment`` output: label images, facet images and overlays a person can check at a glance.

Layout of OUT (written to a temporary folder, then renamed into place):

    labels/NNNNNN.png    0 = background or support, k >= 1 = object k (same k in every frame)
    facets/NNNNNN.png    0 = none, f >= 1 = facet f of that frame
    overlay/NNNNNN.png   RGB with objects tinted by id, facet borders and id labels; the known
                         planes' pixels in flat colours (``known_plane_pixels``): the support
                         blue, what lies below it dark blue, walls ochre
    segmentation.json    per frame: objects (id, pixels, facets, border), planes; timings

Label images (``label_png``) hold the ids themselves as pixel values, in an 8-bit palette PNG
whose palette is ``palette``'s colour per id (0 black) when every id is below 256 (the PASCAL
VOC convention: PIL and imageio read the ids, a picture viewer shows the colours, not the near
black that small ids are in a grey image), else in a 16-bit grey PNG.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from ipr_shapes.atomic import staged_directory, write_json
from ipr_shapes.errors import IprError
from ipr_shapes.perception import Perception, PerceptionConfig
from ipr_shapes.perception.planes import static_geometry_mask
from ipr_shapes.perception.types import KnownPlane
from ipr_shapes.scene import Frame, Scene

#: Codes of ``known_plane_pixels``: no known plane, on the support (within its clearance),
#: below the support, on a wall.
KNOWN_NONE, KNOWN_SUPPORT, KNOWN_BELOW, KNOWN_WALL = 0, 1, 2, 3
#: Flat overlay colour of each code (none: the dimmed image itself).
KNOWN_COLOURS = {
    KNOWN_SUPPORT: (40, 110, 230),
    KNOWN_BELOW: (20, 40, 100),
    KNOWN_WALL: (200, 150, 40),
}


def palette(ids: np.ndarray) -> np.ndarray:
    """A distinct, deterministic RGB colour (N, 3) uint8 per integer id (golden-angle hues)."""
    hue = (np.asarray(ids, dtype=np.float64) * 0.618033988749895) % 1.0
    h6 = hue * 6.0
    x = 1.0 - np.abs(h6 % 2.0 - 1.0)
    sector = h6.astype(int) % 6
    zero, one = np.zeros_like(hue), np.ones_like(hue)
    table = [
        (one, x, zero),
        (x, one, zero),
        (zero, one, x),
        (zero, x, one),
        (x, zero, one),
        (one, zero, x),
    ]
    rgb = np.stack([np.choose(sector, [t[c] for t in table]) for c in range(3)], axis=-1)
    return (55 + 200 * rgb).astype(np.uint8)


def label_png(labels: np.ndarray) -> bytes:
    """A label image (H, W) of non-negative integer ids as PNG bytes (module doc): 8-bit with
    ``palette``'s colours when the largest id is below 256, else 16-bit grey; either way
    ``np.asarray(PIL.Image.open(...))`` gives the ids back. ValueError for negative ids or ids
    above 65535."""
    import io

    labels = np.asarray(labels)
    if labels.ndim != 2 or labels.dtype.kind not in "iub":
        raise ValueError(f"labels must be a 2-D integer image, got {labels.dtype} {labels.shape}")
    largest = int(labels.max()) if labels.size else 0
    if (labels.size and int(labels.min()) < 0) or largest > 65535:
        raise ValueError("label ids must be in 0..65535")
    buffer = io.BytesIO()
    if largest < 256:
        image = Image.fromarray(labels.astype(np.uint8))  # "L"; putpalette makes it "P"
        colours = palette(np.arange(256))
        colours[0] = 0
        image.putpalette(colours.reshape(-1).tolist())
    else:
        image = Image.fromarray(labels.astype(np.uint16))
    image.save(buffer, format="PNG")
    return buffer.getvalue()


def known_plane_pixels(
    frame: Frame, planes: tuple[KnownPlane, ...], config: PerceptionConfig | None = None
) -> np.ndarray:
    """(H, W) uint8 code of each pixel with a depth reading by the frame's known planes:
    ``KNOWN_SUPPORT`` less than ``support.clearance_m`` above or below the support (what was
    taken as the table), ``KNOWN_BELOW`` further below it, ``KNOWN_WALL`` a wall's pixels
    (``static_geometry_mask``), else ``KNOWN_NONE`` (also every pixel when there is no
    support)."""
    config = config or PerceptionConfig()
    height, width = frame.shape
    codes = np.zeros(height * width, dtype=np.uint8)
    support = next((plane for plane in planes if plane.kind == "support"), None)
    if support is None:
        return codes.reshape(height, width)
    valid = np.flatnonzero(frame.depth_m.reshape(-1) > 0)
    points = frame.points_world().reshape(-1, 3)[valid].astype(np.float64)
    heights = support.signed_distance(points)
    clearance = config.support.clearance_m
    static = static_geometry_mask(points, planes, config)
    codes[valid[static]] = KNOWN_WALL
    codes[valid[np.abs(heights) < clearance]] = KNOWN_SUPPORT
    codes[valid[heights <= -clearance]] = KNOWN_BELOW
    return codes.reshape(height, width)


def overlay_image(
    rgb: np.ndarray,
    labels: np.ndarray,
    facet_labels: np.ndarray,
    known: np.ndarray | None = None,
) -> Image.Image:
    """RGB (H, W, 3) with objects tinted by id, facet borders darkened and ids written; with
    ``known`` (``known_plane_pixels``), the known planes' pixels that are not objects in their
    colours (``KNOWN_COLOURS``, with a quarter of the pixel's grey so edges stay visible)."""
    image = rgb.astype(np.float32) * 0.45
    objects = labels > 0
    if known is not None:
        # Nearly flat: a quarter of the pixel's grey keeps the edges of what lies there visible.
        grey = rgb.astype(np.float32).mean(axis=-1, keepdims=True)
        for code, colour in KNOWN_COLOURS.items():
            mask = (known == code) & ~objects
            image[mask] = 0.75 * np.asarray(colour, np.float32) + 0.25 * grey[mask]
    colours = palette(labels[objects])
    image[objects] = 0.45 * rgb[objects] + 0.55 * colours
    # Facet borders: pixels whose right or lower neighbour has another facet.
    border = np.zeros(labels.shape, dtype=bool)
    border[:, :-1] |= facet_labels[:, :-1] != facet_labels[:, 1:]
    border[:-1, :] |= facet_labels[:-1, :] != facet_labels[1:, :]
    border &= objects
    image[border] *= 0.35
    picture = Image.fromarray(np.clip(image, 0, 255).astype(np.uint8))
    draw = ImageDraw.Draw(picture)
    font = ImageFont.load_default(size=max(12, labels.shape[0] // 30))
    for object_id in np.unique(labels[objects]):
        rows, cols = np.nonzero(labels == object_id)
        x, y = float(np.median(cols)), float(np.median(rows))
        text = str(int(object_id))
        left, top, right, bottom = draw.textbbox((x, y), text, font=font, anchor="mm")
        draw.rectangle([left - 3, top - 2, right + 3, bottom + 2], fill=(0, 0, 0))
        colour = tuple(int(c) for c in palette([object_id])[0])
        draw.text((x, y), text, fill=colour, font=font, anchor="mm")
    return picture


def write_segmentation(
    scene: Scene,
    perception: Perception,
    out_dir: Path,
    *,
    overwrite: bool = False,
    config: PerceptionConfig | None = None,
) -> Path:
    """Write the label, facet and overlay images and a JSON summary; returns ``out_dir``.
    ``config`` is the perception's (its support clearance colours the overlays' support)."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise IprError(
            f"{out_dir}: already exists (fix: choose another folder or pass --overwrite)"
        )
    with staged_directory(out_dir) as staging:
        for name in ("labels", "facets", "overlay"):
            (staging / name).mkdir()
        frames = []
        for frame, labels, facet_labels, objects, planes in zip(
            scene.frames,
            perception.labels,
            perception.facet_labels,
            perception.objects,
            perception.planes,
            strict=True,
        ):
            name = f"{frame.index:06d}.png"
            (staging / "labels" / name).write_bytes(label_png(labels))
            (staging / "facets" / name).write_bytes(label_png(facet_labels))
            known = known_plane_pixels(frame, planes, config)
            overlay = overlay_image(frame.rgb, labels, facet_labels, known)
            overlay.save(staging / "overlay" / name)
            frames.append(
                {
                    "frame": frame.index,
                    "objects": [
                        {
                            "id": obj.id,
                            "pixels": int(obj.pixels.size),
                            "facets": len(obj.facets),
                            "facet_area_m2": [round(f.area_m2, 6) for f in obj.facets],
                            "centroid_m": np.round(obj.centroid, 4).tolist(),
                            "touches_border": obj.touches_border,
                        }
                        for obj in objects
                    ],
                    "planes": [
                        {
                            "kind": plane.kind,
                            "normal": np.round(plane.normal, 5).tolist(),
                            "offset_m": round(float(plane.offset), 5),
                        }
                        for plane in planes
                    ],
                }
            )
        write_json(
            staging / "segmentation.json",
            {
                "format": "ipr-segmentation/1",
                "scene": str(scene.path),
                "object_ids": perception.object_ids,
                "frames": frames,
                "timing_s": {
                    key: (
                        np.round(value, 4).tolist() if isinstance(value, list) else round(value, 4)
                    )
                    for key, value in perception.timing_s.items()
                },
            },
        )
    return out_dir
