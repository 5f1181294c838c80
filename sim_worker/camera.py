"""Simulated depth camera: PyBullet renders from pinhole intrinsics and camera poses.

Conventions (docs/conventions.md): metres and radians (degrees only where a name ends in
``_deg``); a camera pose is the 4×4 camera→world transform of the OpenCV optical frame;
depth images are (H, W) float32 z in metres, 0 where there is no reading, with integer pixel
coordinates at pixel centres (OpenCV's convention). PyBullet's OpenGL view and projection
matrices are built here from the pose and the intrinsics, so the rendered images agree with
what the service's TSDF integration assumes. Views follow VGN: cameras on a sphere about a
centre, ``tilt`` measured from the vertical, ``azimuth`` about world z from +x.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass

import numpy as np
import pybullet

from sim_worker.world import World
from vgn_contract.geometry import invert
from vgn_contract.schemas import Intrinsics

#: The simulated camera of VGN/GIGA: 640×480, fx = fy = 540, principal point at the centre.
SIM_INTRINSICS = Intrinsics(width=640, height=480, fx=540.0, fy=540.0, cx=320.0, cy=240.0)

#: The point the evaluation and data-generation views look at (VGN: the workspace's
#: centre in x, y at z = 0, i.e. 5 cm below the table top).
WORKSPACE_CENTRE = (0.15, 0.15, 0.0)

#: World → OpenGL camera from world → OpenCV camera: flip y and z (a rotation of π about x).
_OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])

#: Z-buffer values at or above this count as background (the buffer is cleared to 1.0).
_BACKGROUND_Z = 1.0 - 1e-6

#: Where each rasteriser samples pixel (column u, row v), relative to the pixel's centre, in
#: pixels (x right, y down), measured by fitting rendered planes (tests/sim_worker/test_sim_camera.py).
#: OpenGL samples pixel centres; PyBullet's TinyRenderer samples pixel corners (integer
#: window coordinates, y up), i.e. half a pixel left of and below the centre.
OPENGL_SAMPLE_OFFSET = (0.0, 0.0)
TINY_SAMPLE_OFFSET = (-0.5, 0.5)


# Matrices -----------------------------------------------------------------------------------
def opengl_projection(
    intrinsics: Intrinsics,
    near: float,
    far: float,
    sample_offset: tuple[float, float] = OPENGL_SAMPLE_OFFSET,
) -> np.ndarray:
    """4×4 OpenGL projection matrix (row-major) equivalent to pinhole ``intrinsics``.

    Maps OpenGL camera coordinates (metres; x right, y up, looking along -z) to clip space
    such that pixel column ``u``, row ``v`` (row 0 at the top of the image, as PyBullet
    returns it) shows the ray through the OpenCV image point ``(u, v)``, where
    ``(u, v) = (fx·X/Z + cx, fy·Y/Z + cy)``. Pixel ``i`` spans ``[i - 0.5, i + 0.5]`` in
    OpenCV coordinates, hence the ``+1`` half-pixel terms. ``sample_offset`` is where the
    rasteriser samples a pixel relative to its centre (see ``TINY_SAMPLE_OFFSET``); it is
    compensated by moving the principal point. ``near`` and ``far`` are the clipping
    distances in metres.
    """
    w, h = intrinsics.width, intrinsics.height
    cx = intrinsics.cx + sample_offset[0]
    cy = intrinsics.cy + sample_offset[1]
    return np.array(
        [
            [2.0 * intrinsics.fx / w, 0.0, 1.0 - (2.0 * cx + 1.0) / w, 0.0],
            [0.0, 2.0 * intrinsics.fy / h, (2.0 * cy + 1.0) / h - 1.0, 0.0],
            [0.0, 0.0, -(far + near) / (far - near), -2.0 * far * near / (far - near)],
            [0.0, 0.0, -1.0, 0.0],
        ]
    )


def opengl_view(camera_pose: np.ndarray) -> np.ndarray:
    """4×4 OpenGL view matrix (row-major, world → OpenGL camera) of ``camera_pose``
    (camera → world, OpenCV optical frame)."""
    return _OPENCV_TO_OPENGL @ invert(np.asarray(camera_pose, dtype=np.float64))


def column_major(matrix: np.ndarray) -> list[float]:
    """The 16 entries of a 4×4 matrix in the column-major order PyBullet expects."""
    return np.asarray(matrix, dtype=np.float64).flatten(order="F").tolist()


def metric_depth(z_buffer: np.ndarray, near: float, far: float) -> np.ndarray:
    """Camera-frame depth (metres, float32) from an OpenGL z-buffer in [0, 1]; background
    (the cleared value 1.0) becomes 0, i.e. no reading."""
    z = np.asarray(z_buffer, dtype=np.float64)
    depth = near * far / (far - (far - near) * z)
    return np.where(z >= _BACKGROUND_Z, 0.0, depth).astype(np.float32)


# Noise --------------------------------------------------------------------------------------
def _linear_upsample_weights(size_in: int, size_out: int) -> np.ndarray:
    """(size_out, size_in) matrix that resamples a 1-D signal linearly, aligning the
    centres of the first and last cells (samples beyond them are held constant)."""
    position = (np.arange(size_out) + 0.5) * size_in / size_out - 0.5
    position = np.clip(position, 0.0, size_in - 1)
    lower = np.floor(position).astype(int)
    upper = np.minimum(lower + 1, size_in - 1)
    fraction = position - lower
    weights = np.zeros((size_out, size_in))
    rows = np.arange(size_out)
    np.add.at(weights, (rows, lower), 1.0 - fraction)
    np.add.at(weights, (rows, upper), fraction)
    return weights


def bilinear_upsample(field: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear resampling of a 2-D ``field`` to ``shape`` (rows, columns)."""
    rows = _linear_upsample_weights(field.shape[0], shape[0])
    cols = _linear_upsample_weights(field.shape[1], shape[1])
    return rows @ field @ cols.T


@dataclass(frozen=True)
class DepthNoise:
    """Depth-sensor noise as in Dex-Net 2.0 and GIGA's ``apply_dex_noise``.

    - Multiplicative: the whole image is scaled by one draw of ``Gamma(k, 1/k)``
      (``gamma_shape`` = k; mean 1, standard deviation 1/√k), a per-frame scale error.
    - Additive: with probability ``field_probability``, a smooth Gaussian field with
      standard deviation ``field_sigma`` metres, drawn on a coarse grid with one sample per
      ``field_cell_px`` pixels and upsampled bilinearly (GIGA: σ 5 mm, 4 px cells, p 0.5).

    Pixels without a reading (0, NaN, inf) stay 0."""

    gamma_shape: float = 1000.0
    field_sigma: float = 0.005
    field_cell_px: float = 4.0
    field_probability: float = 0.5

    def apply(self, depth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy copy of ``depth`` ((H, W) metres, float32); ``rng`` makes it reproducible."""
        depth = np.asarray(depth, dtype=np.float32)
        valid = np.isfinite(depth) & (depth > 0)
        noisy = depth.astype(np.float64) * rng.gamma(self.gamma_shape, 1.0 / self.gamma_shape)
        if rng.random() < self.field_probability:
            noisy += self._smooth_field(depth.shape, rng)
        return np.where(valid, np.maximum(noisy, 1e-6), 0.0).astype(np.float32)

    def _smooth_field(self, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
        coarse_shape = (
            max(1, int(round(shape[0] / self.field_cell_px))),
            max(1, int(round(shape[1] / self.field_cell_px))),
        )
        coarse = rng.standard_normal(coarse_shape) * self.field_sigma
        return bilinear_upsample(coarse, shape)


# Camera -------------------------------------------------------------------------------------
class Camera:
    """A pinhole depth camera rendering a :class:`World` with PyBullet.

    Uses the EGL (OpenGL) renderer when ``world.egl`` is set, else the CPU TinyRenderer.
    ``near`` and ``far`` (metres) clip the view: geometry outside them gives no reading.
    ``noise`` (off by default) is applied to every depth image, drawing from ``rng``.
    """

    def __init__(
        self,
        world: World,
        intrinsics: Intrinsics = SIM_INTRINSICS,
        near: float = 0.1,
        far: float = 2.0,
        noise: DepthNoise | None = None,
        rng: np.random.Generator | None = None,
    ) -> None:
        if not 0 < near < far:
            raise ValueError(f"need 0 < near < far, got near={near}, far={far}")
        self.world = world
        self.intrinsics = intrinsics
        self.near = near
        self.far = far
        self.noise = noise
        self.rng = rng if rng is not None else np.random.default_rng()
        offset = OPENGL_SAMPLE_OFFSET if world.egl else TINY_SAMPLE_OFFSET
        self._projection = column_major(opengl_projection(intrinsics, near, far, offset))

    @property
    def renderer(self) -> int:
        """The PyBullet renderer used: EGL's OpenGL when loaded, else TinyRenderer."""
        return pybullet.ER_BULLET_HARDWARE_OPENGL if self.world.egl else pybullet.ER_TINY_RENDERER

    def render_depth(self, camera_pose: np.ndarray, hide: Collection[int] = ()) -> np.ndarray:
        """(H, W) float32 depth in metres (z in the camera frame, 0 = no geometry) seen from
        ``camera_pose`` (camera → world, OpenCV optical frame), with ``noise`` if set.

        Pixels that see a body of ``hide`` read nothing (0): a robot filters its own hand out of
        its camera's depth, and what the hand covers stays unseen."""
        if hide:
            depth, body = self.render(camera_pose)
            return np.where(np.isin(body, list(hide)), 0.0, depth).astype(np.float32)
        _, z_buffer, _ = self._capture(camera_pose, pybullet.ER_NO_SEGMENTATION_MASK)
        return self._depth(z_buffer)

    def render(self, camera_pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Depth as :meth:`render_depth` and an (H, W) int32 segmentation: the PyBullet body
        id seen at each pixel, -1 for background."""
        _, z_buffer, segmentation = self._capture(camera_pose, 0)
        body = np.where(segmentation >= 0, segmentation & ((1 << 24) - 1), -1)
        return self._depth(z_buffer), body.astype(np.int32)

    def render_rgb(self, camera_pose: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8 colour image from ``camera_pose`` (camera → world, OpenCV frame)."""
        rgba, _, _ = self._capture(camera_pose, pybullet.ER_NO_SEGMENTATION_MASK)
        return np.ascontiguousarray(rgba[..., :3]).astype(np.uint8)

    def _depth(self, z_buffer: np.ndarray) -> np.ndarray:
        depth = metric_depth(z_buffer, self.near, self.far)
        if self.noise is not None:
            depth = self.noise.apply(depth, self.rng)
        return depth

    def _capture(self, camera_pose: np.ndarray, flags: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Raw ``(rgba (H, W, 4), z-buffer (H, W), segmentation (H, W))``, row 0 at the top."""
        h, w = self.intrinsics.height, self.intrinsics.width
        result = self.world.p.getCameraImage(
            width=w,
            height=h,
            viewMatrix=column_major(opengl_view(camera_pose)),
            projectionMatrix=self._projection,
            renderer=self.renderer,
            flags=flags,
        )
        rgba = np.asarray(result[2], dtype=np.uint8).reshape(h, w, 4)
        z_buffer = np.asarray(result[3], dtype=np.float32).reshape(h, w)
        segmentation = np.asarray(result[4], dtype=np.int64).reshape(h, w)
        return rgba, z_buffer, segmentation


# Views --------------------------------------------------------------------------------------
def camera_on_sphere(
    centre: tuple[float, float, float] | np.ndarray, distance: float, tilt: float, azimuth: float
) -> np.ndarray:
    """Camera → world pose (OpenCV optical frame) of a camera ``distance`` metres from
    ``centre`` (world, metres), ``tilt`` radians from the vertical above it and at
    ``azimuth`` radians about world z (from +x), looking at ``centre``.

    The image x axis is the horizontal direction of increasing azimuth, so world +z points
    up in the image: the same pose as ``look_at(eye, centre, up=(0, 0, 1))`` for any tilt
    in (0, π), and still defined for a camera straight above (tilt 0), where ``look_at``'s
    up vector would be parallel to the view.
    """
    centre = np.asarray(centre, dtype=np.float64)
    outward = np.array([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)])
    forward = -outward
    right = np.array([-np.sin(azimuth), np.cos(azimuth), 0.0])
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = right, down, forward
    pose[:3, 3] = centre + distance * outward
    return pose


def six_views(
    distance: float = 0.6,
    tilt_deg: float = 30.0,
    centre: tuple[float, float, float] = WORKSPACE_CENTRE,
    count: int = 6,
) -> list[np.ndarray]:
    """VGN's evaluation views: ``count`` camera poses (camera → world, OpenCV frame) evenly
    spaced in azimuth from 0 on a circle ``distance`` metres from ``centre``, ``tilt_deg``
    from the vertical, each looking at ``centre``."""
    tilt = np.radians(tilt_deg)
    azimuths = 2.0 * np.pi * np.arange(count) / count
    return [camera_on_sphere(centre, distance, tilt, float(azimuth)) for azimuth in azimuths]


def side_view(
    distance: float = 0.6,
    tilt_deg: float = 60.0,
    azimuth_deg: float = -90.0,
    centre: tuple[float, float, float] = (0.15, 0.15, 0.10),
) -> np.ndarray:
    """GIGA's single "side view" (camera → world, OpenCV frame): 0.6 m from (0.15, 0.15,
    0.10) (the workspace centre, a third of the way up), 60° from the vertical, from the
    -y side (azimuth -90°), so the camera sits at about (0.15, -0.37, 0.40)."""
    return camera_on_sphere(centre, distance, np.radians(tilt_deg), np.radians(azimuth_deg))


def random_views(
    rng: np.random.Generator,
    count: int,
    distance: tuple[float, float] = (0.48, 0.72),
    tilt_deg: tuple[float, float] = (0.0, 45.0),
    centre: tuple[float, float, float] = WORKSPACE_CENTRE,
) -> list[np.ndarray]:
    """VGN's data-generation views: ``count`` poses (camera → world, OpenCV frame) with
    distance ~ U(``distance``) metres, tilt from vertical ~ U(``tilt_deg``) and azimuth
    ~ U(0°, 360°), looking at ``centre``. Reproducible for a given ``rng`` state."""
    poses = []
    for _ in range(count):
        r = rng.uniform(*distance)
        tilt = np.radians(rng.uniform(*tilt_deg))
        azimuth = rng.uniform(0.0, 2.0 * np.pi)
        poses.append(camera_on_sphere(centre, r, tilt, azimuth))
    return poses
