"""What the viewer draws, as plain JSON: the fused surface, the workspace cube and the grasps.

Geometry is prepared here rather than in the browser so the page stays a thin renderer and the
same numbers can be checked in Python.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from pydantic import Field

from vgn_contract.geometry import gripper_outline, matrix_from_pose
from vgn_contract.schemas import Grasp, GraspQuery, GraspResult, SessionInfo

#: The browser stays responsive up to a few tens of thousands of markers.
DEFAULT_MAX_POINTS = 30000


class ViewQuery(GraspQuery):
    """The grasp query's options plus how the page shows them."""

    max_grasps: int | None = Field(default=20, ge=1, le=500, description="grasps drawn and listed")
    refresh: float = Field(
        default=2.0,
        ge=0.0,
        le=3600.0,
        description="seconds between checks for new frames (the view re-plans when they arrive); 0: never",
    )
    max_points: int = Field(
        default=DEFAULT_MAX_POINTS, ge=100, le=500000, description="surface points drawn at most"
    )
    standalone: bool = Field(
        default=False,
        description="the page only: inline plotly.js (4.6 MB), so that it works saved to a file, offline",
    )

    def grasp_query(self) -> GraspQuery:
        """The planning options alone, as the grasp request would send them."""
        return GraspQuery.model_validate(self.model_dump(include=set(GraspQuery.model_fields)))


def subsample(cloud: np.ndarray, max_points: int) -> np.ndarray:
    """Every k-th point, so a dense surface stays evenly covered and the choice is repeatable."""
    if len(cloud) <= max_points:
        return cloud
    step = math.ceil(len(cloud) / max_points)
    return cloud[::step]


def workspace_edges(info: SessionInfo) -> list[list[float] | None]:
    """The 12 edges of the workspace cube in the world frame, as one polyline broken by ``None``."""
    size = info.workspace.size
    pose = matrix_from_pose(
        np.asarray(info.workspace.pose.position), np.asarray(info.workspace.pose.orientation)
    )
    corners = np.array([[x, y, z] for x in (0, size) for y in (0, size) for z in (0, size)])
    world = corners @ pose[:3, :3].T + pose[:3, 3]
    path: list[list[float] | None] = []
    for a in range(8):
        for b in range(a + 1, 8):
            if bin(a ^ b).count("1") == 1:  # corners differing in one coordinate share an edge
                path += [_rounded(world[a]), _rounded(world[b]), None]
    return path


def grasp_outline(grasp: Grasp, finger_depth: float | None = None) -> list[list[float] | None]:
    """The gripper at ``grasp`` (palm, both fingers at its width and ``finger_depth`` long, default
    the default hand's, a stem) as a polyline, world frame."""
    world = gripper_outline(grasp.as_matrix(), grasp.width, finger_depth)
    return [_rounded(point) if np.all(np.isfinite(point)) else None for point in world]


def tilt_degrees(grasp: Grasp) -> float:
    """Angle between the approach and straight down (0: a top-down grasp)."""
    cosine = float(np.clip(-grasp.approach[2] / max(np.linalg.norm(grasp.approach), 1e-12), -1.0, 1.0))
    return round(math.degrees(math.acos(cosine)), 1)


def build_scene(
    info: SessionInfo,
    cloud: np.ndarray,
    result: GraspResult | None,
    query: ViewQuery,
    planning_error: str | None = None,
    finger_depth: float | None = None,
) -> dict[str, Any]:
    """The page's data: everything it draws and lists, JSON-ready; grasps drawn with fingers
    ``finger_depth`` long (the session's hand; default the default hand's)."""
    shown = subsample(cloud[np.all(np.isfinite(cloud), axis=1)], query.max_points)
    grasps = result.grasps if result else []
    return {
        "session_id": info.session_id,
        "frame_count": info.frame_count,
        "workspace": {"size": info.workspace.size, "resolution": info.workspace.resolution},
        "workspace_edges": workspace_edges(info),
        "cloud": {
            "total": len(cloud),
            "points": np.round(shown[:, :3], 4).tolist(),
            "normals": np.round(shown[:, 3:6], 3).tolist(),
        },
        "grasps": [
            {
                "rank": rank,
                "quality": round(g.quality, 4),
                "width": round(g.width, 5),
                "tilt_deg": tilt_degrees(g),
                "position": _rounded(np.asarray(g.position)),
                "outline": grasp_outline(g, finger_depth),
            }
            for rank, g in enumerate(grasps, 1)
        ],
        "planner": query.planner,
        "model": result.model if result else None,
        "threshold": result.threshold if result else query.threshold,
        "planning_ms": result.planning_ms if result else None,
        "planning_error": planning_error,
        "query": query.model_dump(exclude_none=True),
    }


def _rounded(point: np.ndarray) -> list[float]:
    return [round(float(v), 5) for v in point]
