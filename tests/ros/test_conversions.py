"""The bridge's message conversions and frame pairing, without a ROS graph (docs/ros2.md)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from tests.ros import need_ros

need_ros()

from geometry_msgs.msg import TransformStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from ros_bridge import outputs  # noqa: E402
from ros_bridge.assemble import Frame, FrameAssembler  # noqa: E402
from ros_bridge.convert import camera_pose, depth_array, fixed_pose, intrinsics, seconds  # noqa: E402
from ros_bridge.poses import FixedPose, TopicPoses  # noqa: E402
from ros_bridge.problems import Complaints, Refused, Waiting  # noqa: E402
from ros_bridge.settings import PARAMETERS, settings_from  # noqa: E402
from tests.ros import ros_messages as make  # noqa: E402
from vgn_contract.schemas import Grasp, Intrinsics  # noqa: E402

CAMERA = Intrinsics(width=4, height=3, fx=5.0, fy=5.0, cx=2.0, cy=1.5)


def test_16uc1_rows_are_read_by_step_in_either_byte_order():
    depth = np.arange(12, dtype=np.uint16).reshape(3, 4) * 100
    msg = make.image(depth, 1.0)
    assert np.array_equal(depth_array(msg), depth) and depth_array(msg).dtype == np.uint16
    padded = np.zeros((3, 6), dtype=">u2")
    padded[:, :4] = depth
    msg = make.image(depth, 1.0)
    msg.is_bigendian, msg.step, msg.data = 1, 12, padded.tobytes()
    assert np.array_equal(depth_array(msg), depth)


def test_32fc1_is_metres():
    depth = np.full((3, 4), 0.625, dtype=np.float32)
    assert np.array_equal(depth_array(make.image(depth, 1.0)), depth)


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"encoding": "rgb8"}, "encoding 'rgb8' is not supported: publish 16UC1"),
        ({"step": 4}, "step 4 is shorter than a row"),
        ({"data": b"\0" * 10}, "holds 10 bytes, expected step x height = 24"),
        ({"width": 0}, "empty"),
    ],
)
def test_a_malformed_image_is_refused_with_what_is_wrong(change, words):
    msg = make.image(np.zeros((3, 4), dtype=np.uint16), 1.0)
    for name, value in change.items():
        setattr(msg, name, value)
    with pytest.raises(Refused, match=words):
        depth_array(msg)


def test_camera_info_gives_the_intrinsics_of_an_image_its_size():
    msg = make.image(np.zeros((3, 4), dtype=np.uint16), 1.0)
    assert intrinsics(make.camera_info(CAMERA, 1.0), msg) == CAMERA
    other = make.image(np.zeros((6, 8), dtype=np.uint16), 1.0)
    with pytest.raises(Refused, match="camera info is for 4x3 images, the depth image is 8x6"):
        intrinsics(make.camera_info(CAMERA, 1.0), other)
    empty = make.camera_info(CAMERA, 1.0)
    empty.k = [0.0] * 9
    with pytest.raises(Refused, match="not a pinhole camera"):
        intrinsics(empty, msg)


def test_poses_from_messages_and_the_parameter():
    matrix = np.eye(4)
    matrix[:3, 3] = [0.1, 0.2, 0.3]
    assert np.allclose(camera_pose(make.pose_stamped(matrix, 1.0)).as_matrix(), matrix)
    transform = TransformStamped()
    transform.transform.translation.x, transform.transform.rotation.w = 0.5, 1.0
    assert camera_pose(transform).position == [0.5, 0.0, 0.0]
    assert fixed_pose([0, 0, 1, 0, 0, 0, 1]).position == [0.0, 0.0, 1.0]
    with pytest.raises(ValueError, match="7 numbers"):
        fixed_pose([0, 0, 1])
    with pytest.raises(ValueError, match="camera_pose parameter is not a valid camera pose"):
        fixed_pose([0, 0, 1, 0, 0, 0, 2])
    assert seconds(make.stamp(12.25)) == 12.25


def test_topic_poses_match_frames_by_stamp_within_the_tolerance():
    poses = TopicPoses("/camera_pose", "world", tolerance=0.05)
    with pytest.raises(Waiting, match="no camera pose received on /camera_pose"):
        poses.at(10.0, "camera_optical")
    for at in (9.0, 10.01, 11.0):
        matrix = np.eye(4)
        matrix[0, 3] = at
        poses.add(make.pose_stamped(matrix, at))
    assert poses.at(10.0, "camera_optical").position[0] == pytest.approx(10.01)
    with pytest.raises(Refused, match="the nearest is 0.490 s older"):
        poses.at(10.5, "camera_optical")
    with pytest.raises(
        Waiting, match="the newest camera pose on /camera_pose is 2.000 s older than the frame"
    ):
        poses.at(13.0, "camera_optical")
    with pytest.raises(Refused, match="is in frame 'map', expected world_frame 'world'"):
        poses.add(make.pose_stamped(np.eye(4), 12.0, frame_id="map"))


def test_an_image_waits_for_its_camera_info_and_pose_then_is_refused_with_the_reason():
    poses = TopicPoses("/camera_pose", "world", tolerance=0.05)
    frames = FrameAssembler(poses, "/depth/camera_info", wait=0.5)
    first = make.image(np.full((3, 4), 500, dtype=np.uint16), 1.0)
    second = make.image(np.full((3, 4), 600, dtype=np.uint16), 2.0)
    assert frames.add(first, now=100.0) == []
    assert frames.add(second, now=100.1) == [], "the second waits behind the first"
    frames.info = make.camera_info(CAMERA, 1.0)
    poses.add(make.pose_stamped(np.eye(4), 0.5))
    assert frames.poll(now=100.2) == [], "both may still get their poses"
    (refused,) = frames.poll(now=100.5)
    assert refused.kind == "pose" and "0.500 s older than the frame" in str(refused)
    assert "waited 0.50 s" in str(refused)
    poses.add(make.pose_stamped(np.eye(4), 2.0))
    (fused,) = frames.poll(now=100.55)
    assert isinstance(fused, Frame) and fused.stamp == 2.0 and fused.depth[0, 0] == 600
    assert fused.intrinsics == CAMERA


def test_an_image_without_camera_info_is_refused_after_the_wait():
    frames = FrameAssembler(FixedPose(fixed_pose([0, 0, 1, 0, 0, 0, 1])), "/depth/camera_info", wait=0.2)
    assert frames.add(make.image(np.zeros((3, 4), dtype=np.uint16), 1.0), now=0.0) == []
    (refused,) = frames.poll(now=0.3)
    assert refused.kind == "camera_info" and "no CameraInfo received on /depth/camera_info" in str(refused)


def test_each_kind_of_problem_is_logged_once_until_a_frame_is_fused():
    said = []
    complaints = Complaints(said.append)
    for _ in range(3):
        complaints.report(Refused("encoding", "bad encoding"))
    complaints.report(Refused("pose", "stale pose"))
    complaints.clear()
    complaints.report(Refused("encoding", "bad encoding"))
    assert said == ["bad encoding", "stale pose", "bad encoding"]


GRASPS = [
    Grasp(position=[0.1, 0.2, 0.3], orientation=[0, 0, 0, 1], approach=[0, 0, 1], width=0.04, quality=0.9),
    Grasp(position=[0.2, 0.1, 0.3], orientation=[1, 0, 0, 0], approach=[0, 0, -1], width=0.06, quality=0.2),
]


def test_grasps_become_poses_scores_and_outlines_best_first():
    at = make.stamp(5.0)
    poses = outputs.pose_array(GRASPS, "world", at)
    assert poses.header.frame_id == "world" and len(poses.poses) == 2
    assert (poses.poses[1].position.x, poses.poses[1].orientation.x) == (0.2, 1.0)
    scores = outputs.scores(GRASPS)
    assert np.allclose(np.reshape(scores.data, (2, 2)), [[0.9, 0.04], [0.2, 0.06]])
    assert [d.size for d in scores.layout.dim] == [2, 2]
    markers = outputs.markers(GRASPS, "world", at).markers
    assert markers[0].action == markers[0].DELETEALL and len(markers) == 3
    first = markers[1]
    assert first.color.g > first.color.r and markers[2].color.r > markers[2].color.g
    points = np.array([[p.x, p.y, p.z] for p in first.points])
    assert len(points) == 8, "three finger and palm strokes and the stem, as point pairs"
    assert np.allclose(points[0], [0.1, 0.2 - 0.02, 0.3 + 0.05]), "a fingertip, 5 cm along the approach"


def test_a_streams_scores_carry_each_grasps_track_id_third():
    tracked = [g.model_copy(update={"track_id": i}) for g, i in zip(GRASPS, (7, 2**24 + 3), strict=True)]
    scores = outputs.scores([*tracked, GRASPS[0]], track_ids=True)
    rows = np.reshape(scores.data, (3, 3))
    assert np.allclose(rows[:2], [[0.9, 0.04, 7], [0.2, 0.06, 3]]), "ids modulo 2**24, exact in float32"
    assert np.isnan(rows[2, 2]), "a grasp planned outside the stream has none"
    assert [(d.label, d.size, d.stride) for d in scores.layout.dim] == [
        ("grasp", 3, 9),
        ("quality_width_track_id", 3, 3),
    ]
    empty = outputs.scores([], track_ids=True)
    assert empty.data.tolist() == [] and [d.size for d in empty.layout.dim] == [0, 3]
    assert outputs.scores(tracked).layout.dim[1].label == "quality_width", "no id column outside a stream"


def _parameters(**changes):
    values = {
        name: None if isinstance(default, Parameter.Type) else default
        for name, (default, _) in PARAMETERS.items()
    }
    values["pose_source"] = "topic"
    return values | changes


def test_settings_are_checked_with_the_parameter_named():
    settings = settings_from(_parameters(service_url="grpc://robot:50051", max_grasps=3, clearance=False))
    assert not settings.continuous
    assert settings_from(_parameters(service_url="grpcs://robot:443", continuous=True)).continuous
    assert settings.grasp_options == {"planner": "vgn", "max_grasps": 3, "clearance": False}
    assert settings.pose_source == "topic" and settings.workspace.size == 0.30
    assert (
        settings.gripper is None
        and settings_from(_parameters(gripper="robotiq-2f85")).gripper == "robotiq-2f85"
    )
    assert (
        settings_from(_parameters(pose_source="auto", camera_pose=[0, 0, 1, 0, 0, 0, 1])).pose_source
        == "fixed"
    )
    for changes, words in [
        ({"service_url": "ftp://x"}, "service_url must start with http://"),
        ({"threshold": 1.5}, "threshold"),
        ({"planner": "magic"}, "planner"),
        ({"gripper": "Franka Hand"}, "gripper must be a hand's name"),
        ({"wait": -1.0}, "wait must be a finite number at least 0"),
        ({"timeout": 0.0}, "timeout must be a finite number above 0"),
        ({"pose_source": "fixed"}, "pose_source fixed needs the camera_pose parameter"),
        ({"pose_source": "gps"}, "pose_source must be one of auto, tf, topic, fixed"),
        ({"workspace.size": -1.0}, "workspace.* parameters are not a valid workspace"),
        (
            {"continuous": True, "service_url": "http://robot:8000"},
            "continuous needs a grpc:// or grpcs:// service_url",
        ),
        (
            {"continuous": True, "fuse_on_request": True, "service_url": "grpc://robot:50051"},
            "continuous and fuse_on_request do not go together",
        ),
    ]:
        with pytest.raises(ValueError, match=words):
            settings_from(_parameters(**changes))


def test_the_page_names_every_parameter():
    page = (Path(__file__).resolve().parents[2] / "docs" / "ros2.md").read_text()
    missing = [name for name in PARAMETERS if f"`{name}`" not in page]
    assert not missing, f"docs/ros2.md does not describe {missing}"


class _FakeTf2:
    """Stands in for tf2_ros, which has no wheel: a buffer holding transforms by stamp."""

    class TransformException(Exception):
        pass

    def __init__(self, stamps: list[float]) -> None:
        tf2 = self

        class Buffer:
            def lookup_transform(self, target, source, time):
                wanted = time.nanoseconds * 1e-9
                if not stamps or (wanted and wanted not in stamps):
                    raise tf2.TransformException(f"no {target} <- {source} at {wanted}")
                found = TransformStamped()
                found.header.frame_id, found.child_frame_id = target, source
                found.header.stamp = make.stamp(wanted or max(stamps))
                found.transform.translation.x, found.transform.rotation.w = wanted or max(stamps), 1.0
                return found

        self.Buffer = Buffer
        self.TransformListener = lambda buffer, node: None


def test_tf_poses_take_the_transform_at_the_stamp_or_the_newest_within_the_tolerance(monkeypatch):
    from ros_bridge.poses import TfPoses

    monkeypatch.setitem(sys.modules, "tf2_ros", _FakeTf2([5.0, 6.0]))
    poses = TfPoses(None, "world", tolerance=0.05)
    assert poses.at(5.0, "camera_optical").position[0] == 5.0
    assert poses.at(6.03, "camera_optical").position[0] == 6.0, "the newest, 0.03 s before the frame"
    with pytest.raises(Waiting, match="the newest transform world <- camera_optical in TF is 1.000 s older"):
        poses.at(7.0, "camera_optical")
    with pytest.raises(Refused, match="no header.frame_id"):
        poses.at(5.0, "")
    monkeypatch.setitem(sys.modules, "tf2_ros", _FakeTf2([]))
    with pytest.raises(Waiting, match="no transform world <- camera_optical in TF"):
        TfPoses(None, "world", tolerance=0.05).at(5.0, "camera_optical")


def test_a_transform_topic_gives_the_pose_of_the_frame_it_names():
    poses = TopicPoses("/camera_transform", "world", tolerance=0.05)
    transform = TransformStamped()
    transform.header.frame_id, transform.child_frame_id = "world", "camera_optical"
    transform.header.stamp = make.stamp(3.0)
    transform.transform.translation.z, transform.transform.rotation.w = 0.7, 1.0
    poses.add(transform)
    assert poses.at(3.0, "camera_optical").position == [0.0, 0.0, 0.7]
    with pytest.raises(Refused, match="is for frame 'camera_optical', the depth image is in 'wrist_optical'"):
        poses.at(3.0, "wrist_optical")


def test_help_lists_every_parameter_and_starts_no_node(capsys):
    from ros_bridge.cli import main

    assert main(["vgn-ros", "--help"]) == 0
    shown = capsys.readouterr().out
    assert shown.startswith("usage: vgn-ros") and all(f"  {name} (" in shown for name in PARAMETERS)
    assert "  grip (unset)" in shown and "Type." not in shown  # a ROS type is no default
