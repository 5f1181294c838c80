"""The VGN grasp planner: a loaded network plus detection, independent of any front end."""

from __future__ import annotations

import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from service.baseline import AntipodalConfig
from service.baseline.antipodal import in_region
from service.errors import ModelNotReady
from service.runtime import usable_cores
from service.vgn.batching import MicroBatcher
from service.vgn.checkpoint import card_summary, load_vgn, weights_id
from service.vgn.detection import DetectionConfig, grasp_scores, grasps_from_scores
from service.vgn.fast import FastVGN
from service.vgn.network import PARAMETER_COUNT, VGN
from service.vgn.outputs import ComputedHeads, HeadsOnDemand, NetworkOutput
from service.vgn.turns import average_turned_quality, turned_grids
from vgn_contract.schemas import ANTIPODAL_DEFAULT_THRESHOLD, VGN_DEFAULT_THRESHOLD, Grasp, GraspQuery

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
        max_approach_angle_rad=None if angle is None else math.radians(angle),
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
        max_approach_angle_rad=detection.max_approach_angle_rad,
    )


def in_requested_region(grasps: list[Grasp], query: GraspQuery, workspace_pose: np.ndarray) -> list[Grasp]:
    """The ``grasps`` (world frame) that lie in the request's crop box and approach cone: the
    planners apply both, but a check's alternative pose (turned, tilted, stepped back) can leave them."""
    config = detection_config(query, 0.0)
    if not grasps or (config.crop_min is None and config.crop_max is None and config.approach is None):
        return grasps
    positions = np.array([g.position for g in grasps], dtype=np.float64)
    approaches = Rotation.from_quat([g.orientation for g in grasps]).as_matrix()[:, :, 2]
    keep = in_region(positions, approaches, workspace_pose, config)
    return [grasp for grasp, inside in zip(grasps, keep, strict=True) if inside]


def resolve_device(name: str) -> torch.device:
    """The torch device named by ``VGN_DEVICE``: ``auto`` takes CUDA when there is one."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def native_bf16(device: torch.device) -> bool:
    """Whether ``device`` runs bfloat16 convolutions natively (AVX512-BF16/AMX on a CPU)."""
    if device.type != "cpu":
        return False
    try:
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):
        return False


def resolve_precision(name: str, device: torch.device) -> torch.dtype:
    """``auto``: bfloat16 on CPUs with native support (agreement with float32 is tested on
    recorded scenes), float32 elsewhere."""
    if name == "bf16" or (name == "auto" and native_bf16(device)):
        return torch.bfloat16
    return torch.float32


def default_batch_window_ms(device: torch.device) -> float:
    """How long the first request of a batch waits for others: on a GPU a batch costs about
    what one grid costs, so a short wait pays; on a CPU it would only add latency."""
    return 2.0 if device.type == "cuda" else 0.0


def default_lanes(device: torch.device) -> int:
    """How many parts of a batch run side by side: on a CPU, one per group of torch threads
    the usable cores hold, since a batch on few threads costs what its grids cost one by
    one and torch releases the GIL; a GPU takes a batch whole."""
    return max(1, usable_cores() // torch.get_num_threads()) if device.type == "cpu" else 1


@dataclass(frozen=True)
class InferenceOptions:
    """How the network runs: ``fast`` (folded, fused heads) or ``reference`` (VGN as
    trained, float32), its precision, micro-batching (``lanes``: parts of a batch run
    side by side; ``None``: :func:`default_lanes`), and where the fast form computes
    rotation and width (``heads``, see :func:`resolve_heads`)."""

    form: str = "fast"
    precision: str = "auto"
    batch_window_ms: float | None = None
    max_batch: int = 32
    lanes: int | None = None
    heads: str = "auto"


#: Where the fast network computes rotation and width: at the voxels detection reads, on the
#: CPU (``on-demand``), or at every voxel with the quality head (``whole``).
HEADS = ("auto", "on-demand", "whole")


def resolve_heads(heads: str, device: torch.device) -> str:
    """``auto``: on demand on a CPU, where the heads' last convolution is a large share of the
    network's arithmetic; whole on a GPU, where that convolution costs next to nothing and reading
    a few hundred voxels would move the features to the CPU and gather there, under the
    interpreter lock that concurrent requests share (docs/design.md has the figures)."""
    if heads not in HEADS:
        raise ValueError(f"heads must be one of {HEADS}, got {heads!r}")
    if heads != "auto":
        return heads
    return "on-demand" if device.type == "cpu" else "whole"


class GraspPlanner:
    """Runs VGN on a grid and turns its output into world-frame grasps.

    Without weights the planner exists but is not ready: ``plan`` raises ``ModelNotReady``.
    A planner built ``alongside`` another (a second network of the service) takes turns with it:
    one forward pass at a time, whichever network's, on the same lanes, so that two networks
    do not oversubscribe the cores that one batch already fills.
    """

    def __init__(
        self,
        network: VGN | None,
        device: torch.device,
        model_id: str | None,
        source: str | None,
        card: dict[str, Any] | None = None,
        options: InferenceOptions = InferenceOptions(),
        alongside: GraspPlanner | None = None,
    ) -> None:
        self.device = device
        self.model_id = model_id
        self.source = source
        self.card = card
        self.options = options
        self.dtype = resolve_precision(options.precision, device) if options.form == "fast" else torch.float32
        heads = resolve_heads(options.heads, device)  # validated whatever the form
        self.heads = heads if options.form == "fast" else "whole"  # the reference network's come whole
        self._network: torch.nn.Module | None = None
        if network is not None:
            network = network.eval()
            form = FastVGN.from_vgn(network, self.dtype) if options.form == "fast" else network
            self._network = form.to(device)
        window_ms = options.batch_window_ms
        self.batch_window_ms = default_batch_window_ms(device) if window_ms is None else window_ms
        self._batcher = MicroBatcher(self._forward_batch, self.batch_window_ms / 1e3, options.max_batch)
        if alongside is not None:
            self.lanes, self._lane_pool, self._turn = alongside.lanes, alongside._lane_pool, alongside._turn
        else:
            self.lanes = default_lanes(device) if options.lanes is None else max(1, options.lanes)
            self._lane_pool = (
                ThreadPoolExecutor(self.lanes - 1, thread_name_prefix="vgn-lane") if self.lanes > 1 else None
            )
            self._turn = threading.Lock()  # one forward pass at a time, of the planners that share it

    @classmethod
    def from_path(
        cls,
        path: Path | None,
        device: str = "auto",
        options: InferenceOptions = InferenceOptions(),
        alongside: GraspPlanner | None = None,
    ) -> GraspPlanner:
        """Load and warm up the weights at ``path``; ``None`` gives a planner with no model.
        ``alongside``: a planner whose forward passes and lanes this one shares."""
        torch_device = resolve_device(device)
        if path is None:
            return cls(None, torch_device, None, None, options=options, alongside=alongside)
        network = load_vgn(path)  # first: a missing file is a CheckpointError that says so
        model_id = weights_id(path)
        card = card_summary(path, model_id)
        planner = cls(network, torch_device, model_id, str(path), card, options, alongside)
        planner.warm_up()
        return planner

    def runtime(self) -> dict[str, Any]:
        """How the network runs, for ``GET /model``."""
        return {
            "inference": self.options.form,
            "precision": str(self.dtype).removeprefix("torch."),
            "heads": self.heads,
            "batch_window_ms": self.batch_window_ms,
            "max_batch": self.options.max_batch,
            "lanes": self.lanes,
            "batches": self._batcher.stats.as_dict(),
        }

    @property
    def default_threshold(self) -> float:
        """The threshold of requests that give none: the card's operating threshold, else VGN's."""
        threshold = (self.card or {}).get("threshold")
        if isinstance(threshold, int | float) and 0.0 <= threshold <= 1.0:
            return float(threshold)
        return VGN_DEFAULT_THRESHOLD

    @property
    def ready(self) -> bool:
        """Whether weights are loaded, so that ``plan`` can run."""
        return self._network is not None

    @property
    def parameters(self) -> int:
        """The network's parameter count (the architecture fixes it, weights or not)."""
        return PARAMETER_COUNT

    def warm_up(self, resolution: int = 40) -> None:
        """One forward pass so the first real request does not pay for lazy initialisation."""
        self.infer(np.zeros((resolution,) * 3, dtype=np.float32))

    def infer(self, grid: np.ndarray, turn_average: bool = False) -> NetworkOutput:
        """Network output for one (N, N, N) grid; concurrent calls share forward passes.

        With ``turn_average`` quality and orientation are the means over the grid's four
        quarter turns about gravity (one batch of four grids; see :mod:`service.vgn.turns`);
        widths stay those of the unturned grid. Orientations are averaged on demand
        (:meth:`NetworkOutput.rotation_where`); ``rotation`` holds the unturned grid's.
        """
        if self._network is None:
            raise ModelNotReady(NO_MODEL_MESSAGE)
        grid = np.ascontiguousarray(grid, dtype=np.float32)
        if not turn_average:
            return self._batcher.run(grid)
        outputs = self._batcher.run_many(list(turned_grids(grid)))  # rows of one stacked array: contiguous
        quality = average_turned_quality([output.quality for output in outputs])
        turned = tuple(output.heads for output in outputs)
        return NetworkOutput(quality, outputs[0].heads, turned_rotations=turned)

    def _forward_batch(self, grids: np.ndarray) -> list[NetworkOutput]:
        """One forward pass over (B, N, N, N) grids, split into up to ``lanes`` parts that run
        side by side (see :func:`default_lanes`)."""
        assert self._network is not None
        lanes = min(len(grids), self.lanes)
        with self._turn:
            if lanes > 1 and self._lane_pool is not None:
                # The calling thread runs the first part itself: it is awake and its caches are
                # warm, while each hand-off to an idle lane costs a wake-up.
                first, *others = np.array_split(grids, lanes)
                pending = [self._lane_pool.submit(self._forward_part, part) for part in others]
                parts = [self._forward_part(first), *(future.result() for future in pending)]
            else:
                parts = [self._forward_part(grids)]
        return [output for part in parts for output in part]

    def _forward_part(self, grids: np.ndarray) -> list[NetworkOutput]:
        """The outputs of one forward pass over (B, N, N, N) grids, one per grid. Each lane
        splits its own part, so the copies below run side by side too. With heads on demand the
        fast network runs the quality head alone; rotation and width are computed where read."""
        tensor = torch.from_numpy(np.ascontiguousarray(grids))[:, None].to(self.device)
        network = self._network
        with torch.inference_mode():
            if not isinstance(network, FastVGN) or self.heads == "whole":
                quality, rotation, width = (t.cpu().numpy() for t in network(tensor))
                # Copies, so that an output a session keeps does not hold on to the whole batch.
                return [NetworkOutput(quality[b, 0].copy(), ComputedHeads(rotation[b].copy(), width[b, 0].copy()))
                        for b in range(len(grids))]  # fmt: skip
            features = network.features(tensor)
            quality = network.quality_from(features).cpu().numpy()
            return [NetworkOutput(quality[b, 0].copy(), HeadsOnDemand(network, features[b].clone()))
                    for b in range(len(grids))]  # fmt: skip

    def plan(
        self, grid: np.ndarray, voxel_size: float, workspace_pose: np.ndarray, query: GraspQuery
    ) -> tuple[list[Grasp], float]:
        """Grasps for ``grid`` (workspace frame) in the world frame, best first, and the
        time taken in milliseconds; the request's threshold defaults to ``default_threshold``."""
        started = time.perf_counter()
        grasps = self.detect(grid, self.infer(grid, query.turn_average), voxel_size, workspace_pose, query)
        return grasps, (time.perf_counter() - started) * 1e3

    def detect(
        self,
        grid: np.ndarray,
        output: NetworkOutput,
        voxel_size: float,
        workspace_pose: np.ndarray,
        query: GraspQuery,
    ) -> list[Grasp]:
        """World-frame grasps, best first, from the network's ``output`` on ``grid``."""
        config = detection_config(query, resolved_threshold(query, self.default_threshold))
        score = grasp_scores(grid, output.quality, output.width_at, voxel_size, config)
        rotation = output.rotation_where(score > 0)  # the only voxels detection reads
        return grasps_from_scores(score, rotation, output.width_at, voxel_size, workspace_pose, config)
