"""The planning core: sessions, fusion and grasp planning behind one object.

Front ends (the FastAPI app, the gRPC servicer in ``service.grpc``, in-process benchmarks) call
this and map its ``ServiceError``s to their own codes; nothing here knows about HTTP or gRPC.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import TypeVar

import numpy as np
from scipy.spatial.transform import Rotation

from service.baseline import AntipodalConfig, grips_antipodally, plan_antipodal
from service.checks import Checked, check_grasps, clear_of
from service.clearance import FALLBACK_MARGIN, NETWORK_FINE_MIN_POINTS, ClearanceConfig
from service.cloud_fusion import CloudFusion
from service.depth import decode_depth
from service.errors import InvalidInput, ModelNotReady, SessionNotFound
from service.grip import MIN_GRIP_FRAMES, GripConfig
from service.hands import Hands, planning_for
from service.planner import (
    NO_MODEL_MESSAGE,
    GraspPlanner,
    InferenceOptions,
    antipodal_config,
    in_requested_region,
    resolved_threshold,
)
from service.runtime import configured_threads, runtime_report, tune_malloc
from service.sessions import SessionStore
from service.settings import Settings
from service.snapshot import Snapshot
from service.snapshot import decode as decode_snapshot
from service.snapshot import encode as encode_snapshot
from service.vgn.checkpoint import CheckpointError
from vgn_contract.gripper_description import DEFAULT_GRIPPER, GripperDescription
from vgn_contract.schemas import (
    ANTIPODAL_DEFAULT_THRESHOLD,
    FrameMeta,
    FrameResult,
    Grasp,
    GraspDefaults,
    GraspQuery,
    GraspResult,
    GripperInfo,
    GripperList,
    HandModel,
    Intrinsics,
    ModelInfo,
    OneViewModel,
    RuntimeInfo,
    SessionCreate,
    SessionInfo,
)

CONVENTIONS = {
    "units": "metres, seconds; angles in query parameters in degrees",
    "quaternion": "[x, y, z, w], unit length",
    "camera": "pinhole, OpenCV optical frame (x right, y down, z forward); camera_pose is camera->world",
    "workspace": "cube of side `size` whose corner is at the workspace pose; voxel (i,j,k) at (i,j,k)*voxel_size",
    "grasp_frame": "+z approach, y finger closing axis, origin between the finger bases",
    "grid": "observed |tsdf|<0.98 voxels hold (tsdf+1)/2, others 0; indexed [x, y, z]",
}
#: Volumes fused from this many frames are the one-view network's (``VGN_ONE_VIEW_MODEL``): one fixed
#: camera's side view, too little of the surface for the grip check as well (``MIN_GRIP_FRAMES``).
ONE_VIEW_FRAMES = 1
#: How ``GET /model`` describes a network besides the main one.
Described = TypeVar("Described", OneViewModel, HandModel)


class PlanningService:
    """Sessions of fused depth frames and VGN grasp planning on them (thread-safe)."""

    def __init__(
        self,
        settings: Settings,
        planner: GraspPlanner,
        one_view: GraspPlanner | None = None,
        hand_networks: Mapping[str, GraspPlanner] | None = None,
    ) -> None:
        self.settings = settings
        self.planner = planner
        #: Answers in ``planner``'s place on one-frame volumes of the default hand (:meth:`network_for`).
        self.one_view = one_view
        #: Each hand's own network, by hand name: it answers every session of its hand (:meth:`network_for`).
        self.hand_networks = dict(sorted((hand_networks or {}).items()))
        self.grip_config = GripConfig(preferred_alignment=settings.grip_preferred_alignment)
        self.hands = Hands.build(settings.grippers, settings.network_grippers, self.hand_networks)
        self.sessions = SessionStore(
            settings.max_sessions,
            settings.session_ttl_s,
            settings.cloud_resolution,
            settings.cloud_max_pending_frames,
            cloud_fusion=CloudFusion(max_queued_bytes=int(settings.cloud_max_queued_mb * 2**20)),
            register_scale=settings.depth_scale_registration,
        )

    @classmethod
    def from_settings(cls, settings: Settings) -> PlanningService:
        """Load the configured networks (``CheckpointError`` for weights that cannot be loaded,
        ``ValueError`` for a hand setting that names an unknown hand or a file that is no hand)."""
        import torch

        hands = Hands.build(settings.grippers, settings.network_grippers)  # checked before any weights load
        torch.set_num_threads(settings.torch_threads or configured_threads())
        tune_malloc()
        options = InferenceOptions(
            settings.inference,
            settings.precision,
            settings.batch_window_ms,
            settings.max_batch,
            settings.lanes,
            settings.heads,
        )
        planner = GraspPlanner.from_path(settings.model_path(), settings.device, options)
        hand_networks = load_hand_networks(settings, hands, planner)
        return cls(settings, planner, load_one_view(settings, planner), hand_networks)

    def close(self) -> None:
        """Free the sessions and end the cloud worker thread (at shutdown)."""
        self.sessions.close()

    # Sessions -----------------------------------------------------------------------------
    def create_session(self, spec: SessionCreate) -> SessionInfo:
        """Open a session for the hand ``spec`` names (``InvalidInput`` for an unknown one,
        ``GripperNotServed`` for one no network serves; ``SessionExists`` for a taken id,
        ``CapacityExceeded`` when every one is busy)."""
        hand = self.hands.resolve(spec.gripper)
        return self.sessions.create(spec, hand=hand).info(self.sessions.ttl_s)

    def grippers(self) -> GripperList:
        """The hands this service knows, each with the network that serves it (or none) and that
        network's operating threshold."""
        return GripperList(
            grippers=[self._gripper_info(name, hand) for name, hand in sorted(self.hands.known.items())],
            default=DEFAULT_GRIPPER,
        )

    def _gripper_info(self, name: str, hand: GripperDescription) -> GripperInfo:
        """One hand as ``GET /grippers`` lists it."""
        network = self.served_by(name)
        return GripperInfo(
            name=name,
            version=hand.version,
            description=hand.description,
            max_opening=hand.max_opening,
            finger_depth=hand.finger_depth,
            network=None if network is None else network.model_id or "vgn (no weights loaded yet)",
            threshold=None if network is None else network.default_threshold,
        )

    def served_by(self, name: str) -> GraspPlanner | None:
        """The network that plans for the hand ``name`` (the main one also on a volume of one
        frame); ``None`` when none does."""
        if name not in self.hands.served:
            return None
        return self.hand_networks.get(name, self.planner)

    def export_session(self, session_id: str) -> bytes:
        """A session's snapshot (``service.snapshot``): its settings, counts and volumes, the
        frames still queued for its cloud fused first. The session stays as it was."""
        with self.sessions.use(session_id) as session:
            coarse, fine = session.volume.state()
            state = Snapshot(session.session_id, session.workspace, session.intrinsics, session.frame_count,
                             round(session.integration_ms, 3), coarse, fine, session.volume.decay,
                             session.hand.name)  # fmt: skip
        return encode_snapshot(state)

    def import_session(self, data: bytes, session_id: str | None = None) -> SessionInfo:
        """Open a session from a snapshot, under its own id or ``session_id``; ``InvalidInput``
        for a damaged or foreign file, ``SessionExists`` for a taken id."""
        snapshot = decode_snapshot(data)
        spec = SessionCreate.model_validate({
            "session_id": session_id or snapshot.session_id,
            "workspace": snapshot.workspace,
            "intrinsics": snapshot.intrinsics,
            "decay": snapshot.decay,
            "gripper": snapshot.gripper,
        })  # fmt: skip
        hand = self.hands.resolve(spec.gripper)
        return self.sessions.create(spec, snapshot, hand).info(self.sessions.ttl_s)

    def session_info(self, session_id: str) -> SessionInfo:
        """A session's state; ``SessionNotFound`` once it is gone or expired."""
        return self.sessions.info(session_id)

    def list_sessions(self) -> list[SessionInfo]:
        """Every live session, the expired ones dropped first."""
        return self.sessions.list()

    def delete_session(self, session_id: str) -> None:
        """Drop a session and free its volumes now; a request still holding it finishes on its own copy."""
        self.sessions.delete(session_id)

    def reset_session(self, session_id: str) -> SessionInfo:
        """Empty a session's volumes but keep its workspace and intrinsics, waiting for its current user."""
        with self.sessions.use(session_id) as session:
            session.reset()
            return session.info(self.sessions.ttl_s)

    # Frames -------------------------------------------------------------------------------
    def add_encoded_frame(
        self, session_id: str, data: bytes, media_type: str, meta: FrameMeta
    ) -> FrameResult:
        """Decode an uploaded depth image (PNG or raw float32) and fuse it.

        The image is decoded and checked before the session is touched, so a rejected frame
        leaves the volume as it was. An unknown session is reported before any decoding.
        """
        self.sessions.info(session_id)
        intrinsics = self._frame_intrinsics(session_id, meta.intrinsics)
        depth = decode_depth(data, media_type, intrinsics, meta.depth_scale)  # float32, invalid = 0
        return self._integrate(session_id, depth, meta.camera_pose.as_matrix(), intrinsics, meta.max_depth)

    def add_frame(
        self,
        session_id: str,
        depth: np.ndarray,
        camera_pose: np.ndarray,
        intrinsics: Intrinsics | None = None,
        max_depth: float = 2.0,
    ) -> FrameResult:
        """Fuse a depth image (H, W) in metres taken from ``camera_pose`` (4×4 camera → world).

        Invalid readings (0, NaN, inf) are ignored; ``intrinsics`` default to the session's.
        """
        intrinsics = self._frame_intrinsics(session_id, intrinsics)
        depth = np.asarray(depth)
        if depth.shape != (intrinsics.height, intrinsics.width):
            raise InvalidInput(
                f"depth has shape {depth.shape}, intrinsics say {(intrinsics.height, intrinsics.width)}"
            )
        depth = np.where(np.isfinite(depth), depth, 0.0).astype(np.float32)
        return self._integrate(session_id, depth, camera_pose, intrinsics, max_depth)

    def _integrate(self, session_id: str, depth: np.ndarray, camera_pose: np.ndarray, intrinsics: Intrinsics,
                   max_depth: float) -> FrameResult:  # fmt: skip
        with self.sessions.use(session_id) as session:
            started = time.perf_counter()
            session.volume.integrate(depth, intrinsics, camera_pose, max_depth)
            elapsed_ms = (time.perf_counter() - started) * 1e3
            session.fused_frame(elapsed_ms)
            return FrameResult(session_id=session_id, frame_count=session.frame_count,
                               integration_ms=round(elapsed_ms, 3))  # fmt: skip

    def _frame_intrinsics(self, session_id: str, intrinsics: Intrinsics | None) -> Intrinsics:
        if intrinsics is not None:
            return intrinsics
        session_intrinsics = self.sessions.info(session_id).intrinsics
        if session_intrinsics is None:
            raise InvalidInput("frame has no intrinsics and the session has no default intrinsics")
        return session_intrinsics

    # Read-outs ----------------------------------------------------------------------------
    def grid(self, session_id: str) -> np.ndarray:
        """The session's (N, N, N) float32 network input, workspace frame."""
        with self.sessions.use(session_id) as session:
            return session.volume.grid()

    def cloud(self, session_id: str) -> np.ndarray:
        """(M, 6) float32 surface points and normals, world frame."""
        with self.sessions.use(session_id) as session:
            return session.volume.cloud()

    def plan(self, session_id: str, query: GraspQuery) -> GraspResult:
        """Ranked grasps (world frame, best first) on the session's fused volume, by VGN or,
        with ``planner="antipodal"``, by the geometric baseline on its cloud (no model needed).
        Options the query leaves unset (turn averaging, the clearance and grip checks) take the operator's
        defaults, so a plain request gets the service's best answer. No queued cloud frame
        starts fusing meanwhile (it would hold the GIL for tens of milliseconds)."""
        with self.sessions.cloud_fusion.planning(), planning_for(self.sessions.hand(session_id)):
            return self._plan(session_id, query)

    def _plan(self, session_id: str, query: GraspQuery) -> GraspResult:
        self.sessions.info(session_id)  # an unknown session is a 404 whatever the model
        baseline = query.planner == "antipodal"
        turn_average = None
        if not baseline and not self.planner.ready:
            raise ModelNotReady(NO_MODEL_MESSAGE)
        clearance = self.settings.clearance if query.clearance is None else query.clearance
        grip_on = self.settings.grip if query.grip is None else query.grip
        with self.sessions.use(session_id) as session:
            started = time.perf_counter()
            grip = grip_on and session.frame_count >= MIN_GRIP_FRAMES
            observed = session.volume.cloud() if baseline else session.volume.grid()
            grid = (session.volume.grid() if baseline else observed) if grip else None
            # The grid the support plane is found on, for clearing the surface's pairs.
            support_grid = grid if grid is not None else observed if not baseline else None
            if support_grid is None and clearance:
                support_grid = session.volume.grid()
            # The antipodal check refines the grip check where it runs: whether the pads meet opposed
            # faces (one frame shows one face of each object: no grip check then), on the grid's faces
            # first; the fine cloud is read only where those do not settle it.
            opposing = self.settings.antipodal_check and not baseline and grip
            points, faces = session.volume.surface() if clearance or opposing else (None, None)
            surface, faces = (points if clearance else None), (faces if opposing else None)
            voxel_size, workspace_pose = session.workspace.voxel_size, session.volume.workspace_pose
            workspace_size = session.workspace.size
            session_hand = session.hand
            frame_count, integration_ms = session.frame_count, session.integration_ms
            revision, kept = session.revision, session.network_output
        # Planning runs outside the session lock so frames can keep arriving.
        # With a check, every grasp is checked and only then are max_grasps kept.
        ranked = query.model_copy(update={"max_grasps": None}) if clearance or grip else query
        network = self.network_for(frame_count, session_hand)
        if baseline:
            grasps, model, threshold = [], "antipodal", antipodal_config(ranked).threshold
        else:
            turn_average = self.settings.turn_average if query.turn_average is None else query.turn_average
            # One revision: one frame count and the session's one hand, so one network.
            key = (revision, turn_average)
            reuse = self.settings.reuse_output and kept is not None and kept[0] == key
            output = kept[1] if reuse else network.infer(observed, turn_average)
            grasps = network.detect(observed, output, voxel_size, workspace_pose, ranked)
            if self.settings.reuse_output and not reuse:
                self._keep_output(session_id, key, output)
            model = network.model_id or ""
            threshold = resolved_threshold(query, network.default_threshold)

        margin = ClearanceConfig()  # the clearance check's, relaxed below where it leaves nothing
        # The surface taken to go on past the cube's sides; dropped below where it leaves nothing.
        past_sides = True

        def checked_of(candidates: list[Grasp], grip_grid: np.ndarray | None = grid) -> Checked:
            return check_grasps(candidates, surface, grip_grid, voxel_size, workspace_pose, workspace_size,
                                self.grip_config, self.settings.alternatives, margin, past_sides)  # fmt: skip

        cloud: np.ndarray | None = observed if baseline else None

        def fine_cloud() -> np.ndarray:
            nonlocal cloud
            if cloud is None:
                with self.sessions.use(session_id) as session:
                    cloud = session.volume.cloud()
            return cloud

        found_pairs: dict[AntipodalConfig, list[Grasp]] = {}

        def cleared_on_fine_cloud(checked: Checked, network: bool = True) -> Checked:
            # Cleared against the fine cloud as well as the grid's surface: the grid's coarser surface
            # misses what brushes past the fingers. The network's grasps take more of its points to veto.
            if surface is None:
                return checked
            hand = replace(margin, min_points=NETWORK_FINE_MIN_POINTS) if network else margin
            kept = clear_of(checked.grasps, fine_cloud()[:, :3], support_grid, voxel_size, workspace_pose,
                            workspace_size, hand, workspace_size / self.settings.cloud_resolution, past_sides)  # fmt: skip
            dropped = (checked.clearance_dropped or 0) + len(checked.grasps) - len(kept)
            return replace(checked, grasps=kept, clearance_dropped=dropped)

        def checked_pairs(config: AntipodalConfig, grip_grid: np.ndarray | None = grid) -> Checked:
            # The surface's pairs, cleared against the fine cloud they were found on.
            if config not in found_pairs:
                found_pairs[config] = plan_antipodal(fine_cloud(), workspace_pose, config, session_hand)
            return cleared_on_fine_cloud(checked_of(found_pairs[config], grip_grid), network=False)

        def answer() -> tuple[Checked, str, float, bool]:
            """The checked grasps, the model and threshold that answer, and whether the threshold fell back."""
            answering, threshold_now = model, threshold
            checked = checked_pairs(antipodal_config(ranked)) if baseline else checked_of(grasps)
            if faces is not None and checked.grasps:
                checked, answering = self._opposed(
                    checked, answering, faces, fine_cloud, session_hand, checked_pairs, ranked,
                    cleared_on_fine_cloud,
                )  # fmt: skip
                if answering == "antipodal":  # the surface's pairs answer, at the baseline's threshold
                    threshold_now = antipodal_config(ranked).threshold
            floor = self.settings.fallback_threshold
            checks_ran = surface is not None or grid is not None
            fallback = (not baseline and checks_ran and not checked.grasps and query.threshold is None
                        and floor < threshold_now)  # fmt: skip
            if fallback:
                # Nothing passed at the operating threshold: rather than leave the robot with nothing to
                # do, answer with what the checks vouch for down to the floor, and say so in ``threshold``.
                lower = ranked.model_copy(update={"threshold": floor})
                threshold_now = floor
                # The surface's pairs first, under the clearance check alone: their own antipodal test on
                # the fine cloud stands in for the grip check, whose coarse grid misses thin walls. Then
                # the network's grasps below its threshold, where the surface offers none.
                pairs = None
                if self.settings.surface_fallback:
                    pairs = checked_pairs(antipodal_config(lower), None)
                if pairs is not None and pairs.grasps:
                    # Those whose pads meet opposed faces of the grid's surface too, where there are some.
                    kept = (
                        self._opposed_on_grid(pairs.grasps, faces, session_hand) if faces is not None else []
                    )
                    narrow = self._narrow_first(kept or pairs.grasps, session_hand)
                    checked, answering = replace(pairs, grasps=narrow), "antipodal"
                else:
                    checked = checked_of(network.detect(observed, output, voxel_size, workspace_pose, lower))
                    if cloud is not None:  # read for the pairs: it clears the network's grasps too
                        checked = cleared_on_fine_cloud(checked)
            return checked, answering, threshold_now, fallback

        checked, answering, answered_threshold, fallback = answer()
        if surface is not None and not checked.grasps and margin.margin > FALLBACK_MARGIN:
            # Nothing clears the wider hand: what clears the narrower one, rather than nothing.
            margin = replace(margin, margin=FALLBACK_MARGIN)
            checked, answering, answered_threshold, fallback = answer()
        if surface is not None and not checked.grasps:
            # Nothing clears the surface carried on past the cube's sides either: what clears the surface
            # as observed, rather than nothing (an object across a side is otherwise never offered).
            past_sides = False
            checked, answering, answered_threshold, fallback = answer()
        model, threshold = answering, answered_threshold
        grasps = in_requested_region(checked.grasps, query, workspace_pose)[: query.max_grasps]
        return GraspResult(
            grasps=grasps,
            planning_ms=round((time.perf_counter() - started) * 1e3, 3),
            integration_ms=round(integration_ms, 3),
            frame_count=frame_count,
            model=model,
            threshold=threshold,
            clearance_dropped=checked.clearance_dropped,
            grip_dropped=checked.grip_dropped,
            workspace_dropped=checked.workspace_dropped,
            turn_average=turn_average,
            clearance=clearance,
            grip=grip_on,
            fallback=fallback,
            clearance_margin=margin.margin if surface is not None else None,
        )

    def _opposed(
        self,
        checked: Checked,
        model: str,
        faces: np.ndarray,
        fine_cloud: Callable[[], np.ndarray],
        hand: GripperDescription,
        checked_pairs: Callable[[AntipodalConfig], Checked],
        query: GraspQuery,
        cleared_on_fine_cloud: Callable[[Checked], Checked],
    ) -> tuple[Checked, str]:
        """The antipodal check on checked VGN grasps. In turn, the first of these that is not empty
        answers: the VGN grasps whose pads meet opposed faces of the grid's surface (``faces``); the
        surface's antipodal pairs that pass every check and meet opposed faces of the grid's surface
        too; the VGN grasps whose pads meet opposed faces of the fine cloud; the other checked pairs;
        the VGN grasps as they were. Pairs answer narrow ones first (``_narrow_first``). Past the
        first, the fine cloud has been read, so the VGN grasps are cleared against it as the pairs are
        (``cleared_on_fine_cloud``). Returns the grasps and the model that answers."""
        kept = self._opposed_on_grid(checked.grasps, faces, hand)
        if kept:
            return replace(checked, grasps=kept), model
        pairs = checked_pairs(antipodal_config(query))
        kept = self._opposed_on_grid(pairs.grasps, faces, hand)
        if kept:
            return replace(pairs, grasps=self._narrow_first(kept, hand)), "antipodal"
        checked = cleared_on_fine_cloud(checked)
        fine_cone = math.radians(self.settings.antipodal_check_angle)
        kept = opposed_grasps(checked.grasps, fine_cloud(), hand, fine_cone)
        if kept:
            return replace(checked, grasps=kept), model
        if pairs.grasps:
            return replace(pairs, grasps=self._narrow_first(pairs.grasps, hand)), "antipodal"
        return checked, model

    def _opposed_on_grid(
        self, grasps: list[Grasp], faces: np.ndarray, hand: GripperDescription
    ) -> list[Grasp]:
        """The ``grasps`` whose pads meet opposed faces of the grid's surface (``faces``) within its cone."""
        return opposed_grasps(grasps, faces, hand, math.radians(self.settings.antipodal_check_grid_angle))

    def _narrow_first(self, pairs: list[Grasp], hand: GripperDescription) -> list[Grasp]:
        """The surface's ``pairs`` that close on at most ``narrow_pair_share`` of the hand's opening,
        where some do, else all of them: a pair that spans most of the opening slips more often."""
        widest = self.settings.narrow_pair_share * hand.max_opening
        return [pair for pair in pairs if pair.width <= widest] or pairs

    def network_for(self, frame_count: int, hand: GripperDescription) -> GraspPlanner:
        """The network for a volume fused from ``frame_count`` frames, planning for ``hand``: the
        hand's own network whatever the frame count, where it has one; else the one-view network on
        one frame of the default hand, whose grasps it was trained on; the main network otherwise,
        and wherever no one-view network is loaded."""
        own = self.hand_networks.get(hand.name)
        if own is not None:
            return own
        one_view = frame_count == ONE_VIEW_FRAMES and hand.name == DEFAULT_GRIPPER
        return self.one_view if one_view and self.one_view is not None else self.planner

    def _keep_output(self, session_id: str, key: tuple[int, bool], output: object) -> None:
        """Keep a session's network output, with the (revision, turn averaging) it was made
        for, for the next request, unless a frame arrived (or the session went) meanwhile."""
        try:
            with self.sessions.use(session_id) as session:
                if session.revision == key[0]:
                    session.network_output = (key, output)
        except SessionNotFound:
            pass

    def grasp_defaults(self) -> GraspDefaults:
        """What a grasp request gets for each option it leaves unset (``plan`` applies the same)."""
        return GraspDefaults(
            turn_average=self.settings.turn_average,
            clearance=self.settings.clearance,
            grip=self.settings.grip,
            threshold=self.planner.default_threshold,
            antipodal_threshold=ANTIPODAL_DEFAULT_THRESHOLD,
            fallback_threshold=self.settings.fallback_threshold,
        )

    def model_info(self) -> ModelInfo:
        """What ``GET /model`` reports: the weights, device, card, request defaults (the threshold
        among them) and runtime settings."""
        defaults = self.grasp_defaults()
        # The runtime still repeats the defaults it held before they had a model of their own.
        repeated = defaults.model_dump(
            include=set(RuntimeInfo.model_fields) & set(GraspDefaults.model_fields)
        )
        return ModelInfo(
            loaded=self.planner.ready,
            model_id=self.planner.model_id,
            source=self.planner.source,
            architecture="VGN (Breyer et al., CoRL 2020)",
            parameters=self.planner.parameters,
            device=str(self.planner.device),
            detail=None if self.planner.ready else NO_MODEL_MESSAGE,
            conventions=CONVENTIONS,
            card=self.planner.card,
            defaults=defaults,
            runtime=RuntimeInfo.model_validate({**runtime_report(), **self.planner.runtime(), **repeated}),
            one_view=self._one_view_info(),
            hand_models=[
                info
                for name, network in self.hand_networks.items()
                if (info := described(network, HandModel, name)) is not None
            ],
        )

    def _one_view_info(self) -> OneViewModel | None:
        """The one-view network as ``GET /model`` reports it; ``None`` when none is loaded."""
        return None if self.one_view is None else described(self.one_view, OneViewModel, DEFAULT_GRIPPER)


def described(network: GraspPlanner, model: type[Described], gripper: str) -> Described | None:
    """A network besides the main one as ``GET /model`` reports it, answering ``gripper``'s
    sessions; ``None`` without weights."""
    if network.model_id is None or network.source is None:
        return None
    return model(model_id=network.model_id, source=network.source, threshold=network.default_threshold,
                 gripper=gripper, card=network.card)  # fmt: skip


def opposed_grasps(
    grasps: list[Grasp], cloud: np.ndarray, hand: GripperDescription, cone: float
) -> list[Grasp]:
    """The ``grasps`` whose pads meet opposed faces of ``cloud`` (world points and normals) within
    ``cone`` radians of the closing axis, in their order."""
    if not grasps:
        return []
    rotations = Rotation.from_quat([g.orientation for g in grasps]).as_matrix()
    positions = np.array([g.position for g in grasps])
    opposed = grips_antipodally(cloud, positions, rotations, hand, cone)
    return [grasp for grasp, keep in zip(grasps, opposed, strict=True) if keep]


def load_one_view(settings: Settings, main: GraspPlanner) -> GraspPlanner | None:
    """The one-view network ``settings`` name, taking turns with ``main`` on the same cores;
    ``None`` when they name none. A file that cannot be loaded stops the start-up, naming the
    setting, since two weights files are in play."""
    path = settings.one_view_model_path()
    if path is None:
        return None
    try:
        return GraspPlanner.from_path(path, settings.device, main.options, alongside=main)
    except CheckpointError as error:
        raise CheckpointError(f"VGN_ONE_VIEW_MODEL: {error}") from None


def load_hand_networks(settings: Settings, hands: Hands, main: GraspPlanner) -> dict[str, GraspPlanner]:
    """The hands' own networks that ``settings`` name, by hand, each taking turns with ``main``
    as the one-view network does. A name that is no known hand, a file that cannot be loaded and a
    card whose data another hand labelled stop the start-up, naming the setting and the hand."""
    hands.checked("VGN_HAND_MODELS", settings.hand_models)
    return {
        name: load_hand_network(name, hands.known[name], path, settings, main)
        for name, path in settings.hand_model_paths(hands.known).items()
    }


def load_hand_network(
    name: str, hand: GripperDescription, path: Path, settings: Settings, main: GraspPlanner
) -> GraspPlanner:
    """The network at ``path`` for ``hand``, after checking that its card (where it records the
    hand that labelled its data) names this hand's version: another hand's grasps would be wrong."""
    try:
        network = GraspPlanner.from_path(path, settings.device, main.options, alongside=main)
    except CheckpointError as error:
        raise CheckpointError(f"VGN_HAND_MODELS: {name}: {error}") from None
    recorded = (network.card or {}).get("gripper")
    if recorded is not None and recorded != hand.version:
        raise CheckpointError(
            f"VGN_HAND_MODELS: {name}: the card of {path} says its data was labelled by the hand "
            f"{recorded!r}, but {name} is {hand.version!r}; train a network on {name}'s data"
        )
    return network
