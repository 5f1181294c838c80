"""The vgn-ros node: camera topics in, one service session, grasps out.

It only wires topics, parameters and services to ``assemble``, ``outputs`` and the project's
client; what a frame or a grasp becomes is decided in those plain modules.
"""

from __future__ import annotations

import queue
import time
from dataclasses import dataclass
from typing import Any

import httpx
from geometry_msgs.msg import PoseArray, PoseStamped, TransformStamped
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.task import Future
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Float32MultiArray
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from client.connect import connect
from client.http import NotFound, VGNError
from client.recovery import Replay
from ros_bridge import outputs, settings
from ros_bridge.assemble import Frame, FrameAssembler
from ros_bridge.poses import FixedPose, PoseSource, TfPoses, TopicPoses
from ros_bridge.problems import Complaints, Refused
from ros_bridge.stream import Ended, TrackStream, Update
from vgn_contract.schemas import Grasp, GraspResult

#: What a call to an unreachable or failing service raises, over HTTP and gRPC.
SERVICE_ERRORS = (VGNError, httpx.TransportError, ConnectionError, TimeoutError)
IMAGE_TOPIC, INFO_TOPIC, POSE_TOPIC = "depth/image_rect", "depth/camera_info", "camera_pose"
#: The client's rebuilding of a session lost with a replica, kept short: the node fuses on its one
#: thread, and a camera streams on while a call waits, so a frame is better refused than late.
REPLAY = Replay(attempts=2)
#: The last plan stays with its topics: a subscriber asking for transient-local durability (RViz,
#: a pick that starts later) gets it on joining, and any other gets the next one.
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
#: How often frames waiting for their camera info or pose are looked at again (s).
POLL_PERIOD = 0.05


@dataclass
class _FuseCall:
    """A ``~/fuse`` call waiting for its frame: ``answer`` gets (success, message) once the first
    image after the call is fused or refused, or none came by ``deadline`` (monotonic s)."""

    answer: Future
    deadline: float
    taken: bool = False  # its image has arrived; later ones are passed over


class BridgeNode(Node):
    """Fuses each depth frame into one service session; ``~/plan`` publishes the ranked grasps,
    ``~/reset`` empties the session, ``~/status`` says what the bridge has. With
    ``fuse_on_request`` only the frame after each ``~/fuse`` call is fused. With ``continuous``
    the frames go through a gRPC ``Track`` stream instead, and the grasps planned after each are
    published as they come. ``ValueError`` at construction names a bad parameter."""

    def __init__(self, name: str = "vgn_bridge", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        settings.declare(self)
        self.settings = settings.read(self)
        self.counts = {"received": 0, "fused": 0, "refused": 0}
        self._complaints = Complaints(self.get_logger().warning)
        s = self.settings
        # Frames sent through a stream are not kept to rebuild a lost session: without a replay
        # a lost session is reported, and a new one opens.
        self._client = connect(s.service_url, s.api_key, s.timeout, None if s.continuous else REPLAY)
        self._session: str | None = None
        self._track: TrackStream | None = None
        self._updates = 0
        self._last_plan: GraspResult | None = None
        self._tracking = False  # a stream has planned since the start or since one failed
        self._topic_poses: TopicPoses | None = None
        self._fuse_call: _FuseCall | None = None
        info_topic = self.resolve_topic_name(INFO_TOPIC)
        self._frames = FrameAssembler(self._pose_source(), info_topic, self.settings.wait)
        camera_qos = qos_profile_sensor_data
        if self.settings.reliable:
            camera_qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(Image, IMAGE_TOPIC, self._on_image, camera_qos)
        self.create_subscription(CameraInfo, INFO_TOPIC, self._on_info, camera_qos)
        self._grasps = self.create_publisher(PoseArray, "~/grasps", LATCHED)
        self._scores = self.create_publisher(Float32MultiArray, "~/grasp_scores", LATCHED)
        self._markers = self.create_publisher(MarkerArray, "~/grasp_markers", LATCHED)
        self.create_service(Trigger, "~/plan", self._plan)
        self.create_service(Trigger, "~/reset", self._reset)
        self.create_service(Trigger, "~/status", self._report_status)
        # A group of its own: the call waits for a frame, and the camera's callbacks must run meanwhile.
        self.create_service(
            Trigger, "~/fuse", self._fuse_next_frame, callback_group=MutuallyExclusiveCallbackGroup()
        )
        self.create_timer(POLL_PERIOD, self._poll)
        if s.continuous:
            self._track = self._open_track()
        self.get_logger().info(
            f"fusing {self.resolve_topic_name(IMAGE_TOPIC)} into a session on {s.service_url} "
            f"(camera pose from {s.pose_source}"
            + ("; planning after every frame over a Track stream)" if s.continuous else ")")
        )

    def _open_track(self) -> TrackStream:
        """The Track stream, handing its updates to this node's thread through a guard condition."""
        s = self.settings
        events: queue.SimpleQueue[Update | Ended] = queue.SimpleQueue()

        def drain() -> None:
            while True:
                try:
                    event = events.get_nowait()
                except queue.Empty:
                    return
                self._on_track(event)

        wake = self.create_guard_condition(drain)

        def deliver(event: Update | Ended) -> None:
            events.put(event)
            if self._track is not None:  # None once closed: the guard condition may be gone
                wake.trigger()

        return TrackStream(
            lambda: connect(s.service_url, s.api_key, s.timeout, None),
            deliver,
            s.grasp_options | {"depth_scale": s.depth_scale, "max_depth": s.max_depth},
        )

    def _pose_source(self) -> PoseSource:
        s = self.settings
        if s.pose_source == "fixed":
            assert s.camera_pose is not None
            return FixedPose(s.camera_pose)
        if s.pose_source == "tf":
            return TfPoses(self, s.world_frame, s.pose_tolerance)
        topic = self.resolve_topic_name(POSE_TOPIC)
        self._topic_poses = TopicPoses(topic, s.world_frame, s.pose_tolerance)
        kind = PoseStamped if s.pose_type == "PoseStamped" else TransformStamped
        self.create_subscription(kind, POSE_TOPIC, self._on_pose, 50)
        return self._topic_poses

    # Camera topics.

    def _on_info(self, msg: CameraInfo) -> None:
        self._frames.info = msg
        self._poll()

    def _on_pose(self, msg: PoseStamped | TransformStamped) -> None:
        assert self._topic_poses is not None
        try:
            self._topic_poses.add(msg)
        except Refused as problem:
            self._complaints.report(problem)
            return
        self._poll()

    def _on_image(self, msg: Image) -> None:
        self.counts["received"] += 1
        if self.settings.fuse_on_request:
            call = self._fuse_call
            if call is None or call.taken:
                return  # passed over: only the first image after a ~/fuse call is fused
            call.taken = True
        self._handle(self._frames.add(msg, time.monotonic()))

    def _poll(self) -> None:
        call = self._fuse_call
        if call is not None and not call.taken and time.monotonic() > call.deadline:
            topic = self.resolve_topic_name(IMAGE_TOPIC)
            self._answer_fuse(False, f"no depth image arrived on {topic} within {self.settings.timeout:g} s")
        self._handle(self._frames.poll(time.monotonic()))

    def _handle(self, decided: list[Frame | Refused]) -> None:
        for item in decided:
            if isinstance(item, Frame):
                self._fuse(item)
            else:
                self._refuse(item)

    def _refuse(self, problem: Refused) -> None:
        self.counts["refused"] += 1
        self._complaints.report(problem)
        self._answer_fuse(False, f"the frame was not fused: {problem}")

    def _fuse(self, frame: Frame) -> None:
        s = self.settings
        try:
            session = self._session_id()
            if self._track is not None:
                self._send(session, frame)
                return
            self._client.add_frame(
                session, frame.depth, frame.pose, frame.intrinsics, s.depth_scale, s.max_depth
            )
        except SERVICE_ERRORS as error:
            self._refuse(self._service_problem(error, "did not fuse the frame"))
            return
        self.counts["fused"] += 1
        self._complaints.clear()
        self._answer_fuse(True, f"fused the frame into session {session}")

    # Fusing on request.

    async def _fuse_next_frame(
        self, request: Trigger.Request, response: Trigger.Response
    ) -> Trigger.Response:
        """``~/fuse``: fuse the first image that arrives after the call, and answer once it is
        fused or refused (a wrist camera's frame taken with the arm held still)."""
        if not self.settings.fuse_on_request:
            response.success = False
            response.message = "every frame is fused as it arrives: fuse_on_request makes ~/fuse pick them"
            return response
        if self._fuse_call is not None:
            response.success, response.message = False, "another ~/fuse call is waiting for its frame"
            return response
        call = self._fuse_call = _FuseCall(Future(), time.monotonic() + self.settings.timeout)
        response.success, message = await call.answer
        response.message = f"{message}; {self._counts()}"
        return response

    def _answer_fuse(self, success: bool, message: str) -> None:
        """Answer the waiting ``~/fuse`` call, if any, once its frame is decided."""
        call, self._fuse_call = self._fuse_call, None
        if call is not None:
            call.answer.set_result((success, message))

    # Planning continuously.

    def _send(self, session: str, frame: Frame) -> None:
        """Hand a frame to the Track stream; it counts as fused once its update comes."""
        assert self._track is not None
        dropped = self._track.send(session, frame)
        if dropped:
            self.counts["refused"] += dropped
            self._complaints.report(
                Refused(
                    "backlog", "the Track stream is behind the camera: the oldest waiting frames are dropped"
                )
            )

    def _on_track(self, event: Update | Ended) -> None:
        """An update of the Track stream is published, unless a reset made it stale; a failed
        stream is logged once, and opened again by the stream itself."""
        if self._track is None:  # closed
            return
        if isinstance(event, Ended):
            self.counts["refused"] += event.lost
            if event.error is not None:
                problem = self._service_problem(event.error, "ended the Track stream")
                self._complaints.report(
                    Refused(
                        "stream", f"the Track stream ended: {problem}; it opens again with the next frames"
                    )
                )
                self._tracking = False
            return
        self.counts["fused"] += 1
        self._complaints.clear()
        if event.stream != self._track.stream:
            return  # planned before a reset
        self._updates += 1
        self._last_plan = event.result
        if not self._tracking:
            self._tracking = True
            self.get_logger().info(
                f"planning continuously on session {self._session}: grasps publish after every frame"
            )
        self._publish(event.result.grasps)

    # The service.

    def _session_id(self) -> str:
        """The session frames go to, opened on first use (the service may come up after the node)."""
        if self._session is None:
            s = self.settings
            opened = self._client.create_session(
                session_id=s.session_id, workspace=s.workspace, gripper=s.gripper
            )
            self._session = opened.session_id
            self.get_logger().info(
                f"opened session {self._session} for the {opened.gripper} hand on {s.service_url}"
            )
        return self._session

    def _service_problem(self, error: Exception, what: str) -> Refused:
        url = self.settings.service_url
        if isinstance(error, NotFound) and self._session is not None:
            lost, self._session = self._session, None
            return Refused(
                "session", f"session {lost} is gone from {url} (expired or deleted): a new one opens"
            )
        if isinstance(error, httpx.TransportError | ConnectionError | TimeoutError):
            return Refused(
                "service", f"the service at {url} is unreachable ({type(error).__name__}: {error})"
            )
        return Refused("service", f"the service at {url} {what}: {type(error).__name__}: {error}")

    def _counts(self) -> str:
        c = self.counts
        return f"frames: {c['received']} received, {c['fused']} fused, {c['refused']} refused"

    def _report_status(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """What the bridge has: its session, its counts, the camera info and the poses it holds."""
        info = self._frames.info
        camera = f"{info.width}x{info.height}" if info is not None else "none yet"
        poses = (
            f"{len(self._topic_poses)} kept" if self._topic_poses is not None else self.settings.pose_source
        )
        session = self._session or "not opened yet"
        response.success = True
        response.message = (
            f"session: {session}; {self._counts()}; camera info: {camera}; camera poses: {poses}"
        )
        if self._track is not None:
            last = self._last_plan
            response.message += f"; continuous: {self._updates} plans published" + (
                f", the last {len(last.grasps)} grasps from {last.frame_count} fused frames" if last else ""
            )
        return response

    def _plan(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            result = self._client.grasps(self._session_id(), **self.settings.grasp_options)
        except SERVICE_ERRORS as error:
            problem = self._service_problem(error, "did not plan")
            self._complaints.report(problem)
            response.success, response.message = False, f"{problem}; {self._counts()}"
            return response
        self._publish(result.grasps)
        response.success = True
        response.message = (
            f"{len(result.grasps)} grasps from {result.frame_count} fused frames "
            f"(threshold {result.threshold:.2f}); {self._counts()}"
        )
        return response

    def _reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self._track is not None:  # its frames in flight first: none may land after the reset
            self.counts["refused"] += self._track.stop(self.settings.timeout)
        try:
            self._client.reset_session(self._session_id())
        except SERVICE_ERRORS as error:
            problem = self._service_problem(error, "did not reset the session")
            self._complaints.report(problem)
            response.success, response.message = False, str(problem)
            return response
        self._publish([])
        self._last_plan = None
        response.success, response.message = True, f"session {self._session} emptied"
        return response

    def _publish(self, grasps: list[Grasp]) -> None:
        frame, stamp = self.settings.world_frame, self.get_clock().now().to_msg()
        self._grasps.publish(outputs.pose_array(grasps, frame, stamp))
        # In continuous mode every message has the track id column, NaN for ~/plan's grasps.
        self._scores.publish(outputs.scores(grasps, track_ids=self.settings.continuous))
        self._markers.publish(outputs.markers(grasps, frame, stamp))

    def close(self) -> None:
        """Cancel the Track stream, if any, and close the connection to the service (the session
        stays on it, to plan from again)."""
        if self._track is not None:
            track, self._track = self._track, None
            track.close()
        self._client.close()
