"""TSDF fusion of depth frames with Open3D, and the read-outs the network and users need."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from client.geometry import invert
from client.schemas import Intrinsics

#: Truncation distance in voxels (docs/conventions.md).
TRUNCATION_VOXELS = 4
#: Open3D's voxel read-out drops voxels with |tsdf| at or beyond this; VGN trained on that.
OBSERVED_TSDF_LIMIT = 0.98


def _pinhole(intrinsics: Intrinsics) -> o3d.camera.PinholeCameraIntrinsic:
    i = intrinsics
    return o3d.camera.PinholeCameraIntrinsic(i.width, i.height, i.fx, i.fy, i.cx, i.cy)


class _FrameBuffer:
    """A reusable Open3D RGBD image of one size, filled in place.

    Building an ``RGBDImage`` per frame costs ~4 ms for 640×480 (mostly Open3D's copies);
    writing into a cached one costs ~0.1 ms, and the fused result is identical. Open3D
    wants a colour image beside the depth even for a colourless volume.
    """

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

    def integrate(
        self, depth: np.ndarray, intrinsics: Intrinsics, camera_in_workspace: np.ndarray, max_depth: float
    ) -> None:
        """Fuse an (H, W) depth image in metres (0 = no reading) seen from
        ``camera_in_workspace`` (camera → workspace, 4×4, OpenCV optical frame)."""
        extrinsic = invert(camera_in_workspace)  # Open3D wants workspace → camera.
        if self._buffer is None or self._buffer.shape != depth.shape:
            self._buffer = _FrameBuffer(*depth.shape)
        self._volume.integrate(self._buffer.fill(depth, max_depth), _pinhole(intrinsics), extrinsic)

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


class SceneVolume:
    """What a session fuses: the coarse grid the network reads, and a finer volume for the
    point cloud, both in the workspace whose corner sits at ``workspace_pose`` in the world.

    The fine volume (120³) costs ~15x the coarse one to integrate (~25 ms a frame here) and
    only cloud readers need it, so frames are queued and fused into it when a cloud is asked
    for, which keeps frame uploads at the coarse volume's cost. Past ``max_pending`` queued
    frames (memory: 1.2 MB each at 640×480) the upload that overflows fuses them.
    """

    def __init__(self, size: float, resolution: int, workspace_pose: np.ndarray, cloud_resolution: int,
                 max_pending: int = 16):  # fmt: skip
        self.max_pending = max_pending
        self.workspace_pose = np.asarray(workspace_pose, dtype=np.float64)
        self._world_to_workspace = invert(self.workspace_pose)
        self._size, self._resolution, self._cloud_resolution = size, resolution, cloud_resolution
        self.reset()

    def reset(self) -> None:
        self.coarse = TSDFVolume(self._size, self._resolution)
        self._fine: TSDFVolume | None = None
        self._pending: list[tuple[np.ndarray, Intrinsics, np.ndarray, float]] = []

    def integrate(self, depth: np.ndarray, intrinsics: Intrinsics, camera_pose: np.ndarray, max_depth: float):
        """Fuse a depth image (metres) taken from ``camera_pose`` (camera → world)."""
        camera_in_workspace = self._world_to_workspace @ camera_pose
        self.coarse.integrate(depth, intrinsics, camera_in_workspace, max_depth)
        self._pending.append((depth, intrinsics, camera_in_workspace, max_depth))
        if len(self._pending) > self.max_pending:
            self._flush_fine()

    def grid(self) -> np.ndarray:
        """The network input, (N, N, N) float32 in the workspace frame (see ``TSDFVolume.grid``)."""
        return self.coarse.grid()

    def cloud(self) -> np.ndarray:
        """(M, 6) float32 points and unit normals of the fused surface in the *world* frame."""
        self._flush_fine()
        assert self._fine is not None
        points, normals = self._fine.surface_cloud()
        rotation, translation = self.workspace_pose[:3, :3], self.workspace_pose[:3, 3]
        world_points = points @ rotation.T + translation
        world_normals = normals @ rotation.T
        return np.hstack([world_points, world_normals]).astype(np.float32)

    def _flush_fine(self) -> None:
        if self._fine is None:
            self._fine = TSDFVolume(self._size, self._cloud_resolution)
        for depth, intrinsics, camera_in_workspace, max_depth in self._pending:
            self._fine.integrate(depth, intrinsics, camera_in_workspace, max_depth)
        self._pending.clear()
