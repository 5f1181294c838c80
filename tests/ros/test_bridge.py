"""vgn-ros on a real ROS 2 graph: a test node publishes a camera's Image, CameraInfo and pose,
the bridge runs as its own process and fuses into a real service on loopback (docs/ros2.md).

The graph is private: a random ROS_DOMAIN_ID and discovery kept on this machine.
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tests.ros import need_ros

need_ros()

from geometry_msgs.msg import PoseArray, PoseStamped  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from std_msgs.msg import Float32MultiArray  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from client import Intrinsics, NotFound, Pose, VGNClient, Workspace, connect  # noqa: E402
from service.launch.embedded import EmbeddedService, free_port  # noqa: E402
from tests.client.test_client_light import GRPC, HEAVY, _blocked_env  # noqa: E402
from tests.ros import ros_messages as make  # noqa: E402
from tests.ros.graph import LATCHED, RELIABLE, Bridge, Graph, private_domain  # noqa: E402
from vgn_contract.geometry import gripper_outline  # noqa: E402
from vgn_contract.schemas import Grasp  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "examples" / "sample_scene.npz"
PARAMETERS_FILE = ROOT / "examples" / "ros2" / "vgn_bridge.yaml"
GRASP_OPTIONS = {"max_grasps": 5}
OTHER_HAND = "robotiq-2f85"


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedService]:
    """The packaged networks behind HTTP and gRPC, as `vgn-client serve` runs them: the main one and
    the second built-in hand's own (for the gripper parameter; franka stays the default)."""
    log = tmp_path_factory.mktemp("ros") / "service.log"
    unset = ("VGN_MODEL", "VGN_API_KEY", "VGN_TURN_AVERAGE", "VGN_CLEARANCE", "VGN_GRIP", "VGN_GRIPPERS",
             "VGN_NETWORK_GRIPPERS", "VGN_HAND_MODELS")  # fmt: skip
    env = {"VGN_TORCH_THREADS": "1"}
    with EmbeddedService(env=env, unset=unset, log_path=log, grpc=True) as running:
        yield running


@pytest.fixture(scope="module")
def graph() -> Iterator[Graph]:
    with private_domain():
        graph = Graph()
        try:
            yield graph
        finally:
            graph.close()


@pytest.fixture(scope="module")
def scene() -> dict[str, np.ndarray]:
    return dict(np.load(SAMPLE))


@pytest.fixture
def vgn(service: EmbeddedService) -> Iterator[VGNClient]:
    with VGNClient(service.url) as client:
        yield client


class Camera:
    """The robot's side: publishers for a bridge's camera topics."""

    def __init__(self, graph: Graph, bridge: Bridge, camera: Intrinsics | None) -> None:
        self.graph, self.bridge = graph, bridge
        node = graph.node
        self.image = node.create_publisher(Image, bridge.topic("depth/image_rect"), RELIABLE)
        self.info = node.create_publisher(CameraInfo, bridge.topic("depth/camera_info"), RELIABLE)
        self.pose = node.create_publisher(PoseStamped, bridge.topic("camera_pose"), RELIABLE)
        graph.spin_until(
            lambda: all(p.get_subscription_count() for p in (self.image, self.info, self.pose)),
            30,
            "the bridge did not subscribe to the camera topics",
        )

        # Each side of a topic matches the other on its own, and the bridge drops what a publisher
        # sends before it has matched it: send camera info (if any) and a pose stamped long before
        # the test's frames until the bridge says it holds them, as a camera streams them.
        def holds_them() -> bool:
            if camera is not None:
                self.info.publish(make.camera_info(camera, 0.0))
            self.pose.publish(make.pose_stamped(np.eye(4), 0.0))
            graph.spin_for(0.05)
            status = graph.call(bridge.topic("status")).message
            return "camera poses: 0 kept" not in status and (
                camera is None or "camera info: none" not in status
            )

        graph.spin_until(holds_them, 30, "the bridge did not receive camera info and poses")

    def publish(
        self, depth: np.ndarray, matrix: np.ndarray, camera: Intrinsics | None, at: float, **image
    ) -> None:
        """Pose and camera info first, then the image, all stamped ``at``."""
        self.pose.publish(make.pose_stamped(matrix, at))
        if camera is not None:
            self.info.publish(make.camera_info(camera, at))
        self.image.publish(make.image(depth, at, **image))

    def close(self) -> None:
        for publisher in (self.image, self.info, self.pose):
            self.graph.node.destroy_publisher(publisher)


@pytest.fixture
def start(graph: Graph, tmp_path: Path) -> Iterator:
    """Start a bridge with parameters (``wait`` short, the pose from the topic); yields a camera for it."""
    running: list[tuple[Bridge, Camera]] = []

    def start(
        camera: Intrinsics | None,
        params_file: Path | None = None,
        env: dict[str, str] | None = None,
        **parameters: object,
    ) -> tuple[Bridge, Camera]:
        namespace = f"/vgn_test_{uuid.uuid4().hex[:8]}"
        defaults = {"pose_source": "topic", "reliable": True, "wait": 0.3, "timeout": 5.0}
        log = tmp_path / f"{namespace[1:]}.log"
        bridge = Bridge(namespace, defaults | parameters, log, params_file, env)
        try:
            publisher = Camera(graph, bridge, camera)
        except TimeoutError as error:
            bridge.stop()
            raise AssertionError(f"{error}:\n{bridge.text()}") from None
        running.append((bridge, publisher))
        return bridge, publisher

    yield start
    for bridge, camera in running:
        camera.close()
        bridge.stop()


def _camera(scene: dict[str, np.ndarray]) -> Intrinsics:
    width, height, fx, fy, cx, cy = scene["intrinsics"]
    return Intrinsics(width=int(width), height=int(height), fx=fx, fy=fy, cx=cx, cy=cy)


def _workspace(scene: dict[str, np.ndarray]) -> Workspace:
    return Workspace(
        size=0.30, resolution=40, pose=Pose(position=[0.0, 0.0, float(scene["table_height"]) - 0.05])
    )


def _frames(vgn: VGNClient, session_id: str) -> int:
    try:
        return vgn.session(session_id).frame_count
    except NotFound:
        return 0


@pytest.mark.parametrize("encoding", ["16UC1", "32FC1"])
def test_published_frames_give_the_grasps_the_python_client_gets(encoding, service, graph, start, scene, vgn):
    camera, workspace = _camera(scene), _workspace(scene)
    depths = (
        list(scene["depth_mm"])
        if encoding == "16UC1"
        else [(d / 1000.0).astype(np.float32) for d in scene["depth_mm"]]
    )
    # 16UC1 over HTTP, 32FC1 over gRPC: the bridge takes either URL.
    url = service.url if encoding == "16UC1" else service.grpc_url
    session_id = f"ros-{uuid.uuid4().hex}"
    bridge, publisher = start(
        camera,
        wait=5.0,  # a loaded machine may deliver a pose after its image: a frame waits rather than being refused
        service_url=url,
        session_id=session_id,
        **{"workspace.position": list(workspace.pose.position)},
        **GRASP_OPTIONS,
    )
    got: dict[str, object] = {}
    graph.node.create_subscription(PoseArray, bridge.topic("grasps"), lambda m: got.update(poses=m), RELIABLE)
    graph.node.create_subscription(
        Float32MultiArray, bridge.topic("grasp_scores"), lambda m: got.update(scores=m), RELIABLE
    )
    graph.node.create_subscription(
        MarkerArray, bridge.topic("grasp_markers"), lambda m: got.update(markers=m), RELIABLE
    )
    for index, (depth, pose) in enumerate(zip(depths, scene["camera_poses"], strict=True)):
        publisher.publish(depth, pose, camera, at=1000.0 + index)
        graph.spin_until(
            lambda n=index + 1: _frames(vgn, session_id) == n,
            30,
            f"frame {index} was not fused",
            log=bridge.text,
        )
    answer = graph.call(bridge.topic("plan"))
    assert answer.success, answer.message
    graph.spin_until(
        lambda: {"poses", "scores", "markers"} <= got.keys(), 10, "no grasps or markers were published"
    )

    with connect(url) as python:
        own = python.create_session(workspace=workspace).session_id
        for depth, pose in zip(depths, scene["camera_poses"], strict=True):
            python.add_frame(own, depth, pose, camera)
        expected = python.grasps(own, **GRASP_OPTIONS).grasps
        python.delete_session(own)
    assert expected, "the sample scene has grasps"
    poses = got["poses"]
    assert poses.header.frame_id == "world"
    positions = np.array([[p.position.x, p.position.y, p.position.z] for p in poses.poses])
    orientations = np.array(
        [[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w] for p in poses.poses]
    )
    assert positions.shape == (len(expected), 3)
    assert np.abs(positions - [g.position for g in expected]).max() < 1e-6
    assert np.abs(orientations - [g.orientation for g in expected]).max() < 1e-6
    scores = np.reshape(got["scores"].data, (-1, 2))
    assert np.allclose(scores, [[g.quality, g.width] for g in expected], atol=1e-6)
    assert f"{len(expected)} grasps from 4 fused frames" in answer.message
    assert "4 received, 4 fused, 0 refused" in answer.message
    _assert_outlines(got["markers"], expected)

    reset = graph.call(bridge.topic("reset"))
    assert reset.success and reset.message == f"session {session_id} emptied"
    graph.spin_until(
        lambda: not got["poses"].poses and len(got["markers"].markers) == 1,
        10,
        "the reset did not clear the grasps and markers",
    )
    assert _frames(vgn, session_id) == 0


def _assert_outlines(markers: MarkerArray, grasps: list[Grasp]) -> None:
    """The previous plan's outlines deleted, then each grasp's gripper outline in the world frame,
    greener for a better grasp."""
    clear, *outlines = markers.markers
    assert clear.action == Marker.DELETEALL
    assert len(outlines) == len(grasps)
    for marker, grasp in zip(outlines, grasps, strict=True):
        assert marker.header.frame_id == "world" and marker.type == Marker.LINE_LIST
        drawn = np.array([[p.x, p.y, p.z] for p in marker.points])
        outline = gripper_outline(grasp.as_matrix(), grasp.width)
        outline = outline[~np.isnan(outline).any(axis=1)]
        # Each drawn point is a point of the outline, and each outline point is drawn.
        assert np.abs(drawn[:, None] - outline[None]).max(axis=2).min(axis=1).max() < 1e-6
        assert np.abs(outline[:, None] - drawn[None]).max(axis=2).min(axis=1).max() < 1e-6
        assert (marker.color.g >= marker.color.r) == (grasp.quality >= 0.5)


def _status_says(graph: Graph, bridge: Bridge, words: str, timeout: float = 30) -> str:
    """The bridge's status once it says ``words``."""
    return graph.spin_until(
        lambda: words in (message := graph.call(bridge.topic("status")).message) and message,
        timeout,
        f"the bridge's status did not say {words!r}",
        log=bridge.text,
    )


def _published(got: dict[str, object]) -> np.ndarray | None:
    """[x, y, z, qx, qy, qz, qw, quality, width(, track_id)] per published grasp, as many score
    columns as the layout says; None before both topics have a message of the same plan."""
    if "poses" not in got or "scores" not in got:
        return None
    columns = got["scores"].layout.dim[1].size
    poses, scores = got["poses"].poses, np.reshape(got["scores"].data, (-1, columns))
    if len(poses) != len(scores):
        return None
    rows = [[p.position.x, p.position.y, p.position.z] for p in poses]
    quaternions = [[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w] for p in poses]
    return np.hstack([np.reshape(rows, (-1, 3)), np.reshape(quaternions, (-1, 4)), scores])


def test_continuous_planning_publishes_the_python_clients_grasps_without_plan(
    service, graph, start, scene, vgn
):
    """With ``continuous`` the grasps after every fused frame are published, over a Track
    stream; after the last frame they are what the Python client's own Track stream plans on the
    same frames, track ids included, and a reset ends the stream, clears the grasps and the next
    frame opens a new one, whose ids start again."""
    camera, workspace = _camera(scene), _workspace(scene)
    session_id = f"ros-{uuid.uuid4().hex}"
    bridge, publisher = start(
        camera,
        wait=5.0,  # a loaded machine may deliver a pose after its image: a frame waits rather than being refused
        service_url=service.grpc_url,
        session_id=session_id,
        continuous=True,
        **{"workspace.position": list(workspace.pose.position)},
        **GRASP_OPTIONS,
    )
    got: dict[str, object] = {}
    graph.node.create_subscription(PoseArray, bridge.topic("grasps"), lambda m: got.update(poses=m), LATCHED)
    graph.node.create_subscription(
        Float32MultiArray, bridge.topic("grasp_scores"), lambda m: got.update(scores=m), LATCHED
    )
    depths, poses = list(scene["depth_mm"]), scene["camera_poses"]
    for index, (depth, pose) in enumerate(zip(depths, poses, strict=True)):
        publisher.publish(depth, pose, camera, at=1000.0 + index)
        _status_says(graph, bridge, f"{index + 1} plans published, the last")
    status = _status_says(graph, bridge, "grasps from 4 fused frames")
    assert "4 received, 4 fused, 0 refused" in status

    with connect(service.grpc_url) as python:
        own = python.create_session(workspace=workspace).session_id
        frames = zip(depths, poses, strict=True)
        expected = list(python.track(own, frames, intrinsics=camera, **GRASP_OPTIONS))[-1].grasps
        planned = python.grasps(own, **GRASP_OPTIONS).grasps
        python.delete_session(own)
    assert expected, "the sample scene has grasps"
    assert [g.position for g in expected] == [g.position for g in planned], "a stream plans as GetGrasps"
    wanted = np.array([[*g.position, *g.orientation, g.quality, g.width, g.track_id] for g in expected])

    def published_wanted() -> bool:
        published = _published(got)
        return (
            published is not None
            and published.shape == wanted.shape
            and np.allclose(published, wanted, atol=1e-6, rtol=0)
        )

    graph.spin_until(
        published_wanted,
        10,
        f"the published grasps are not the Python client's {wanted}",
        log=lambda: f"published: {_published(got)}",
    )
    assert got["poses"].header.frame_id == "world"
    assert f"the last {len(expected)} grasps from 4 fused frames" in status

    answer = graph.call(bridge.topic("reset"))
    assert answer.success, answer.message
    graph.spin_until(lambda: not got["poses"].poses, 10, "the reset did not clear the grasps")
    publisher.publish(depths[0], poses[0], camera, at=2000.0)
    _status_says(graph, bridge, "5 plans published, the last")
    assert "grasps from 1 fused frames" in _status_says(graph, bridge, "5 fused, 0 refused")
    fresh = graph.spin_until(
        lambda: (published := _published(got)) is not None and len(published) > 0 and [published],
        10,
        "the new stream's grasps were not published",
    )[0]
    assert fresh[:, -1].tolist() == list(range(1, len(fresh) + 1)), "a new stream numbers its grasps anew"
    assert _frames(vgn, session_id) == 1
    assert "Traceback" not in bridge.text()


def test_a_dropped_track_stream_is_logged_once_and_opened_again(graph, start, scene, tmp_path):
    """The service restarts under a continuous bridge: the node keeps running, says once that
    the stream ended, and plans again on a new session once the service is back."""
    own = EmbeddedService(
        env={"VGN_TORCH_THREADS": "1"},
        unset=("VGN_MODEL", "VGN_API_KEY"),
        log_path=tmp_path / "restarted.log",
        grpc=True,
    ).start()
    try:
        camera = _camera(scene)
        bridge, publisher = start(camera, wait=5.0, service_url=own.grpc_url, continuous=True, max_grasps=1)
        depth, pose = scene["depth_mm"][0], scene["camera_poses"][0]
        at = iter(range(10, 10_000))
        publisher.publish(depth, pose, camera, next(at))
        _status_says(graph, bridge, "1 plans published")
        own.stop()
        for _ in range(3):
            publisher.publish(depth, pose, camera, next(at))
            graph.spin_for(0.3)
        graph.spin_until(
            lambda: "the Track stream ended" in bridge.text(), 30, "no drop was logged", log=bridge.text
        )
        own.start()

        def planned_again() -> bool:
            publisher.publish(depth, pose, camera, next(at))
            graph.spin_for(0.5)
            return "2 plans published" in graph.call(bridge.topic("status")).message

        graph.spin_until(planned_again, 60, "the bridge did not plan again", log=bridge.text)
        assert bridge.process.poll() is None, bridge.text()
        _assert_logged_once(bridge, "the Track stream ended: the service at")
        assert bridge.text().count("opened session") == 2, "the restarted service lost the session"
        assert "Traceback" not in bridge.text()
    finally:
        own.stop()


def test_the_api_key_parameter_reaches_a_service_that_asks_for_one(graph, start, scene, tmp_path):
    """A wrong key is logged once as the service's refusal and nothing is fused; the right one fuses."""
    keyed = EmbeddedService(
        env={"VGN_TORCH_THREADS": "1", "VGN_API_KEY": "right-key"},
        unset=("VGN_MODEL",),
        log_path=tmp_path / "keyed.log",
    ).start()
    try:
        camera, depth, pose = _camera(scene), scene["depth_mm"][0], scene["camera_poses"][0]
        wrong, publisher = start(camera, wait=5.0, service_url=keyed.url, api_key="wrong-key")
        for at in (10.0, 11.0):
            publisher.publish(depth, pose, camera, at)
        assert "2 received, 0 fused, 2 refused" in _refused_twice(graph, wrong)
        _assert_logged_once(wrong, f"the service at {keyed.url} did not fuse the frame: Unauthorized")
        session_id = f"ros-{uuid.uuid4().hex}"
        right, publisher = start(
            camera, wait=5.0, service_url=keyed.url, api_key="right-key", session_id=session_id
        )
        publisher.publish(depth, pose, camera, at=10.0)
        with VGNClient(keyed.url, api_key="right-key") as vgn:
            graph.spin_until(
                lambda: _frames(vgn, session_id) == 1, 30, "the frame was not fused", log=right.text
            )
    finally:
        keyed.stop()


def test_continuous_planning_needs_a_grpc_url(graph, tmp_path):
    parameters = {"continuous": True, "service_url": f"http://127.0.0.1:{free_port()}"}
    bridge = Bridge("/vgn_test_http", parameters, tmp_path / "http.log")
    assert bridge.process.wait(timeout=30) == 2
    bridge.stop()
    assert "vgn-ros: continuous needs a grpc:// or grpcs:// service_url" in bridge.text()


def _refused_twice(graph: Graph, bridge: Bridge) -> str:
    """The status once the bridge has refused both frames (it counts them)."""
    return graph.spin_until(
        lambda: (
            (answer := graph.call(bridge.topic("status")))
            and "2 refused" in answer.message
            and answer.message
        ),
        20,
        f"the bridge did not refuse both frames:\n{bridge.text()}",
    )


def _assert_logged_once(bridge: Bridge, words: str) -> None:
    text = bridge.text()
    assert text.count(words) == 1, f"{words!r} should be logged once:\n{text}"


@pytest.mark.parametrize(
    ("problem", "words"),
    [
        (
            "encoding",
            "depth image encoding 'rgb8' is not supported: publish 16UC1 (millimetres) or 32FC1 (metres)",
        ),
        ("camera_info", "no CameraInfo received on /"),
        ("stale_pose", "s older than the frame (pose_tolerance 0.05 s)"),
    ],
)
def test_bad_input_is_logged_once_and_nothing_is_fused(problem, words, service, graph, start, scene, vgn):
    session_id = f"ros-{uuid.uuid4().hex}"
    camera = None if problem == "camera_info" else _camera(scene)
    bridge, publisher = start(camera, service_url=service.url, session_id=session_id, pose_tolerance=0.05)
    depth, pose = scene["depth_mm"][0], scene["camera_poses"][0]
    for at in (10.0, 11.0):
        if problem == "encoding":
            publisher.publish(depth, pose, camera, at, encoding="rgb8")
        elif problem == "stale_pose":
            publisher.pose.publish(make.pose_stamped(pose, at - 2.0))
            publisher.info.publish(make.camera_info(camera, at))
            publisher.image.publish(make.image(depth, at))
        else:
            publisher.publish(depth, pose, camera, at)
    message = _refused_twice(graph, bridge)
    assert "2 received, 0 fused, 2 refused" in message
    _assert_logged_once(bridge, words)
    assert _frames(vgn, session_id) == 0


def test_the_session_plans_for_the_gripper_parameters_hand(service, graph, start, scene, vgn):
    session_id = f"ros-{uuid.uuid4().hex}"
    camera = _camera(scene)
    bridge, publisher = start(
        camera, wait=5.0, service_url=service.url, session_id=session_id, gripper=OTHER_HAND
    )
    publisher.publish(scene["depth_mm"][0], scene["camera_poses"][0], camera, at=10.0)
    graph.spin_until(lambda: _frames(vgn, session_id) == 1, 30, "the frame was not fused", log=bridge.text)
    assert vgn.session(session_id).gripper == OTHER_HAND
    assert f"opened session {session_id} for the {OTHER_HAND} hand" in bridge.text()


def test_a_hand_the_service_does_not_know_is_logged_once_and_nothing_is_fused(service, graph, start, scene):
    # wait: a loaded machine may deliver a pose after its image, and this frame is to reach the service.
    bridge, publisher = start(_camera(scene), wait=5.0, service_url=service.url, gripper="schunk-egp")
    for at in (10.0, 11.0):
        publisher.publish(scene["depth_mm"][0], scene["camera_poses"][0], _camera(scene), at)
    assert "2 received, 0 fused, 2 refused" in _refused_twice(graph, bridge)
    _assert_logged_once(bridge, "unknown gripper 'schunk-egp'; this service knows: franka")
    assert "opened session" not in bridge.text()


def _call_while_streaming(
    graph: Graph, publisher: Camera, service: str, frame: tuple, timeout: float = 20, **image
) -> Trigger.Response:
    """Call a Trigger service while the camera streams ``frame`` (depth, pose, camera; ``image``
    for ``make.image``) at 10 Hz, stamped anew each time; the answer."""
    client = graph.node.create_client(Trigger, service)
    graph.spin_until(client.service_is_ready, timeout, f"{service} did not come up")
    future = client.call_async(Trigger.Request())
    at = iter(range(100, 10_000))

    def answered() -> Trigger.Response | None:
        publisher.publish(*frame, at=float(next(at)), **image)
        graph.spin_for(0.1)
        return future.done() and future.result()

    answer = graph.spin_until(answered, timeout, f"{service} did not answer")
    graph.node.destroy_client(client)
    return answer


def test_fuse_on_request_fuses_one_frame_per_call(service, graph, start, scene, vgn):
    """With ``fuse_on_request`` a streaming camera's frames are passed over until ``~/fuse`` is
    called; the call fuses the first frame after it, and answers once it is fused."""
    session_id = f"ros-{uuid.uuid4().hex}"
    camera = _camera(scene)
    bridge, publisher = start(
        camera, wait=5.0, service_url=service.url, session_id=session_id, fuse_on_request=True
    )
    views = list(zip(scene["depth_mm"], scene["camera_poses"], strict=True))
    for at in (10.0, 11.0):
        publisher.publish(*views[0], camera, at)
    _status_says(graph, bridge, "2 received, 0 fused, 0 refused")
    assert _frames(vgn, session_id) == 0
    for count, (depth, pose) in enumerate(views[:2], 1):
        answer = _call_while_streaming(graph, publisher, bridge.topic("fuse"), (depth, pose, camera))
        assert answer.success, answer.message
        assert answer.message.startswith(f"fused the frame into session {session_id}; frames: ")
        assert f"{count} fused, 0 refused" in answer.message
        assert _frames(vgn, session_id) == count, "one frame per call, however many the camera sent"
    graph.spin_for(0.5)
    assert _frames(vgn, session_id) == 2


def test_a_fuse_call_answers_why_its_frame_was_not_fused(service, graph, start, scene, vgn):
    camera = _camera(scene)
    session_id = f"ros-{uuid.uuid4().hex}"
    bridge, publisher = start(
        camera, service_url=service.url, session_id=session_id, fuse_on_request=True, timeout=1.0
    )
    depth, pose = scene["depth_mm"][0], scene["camera_poses"][0]
    answer = graph.call(bridge.topic("fuse"))  # the camera sends nothing
    assert not answer.success
    assert answer.message.startswith(
        f"no depth image arrived on {bridge.topic('depth/image_rect')} within 1 s"
    )
    bad = _call_while_streaming(
        graph, publisher, bridge.topic("fuse"), (depth, pose, camera), encoding="rgb8"
    )
    assert not bad.success
    assert bad.message.startswith("the frame was not fused: depth image encoding 'rgb8' is not supported")
    assert "1 refused" in bad.message
    assert _frames(vgn, session_id) == 0


def test_fuse_answers_that_every_frame_is_fused_without_fuse_on_request(service, graph, start, scene):
    bridge, _ = start(_camera(scene), service_url=service.url)
    answer = graph.call(bridge.topic("fuse"))
    assert not answer.success and "every frame is fused as it arrives" in answer.message


def test_an_unreachable_service_is_logged_once(graph, start, scene):
    url = f"http://127.0.0.1:{free_port()}"
    bridge, publisher = start(_camera(scene), wait=5.0, service_url=url)  # the frames reach the service call
    for at in (10.0, 11.0):
        publisher.publish(scene["depth_mm"][0], scene["camera_poses"][0], _camera(scene), at)
    assert "2 received, 0 fused, 2 refused" in _refused_twice(graph, bridge)
    answer = graph.call(bridge.topic("plan"))
    assert not answer.success and answer.message.startswith(
        f"the service at {url} is unreachable (ConnectError"
    )
    _assert_logged_once(bridge, f"the service at {url} is unreachable")


@pytest.mark.parametrize(
    ("parameter", "value", "words"),
    [
        ("threshold", 2.0, "vgn-ros: threshold: Input should be less than or equal to 1"),
        ("gripper", "Franka Hand", "vgn-ros: gripper must be a hand's name"),
        (
            "max_grasps",
            "many",
            "vgn-ros: parameter max_grasps: Trying to set parameter 'max_grasps' to 'many'",
        ),
    ],
)
def test_a_bad_parameter_stops_the_node_with_its_name(parameter, value, words, graph, tmp_path):
    bridge = Bridge("/vgn_test_bad", {parameter: value}, tmp_path / "bad.log")
    assert bridge.process.wait(timeout=30) == 2
    bridge.stop()
    assert words in bridge.text()


def test_the_example_parameters_file_configures_the_node(service, start, graph, scene, vgn, tmp_path):
    """docs/ros2.md's parameters file, with the test's service and session on top, on what
    `pip install ".[ros]"` installs: the server's packages, torch, open3d and grpcio cannot be
    imported by the node."""
    session_id = f"ros-{uuid.uuid4().hex}"
    bridge, publisher = start(
        _camera(scene),
        PARAMETERS_FILE,
        _blocked_env(tmp_path, HEAVY + GRPC, allowed=("service.launch",)),
        wait=5.0,  # a loaded machine may deliver the pose after the image: the frame waits for it
        service_url=service.url,
        session_id=session_id,
    )
    publisher.publish(scene["depth_mm"][0], scene["camera_poses"][0], _camera(scene), at=10.0)
    graph.spin_until(lambda: _frames(vgn, session_id) == 1, 30, "the frame was not fused", log=bridge.text)
    workspace = vgn.session(session_id).workspace
    assert workspace.pose.position == [0.45, -0.15, -0.03] and workspace.size == 0.30
    answer = graph.call(bridge.topic("plan"))
    assert answer.success and "grasps from 1 fused frames" in answer.message
