"""Settings of the benchmark scene generator: one frozen dataclass, validated before use.

Units are metres, seconds, kilograms, degrees (angles named ``*_deg``) and pixels. Ranges are
``(low, high)`` tuples sampled uniformly per scene or per object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

KINDS = ("static", "dynamic")
ARRANGEMENTS = ("table", "container", "drawer")
OBJECT_SOURCES = ("auto", "ycb", "procedural")


@dataclass(frozen=True)
class SynthConfig:
    """Parameters of generated scenes (defaults give the project's benchmark scenes).

    Image and camera:
        width, height: image size in pixels.
        focal_px: focal length range in pixels *for a 640-pixel-wide image* (RealSense-like);
            scaled with ``width``. fy differs from fx by at most ``focal_aspect_jitter`` (ratio).
        principal_jitter_px: max offset of (cx, cy) from the image centre, in pixels at 640 wide.
        camera_distance_m: distance from the camera centre to the pile centre.
        camera_elevation_deg: angle of the optical axis below the horizontal.
        drawer_elevation_deg: the same for drawer scenes (lower, so that the front wall occludes).
        drawer_azimuth_spread_deg: drawer cameras look at the front wall within +- this angle of
            its normal.
    Objects and arrangements:
        min_objects, max_objects: objects per scene (inclusive).
        object_source: "auto" (YCB when the folder exists, else procedural), "ycb", "procedural".
        min_solidity: YCB pool rule, volume / convex-hull volume (MuJoCo collides hulls).
        extra_objects: YCB objects (file stems such as "025_mug") added to the pool although
            the pool rule drops them, e.g. open containers for segmentation development; a name
            given twice is drawn twice as often. MuJoCo still collides their convex hulls, so a
            cup can hold nothing and objects rest on its rim. Default none.
        min_extent_m, max_extent_m: YCB pool rule on the smallest / largest bounding-box extent.
        boxed_max_extent_m: container and drawer scenes use only objects whose largest extent
            is at most this (tall boxes and bottles lean out over the rim or overflow).
        density_range_kg_m3: YCB pool rule, plausible catalogue mass / mesh volume.
        procedural_density_kg_m3: density range of procedural shapes (mass = density x volume).
        friction: per-object sliding friction range (MuJoCo takes the max of the two geoms;
            table, walls and pusher use ``support_friction``, below the range).
        support_friction: sliding friction of table, walls and pusher.
        torsional_friction, rolling_friction_m: MuJoCo condim-6 coefficients (rolling in m;
            0.002 m stops balls and cans within a few cm instead of letting them roll away).
        drop_radius_m: objects are dropped above a disc of this radius around the drop centre.
        drop_gap_m: clearance between a dropped object and the pile top when it is released.
        drop_damping_s: time constant of the velocity damping applied while dropping (removed
            for the final settle).
        min_pile_fraction: at least this share of the objects (and at least 3, or all when
            fewer) must form one group connected by contacts; the rest may lie apart.
    Physics:
        timestep_s: MuJoCo step.
        settle_linear_m_s, settle_angular_rad_s: every object slower than these = settled.
        settle_max_s: give up (reject the configuration) after this much simulated time.
        drop_settle_max_s: max simulated time between two drops.
        max_penetration_m: deeper contacts reject a configuration.
    Visibility:
        min_visible_px: pixels of frame 0 that make an object visible (contract: 100).
        min_visible_objects: visible objects required in frame 0.
        drawer_min_occluded_fraction: share of the objects' pixels the drawer front must hide.
    Pushes (dynamic scenes):
        pushes: number of pushes range (inclusive); frames = pushes + 1.
        static_frames: frames of a static scene (same state, independent sensor noise).
        pusher_radius_m, pusher_length_m: the vertical capsule (length tip to tip).
        pusher_lift_m: height of the capsule's bottom tip above the support.
        push_distance_m: travel of the capsule centre.
        push_speed_m_s: speed of the capsule centre.
        push_clearance_m: min distance of the capsule to objects at the start and to walls.
        min_push_displacement_m: a push should move some object at least this far.
        push_stop_intrusion_m: the capsule stops (force limit) when it sinks this deep into a
            jammed object; the push's recorded distance is the distance travelled.
        push_attempts: candidate pushes tried per push.
    Sensor:
        depth_range_m: readings outside are 0 (no return).
        depth_noise_base_m, depth_noise_quadratic_m, depth_noise_reference_m: axial noise
            sigma(z) = base + quadratic * (z - reference)^2 (Nguyen et al. 2012, Kinect).
        edge_jump_m: a depth jump larger than this (or 3 % of the depth) marks a discontinuity.
        edge_dropout_probability: chance that a pixel next to a discontinuity reads 0.
        holes_per_frame: mean number of random holes (Poisson) at 640x480, scaled by area.
        hole_radius_px: hole radius range in pixels at 640 wide.
        rgb_noise_std: Gaussian noise on RGB values (8-bit levels).
    Retries and output:
        max_attempts: configurations tried before giving up (each one deterministic).
        write_preview: write ``preview.png`` in the scene folder.
        preview_width_px: width of one preview panel.
        write_clean_depth: also write the noise-free depth (``depth_clean/``, uint16 mm) for
            studying the sensor model; not part of the scene contract.
    """

    width: int = 640
    height: int = 480
    focal_px: tuple[float, float] = (600.0, 620.0)
    focal_aspect_jitter: float = 0.003
    principal_jitter_px: float = 4.0
    camera_distance_m: tuple[float, float] = (0.5, 0.9)
    camera_elevation_deg: tuple[float, float] = (35.0, 65.0)
    drawer_elevation_deg: tuple[float, float] = (35.0, 45.0)
    drawer_azimuth_spread_deg: float = 30.0

    min_objects: int = 3
    max_objects: int = 8
    object_source: str = "auto"
    min_solidity: float = 0.75
    extra_objects: tuple[str, ...] = ()
    min_extent_m: float = 0.015
    max_extent_m: float = 0.26
    boxed_max_extent_m: float = 0.2
    density_range_kg_m3: tuple[float, float] = (50.0, 3000.0)
    procedural_density_kg_m3: tuple[float, float] = (250.0, 900.0)
    friction: tuple[float, float] = (0.4, 1.0)
    support_friction: float = 0.3
    torsional_friction: float = 0.005
    rolling_friction_m: float = 0.002
    drop_radius_m: float = 0.04
    drop_gap_m: float = 0.005
    drop_damping_s: float = 0.15
    min_pile_fraction: float = 0.6

    timestep_s: float = 0.002
    settle_linear_m_s: float = 0.005
    settle_angular_rad_s: float = 0.05
    settle_max_s: float = 6.0
    drop_settle_max_s: float = 0.6
    max_penetration_m: float = 0.005

    min_visible_px: int = 100
    min_visible_objects: int = 3
    drawer_min_occluded_fraction: float = 0.05

    pushes: tuple[int, int] = (1, 3)
    static_frames: int = 1
    pusher_radius_m: float = 0.01
    pusher_length_m: float = 0.15
    pusher_lift_m: float = 0.005
    push_distance_m: tuple[float, float] = (0.05, 0.12)
    push_speed_m_s: tuple[float, float] = (0.04, 0.06)
    push_clearance_m: float = 0.005
    min_push_displacement_m: float = 0.01
    push_stop_intrusion_m: float = 0.004
    push_attempts: int = 8

    depth_range_m: tuple[float, float] = (0.2, 3.0)
    depth_noise_base_m: float = 0.0012
    depth_noise_quadratic_m: float = 0.0019
    depth_noise_reference_m: float = 0.4
    edge_jump_m: float = 0.02
    edge_dropout_probability: float = 0.5
    holes_per_frame: float = 6.0
    hole_radius_px: tuple[float, float] = (2.0, 7.0)
    rgb_noise_std: float = 2.0

    max_attempts: int = 30
    write_preview: bool = True
    preview_width_px: int = 320
    write_clean_depth: bool = False

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ValueError naming the first bad field and the accepted values (called on
        construction, so a SynthConfig that exists is valid)."""
        _require(
            isinstance(self.extra_objects, tuple)
            and all(isinstance(name, str) for name in self.extra_objects),
            f"extra_objects must be a tuple of YCB object names, got {self.extra_objects!r}",
        )
        for item in fields(self):
            value = getattr(self, item.name)
            if isinstance(value, bool | str) or item.name == "extra_objects":
                continue
            numbers = value if isinstance(value, tuple) else (value,)
            if not all(
                isinstance(n, int | float) and not isinstance(n, bool) and math.isfinite(n)
                for n in numbers
            ):
                raise ValueError(f"SynthConfig.{item.name} must hold finite numbers, got {value!r}")
            if isinstance(value, tuple) and (len(value) != 2 or value[0] > value[1]):
                raise ValueError(
                    f"SynthConfig.{item.name} must be a (low, high) pair with low <= high, "
                    f"got {value!r}"
                )
        for name in (
            "width",
            "height",
            "min_objects",
            "max_objects",
            "min_visible_px",
            "min_visible_objects",
            "static_frames",
            "push_attempts",
            "max_attempts",
            "preview_width_px",
        ):
            _require(isinstance(getattr(self, name), int), f"{name} must be an integer")
        for name in ("pushes",):
            _require(
                all(isinstance(n, int) for n in getattr(self, name)), f"{name} must be integers"
            )
        _require(
            self.width >= 32 and self.height >= 32,
            f"width and height must be >= 32 pixels, got {self.width}x{self.height}",
        )
        _require(
            1 <= self.min_objects <= self.max_objects,
            f"need 1 <= min_objects <= max_objects, got {self.min_objects}, {self.max_objects}",
        )
        _require(
            self.object_source in OBJECT_SOURCES,
            f"object_source must be one of {OBJECT_SOURCES}, got {self.object_source!r}",
        )
        _require(self.focal_px[0] > 0, "focal_px must be positive")
        _require(self.camera_distance_m[0] > 0.1, "camera_distance_m must be > 0.1 m")
        for name in ("camera_elevation_deg", "drawer_elevation_deg"):
            low, high = getattr(self, name)
            _require(low > 0 and high < 90, f"{name} must lie strictly between 0 and 90 degrees")
        _require(self.friction[0] > 0, "friction must be positive")
        _require(self.procedural_density_kg_m3[0] > 0, "procedural_density_kg_m3 must be > 0")
        _require(0 < self.timestep_s <= 0.01, "timestep_s must be in (0, 0.01] s")
        _require(
            self.settle_max_s > 0 and self.drop_settle_max_s > 0 and self.drop_damping_s > 0,
            "settle times and drop_damping_s must be > 0",
        )
        _require(0 <= self.min_pile_fraction <= 1, "min_pile_fraction must be in [0, 1]")
        _require(
            self.min_visible_objects >= 0 and self.min_visible_px >= 1,
            "min_visible_objects must be >= 0 and min_visible_px >= 1",
        )
        _require(
            self.min_visible_objects <= self.min_objects,
            "min_visible_objects cannot exceed min_objects",
        )
        _require(self.pushes[0] >= 1, "pushes must be at least 1 for dynamic scenes")
        _require(self.static_frames >= 1, "static_frames must be >= 1")
        _require(
            self.pusher_radius_m > 0 and self.pusher_length_m >= 2 * self.pusher_radius_m,
            "pusher needs radius > 0 and length >= 2 x radius",
        )
        _require(
            self.push_distance_m[0] > 0 and self.push_speed_m_s[0] > 0,
            "push distance and speed must be positive",
        )
        _require(self.push_attempts >= 1 and self.max_attempts >= 1, "attempt counts must be >= 1")
        _require(self.depth_range_m[0] > 0, "depth_range_m must be positive")
        _require(
            0 <= self.edge_dropout_probability <= 1, "edge_dropout_probability must be in [0, 1]"
        )
        _require(
            self.holes_per_frame >= 0 and self.hole_radius_px[0] > 0,
            "holes_per_frame must be >= 0 and hole radii > 0",
        )
        _require(
            self.rgb_noise_std >= 0 and self.depth_noise_base_m >= 0, "noise levels must be >= 0"
        )
        _require(self.preview_width_px >= 32, "preview_width_px must be >= 32")


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(f"SynthConfig: {message}")
