"""TSDF fusion of depth frames with Open3D, and the read-outs the network and users need."""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass

import numpy as np
import open3d as o3d
import torch

from service.cloud_fusion import CloudFusion, shared_fusion
from service.depth_scale import SceneScale, depth_scale
from vgn_contract.geometry import invert
from vgn_contract.schemas import Intrinsics

#: Truncation distance in voxels (docs/conventions.md).
TRUNCATION_VOXELS = 4
#: Open3D's voxel read-out drops voxels with |tsdf| at or beyond this; VGN trained on that.
OBSERVED_TSDF_LIMIT = 0.98


def _pinhole(intrinsics: Intrinsics) -> o3d.camera.PinholeCameraIntrinsic:
    i = intrinsics
    return o3d.camera.PinholeCameraIntrinsic(i.width, i.height, i.fx, i.fy, i.cx, i.cy)


class _FrameBuffer:
    """A reusable Open3D RGBD image of one size, filled in place.

    Building an ``RGBDImage`` per frame is mostly Open3D's copies; writing into a cached one
    is far cheaper, and the fused result is identical. Open3D wants a colour image beside
    the depth even for a colourless volume."""

    def __init__(self, height: int, width: int) -> None:
        self.shape = (height, width)
        color = o3d.geometry.Image(np.zeros((height, width, 3), dtype=np.uint8))
        depth = o3d.geometry.Image(np.zeros((height, width), dtype=np.float32))
        self.image = o3d.geometry.RGBDImage.create_from_color_and_depth(
            color, depth, depth_scale=1.0, depth_trunc=np.inf, convert_rgb_to_intensity=False
        )
        self._depth = np.asarray(self.image.depth)  # a writable view of Open3D's memory

    def fill(self, depth: np.ndarray, max_depth: float) -> o3d.geometry.RGBDImage:
        np.copyto(self._depth, depth)
        self._depth[self._depth > max_depth] = 0.0
        return self.image


class TSDFVolume:
    """One Open3D ``UniformTSDFVolume``: a cube of ``size`` metres, ``resolution`` voxels a
    side, whose corner is the origin of the *workspace* frame."""

    def __init__(self, size: float, resolution: int) -> None:
        self.size = size
        self.resolution = resolution
        self.voxel_size = size / resolution
        self._volume = o3d.pipelines.integration.UniformTSDFVolume(
            length=size,
            resolution=resolution,
            sdf_trunc=TRUNCATION_VOXELS * self.voxel_size,
            color_type=o3d.pipelines.integration.TSDFVolumeColorType.NoColor,
        )
        self._buffer: _FrameBuffer | None = None  # one, for the last frame size seen
        self._scratch: TSDFVolume | None = None  # what one frame alone fuses (integrate_forgetting)
        self._empty: o3d.utility.Vector2dVector | None = None  # zeros, to empty the scratch volume

    def integrate(
        self, depth: np.ndarray, intrinsics: Intrinsics, camera_in_workspace: np.ndarray, max_depth: float
    ) -> None:
        """Fuse an (H, W) depth image in metres (0 = no reading) seen from
        ``camera_in_workspace`` (camera → workspace, 4×4, OpenCV optical frame)."""
        extrinsic = invert(camera_in_workspace)  # Open3D wants workspace → camera.
        if self._buffer is None or self._buffer.shape != depth.shape:
            self._buffer = _FrameBuffer(*depth.shape)
        self._volume.integrate(self._buffer.fill(depth, max_depth), _pinhole(intrinsics), extrinsic)

    def fuse(
        self, depth: np.ndarray, intrinsics: Intrinsics, camera_in_workspace: np.ndarray, max_depth: float,
        decay: float | None,
    ) -> None:  # fmt: skip
        """``integrate``, or ``integrate_forgetting`` for a session that forgets (``decay`` set)."""
        if decay is None:
            self.integrate(depth, intrinsics, camera_in_workspace, max_depth)
        else:
            self.integrate_forgetting(depth, intrinsics, camera_in_workspace, max_depth, decay)

    def integrate_forgetting(
        self, depth: np.ndarray, intrinsics: Intrinsics, camera_in_workspace: np.ndarray, max_depth: float,
        decay: float,
    ) -> None:  # fmt: skip
        """``integrate``, with what this frame sees again weighed by ``decay`` first.

        Open3D averages each voxel's TSDF over its frames by weight. Scaling the old weight of
        every voxel the frame updates turns that into a moving average which follows a changing
        scene, while what the frame does not see (out of view, or hidden behind the robot's own
        hand) keeps its evidence. The frame is fused into a scratch volume to learn which voxels
        it updates and what it says there, and the two are combined."""
        if self._scratch is None:
            self._scratch = TSDFVolume(self.size, self.resolution)
            self._empty = o3d.utility.Vector2dVector(np.zeros((self.resolution**3, 2)))
        scratch = self._scratch
        scratch._volume.inject_volume_tsdf(self._empty)  # Open3D's reset() keeps the voxels
        scratch.integrate(depth, intrinsics, camera_in_workspace, max_depth)
        new = np.asarray(scratch._volume.extract_volume_tsdf())
        values = np.asarray(self._volume.extract_volume_tsdf())
        seen = new[:, 1] > 0
        old_weight = values[seen, 1] * decay
        weight = old_weight + new[seen, 1]
        values[seen, 0] = (values[seen, 0] * old_weight + new[seen, 0] * new[seen, 1]) / weight
        values[seen, 1] = weight
        self._volume.inject_volume_tsdf(o3d.utility.Vector2dVector(values))

    def grid(self) -> np.ndarray:
        """(N, N, N) float32 network input indexed [i, j, k] along the workspace x, y, z axes.

        Observed voxels with |tsdf| < 0.98 hold (tsdf + 1) / 2 (0.5 = surface, > 0.5 in front
        of it); unobserved and deep voxels hold 0 (docs/conventions.md). Vectorised equivalent of
        reading Open3D's voxel point cloud back voxel by voxel, as VGN did.
        """
        values = np.asarray(self._volume.extract_volume_tsdf())  # (N³, 2): tsdf, weight
        tsdf, weight = values[:, 0], values[:, 1]
        observed = (weight > 0) & (np.abs(tsdf) < OBSERVED_TSDF_LIMIT)
        grid = np.where(observed, (tsdf + 1.0) * 0.5, 0.0).astype(np.float32)
        return grid.reshape(self.resolution, self.resolution, self.resolution)

    def surface_cloud(self) -> tuple[np.ndarray, np.ndarray]:
        """Points (M, 3) and unit normals (M, 3) of the fused surface, workspace frame.

        Normals come from the TSDF gradient and point out of the surface, towards free space.
        """
        cloud = self._volume.extract_point_cloud()
        points = np.asarray(cloud.points, dtype=np.float64)
        if len(points) and not cloud.has_normals():
            cloud.estimate_normals()
        normals = np.asarray(cloud.normals, dtype=np.float64).reshape(-1, 3)
        return points, normals

    def surface_points(self) -> np.ndarray:
        """(M, 3) points where the fused TSDF crosses zero, workspace frame: the observed
        surface at sub-voxel precision, without normals (cheap enough for every request)."""
        return np.asarray(self._volume.extract_point_cloud().points, dtype=np.float64).reshape(-1, 3)

    def state(self) -> np.ndarray:
        """(N³, 2) float32 (tsdf, weight) per voxel, in Open3D's voxel order: everything fusion
        keeps, so ``restore`` of it continues exactly where this volume stands (Open3D holds
        float32, so nothing is lost)."""
        return np.asarray(self._volume.extract_volume_tsdf(), dtype=np.float32)

    def restore(self, state: np.ndarray) -> None:
        """Overwrite every voxel with a ``state()`` of a volume of the same size and resolution."""
        expected = (self.resolution**3, 2)
        if state.shape != expected:
            raise ValueError(f"a {self.resolution}³ volume's state has shape {expected}, got {state.shape}")
        self._volume.inject_volume_tsdf(o3d.utility.Vector2dVector(state.astype(np.float64)))


@dataclass(frozen=True)
class QueuedFrame:
    """A frame waiting for the cloud volume."""

    depth: np.ndarray  # float16 metres (``compact_depth``)
    intrinsics: Intrinsics
    camera_in_workspace: np.ndarray
    max_depth: float
    decay: float | None = None  # the session's forgetting (TSDFVolume.integrate_forgetting)
    scale: float = 1.0  # fused as depth * scale (``service.depth_scale``)

    def scaled_depth(self) -> np.ndarray:
        """The depth to fuse (metres): the compact copy, times ``scale`` in float32 where it is not 1."""
        return self.depth if self.scale == 1.0 else self.depth.astype(np.float32) * np.float32(self.scale)

    @property
    def nbytes(self) -> int:
        """Memory the queued depth holds, counted against the fusion worker's byte budget."""
        return self.depth.nbytes


def compact_depth(depth: np.ndarray) -> np.ndarray:
    """``depth`` as float16: half the memory of float32 (0.6 MB for 640×480) while it waits.

    Its spacing is 0.5 mm at 0.5-1 m and 1 mm at 1-2 m, a fraction of the cloud volume's
    2.5 mm voxels (the cloud moves by well under a voxel, see the tests); a value past
    float16's range becomes inf, which fusion drops like any depth beyond ``max_depth``.
    Every pixel is kept: subsampling where two pixels fit in a voxel halved the memory
    again but moved edges enough to change the antipodal planner's grasps. The cast runs in
    torch, which uses the CPU's conversion instructions where numpy converts value by value."""
    return torch.from_numpy(np.ascontiguousarray(depth, dtype=np.float32)).to(torch.float16).numpy()


class SceneVolume:
    """What a session fuses: the coarse grid the network reads, and a finer volume for the
    point cloud, both in the workspace whose corner sits at ``workspace_pose`` in the world.

    The fine volume (120³) costs many times the coarse one to integrate and only cloud readers
    need it, so an upload fuses the coarse volume and queues a compact copy of the frame
    (``compact_depth``) for the shared ``CloudFusion`` worker (docs/design.md); no frame is dropped.

    Locks: the caller holds the session's lock for ``integrate``, ``reset``, ``grid`` and
    ``cloud``; the worker takes none of the session's. ``_lock`` guards the queue and which
    fine volume is current (short holds); ``_fusing`` is held while integrating into the fine
    volume, so a cloud read waits for the worker's frame in flight. A reset swaps in a new
    queue and volume: a frame the worker was fusing lands in the discarded volume."""

    def __init__(self, size: float, resolution: int, workspace_pose: np.ndarray, cloud_resolution: int,
                 max_pending: int = 512, fusion: CloudFusion | None = None,
                 decay: float | None = None, register_scale: bool = False) -> None:  # fmt: skip
        self.max_pending = max_pending
        #: Each frame is scaled about its camera to meet what the coarse volume holds before it is
        #: fused (``service.depth_scale``).
        self.register_scale = register_scale
        self._scales = SceneScale()
        #: Forgetting: each frame first weighs the evidence it sees again by this
        #: (``TSDFVolume.integrate_forgetting``).
        self.decay = decay
        self.workspace_pose = np.asarray(workspace_pose, dtype=np.float64)
        self._world_to_workspace = invert(self.workspace_pose)
        self._size, self._resolution, self._cloud_resolution = size, resolution, cloud_resolution
        self._fusion = fusion or shared_fusion()
        self._lock = threading.Lock()
        self._room = threading.Condition(self._lock)  # an upload waits here for queue space
        self._fusing = threading.Lock()
        self._pending: deque[QueuedFrame] = deque()
        self._fine: TSDFVolume | None = None
        self._cloud_read = False  # then the worker keeps its volume fused in the background
        self._draining = False  # a quarter full: fused to the end in lulls, read or not
        self._waiting = 0
        self._closed = False
        self.coarse = TSDFVolume(size, resolution)

    @property
    def pending(self) -> int:
        """Frames queued for the cloud volume."""
        return len(self._pending)

    def reset(self) -> None:
        """Start both volumes empty and drop the queued frames; uploads waiting for room go on."""
        with self._lock:
            self.coarse = TSDFVolume(self._size, self._resolution)
            self._fine = None
            self._drop_pending()
            self._scales = SceneScale()

    def close(self) -> None:
        """The session is gone: free the queue and take no more frames for the cloud (an
        upload waiting for room returns)."""
        with self._lock:
            self._closed = True
            self._drop_pending()
        self._fusion.forget(self)

    def integrate(
        self, depth: np.ndarray, intrinsics: Intrinsics, camera_pose: np.ndarray, max_depth: float
    ) -> None:
        """Fuse a depth image (metres) taken from ``camera_pose`` (camera → world)."""
        camera_in_workspace = self._world_to_workspace @ camera_pose
        # Everything that could fail runs before the first volume changes.
        frame = QueuedFrame(compact_depth(depth), intrinsics, camera_in_workspace, max_depth, self.decay)
        if self.register_scale:
            tsdf = self.coarse.state().reshape(self._resolution, self._resolution, self._resolution, 2)
            relative = 1.0
            if tsdf[..., 1].any():
                voxel_size = self._size / self._resolution
                relative = depth_scale(depth, intrinsics, camera_in_workspace, tsdf, voxel_size, max_depth)
            scaled = self._scales.add(frame, relative)
            if len(scaled) > 1:  # the scene's scale moved: its first frames are fused again
                self._fuse_again(scaled)
                return
            frame = scaled[0]
            depth = depth if frame.scale == 1.0 else depth * np.float32(frame.scale)
        self.coarse.fuse(depth, intrinsics, camera_in_workspace, max_depth, self.decay)
        while True:
            with self._lock:
                if self._closed or self._fusion.closed:  # the session or the service is gone
                    return
                if not (self._pending and self._full()):
                    self._pending.append(frame)
                    self._fusion.account(frame.nbytes)
                    break
                self._waiting += 1  # makes the queue due for the worker at once
            self._fusion.notify(self)  # never with _lock held: the worker takes its lock first
            with self._lock:
                try:
                    if not (self._closed or self._fusion.closed) and self._pending and self._full():
                        self._room.wait()
                finally:
                    self._waiting -= 1
        self._fusion.notify(self, frame=True)

    def _fuse_again(self, frames: list[QueuedFrame]) -> None:
        """Fuse the coarse volume again from ``frames`` (the session's first, at their new scales),
        and queue them for a new fine volume in place of what it held."""
        coarse = TSDFVolume(self._size, self._resolution)
        for frame in frames:
            coarse.fuse(
                frame.scaled_depth(),
                frame.intrinsics,
                frame.camera_in_workspace,
                frame.max_depth,
                frame.decay,
            )
        with self._fusing, self._lock:  # not while the worker fuses a frame into the old fine volume
            if self._closed or self._fusion.closed:  # the session or the service is gone
                return
            self.coarse, self._fine = coarse, None
            self._fusion.account(-sum(frame.nbytes for frame in self._pending))
            self._pending = deque(frames)
            self._fusion.account(sum(frame.nbytes for frame in frames))
        self._fusion.notify(self, frame=True)

    def grid(self) -> np.ndarray:
        """The network input, (N, N, N) float32 in the workspace frame (see ``TSDFVolume.grid``)."""
        return self.coarse.grid()

    def surface_points(self) -> np.ndarray:
        """(M, 3) surface points of the coarse volume (the network's), *world* frame: the cheap
        observed geometry the clearance check tests hands against (``TSDFVolume.surface_points``)."""
        return self._to_world(self.coarse.surface_points())

    def surface_cloud(self) -> np.ndarray:
        """(M, 6) float32 points and unit normals (from the TSDF gradient) of the coarse volume's
        surface, *world* frame: the network's view of the faces, cheap enough for every request."""
        return self._in_world(*self.coarse.surface_cloud())

    def surface(self) -> tuple[np.ndarray, np.ndarray]:
        """``surface_points()`` and ``surface_cloud()`` from one read of the coarse volume: Open3D
        extracts points and normals together, and a request with both the clearance and the
        antipodal check would otherwise pay for that twice."""
        points, normals = self.coarse.surface_cloud()
        return self._to_world(points), self._in_world(points, normals)

    def cloud(self) -> np.ndarray:
        """(M, 6) float32 points and unit normals of the fused surface in the *world* frame."""
        self._cloud_read = True
        with self._fusing:
            while self._fuse_oldest():
                pass
            if self._fine is None:
                return np.zeros((0, 6), dtype=np.float32)
            points, normals = self._fine.surface_cloud()
        return self._in_world(points, normals)

    def _to_world(self, points: np.ndarray) -> np.ndarray:
        return points @ self.workspace_pose[:3, :3].T + self.workspace_pose[:3, 3]

    def _in_world(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        return np.hstack([self._to_world(points), normals @ self.workspace_pose[:3, :3].T]).astype(np.float32)

    def state(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The coarse volume's ``TSDFVolume.state()`` and the fine one's (None before any frame
        reached it), the queued frames fused first so that the fine state holds every frame."""
        with self._fusing:
            while self._fuse_oldest():
                pass
            fine = None if self._fine is None else self._fine.state()
        return self.coarse.state(), fine

    def restore(self, coarse: np.ndarray, fine: np.ndarray | None) -> None:
        """Start from a ``state()`` instead of empty volumes (a session moved between services);
        the fine volume keeps the resolution it was saved at, a reset returns to this service's."""
        volume = TSDFVolume(self._size, self._resolution)
        volume.restore(coarse)
        restored_fine = None
        if fine is not None:
            resolution = round(len(fine) ** (1 / 3))
            restored_fine = TSDFVolume(self._size, resolution)
            restored_fine.restore(fine)
        with self._lock:
            self._drop_pending()
            self.coarse, self._fine = volume, restored_fine
            self._scales = SceneScale(settled=True)  # the restored volume's scale is the scene's

    # For the worker (service.cloud_fusion.FusionQueue) -----------------------------------------
    @property
    def cloud_read(self) -> bool:
        """Whether anything has read the fine cloud: from then on the worker keeps it fused in lulls."""
        return self._cloud_read

    def fusion_wanted(self) -> tuple[bool, bool]:
        """For the worker: (worth fusing in a lull: the cloud was read or the queue got a quarter full,
        wanted now: an upload waits for room)."""
        with self._lock:
            if not self._pending:
                self._draining = False
                return False, False
            self._draining = self._draining or len(self._pending) * 4 >= self.max_pending
            return self._cloud_read or self._draining, self._waiting > 0

    def fuse_next(self) -> bool:
        """For the worker: fuse the oldest queued frame; False when the queue is empty."""
        with self._fusing:
            return self._fuse_oldest()

    # Helpers -------------------------------------------------------------------------------------
    def _full(self) -> bool:
        return len(self._pending) >= self.max_pending or self._fusion.over_budget()

    def _fuse_oldest(self) -> bool:
        """Fuse the oldest queued frame and only then dequeue it (a reader holding ``_fusing``
        never sees a frame neither queued nor fused); call with ``_fusing`` held."""
        with self._lock:
            if not self._pending:
                return False
            frame = self._pending[0]
            if self._fine is None:
                self._fine = TSDFVolume(self._size, self._cloud_resolution)
            fine = self._fine
        try:
            # In upload order, as the coarse volume forgot.
            fine.fuse(
                frame.scaled_depth(),
                frame.intrinsics,
                frame.camera_in_workspace,
                frame.max_depth,
                frame.decay,
            )
        finally:  # a frame Open3D refuses is dropped rather than retried forever
            with self._lock:
                if self._fine is fine and self._pending and self._pending[0] is frame:  # else reset
                    self._pending.popleft()
                    self._fusion.account(-frame.nbytes)
                    self._room.notify_all()
        return True

    def _drop_pending(self) -> None:
        dropped, self._pending = self._pending, deque()
        self._fusion.account(-sum(frame.nbytes for frame in dropped))
        self._room.notify_all()
