"""The clutter-removal benchmark (VGN §V-B), driving the service through the client only.

Each round: generate a scene, then repeat { reset the session, render and post the views,
ask for grasps, execute one, remove the grasped object, let the scene settle } until the
table is clear, no grasp is found, or two grasps in a row failed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from client.http import VGNClient
from client.schemas import Grasp
from sim_worker import images
from sim_worker.camera import SIM_INTRINSICS, Camera, DepthNoise, side_view, six_views
from sim_worker.grasping import GraspTrial, execute_grasp
from sim_worker.gripper import Gripper
from sim_worker.metrics import summarize
from sim_worker.objects import object_set
from sim_worker.results import ResultsFolder, RoundRecord
from sim_worker.scenes import generate_scene
from sim_worker.sensors import PoseError, StructuredLightNoise
from sim_worker.service_session import fresh_session
from sim_worker.settings_checks import check_at_least, check_choice, check_fraction
from sim_worker.world import Renderer, World

MAX_CONSECUTIVE_FAILURES = 2

ClutterScene = Literal["blocks", "pile", "packed"]
#: Depth-sensor models (docs/sensors.md): Dex-Net's noise, or a structured-light camera's errors.
Sensor = Literal["dex", "structured-light"]
Views = Literal["six", "side"]
Selection = Literal["best", "random"]
Planner = Literal["vgn", "antipodal"]


@dataclass(frozen=True)
class ClutterConfig:
    """Settings of a clear-scene run; a resumed run must use the same ones."""

    scene: ClutterScene = "blocks"
    objects: str | None = None  # object set name or URDF folder; None = the scene's default
    object_count: int = 5
    rounds: int = 1
    seed: int = 1
    threshold: float | None = None  # None: the service's default (the model's operating threshold)
    views: Views = "six"
    selection: Selection = "best"
    planner: Planner = "vgn"  # antipodal: the service's geometric baseline
    noise: bool = False
    renderer: Renderer = "auto"
    model: str | None = None  # id of the service's weights, recorded with the results
    # Ask the service to drop grasps whose approach hits observed geometry, and VGN for outputs
    # averaged over four quarter turns of the grid; None: the service's default for each
    # (resolve_planner records what that was before a run starts).
    clearance: bool | None = None
    turn_average: bool | None = None
    # A depth sensor's errors on every view (``noise`` is "dex"), and per-view camera pose error.
    sensor: Sensor | None = None
    pose_error: bool = False

    def __post_init__(self) -> None:
        for name, allowed in (
            ("scene", ClutterScene),
            ("views", Views),
            ("selection", Selection),
            ("planner", Planner),
            ("renderer", Renderer),
        ):
            check_choice(name, getattr(self, name), allowed)
        if self.sensor is not None:
            check_choice("sensor", self.sensor, Sensor)
        check_at_least("object_count", self.object_count, 1)
        check_at_least("rounds", self.rounds, 1)
        check_fraction("threshold", self.threshold, optional=True)

    def as_json(self) -> dict:
        """The settings as stored in the results folder's config.json, which a resume must match.

        ``clearance``, ``turn_average``, ``sensor`` and ``pose_error`` are recorded when on; left
        out when off, so folders of runs from before these options still resume. Resolve the
        first two first (``resolve_planner``): unresolved, the service's default is recorded as
        off whatever it is."""
        settings = asdict(self)
        for switch in ("clearance", "turn_average", "sensor", "pose_error"):
            if not settings[switch]:
                del settings[switch]
        return settings

    def depth_noise(self) -> DepthNoise | StructuredLightNoise | None:
        """The noise model of every rendered view (``sensor`` wins over ``noise``)."""
        if self.sensor == "structured-light":
            return StructuredLightNoise(SIM_INTRINSICS)
        if self.sensor == "dex" or self.noise:
            return DepthNoise()
        return None


def camera_views(kind: str) -> list[np.ndarray]:
    """The camera poses of a round: VGN's six views on a circle, or one side view."""
    if kind == "six":
        return six_views()
    if kind == "side":
        return [side_view()]
    raise ValueError(f"unknown views {kind!r}: use 'six' or 'side'")


class ClutterRemoval:
    """Runs rounds in one PyBullet world against one service session."""

    def __init__(
        self, config: ClutterConfig, vgn: VGNClient, results: ResultsFolder, image_dir: Path | None = None
    ) -> None:
        self.config, self.vgn, self.results = config, vgn, results
        self.world = World(renderer=config.renderer)
        self.gripper = Gripper(self.world)
        self.camera = Camera(self.world, noise=config.depth_noise())
        self.pose_error = PoseError() if config.pose_error else None
        self.views = camera_views(config.views)
        self.objects = object_set(config.objects or "", config.scene)
        self.image_dir = image_dir
        self.session_id = vgn.create_session(intrinsics=SIM_INTRINSICS).session_id

    def close(self) -> None:
        """Delete the service session and close the simulator, even when the first fails."""
        try:
            self.vgn.delete_session(self.session_id)
        finally:
            self.world.close()

    def run(self, progress: Callable[[RoundRecord], None] | None = None) -> dict:
        """Run the rounds not finished yet; returns the summary over all finished rounds."""
        done = self.results.finished_rounds()
        for round_id in range(self.config.rounds):
            if round_id in done:
                continue
            record = self.run_round(round_id)
            self.results.commit(record)
            if progress:
                progress(record)
        summary = summarize(self.results.rounds, self.results.grasps)
        self.results.write_summary({"config": self.config.as_json(), **summary})
        return summary

    def run_round(self, round_id: int) -> RoundRecord:
        """One round on the scene of (seed, ``round_id``): grasp until the
        table is clear, no grasp is found, or two grasps in a row fail."""
        started = time.perf_counter()
        rng = np.random.default_rng([self.config.seed, round_id])  # the same scene whenever it runs
        self.camera.rng = rng
        self.world.reset()  # the round depends on (seed, round) alone, not on earlier rounds
        self.gripper = Gripper(self.world)
        generate_scene(self.world, self.config.scene, self.objects, self.config.object_count, rng)
        record = RoundRecord(round_id, f"{self.config.seed}-{round_id}", len(self.world.objects))
        failures = 0
        while self.world.objects and failures < MAX_CONSECUTIVE_FAILURES:
            integration_ms = self._observe()
            client_started = time.perf_counter()
            answer = self.vgn.grasps(
                self.session_id,
                threshold=self.config.threshold,
                planner=self.config.planner,
                clearance=self.config.clearance,
                turn_average=self.config.turn_average,
            )
            client_ms = (time.perf_counter() - client_started) * 1e3
            if not answer.grasps:
                break
            grasp = self._select(answer.grasps, rng)
            if self.image_dir is not None:
                self._save_image(record, grasp)
            trial = execute_grasp(self.world, self.gripper, grasp.as_matrix(), allow_contact=True)
            record.attempts += 1
            record.successes += trial.label
            failures = 0 if trial.label else failures + 1
            row = _grasp_row(
                record, grasp, trial, integration_ms, answer.planning_ms, client_ms, len(answer.grasps)
            )
            row["contact"] = "+".join(self._body_name(body) for body in trial.contact_bodies)
            record.grasps.append(row)
            self.world.wait_for_rest()
            self.world.remove_objects_outside()
        record.cleared = record.successes
        record.seconds = round(time.perf_counter() - started, 3)
        if self.image_dir is not None:
            images.write_contact_sheet(self.image_dir, record)
        return record

    def _observe(self) -> float:
        """Fuse the views of the current scene into a fresh volume; total integration ms."""
        self.session_id = fresh_session(self.vgn, self.session_id)
        total = 0.0
        for pose in self.views:
            depth = self.camera.render_depth(pose)
            # The service is told where the camera was believed to be, not where it was.
            reported = pose if self.pose_error is None else self.pose_error.perturb(pose, self.camera.rng)
            total += self.vgn.add_frame(self.session_id, depth, reported).integration_ms
        return total

    def _body_name(self, body: int) -> str:
        """What the hand touched, for the results: ``table`` or the object's file name."""
        if body == self.world.table:
            return "table"
        found = self.world.objects.get(body)
        return found.urdf.stem if found is not None and found.urdf is not None else f"body{body}"

    def _select(self, grasps: list[Grasp], rng: np.random.Generator) -> Grasp:
        if self.config.selection == "random":
            return grasps[int(rng.integers(len(grasps)))]
        return grasps[0]  # the service ranks best first

    def _save_image(self, record: RoundRecord, grasp: Grasp) -> None:
        """A picture of the scene with the gripper placed, and drawn, at the chosen grasp."""
        self.gripper.reset(grasp.as_matrix())
        rgb = self.camera.render_rgb(self.views[0])
        self.gripper.park()
        images.save_attempt_image(
            self.image_dir,
            record.round_id,
            record.attempts,
            grasp,
            rgb,
            self.views[0],
            self.camera.intrinsics,
        )


def _grasp_row(
    record: RoundRecord,
    grasp: Grasp,
    trial: GraspTrial,
    integration_ms: float,
    planning_ms: float,
    client_ms: float,
    count: int,
) -> dict:
    qx, qy, qz, qw = grasp.orientation
    x, y, z = grasp.position
    return {
        "round_id": record.round_id,
        "scene_id": record.scene_id,
        "qx": qx,
        "qy": qy,
        "qz": qz,
        "qw": qw,
        "x": x,
        "y": y,
        "z": z,
        "width": grasp.width,
        "score": grasp.quality,
        "label": trial.label,
        "integration_time": round(integration_ms, 3),
        "planning_time": round(planning_ms, 3),
        "client_planning_time": round(client_ms, 3),
        "outcome": trial.outcome.value,
        "contact_distance": "" if trial.contact_distance is None else trial.contact_distance,
        "grasp_count": count,
        "trial_time": round(trial.seconds, 4),
    }
