"""Depth-sensor models beyond Dex-Net's: a structured-light / active-stereo camera, and camera
pose error.

A simulated depth image is perfect; a real one is not, and a grasp planner trained and judged
on perfect depth overstates what it does on a robot. The structured-light model reproduces the
errors that matter for grasping, each from the literature on Kinect- and RealSense-type
sensors: axial noise growing with the square of the distance, readings lost on steep
surfaces, projector shadows, dropped and flying pixels at depth edges, and quantisation.
docs/sensors.md lists the models, their parameters and sources. Pixels with no reading are 0,
as everywhere in the simulator; all draws come from the ``rng`` passed in, so an observation
is reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from vgn_contract.schemas import Intrinsics


def _camera_points(depth: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(H, W, 3) camera-frame points of a depth image (OpenCV frame, metres)."""
    h, w = depth.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    z = depth.astype(np.float64)
    return np.stack(
        [(u - intrinsics.cx) * z / intrinsics.fx, (v - intrinsics.cy) * z / intrinsics.fy, z], axis=-1
    )


def _normals(points: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit surface normals from neighbouring points: along each image axis the
    one-sided difference towards the nearer neighbour in depth, so a pixel at a depth jump gets
    the normal of its own surface, not of the jump."""

    def one_sided(axis: int) -> np.ndarray:
        forward = np.diff(points, axis=axis, append=np.take(points, [-1], axis=axis))
        backward = np.diff(points, axis=axis, prepend=np.take(points, [0], axis=axis))
        use_forward = np.abs(forward[..., 2]) < np.abs(backward[..., 2])
        use_forward |= np.all(backward == 0, axis=-1)  # the first row or column has no backward step
        return np.where(use_forward[..., None], forward, backward)

    normals = np.cross(one_sided(1), one_sided(0))
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)


def shadowed(depth: np.ndarray, intrinsics: Intrinsics, baseline: float) -> np.ndarray:
    """(H, W) bool: valid pixels whose point the projector, ``baseline`` metres along the camera's
    +x axis and looking the same way, cannot see because a nearer surface is in the way."""
    valid = depth > 0
    points = _camera_points(depth, intrinsics)[valid]
    in_projector = points - np.array([baseline, 0.0, 0.0])
    z = in_projector[:, 2]
    u = np.rint(intrinsics.fx * in_projector[:, 0] / z + intrinsics.cx).astype(np.int64)
    v = np.rint(intrinsics.fy * in_projector[:, 1] / z + intrinsics.cy).astype(np.int64)
    inside = (u >= 0) & (u < intrinsics.width) & (v >= 0) & (v < intrinsics.height)
    nearest = np.full(intrinsics.height * intrinsics.width, np.inf)
    pixel = v[inside] * intrinsics.width + u[inside]
    order = np.lexsort((z[inside], pixel))  # by projector pixel, nearest first
    first = np.unique(pixel[order], return_index=True)[1]
    nearest[pixel[order][first]] = z[inside][order][first]
    nearest = nearest.reshape(intrinsics.height, intrinsics.width)
    # A point is lit when it is (within a little more than its pixel's depth step) the nearest
    # surface along its projector ray; anything well behind that surface is in its shadow.
    tolerance = 0.004 + 0.01 * z
    lit = np.zeros(len(z), dtype=bool)
    lit[inside] = z[inside] <= nearest[v[inside], u[inside]] + tolerance[inside]
    mask = np.zeros(depth.shape, dtype=bool)
    mask[valid] = ~lit
    return mask


@dataclass(frozen=True)
class StructuredLightNoise:
    """A structured-light / active-stereo depth camera's errors (module docstring), applied to
    rendered depth images of ``intrinsics``; ``apply(depth, rng)`` as ``DepthNoise``."""

    intrinsics: Intrinsics
    sigma_base: float = 0.0012
    sigma_quadratic: float = 0.0019
    sigma_reference_z: float = 0.4
    steep_start_deg: float = 70.0
    steep_end_deg: float = 85.0
    baseline: float = 0.05
    edge_jump: float = 0.01
    edge_dropout: float = 0.5
    flying_pixel: float = 0.3
    quantum: float = 0.001

    def sigma(self, z: np.ndarray) -> np.ndarray:
        """Axial standard deviation (metres) at distance ``z`` metres."""
        return self.sigma_base + self.sigma_quadratic * (z - self.sigma_reference_z) ** 2

    def apply(self, depth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy copy of ``depth`` ((H, W) metres, float32, 0 = no reading)."""
        depth = np.where(np.isfinite(depth), depth, 0.0).astype(np.float64)
        valid = depth > 0
        edge, behind = self._discontinuities(depth, valid)
        lost = shadowed(depth, self.intrinsics, self.baseline) | self._steep(depth, valid, rng)
        noisy = np.where(valid, depth + rng.standard_normal(depth.shape) * self.sigma(depth), 0.0)
        draw, mix = rng.random(depth.shape), rng.random(depth.shape)
        lost |= edge & (draw < self.edge_dropout)
        flying = edge & (draw >= self.edge_dropout) & (draw < self.edge_dropout + self.flying_pixel)
        noisy = np.where(flying, depth + mix * (behind - depth), noisy)
        noisy = np.where(lost, 0.0, noisy)
        noisy = np.rint(noisy / self.quantum) * self.quantum
        return np.where(noisy > 0, noisy, 0.0).astype(np.float32)

    def _steep(self, depth: np.ndarray, valid: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        points = _camera_points(depth, self.intrinsics)
        rays = points / np.maximum(np.linalg.norm(points, axis=-1, keepdims=True), 1e-9)
        cosine = np.abs(np.sum(_normals(points) * rays, axis=-1))
        angle = np.degrees(np.arccos(np.clip(cosine, 0.0, 1.0)))
        span = max(self.steep_end_deg - self.steep_start_deg, 1e-9)
        probability = np.clip((angle - self.steep_start_deg) / span, 0.0, 1.0)
        return valid & (rng.random(depth.shape) < probability)

    def _discontinuities(self, depth: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels at a depth jump of more than ``edge_jump`` (a second difference, so a smooth
        but steep surface is not an edge), and the depth of their farthest neighbour (where a
        flying pixel smears towards)."""
        padded = np.pad(np.where(valid, depth, np.nan), 1, mode="edge")
        centre = padded[1:-1, 1:-1]
        left, right, up, down = padded[1:-1, :-2], padded[1:-1, 2:], padded[:-2, 1:-1], padded[2:, 1:-1]
        bend = np.fmax(np.abs(left - 2 * centre + right), np.abs(up - 2 * centre + down))
        behind = np.fmax.reduce([left, right, up, down, centre])
        return valid & (np.nan_to_num(bend) > self.edge_jump), np.nan_to_num(behind, nan=0.0)


@dataclass(frozen=True)
class PoseError:
    """Camera pose error per view: the pose a robot reports differs from where the camera was by
    a random translation (σ ``position_sigma`` metres per axis) and rotation (angle σ
    ``rotation_sigma_deg`` about a random axis), as hand-eye calibration and arm kinematics leave it."""

    position_sigma: float = 0.005
    rotation_sigma_deg: float = 1.0

    def perturb(self, camera_pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The reported camera → world pose for the true ``camera_pose``."""
        axis = rng.standard_normal(3)
        axis /= max(np.linalg.norm(axis), 1e-12)
        angle = np.radians(self.rotation_sigma_deg) * rng.standard_normal()
        reported = np.array(camera_pose, dtype=np.float64)
        reported[:3, :3] = Rotation.from_rotvec(axis * angle).as_matrix() @ reported[:3, :3]
        reported[:3, 3] += rng.standard_normal(3) * self.position_sigma
        return reported
