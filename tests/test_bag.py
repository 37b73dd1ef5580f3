"""ipr-shapes import-bag: bags written with rosbags' own writers (ROS 2 sqlite3 and mcap, ROS 1) from a
scene folder convert back into the same scene; bad bags fail in one line, writing nothing."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags", reason="the 'ros' extra (rosbags) is not installed")

from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from scipy.spatial.transform import Rotation

from ipr_shapes.bag import BagOptions
from ipr_shapes.camera import invert_transform, make_transform
from ipr_shapes.cli import EXIT_INPUT_ERROR, BagOptionsDefaults, main
from ipr_shapes.scene import Scene, load_scene

#: A fixed world -> camera mount (static tf), the rest of the chain is dynamic.
MOUNT = make_transform(Rotation.from_euler("z", 30, degrees=True).as_matrix(), [0.2, -0.1, 0.5])
T0_NS = 1_700_000_000_000_000_000
FRAME_GAP_NS = 4_000_000_000


@dataclass
class BagSpec:
    """What to write into a test bag (defaults: a faithful recording of the scene)."""

    ros1: bool = False
    mcap: bool = False
    colour_encoding: str = "bgr8"
    depth_encoding: str = "16UC1"
    depth_offset_ns: int = 5_000_000  # depth 5 ms after colour
    skip_topics: tuple[str, ...] = ()
    depth_crop: bool = False
    tf: bool = True
    pusher: bool = True
    curved_push: bool = False
    extra: dict = field(default_factory=dict)


def _time(types, ns: int):
    return types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _header(types, ros1: bool, ns: int, frame_id: str):
    Header = types["std_msgs/msg/Header"]
    if ros1:
        return Header(seq=0, stamp=_time(types, ns), frame_id=frame_id)
    return Header(stamp=_time(types, ns), frame_id=frame_id)


def _image(types, ros1, ns, frame_id, pixels: np.ndarray, encoding: str):
    height, width = pixels.shape[:2]
    data = np.ascontiguousarray(pixels).view(np.uint8).reshape(-1)
    return types["sensor_msgs/msg/Image"](
        header=_header(types, ros1, ns, frame_id),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=data.size // height,
        data=data,
    )


def _info(types, ros1, ns, frame_id, K, shape):
    roi = types["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    matrices = {"d": np.zeros(5), "k": K.reshape(-1), "r": np.eye(3).reshape(-1)}
    matrices["p"] = np.hstack([K, np.zeros((3, 1))]).reshape(-1)
    if ros1:
        matrices = {name.upper(): value for name, value in matrices.items()}
    return types["sensor_msgs/msg/CameraInfo"](
        header=_header(types, ros1, ns, frame_id),
        height=shape[0],
        width=shape[1],
        distortion_model="plumb_bob",
        binning_x=0,
        binning_y=0,
        roi=roi,
        **matrices,
    )


def _tf(types, ros1, ns, parent, child, matrix):
    quaternion = Rotation.from_matrix(matrix[:3, :3]).as_quat()
    transform = types["geometry_msgs/msg/Transform"](
        translation=types["geometry_msgs/msg/Vector3"](*matrix[:3, 3]),
        rotation=types["geometry_msgs/msg/Quaternion"](*quaternion),
    )
    stamped = types["geometry_msgs/msg/TransformStamped"](
        header=_header(types, ros1, ns, parent), child_frame_id=child, transform=transform
    )
    return types["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def _pose(types, ros1, ns, frame_id, position):
    pose = types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](*position),
        orientation=types["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
    )
    return types["geometry_msgs/msg/PoseStamped"](
        header=_header(types, ros1, ns, frame_id), pose=pose
    )


def write_bag(scene: Scene, depth_mm: list[np.ndarray], path: Path, spec: BagSpec) -> Path:
    """A bag of ``scene`` as a RealSense driver, tf and a pusher controller would record it."""
    store = get_typestore(Stores.ROS1_NOETIC if spec.ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in store.types:  # not in rosbags' noetic store
        store.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
    types = store.types
    serialize = store.serialize_ros1 if spec.ros1 else store.serialize_cdr
    if spec.ros1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if spec.mcap else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
    defaults = BagOptions()
    optical = "camera_color_optical_frame"
    topics = {
        defaults.rgb_topic: "sensor_msgs/msg/Image",
        defaults.depth_topic: "sensor_msgs/msg/Image",
        defaults.info_topic: "sensor_msgs/msg/CameraInfo",
    }
    if spec.tf:
        topics |= {"/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage"}
    if spec.pusher:
        topics["/pusher/pose"] = "geometry_msgs/msg/PoseStamped"
    messages = []  # (topic, ns, message)
    for frame, mm in zip(scene.frames, depth_mm, strict=True):
        ns = T0_NS + frame.index * FRAME_GAP_NS
        rgb = frame.rgb[..., ::-1] if spec.colour_encoding == "bgr8" else frame.rgb
        messages.append(
            (
                defaults.rgb_topic,
                ns,
                _image(types, spec.ros1, ns, optical, rgb, spec.colour_encoding),
            )
        )
        depth = mm.astype(np.float32) / 1000 if spec.depth_encoding == "32FC1" else mm
        if spec.depth_crop:
            depth = depth[:, :-8]
        depth_ns = ns + spec.depth_offset_ns
        messages.append(
            (
                defaults.depth_topic,
                depth_ns,
                _image(types, spec.ros1, depth_ns, optical, depth, spec.depth_encoding),
            )
        )
        messages.append(
            (defaults.info_topic, ns, _info(types, spec.ros1, ns, optical, frame.K, frame.shape))
        )
        if spec.tf:  # dynamic: camera_link -> optical, so that world -> optical is the pose
            link_from_camera = invert_transform(MOUNT) @ frame.world_from_camera
            messages.append(
                ("/tf", ns, _tf(types, spec.ros1, ns, "camera_link", optical, link_from_camera))
            )
    if spec.tf:
        messages.append(
            ("/tf_static", T0_NS, _tf(types, spec.ros1, T0_NS, "world", "camera_link", MOUNT))
        )
    if spec.pusher:
        for push in scene.pushes:
            begin = T0_NS + push.before_frame * FRAME_GAP_NS + FRAME_GAP_NS // 4
            duration_ns = int(push.distance_m / push.speed_m_s * 1e9)
            for k in range(5):
                position = push.start_m + push.direction * push.distance_m * k / 4
                if spec.curved_push and k == 2:
                    position = position + np.array([0.0, 0.0, 0.05])
                ns = begin + duration_ns * k // 4
                messages.append(
                    ("/pusher/pose", ns, _pose(types, spec.ros1, ns, "world", position))
                )
    with writer:
        connections = {
            topic: writer.add_connection(topic, kind, typestore=store)
            for topic, kind in topics.items()
            if topic not in spec.skip_topics
        }
        for topic, ns, message in sorted(messages, key=lambda item: item[1]):
            if topic in connections:
                writer.write(connections[topic], ns, serialize(message, topics[topic]))
    return path


def _depth_mm(scene_dir: Path, scene: Scene) -> list[np.ndarray]:
    from PIL import Image

    return [
        np.asarray(Image.open(scene_dir / "depth" / f"{f.index:06d}.png")).astype(np.uint16)
        for f in scene.frames
    ]


def _convert(bag: Path, out: Path, *extra: str) -> int:
    return main(["import-bag", str(bag), "-o", str(out), *extra])


@pytest.mark.parametrize(
    "spec",
    [
        BagSpec(),
        BagSpec(mcap=True, colour_encoding="rgb8", depth_encoding="32FC1"),
        BagSpec(ros1=True),
    ],
    ids=["ros2-sqlite3", "ros2-mcap", "ros1"],
)
def test_a_bag_of_a_scene_converts_back_into_the_scene(
    scene_dir: Path, tmp_path: Path, spec, capsys
):
    scene = load_scene(scene_dir)
    bag = write_bag(
        scene, _depth_mm(scene_dir, scene), tmp_path / ("in.bag" if spec.ros1 else "in"), spec
    )
    out = tmp_path / "out"
    args = ["--world-frame", "world", "--pusher-topic", "/pusher/pose"]
    assert _convert(bag, out, *args) == 0, capsys.readouterr().err
    assert main(["check", str(out)]) == 0
    back = load_scene(out)
    assert len(back.frames) == len(scene.frames)
    for a, b in zip(back.frames, scene.frames, strict=True):
        assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth_m, b.depth_m)
        assert np.array_equal(a.K, b.K)
        assert np.allclose(a.world_from_camera, b.world_from_camera, atol=1e-6)
    assert len(back.pushes) == len(scene.pushes) == 1
    for a, b in zip(back.pushes, scene.pushes, strict=True):
        assert (a.before_frame, a.after_frame) == (b.before_frame, b.after_frame)
        assert np.allclose(a.start_m, b.start_m, atol=1e-6)
        assert np.allclose(a.direction, b.direction, atol=1e-6)
        assert a.distance_m == pytest.approx(b.distance_m, abs=1e-6)
        assert a.speed_m_s == pytest.approx(b.speed_m_s, rel=1e-3)
    assert back.pusher.radius_m == 0.01 and np.allclose(back.pusher.axis, [0, 0, 1])


def test_without_a_world_frame_the_scene_has_no_poses(scene_dir: Path, tmp_path: Path):
    scene = load_scene(scene_dir)
    bag = write_bag(
        scene, _depth_mm(scene_dir, scene), tmp_path / "in", BagSpec(tf=False, pusher=False)
    )
    assert _convert(bag, tmp_path / "out") == 0
    back = load_scene(tmp_path / "out")
    assert back.world_frame_source == "support_plane" and not back.pushes
    assert np.array_equal(back.frames[1].rgb, scene.frames[1].rgb)


def test_the_cli_defaults_are_the_options_defaults():
    defaults = BagOptions()
    for name in ("rgb_topic", "depth_topic", "info_topic", "max_dt_s", "max_tf_dt_s"):
        assert getattr(BagOptionsDefaults, name) == getattr(defaults, name)
    assert BagOptionsDefaults.pusher_radius_m == defaults.pusher_radius_m


@pytest.mark.parametrize(
    "spec, args, words",
    [
        (
            BagSpec(skip_topics=("/camera/color/camera_info",)),
            (),
            "topic /camera/color/camera_info is not in the bag",
        ),
        (BagSpec(depth_crop=True), (), "depth is 152x120 but colour is 160x120"),
        (BagSpec(colour_encoding="yuv422"), (), "unknown colour encoding 'yuv422'"),
        (BagSpec(depth_offset_ns=50_000_000), (), "within 0.02 s"),
        (
            BagSpec(curved_push=True),
            ("--world-frame", "world", "--pusher-topic", "/pusher/pose"),
            "not a straight stroke",
        ),
        (BagSpec(tf=False), ("--world-frame", "world"), "none of /tf, /tf_static is in the bag"),
        (BagSpec(), ("--world-frame", "map"), "no tf chain from map to camera_color_optical_frame"),
        (BagSpec(), ("--pusher-topic", "/pusher/pose"), "pushes need camera poses"),
        (
            BagSpec(),
            ("--rgb-topic", "/camera/color/camera_info"),
            "carries sensor_msgs/msg/CameraInfo",
        ),
    ],
    ids=[
        "missing-topic",
        "sizes",
        "encoding",
        "no-pairs",
        "curved-push",
        "no-tf",
        "bad-frame",
        "push-no-poses",
        "wrong-type",
    ],
)
def test_bad_bags_fail_in_one_line_and_write_nothing(
    scene_dir: Path, tmp_path: Path, capsys, spec, args, words
):
    scene = load_scene(scene_dir)
    bag = write_bag(scene, _depth_mm(scene_dir, scene), tmp_path / "in", spec)
    out = tmp_path / "out"
    assert _convert(bag, out, *args) == EXIT_INPUT_ERROR
    err = capsys.readouterr().err.strip()
    assert err.startswith("ipr-shapes import-bag: error: ") and words in err and "\n" not in err, (
        err
    )
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["in", "scene"]


def test_empty_and_unreadable_bags_fail_clearly(tmp_path: Path, capsys):
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Writer2(tmp_path / "empty", version=9) as writer:
        writer.add_connection("/camera/color/image_raw", "sensor_msgs/msg/Image", typestore=store)
    assert _convert(tmp_path / "empty", tmp_path / "out") == EXIT_INPUT_ERROR
    assert "holds no messages" in capsys.readouterr().err
    (tmp_path / "junk.bag").write_bytes(b"not a bag at all")
    assert _convert(tmp_path / "junk.bag", tmp_path / "out") == EXIT_INPUT_ERROR
    assert "cannot read the bag" in capsys.readouterr().err
    assert _convert(tmp_path / "nothing", tmp_path / "out") == EXIT_INPUT_ERROR
    assert "bag not found" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
