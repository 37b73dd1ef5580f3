"""ROS bags to scene folders (``ipr-shapes import-bag``): ROS 2 bags (sqlite3 or mcap) and ROS 1 bags,
read with ``rosbags`` (pure Python; no ROS installation needed).

Why: robots record RGB-D streams, camera poses and the arm's motion as bags; this makes them the
BOP scene folder every ipr command reads, validated by ``ipr_shapes.from_arrays``'s rules before
anything is written (then written atomically by ``ipr_shapes.scene.write_scene``).

What is read (docs/FORMATS.md, "ROS bags"):

- colour: ``sensor_msgs/Image``, encoding ``rgb8``, ``bgr8``, ``rgba8`` or ``bgra8``; each
  colour image with a depth image within ``max_dt_s`` (nearest header stamps, each depth image
  used once) is a frame, in time order;
- depth: ``sensor_msgs/Image`` registered to the colour camera (same size), ``16UC1``/``mono16``
  in millimetres or ``32FC1`` in metres (NaN, inf, 0: no reading); written as millimetres;
- intrinsics: ``sensor_msgs/CameraInfo`` (its ``K``/``k``), the message nearest each frame;
- camera poses (optional, ``world_frame``): ``tf2_msgs/TFMessage`` on ``/tf`` and ``/tf_static``,
  chained from ``world_frame`` to the colour image's ``header.frame_id`` (an optical frame: x
  right, y down, z forward), the transform nearest each frame (no interpolation; dynamic
  transforms within ``max_tf_dt_s``); ``world_frame`` must be z-up (REP 103);
- pushes (optional, ``pusher_topic``): ``geometry_msgs/PoseStamped`` of the pusher's centre,
  published during each straight push stroke only; the samples between two consecutive frames
  make one push from the first sample's position to the last's, at their mean speed (the
  orientation is ignored). They must lie within ``STRAIGHT_TOLERANCE_M`` of that line.
"""

from __future__ import annotations

import logging
from collections import defaultdict, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ipr_shapes.arrays import from_arrays
from ipr_shapes.atomic import check_output_location
from ipr_shapes.camera import invert_transform, make_transform
from ipr_shapes.errors import BagError
from ipr_shapes.scene import Push, Pusher, write_scene

log = logging.getLogger(__name__)

#: A push's samples may stray this far (m) from the straight line from the first to the last.
STRAIGHT_TOLERANCE_M = 0.01
COLOUR_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8")
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")
IMAGE_TYPE = "sensor_msgs/msg/Image"
INFO_TYPE = "sensor_msgs/msg/CameraInfo"
TF_TYPE = "tf2_msgs/msg/TFMessage"
POSE_TYPE = "geometry_msgs/msg/PoseStamped"


@dataclass(frozen=True)
class BagOptions:
    """How a bag becomes a scene (``ipr-shapes import-bag`` options; defaults are the RealSense ROS
    driver's topic names).

    Attributes:
        rgb_topic, depth_topic, info_topic: the colour, registered depth and camera-info topics.
        world_frame: the tf frame (z up) camera poses are given in; None: no poses (a static
            camera; the world frame then comes from frame 0's support).
        tf_topics: the tf topics read when ``world_frame`` is given.
        pusher_topic: the pusher centre's ``PoseStamped`` topic; None: no pushes.
        max_dt_s: the largest colour-depth stamp difference of a frame (s).
        max_tf_dt_s: the largest stamp difference between a frame and a dynamic transform (s).
        pusher_radius_m, pusher_length_m: the capsule pusher (m), its axis the world's z.
        push_speed_m_s: the speed written when a push's samples share one stamp.
    """

    rgb_topic: str = "/camera/color/image_raw"
    depth_topic: str = "/camera/aligned_depth_to_color/image_raw"
    info_topic: str = "/camera/color/camera_info"
    world_frame: str | None = None
    tf_topics: tuple[str, ...] = ("/tf", "/tf_static")
    pusher_topic: str | None = None
    max_dt_s: float = 0.02
    max_tf_dt_s: float = 0.1
    pusher_radius_m: float = 0.01
    pusher_length_m: float = 0.15
    push_speed_m_s: float = 0.05


@dataclass(frozen=True, eq=False)
class _Stamped:
    """One message: its header stamp (ns), and the decoded message."""

    stamp_ns: int
    message: Any


@dataclass(eq=False)
class _TfTree:
    """Transforms parent_from_child (4, 4) by (parent, child): static ones, and per dynamic
    edge its (stamp ns, transform) list."""

    static: dict[tuple[str, str], np.ndarray] = field(default_factory=dict)
    dynamic: dict[tuple[str, str], list[tuple[int, np.ndarray]]] = field(
        default_factory=lambda: defaultdict(list)
    )


def _stamp_ns(message: Any) -> int:
    stamp = message.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _field(message: Any, *names: str) -> Any:
    """The first of ``names`` the message has (ROS 1 and ROS 2 spell some fields differently:
    CameraInfo's ``K`` and ``k``)."""
    for name in names:
        if hasattr(message, name):
            return getattr(message, name)
    raise AttributeError(names[0])


def _open_reader(bag: Path):
    try:
        from rosbags.highlevel import AnyReader
    except ImportError:  # pragma: no cover - the lock installs it
        raise BagError(
            bag, "reading bags needs the rosbags package", "pip install 'ipr-shapes[ros]'"
        ) from None
    if not bag.exists():
        raise BagError(bag, "bag not found", "give a ROS 2 bag folder or a ROS 1 .bag file")
    try:
        reader = AnyReader([bag])
        reader.open()
    except Exception as error:  # rosbags raises several types for unreadable bags
        detail = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise BagError(
            bag,
            f"cannot read the bag: {detail}",
            "give a ROS 2 bag folder (sqlite3 or mcap) or a ROS 1 .bag file",
        ) from None
    return reader


def _read_topics(
    reader: Any, bag: Path, wanted: list[tuple[str, str, tuple[str, ...]]]
) -> dict[str, list]:
    """Every message of the ``wanted`` topics ((option, topic, accepted types)), decoded, in
    bag order, by topic; BagError for a missing topic, one of another type, or an empty one."""
    present = {c.topic: c.msgtype for c in reader.connections}
    if not present or not reader.message_count:
        raise BagError(bag, "the bag holds no messages", "record the camera topics into it")
    listing = ", ".join(f"{topic} ({kind})" for topic, kind in sorted(present.items()))
    for option, topic, kinds in wanted:
        if topic not in present:
            raise BagError(
                bag,
                f"topic {topic} is not in the bag (it has: {listing})",
                f"name the right topic with {option}",
            )
        if present[topic] not in kinds:
            raise BagError(
                bag,
                f"topic {topic} ({option}) carries {present[topic]}, not {' or '.join(kinds)}",
                f"name a topic of that type with {option}",
            )
    topics = {topic for _, topic, _ in wanted}
    connections = [c for c in reader.connections if c.topic in topics]
    messages: dict[str, list] = {topic: [] for topic in topics}
    for connection, _, raw in reader.messages(connections=connections):
        messages[connection.topic].append(reader.deserialize(raw, connection.msgtype))
    for option, topic, _ in wanted:
        if not messages[topic] and option != "tf":
            raise BagError(bag, f"topic {topic} has no messages", "record it into the bag")
    return messages


def _image_rows(message: Any, channels: int, dtype: np.dtype, topic: str, bag: Path) -> np.ndarray:
    """(H, W, channels) array of an Image message, honouring its row ``step`` and endianness."""
    height, width, step = int(message.height), int(message.width), int(message.step)
    item = np.dtype(dtype).itemsize * channels
    data = np.frombuffer(bytes(message.data), dtype=np.uint8)
    if height == 0 or width == 0 or step < width * item or data.size < height * step:
        raise BagError(
            bag,
            f"{topic}: image {width}x{height} with step {step} holds {data.size} bytes",
            "record complete images",
        )
    rows = data[: height * step].reshape(height, step)[:, : width * item]
    order = ">" if message.is_bigendian else "<"
    typed = np.dtype(dtype).newbyteorder(order) if np.dtype(dtype).itemsize > 1 else dtype
    return rows.copy().view(typed).reshape(height, width, channels).astype(dtype)


def _colour(message: Any, topic: str, bag: Path) -> np.ndarray:
    encoding = str(message.encoding)
    if encoding not in COLOUR_ENCODINGS:
        raise BagError(
            bag,
            f"{topic}: unknown colour encoding {encoding!r}",
            f"record colour as one of {', '.join(COLOUR_ENCODINGS)}",
        )
    pixels = _image_rows(message, 4 if encoding.endswith("a8") else 3, np.uint8, topic, bag)
    pixels = pixels[..., :3]
    return np.ascontiguousarray(pixels[..., ::-1] if encoding.startswith("bgr") else pixels)


def _depth(message: Any, topic: str, bag: Path) -> np.ndarray:
    """(H, W) float32 metres, 0 where no reading."""
    encoding = str(message.encoding)
    if encoding in ("16UC1", "mono16"):
        return _image_rows(message, 1, np.uint16, topic, bag)[..., 0].astype(np.float32) / 1000
    if encoding == "32FC1":
        metres = _image_rows(message, 1, np.float32, topic, bag)[..., 0]
        return np.where(np.isfinite(metres) & (metres > 0), metres, 0).astype(np.float32)
    raise BagError(
        bag,
        f"{topic}: unknown depth encoding {encoding!r}",
        "record depth as 16UC1 (millimetres) or 32FC1 (metres)",
    )


def _nearest(items: list[_Stamped], stamp_ns: int) -> tuple[int, _Stamped]:
    index = min(range(len(items)), key=lambda i: abs(items[i].stamp_ns - stamp_ns))
    return index, items[index]


def _pair_frames(
    colours: list[_Stamped], depths: list[_Stamped], max_dt_s: float
) -> list[tuple[_Stamped, _Stamped]]:
    """Colour and depth images paired by nearest stamp within ``max_dt_s``, each depth image at
    most once, in time order."""
    limit = int(round(max_dt_s * 1e9))
    used: set[int] = set()
    pairs = []
    for colour in sorted(colours, key=lambda item: item.stamp_ns):
        free = [
            (abs(d.stamp_ns - colour.stamp_ns), i) for i, d in enumerate(depths) if i not in used
        ]
        if not free:
            break
        gap, index = min(free)
        if gap <= limit:
            used.add(index)
            pairs.append((colour, depths[index]))
    return pairs


def _transform(translation: Any, rotation: Any, what: str, bag: Path) -> np.ndarray:
    """parent_from_child (4, 4) of a geometry_msgs Transform/Pose's parts."""
    from scipy.spatial.transform import Rotation

    quaternion = np.array([rotation.x, rotation.y, rotation.z, rotation.w], dtype=np.float64)
    offset = np.array([translation.x, translation.y, translation.z], dtype=np.float64)
    if not (np.all(np.isfinite(quaternion)) and np.all(np.isfinite(offset))):
        raise BagError(bag, f"{what}: NaN or inf in a transform", "record finite transforms")
    norm = float(np.linalg.norm(quaternion))
    if norm < 1e-6:
        raise BagError(bag, f"{what}: zero quaternion", "record unit quaternions")
    return make_transform(Rotation.from_quat(quaternion / norm).as_matrix(), offset)


def _tf_tree(messages: dict[str, list], options: BagOptions, bag: Path) -> _TfTree:
    tree = _TfTree()
    for topic in options.tf_topics:
        for message in messages.get(topic, []):
            for item in message.transforms:
                parent, child = item.header.frame_id.lstrip("/"), item.child_frame_id.lstrip("/")
                matrix = _transform(
                    item.transform.translation,
                    item.transform.rotation,
                    f"tf {parent} -> {child}",
                    bag,
                )
                if topic.endswith("static"):
                    tree.static[(parent, child)] = matrix
                else:
                    tree.dynamic[(parent, child)].append((_stamp_ns(item), matrix))
    return tree


def _lookup(
    tree: _TfTree, target: str, source: str, stamp_ns: int, max_dt_s: float, bag: Path
) -> np.ndarray:
    """target_from_source (4, 4) at ``stamp_ns``: the tf chain between the frames, each dynamic
    edge's transform nearest in time (within ``max_dt_s``)."""
    target, source = target.lstrip("/"), source.lstrip("/")
    limit = int(round(max_dt_s * 1e9))
    edges: dict[str, list[tuple[str, Callable[[], np.ndarray | None]]]] = defaultdict(list)

    def at_time(samples: list[tuple[int, np.ndarray]]) -> np.ndarray | None:
        stamp, matrix = min(samples, key=lambda s: abs(s[0] - stamp_ns))
        return matrix if abs(stamp - stamp_ns) <= limit else None

    for (parent, child), matrix in tree.static.items():
        edges[parent].append((child, lambda m=matrix: m))
        edges[child].append((parent, lambda m=matrix: invert_transform(m)))
    for (parent, child), samples in tree.dynamic.items():
        edges[parent].append((child, lambda s=samples: at_time(s)))
        edges[child].append(
            (parent, lambda s=samples: None if (m := at_time(s)) is None else invert_transform(m))
        )
    # Breadth-first from the target: target_from_frame for each frame reached.
    reached = {target: np.eye(4)}
    stale: list[str] = []
    queue = deque([target])
    while queue:
        frame = queue.popleft()
        for neighbour, get in edges[frame]:
            if neighbour in reached:
                continue
            matrix = get()
            if matrix is None:
                stale.append(f"{frame} -> {neighbour}")
                continue
            reached[neighbour] = reached[frame] @ matrix
            queue.append(neighbour)
    if source not in reached:
        why = (
            f"no transform within {max_dt_s:g} s of the frame on {', '.join(stale)}"
            if stale
            else "the tf tree does not connect them"
        )
        raise BagError(
            bag,
            f"no tf chain from {target} to {source} at t={stamp_ns / 1e9:.3f} s: {why}",
            "check --world-frame and that /tf, /tf_static were recorded (or leave out "
            "--world-frame for a static camera)",
        )
    return reached[source]


def _pushes(
    samples: list[_Stamped],
    stamps: list[int],
    tree: _TfTree,
    options: BagOptions,
    bag: Path,
) -> list[Push]:
    """Pushes from the pusher centre's poses (module doc), world frame."""
    pushes = []
    for index in range(len(stamps) - 1):
        stroke = [s for s in samples if stamps[index] < s.stamp_ns < stamps[index + 1]]
        if len(stroke) < 2:
            if stroke:
                log.warning(
                    "%s: one pusher sample between frames %d and %d: no push", bag, index, index + 1
                )
            continue
        points = []
        for sample in stroke:
            pose = sample.message.pose
            local = _transform(pose.position, pose.orientation, options.pusher_topic or "", bag)
            frame = sample.message.header.frame_id.lstrip("/")
            world_from_local = (
                np.eye(4)
                if frame == (options.world_frame or "").lstrip("/")
                else _lookup(
                    tree,
                    options.world_frame or "",
                    frame,
                    sample.stamp_ns,
                    options.max_tf_dt_s,
                    bag,
                )
            )
            points.append((world_from_local @ local)[:3, 3])
        points = np.array(points)
        start, end = points[0], points[-1]
        distance = float(np.linalg.norm(end - start))
        where = f"{options.pusher_topic}: pusher samples between frames {index} and {index + 1}"
        if distance < 1e-4:
            raise BagError(bag, f"{where} do not move", "publish the pusher only while it pushes")
        direction = (end - start) / distance
        offsets = points - start
        off_line = offsets - np.outer(offsets @ direction, direction)
        deviation = float(np.linalg.norm(off_line, axis=1).max())
        if deviation > STRAIGHT_TOLERANCE_M:
            raise BagError(
                bag,
                f"{where} are not a straight stroke ({deviation * 100:.1f} cm off the line)",
                "publish the pusher's pose only during each straight push (ipr models straight pushes)",
            )
        duration = (stroke[-1].stamp_ns - stroke[0].stamp_ns) / 1e9
        speed = distance / duration if duration > 0 else options.push_speed_m_s
        pushes.append(Push(index, index + 1, start, direction, distance, speed))
    return pushes


def import_bag(
    bag: Path | str, out: Path | str, options: BagOptions | None = None, *, overwrite: bool = False
) -> Path:
    """Convert a ROS bag (module doc) into a scene folder at ``out``, validated before anything
    is written and written atomically; the folder. BagError (one line: the bag, the problem,
    the fix) on a bad bag; ArrayInputError when what it holds breaks the scene rules."""
    options = options or BagOptions()
    bag = Path(bag)
    out = check_output_location(out, [bag], overwrite=overwrite)
    if options.pusher_topic and not options.world_frame:
        raise BagError(
            bag,
            "pushes need camera poses in a world frame",
            "pass --world-frame FRAME (a z-up tf frame the camera and the pusher resolve to)",
        )
    if not (options.max_dt_s > 0 and options.max_tf_dt_s > 0):
        raise BagError(bag, "the time tolerances must be positive", "give --max-dt > 0")
    reader = _open_reader(bag)
    try:
        wanted = [
            ("--rgb-topic", options.rgb_topic, (IMAGE_TYPE,)),
            ("--depth-topic", options.depth_topic, (IMAGE_TYPE,)),
            ("--info-topic", options.info_topic, (INFO_TYPE,)),
        ]
        if options.world_frame:
            present = {c.topic for c in reader.connections}
            tf_topics = [topic for topic in options.tf_topics if topic in present]
            if not tf_topics:
                raise BagError(
                    bag,
                    f"--world-frame needs tf, but none of {', '.join(options.tf_topics)} is in "
                    "the bag",
                    "record /tf and /tf_static, or leave out --world-frame for a static camera",
                )
            wanted += [("tf", topic, (TF_TYPE,)) for topic in tf_topics]
        if options.pusher_topic:
            wanted.append(("--pusher-topic", options.pusher_topic, (POSE_TYPE,)))
        messages = _read_topics(reader, bag, wanted)
    finally:
        reader.close()

    def stamped(topic: str) -> list[_Stamped]:
        return [_Stamped(_stamp_ns(m), m) for m in messages[topic]]

    pairs = _pair_frames(stamped(options.rgb_topic), stamped(options.depth_topic), options.max_dt_s)
    if not pairs:
        raise BagError(
            bag,
            f"no colour image of {options.rgb_topic} has a depth image of {options.depth_topic} "
            f"within {options.max_dt_s:g} s",
            "check the topics, or allow a larger gap with --max-dt",
        )
    infos = stamped(options.info_topic)
    rgbs, depths, Ks, poses = [], [], [], []
    tree = _tf_tree(messages, options, bag) if options.world_frame else None
    for number, (colour, depth) in enumerate(pairs):
        rgb = _colour(colour.message, options.rgb_topic, bag)
        depth_m = _depth(depth.message, options.depth_topic, bag)
        if rgb.shape[:2] != depth_m.shape:
            raise BagError(
                bag,
                f"frame {number}: depth is {depth_m.shape[1]}x{depth_m.shape[0]} but colour is "
                f"{rgb.shape[1]}x{rgb.shape[0]}",
                "record depth registered to the colour camera (e.g. aligned_depth_to_color)",
            )
        _, info = _nearest(infos, colour.stamp_ns)
        size = (int(info.message.height), int(info.message.width))
        if size != rgb.shape[:2] and size != (0, 0):
            raise BagError(
                bag,
                f"frame {number}: {options.info_topic} is for {size[1]}x{size[0]} images, colour "
                f"is {rgb.shape[1]}x{rgb.shape[0]}",
                "give the colour camera's camera_info topic with --info-topic",
            )
        Ks.append(np.asarray(_field(info.message, "k", "K"), dtype=np.float64).reshape(3, 3))
        rgbs.append(rgb)
        depths.append(depth_m)
        if tree is not None:
            camera = colour.message.header.frame_id
            poses.append(
                _lookup(
                    tree, options.world_frame, camera, colour.stamp_ns, options.max_tf_dt_s, bag
                )
            )
    pushes: list[Push] = []
    pusher = None
    if options.pusher_topic:
        stamps = [colour.stamp_ns for colour, _ in pairs]
        samples = sorted(stamped(options.pusher_topic), key=lambda s: s.stamp_ns)
        pushes = _pushes(samples, stamps, tree, options, bag)
        pusher = Pusher(options.pusher_radius_m, options.pusher_length_m)
    # The scene rules (sizes, depth range, intrinsics, rotations, pushes) before writing.
    scene = from_arrays(
        rgbs,
        depths,
        Ks,
        world_from_camera=poses or None,
        pushes=pushes,
        pusher=pusher,
        name=str(bag),
    )
    log.info("%s: %d frames, %d pushes", bag, len(scene.frames), len(scene.pushes))
    try:
        return write_scene(
            out,
            scene.frames,
            pushes=scene.pushes,
            pusher=scene.pusher,
            write_poses=bool(poses),
            overwrite=overwrite,
        )
    except OSError as error:
        raise BagError(
            out, f"cannot write the scene: {error}", "choose a writable folder"
        ) from None
