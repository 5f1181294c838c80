"""Executed-grasp success of freshly trained weights: a short clutter-removal run on objects the
model never saw, in the simulator, recorded in the model card.

Validation figures are measured on labels; what a user gets is grasps that hold in a scene.
This runs the same clear-scene episodes as the benchmark (the embedded service serving the new
weights, the simulated hand executing its grasps), so the card carries the number that matters.
It needs the simulator extra (pybullet).
"""

from __future__ import annotations

import contextlib
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from client.extras import missing_extra


@dataclass(frozen=True)
class EvaluationConfig:
    """Where and how long to test: ``objects`` a folder of held-out URDFs (or a set name)."""

    objects: str
    scene: str = "pile"
    rounds: int = 10
    object_count: int = 5
    seed: int = 1
    torch_threads: int = 1

    def __post_init__(self) -> None:
        if self.scene not in ("blocks", "pile", "packed"):
            raise ValueError(f"evaluation scene must be blocks, pile or packed, got {self.scene!r}")
        if self.rounds < 1 or self.object_count < 1:
            raise ValueError("evaluation rounds and object count must be >= 1")


def executed_grasp_success(weights: Path, config: EvaluationConfig, results: Path) -> dict[str, Any]:
    """Run ``config.rounds`` clear-scene rounds with ``weights`` at their card's operating
    threshold and return the summary (success rate and cleared with 95 % intervals, outcome
    breakdown) with the settings. ``results`` keeps the rounds, so a rerun resumes."""
    try:
        from client.http import VGNClient
        from service.launch.embedded import EmbeddedService
        from sim_worker.clear_scene import resolve_planner, run_episode
        from sim_worker.clutter import ClutterConfig
        from sim_worker.results import ResultsFolder
    except ImportError as error:
        raise RuntimeError(missing_extra("the executed-grasp evaluation", "sim", error)) from error
    clutter = ClutterConfig(scene=config.scene, objects=config.objects, object_count=config.object_count,
                            rounds=config.rounds, seed=config.seed, renderer="auto")  # fmt: skip
    results.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as stack:
        env = {"VGN_TORCH_THREADS": str(config.torch_threads)}
        service = EmbeddedService(model=weights, env=env, log_path=results / "service.log")
        vgn = stack.enter_context(VGNClient(stack.enter_context(service).url, timeout=120.0))
        clutter = resolve_planner(clutter, vgn)
        summary = run_episode(clutter, vgn, ResultsFolder(results, clutter.as_json()))
    settings = dataclasses.asdict(config) | {
        "threshold": clutter.threshold,
        "turn_average": clutter.turn_average,
        "clearance": clutter.clearance,
        "objects": Path(config.objects).name,
    }
    return {"settings": settings, **summary}
