"""The overlays of ``ipr-shapes segment`` and the gallery show the known planes: the support (what was
taken as the table), what lies below it and walls, in their colours, under the objects."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from ipr_shapes.perception.output import (
    KNOWN_BELOW,
    KNOWN_COLOURS,
    KNOWN_NONE,
    KNOWN_SUPPORT,
    known_plane_pixels,
    label_png,
    overlay_image,
    palette,
)
from ipr_shapes.perception.types import KnownPlane
from tests.conftest import make_frames


def _table() -> KnownPlane:
    return KnownPlane("support", np.array([0.0, 0.0, 1.0]), 0.0, np.zeros((0, 3)))


def test_known_plane_pixels_mark_the_table_below_it_and_nothing_else() -> None:
    frame = make_frames(1)[0]  # the plane z = 0 with a 3 cm high bump in the middle
    codes = known_plane_pixels(frame, (_table(),))
    assert codes.shape == frame.shape and codes.dtype == np.uint8
    height = frame.points_world()[..., 2]
    valid = frame.depth_m > 0
    assert (codes[valid & (np.abs(height) < 0.005)] == KNOWN_SUPPORT).all()
    assert (codes[valid & (height > 0.02)] == KNOWN_NONE).all()  # the bump is no plane
    assert (codes[~valid] == KNOWN_NONE).all()
    lowered = KnownPlane("support", np.array([0.0, 0.0, 1.0]), -0.025, np.zeros((0, 3)))
    codes = known_plane_pixels(frame, (lowered,))  # now the table lies 2.5 cm below it
    assert (codes[valid & (np.abs(height) < 0.005)] == KNOWN_BELOW).all()
    assert (known_plane_pixels(frame, ()) == KNOWN_NONE).all()  # no support: nothing known


def test_overlay_paints_known_planes_under_the_objects() -> None:
    rgb = np.full((20, 30, 3), 200, dtype=np.uint8)
    labels = np.zeros((20, 30), dtype=np.int32)
    labels[5:10, 5:10] = 1
    known = np.full((20, 30), KNOWN_SUPPORT, dtype=np.uint8)
    image = np.asarray(overlay_image(rgb, labels, np.zeros_like(labels), known)).astype(int)
    expected = 0.75 * np.array(KNOWN_COLOURS[KNOWN_SUPPORT]) + 0.25 * 200
    assert np.abs(image[15, 25] - expected).max() <= 1  # the support's colour
    assert np.abs(image[7, 7] - expected).max() > 20  # the object keeps its own tint
    plain = np.asarray(overlay_image(rgb, labels, np.zeros_like(labels))).astype(int)
    assert np.abs(plain[15, 25] - 0.45 * 200).max() <= 1  # without ``known``: dimmed only


def test_label_images_keep_the_ids_and_show_them_in_colour() -> None:
    """``label_png``: the ids read back exactly, and a viewer shows each id in its overlay
    colour (an 8-bit palette), not the near black of small ids in a grey image."""
    labels = np.zeros((12, 16), dtype=np.int64)
    labels[2:6, 3:9], labels[7:11, 1:5] = 3, 250
    with Image.open(io.BytesIO(label_png(labels))) as picture:
        assert picture.mode == "P"
        assert np.array_equal(np.asarray(picture), labels)
        shown = np.asarray(picture.convert("RGB"))
    assert (shown[labels == 0] == 0).all()
    assert np.array_equal(shown[3, 4], palette([3])[0])
    assert np.array_equal(shown[8, 2], palette([250])[0])
    many = np.arange(12 * 16).reshape(12, 16) * 300  # ids above 255: 16-bit grey, still exact
    with Image.open(io.BytesIO(label_png(many))) as picture:
        assert np.array_equal(np.asarray(picture), many)
    with pytest.raises(ValueError, match="0..65535"):
        label_png(-labels)
