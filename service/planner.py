"""The VGN grasp planner: a loaded network plus detection, independent of any front end."""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from client.schemas import ANTIPODAL_DEFAULT_THRESHOLD, VGN_DEFAULT_THRESHOLD, Grasp, GraspQuery
from service.baseline import AntipodalConfig
from service.errors import ModelNotReady
from service.vgn.checkpoint import card_summary, load_vgn, weights_id
from service.vgn.detection import DetectionConfig, detect_grasps
from service.vgn.network import PARAMETER_COUNT, VGN

NO_MODEL_MESSAGE = "no model is configured: set VGN_MODEL to a VGN weights file (.safetensors, .pt or .pth)"


def resolved_threshold(query: GraspQuery, default: float) -> float:
    """The request's threshold, or ``default`` (the planner's) when it gives none."""
    return default if query.threshold is None else query.threshold


def detection_config(query: GraspQuery, threshold: float) -> DetectionConfig:
    """Detection settings of one grasp request (angles arrive in degrees) at ``threshold``."""
    crop_min, crop_max = query.crop_box or (None, None)
    angle = query.max_approach_angle
    return DetectionConfig(
        threshold=threshold,
        nms_size=query.nms_size,
        max_grasps=query.max_grasps,
        crop_min=crop_min,
        crop_max=crop_max,
        approach=query.approach_direction,
        max_approach_angle=None if angle is None else math.radians(angle),
    )


def antipodal_config(query: GraspQuery) -> AntipodalConfig:
    """Settings of the geometric baseline for one grasp request: the same threshold,
    ``max_grasps``, crop (workspace frame) and approach cone as VGN's detection."""
    detection = detection_config(query, resolved_threshold(query, ANTIPODAL_DEFAULT_THRESHOLD))
    return AntipodalConfig(
        threshold=detection.threshold,
        max_grasps=detection.max_grasps,
        crop_min=detection.crop_min,
        crop_max=detection.crop_max,
        approach=detection.approach,
        max_approach_angle=detection.max_approach_angle,
    )


def resolve_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


@dataclass
class NetworkOutput:
    """Voxel-wise network output as numpy: quality (N³), rotation (4, N³), width (N³ voxels)."""

    quality: np.ndarray
    rotation: np.ndarray
    width: np.ndarray


class GraspPlanner:
    """Runs VGN on a grid and turns its output into world-frame grasps.

    Without weights the planner exists but is not ready: ``plan`` raises ``ModelNotReady``.
    """

    def __init__(
        self,
        network: VGN | None,
        device: torch.device,
        model_id: str | None,
        source: str | None,
        card: dict[str, Any] | None = None,
    ):
        self.device = device
        self.model_id = model_id
        self.source = source
        self.card = card
        self._network = network.to(device) if network is not None else None
        self._lock = threading.Lock()  # one forward at a time: the CPU has no spare cores

    @classmethod
    def from_path(cls, path: Path | None, device: str = "auto") -> GraspPlanner:
        """Load and warm up the weights at ``path``; ``None`` gives a planner with no model."""
        torch_device = resolve_device(device)
        if path is None:
            return cls(None, torch_device, None, None)
        model_id = weights_id(path)
        planner = cls(load_vgn(path), torch_device, model_id, str(path), card_summary(path, model_id))
        planner.warm_up()
        return planner

    @property
    def default_threshold(self) -> float:
        """The threshold of requests that give none: the card's operating threshold, else VGN's."""
        threshold = (self.card or {}).get("threshold")
        if isinstance(threshold, int | float) and 0.0 <= threshold <= 1.0:
            return float(threshold)
        return VGN_DEFAULT_THRESHOLD

    @property
    def ready(self) -> bool:
        return self._network is not None

    @property
    def parameters(self) -> int:
        return PARAMETER_COUNT

    def warm_up(self, resolution: int = 40) -> None:
        """One forward pass so the first real request does not pay for lazy initialisation."""
        self.infer(np.zeros((resolution,) * 3, dtype=np.float32))

    def infer(self, grid: np.ndarray) -> NetworkOutput:
        """Network output for one (N, N, N) grid."""
        if self._network is None:
            raise ModelNotReady(NO_MODEL_MESSAGE)
        tensor = torch.from_numpy(np.ascontiguousarray(grid, dtype=np.float32))[None, None]
        with self._lock, torch.inference_mode():
            quality, rotation, width = self._network(tensor.to(self.device))
        return NetworkOutput(
            quality=quality[0, 0].cpu().numpy(),
            rotation=rotation[0].cpu().numpy(),
            width=width[0, 0].cpu().numpy(),
        )

    def plan(self, grid: np.ndarray, voxel_size: float, workspace_pose: np.ndarray, query: GraspQuery):
        """Grasps for ``grid`` (workspace frame) in the world frame, best first, and the
        time taken in milliseconds; the request's threshold defaults to ``default_threshold``."""
        started = time.perf_counter()
        output = self.infer(grid)
        grasps: list[Grasp] = detect_grasps(
            grid,
            output.quality,
            output.rotation,
            output.width,
            voxel_size,
            workspace_pose,
            detection_config(query, resolved_threshold(query, self.default_threshold)),
        )
        return grasps, (time.perf_counter() - started) * 1e3
