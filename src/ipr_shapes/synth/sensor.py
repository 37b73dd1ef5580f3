"""The simulated RGB-D sensor: camera placement, intrinsics, depth and colour noise.

Depth model (all draws from the given generator, so a seed reproduces every pixel):

1. readings outside ``depth_range_m`` are 0 (no return);
2. axial Gaussian noise with sigma(z) = base + quadratic * (z - reference)^2 metres (Nguyen,
   Izadi & Lovell 2012, Kinect: 1.2 mm + 1.9 mm (z - 0.4 m)^2);
3. dropout at depth discontinuities: a pixel whose 4-neighbourhood holds a jump larger than
   ``max(edge_jump_m, 3 % of z)`` (or that touches such a pixel) reads 0 with probability
   ``edge_dropout_probability`` (the projector's shadow and mixed pixels of real sensors);
4. random holes: a Poisson number of elliptic blobs (specular or dark patches) read 0;
5. quantisation to 1 mm (the files store uint16 millimetres, ``depth_scale`` 1.0).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ipr_shapes.camera import look_at
from ipr_shapes.synth.config import SynthConfig

#: Image width at which pixel-valued settings (focal length, hole radii) are given.
REFERENCE_WIDTH = 640


def sample_intrinsics(rng: np.random.Generator, config: SynthConfig) -> np.ndarray:
    """RealSense-like (3, 3) K: fx in ``focal_px`` (scaled to the width), fy within
    ``focal_aspect_jitter`` of fx, principal point near the image centre."""
    scale = config.width / REFERENCE_WIDTH
    fx = rng.uniform(*config.focal_px) * scale
    fy = fx * (1.0 + rng.uniform(-1.0, 1.0) * config.focal_aspect_jitter)
    jitter = config.principal_jitter_px * scale
    cx = (config.width - 1) / 2.0 + rng.uniform(-jitter, jitter)
    cy = (config.height - 1) / 2.0 + rng.uniform(-jitter, jitter)
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def camera_pose(
    target: np.ndarray, distance: float, elevation_deg: float, azimuth_deg: float
) -> np.ndarray:
    """World-from-camera (4, 4), OpenCV axes, of a camera ``distance`` metres from ``target``
    (3,), looking at it from ``elevation_deg`` above the horizontal at ``azimuth_deg`` (from +x
    towards +y), with world z pointing up in the image."""
    elevation, azimuth = np.radians(elevation_deg), np.radians(azimuth_deg)
    offset = np.array(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ]
    )
    return look_at(target + distance * offset, target)


def depth_sigma(z: np.ndarray, config: SynthConfig) -> np.ndarray:
    """Axial noise standard deviation (m) at depth ``z`` (m)."""
    return (
        config.depth_noise_base_m
        + config.depth_noise_quadratic_m * (z - config.depth_noise_reference_m) ** 2
    )


def discontinuities(depth_m: np.ndarray, jump_m: float) -> np.ndarray:
    """(H, W) bool: pixels next to a depth jump larger than ``max(jump_m, 0.03 z)``."""
    jump = np.zeros(depth_m.shape, dtype=bool)
    threshold = np.maximum(jump_m, 0.03 * depth_m)
    vertical = np.abs(np.diff(depth_m, axis=0)) > np.minimum(threshold[1:], threshold[:-1])
    horizontal = np.abs(np.diff(depth_m, axis=1)) > np.minimum(threshold[:, 1:], threshold[:, :-1])
    jump[1:] |= vertical
    jump[:-1] |= vertical
    jump[:, 1:] |= horizontal
    jump[:, :-1] |= horizontal
    return ndimage.binary_dilation(jump, iterations=1)


def hole_mask(shape: tuple[int, int], rng: np.random.Generator, config: SynthConfig) -> np.ndarray:
    """(H, W) bool union of a Poisson number of random elliptic holes."""
    height, width = shape
    scale = width / REFERENCE_WIDTH
    area_scale = (width * height) / (REFERENCE_WIDTH * 480)
    count = int(rng.poisson(config.holes_per_frame * area_scale))
    mask = np.zeros(shape, dtype=bool)
    rows, cols = np.arange(height)[:, None], np.arange(width)[None, :]
    for _ in range(count):
        cy, cx = rng.uniform(0, height), rng.uniform(0, width)
        radii = rng.uniform(*config.hole_radius_px, 2) * scale
        angle = rng.uniform(0, np.pi)
        reach = int(np.ceil(radii.max())) + 1
        r0, r1 = max(0, int(cy) - reach), min(height, int(cy) + reach + 1)
        c0, c1 = max(0, int(cx) - reach), min(width, int(cx) + reach + 1)
        dy, dx = rows[r0:r1] - cy, cols[:, c0:c1] - cx
        u = dx * np.cos(angle) + dy * np.sin(angle)
        v = -dx * np.sin(angle) + dy * np.cos(angle)
        mask[r0:r1, c0:c1] |= (u / radii[0]) ** 2 + (v / radii[1]) ** 2 <= 1.0
    return mask


def noisy_depth(clean_m: np.ndarray, rng: np.random.Generator, config: SynthConfig) -> np.ndarray:
    """(H, W) float32 sensor depth in metres, quantised to 1 mm, 0 where there is no reading.

    ``clean_m`` is the (H, W) noise-free planar depth in metres.
    """
    z = clean_m.astype(np.float64)
    near, far = config.depth_range_m
    valid = (z >= near) & (z <= far)
    noisy = z + rng.standard_normal(z.shape) * depth_sigma(z, config)
    edges = discontinuities(z, config.edge_jump_m)
    dropped = edges & (rng.random(z.shape) < config.edge_dropout_probability)
    holes = hole_mask(z.shape, rng, config)
    keep = valid & ~dropped & ~holes
    quantised = np.round(noisy * 1000.0) / 1000.0
    return np.where(keep, quantised, 0.0).astype(np.float32)


def noisy_rgb(rgb: np.ndarray, rng: np.random.Generator, config: SynthConfig) -> np.ndarray:
    """(H, W, 3) uint8 colour image with Gaussian sensor noise (``rgb_noise_std`` levels)."""
    if config.rgb_noise_std <= 0:
        return rgb.copy()
    noise = rng.standard_normal(rgb.shape) * config.rgb_noise_std
    return np.clip(np.round(rgb + noise), 0, 255).astype(np.uint8)
