"""Analytic test scenes: exact depth images of a box or a lying cylinder on a table, by ray casting.

The world has a table top (plane z = TABLE_Z) and an axis-aligned box standing on it (or a
cylinder lying along x), so every fused surface can be checked against known geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vgn_contract.geometry import look_at
from vgn_contract.schemas import Intrinsics

INTRINSICS = Intrinsics(width=640, height=480, fx=540.0, fy=540.0, cx=319.5, cy=239.5)
TABLE_Z = 0.05


@dataclass(frozen=True)
class BoxScene:
    """A box [lower, upper] (world, metres) on the table plane z = TABLE_Z."""

    lower: tuple[float, float, float] = (0.11, 0.12, TABLE_Z)
    upper: tuple[float, float, float] = (0.19, 0.18, TABLE_Z + 0.06)

    def depth(self, camera_pose: np.ndarray, intrinsics: Intrinsics = INTRINSICS) -> np.ndarray:
        """(H, W) float32 depth (z in the camera frame, metres) seen from ``camera_pose``
        (camera → world, OpenCV optical frame); 0 where a ray hits nothing."""
        u, v = np.meshgrid(np.arange(intrinsics.width), np.arange(intrinsics.height))
        rays_cam = np.stack(
            [(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, np.ones(u.shape)],
            axis=-1,
        )  # z = 1, so the ray parameter is the depth
        rays = rays_cam @ camera_pose[:3, :3].T
        origin = camera_pose[:3, 3]
        t_table = np.where(
            rays[..., 2] < 0, (TABLE_Z - origin[2]) / np.where(rays[..., 2] < 0, rays[..., 2], -1), np.inf
        )
        t_box = self._box_hits(origin, rays)
        depth = np.minimum(t_table, t_box)
        return np.where(np.isfinite(depth), depth, 0.0).astype(np.float32)

    def _box_hits(self, origin: np.ndarray, rays: np.ndarray) -> np.ndarray:
        lower, upper = np.asarray(self.lower), np.asarray(self.upper)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (lower - origin) / rays
            t2 = (upper - origin) / rays
        t_near = np.nanmax(np.minimum(t1, t2), axis=-1)
        t_far = np.nanmin(np.maximum(t1, t2), axis=-1)
        hit = (t_near <= t_far) & (t_near > 0)
        return np.where(hit, t_near, np.inf)

    def distance_to_surface(self, points: np.ndarray) -> np.ndarray:
        """Distance of world points to the visible surface (table top or box)."""
        lower, upper = np.asarray(self.lower), np.asarray(self.upper)
        outside = np.maximum(np.maximum(lower - points, points - upper), 0.0)
        to_box = np.linalg.norm(outside, axis=-1)
        inside = np.all((points > lower) & (points < upper), axis=-1)
        to_box = np.where(inside, np.min(np.minimum(points - lower, upper - points), axis=-1), to_box)
        to_table = np.abs(points[:, 2] - TABLE_Z)
        return np.minimum(to_box, to_table)


def _table_hits(origin: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Ray parameter (depth) where each ray meets the table plane; inf where it does not."""
    down = rays[..., 2] < 0
    return np.where(down, (TABLE_Z - origin[2]) / np.where(down, rays[..., 2], -1), np.inf)


def _camera_rays(camera_pose: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(H, W, 3) world-frame ray directions whose camera z is 1, so a ray parameter is a depth."""
    u, v = np.meshgrid(np.arange(intrinsics.width), np.arange(intrinsics.height))
    rays_cam = np.stack(
        [(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, np.ones(u.shape)], axis=-1
    )
    return rays_cam @ camera_pose[:3, :3].T


@dataclass(frozen=True)
class CylinderScene:
    """A solid cylinder of ``radius`` lying on the table plane, its axis along world x from
    ``x_range[0]`` to ``x_range[1]`` at y = ``axis_y``: a curved surface, as on cans and cups."""

    radius: float = 0.02
    x_range: tuple[float, float] = (0.125, 0.175)
    axis_y: float = 0.15

    def depth(self, camera_pose: np.ndarray, intrinsics: Intrinsics = INTRINSICS) -> np.ndarray:
        """(H, W) float32 depth seen from ``camera_pose`` (as :meth:`BoxScene.depth`)."""
        rays = _camera_rays(camera_pose, intrinsics)
        origin = camera_pose[:3, 3]
        axis_z = TABLE_Z + self.radius
        # The side: (y - axis_y)^2 + (z - axis_z)^2 = radius^2, between the end caps.
        dy, dz = rays[..., 1], rays[..., 2]
        oy, oz = origin[1] - self.axis_y, origin[2] - axis_z
        a, b, c = dy**2 + dz**2, 2 * (oy * dy + oz * dz), oy**2 + oz**2 - self.radius**2
        disc = b**2 - 4 * a * c
        t_side = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * np.maximum(a, 1e-12))
        x_hit = origin[0] + t_side * rays[..., 0]
        on_side = (disc >= 0) & (t_side > 0) & (x_hit >= self.x_range[0]) & (x_hit <= self.x_range[1])
        hits = [_table_hits(origin, rays), np.where(on_side, t_side, np.inf)]
        for x_cap in self.x_range:
            with np.errstate(divide="ignore", invalid="ignore"):
                t_cap = (x_cap - origin[0]) / rays[..., 0]
            py, pz = oy + t_cap * dy, oz + t_cap * dz
            hits.append(np.where((t_cap > 0) & (py**2 + pz**2 <= self.radius**2), t_cap, np.inf))
        depth = np.minimum.reduce(hits)
        return np.where(np.isfinite(depth), depth, 0.0).astype(np.float32)


def circle_views(
    count: int = 6,
    distance: float = 0.6,
    tilt_deg: float = 30.0,
    centre: tuple[float, float, float] = (0.15, 0.15, 0.0),
) -> list[np.ndarray]:
    """VGN's evaluation views: cameras on a circle, ``tilt_deg`` from vertical, looking at ``centre``."""
    tilt = np.radians(tilt_deg)
    poses = []
    for azimuth in np.linspace(0, 2 * np.pi, count, endpoint=False):
        offset = distance * np.array(
            [np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)]
        )
        poses.append(look_at(np.asarray(centre) + offset, centre))
    return poses
