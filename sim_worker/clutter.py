"""The clutter-removal benchmark (VGN §V-B), driving the service through the client only.

Each round: generate a scene, then repeat { reset the session, render and post the views,
ask for grasps, execute one, remove the grasped object, let the scene settle } until the
table is clear, no grasp is found, or two grasps in a row failed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Literal

import numpy as np

from client.http import VGNClient
from sim_worker import images
from sim_worker.camera import SIM_INTRINSICS, Camera, DepthNoise, random_views, side_view, six_views
from sim_worker.closed_loop import (
    ApproachWatch,
    elapsed_ms,
    wrist_arc,
    wrist_scan,
)
from sim_worker.disturbance import Disturbance, Disturber
from sim_worker.grasping import GraspTrial, Outcome, execute_grasp
from sim_worker.gripper import Gripper, GripperSpec
from sim_worker.metrics import summarize
from sim_worker.objects import object_set
from sim_worker.results import ResultsFolder, RoundRecord
from sim_worker.scenes import generate_scene
from sim_worker.sensors import PoseError, StructuredLightNoise
from sim_worker.service_session import fresh_session
from sim_worker.settings_checks import check_at_least, check_choice, check_fraction
from sim_worker.world import Renderer, World
from vgn_contract.gripper_description import GripperDescription, default_gripper
from vgn_contract.schemas import SWITCHES, Grasp, GraspResult

MAX_CONSECUTIVE_FAILURES = 2
#: A closed loop that withdrew this many times in a row ends the round (the scene keeps changing).
MAX_STOPS_IN_A_ROW = 4

ClutterScene = Literal["blocks", "pile", "packed"]
#: Depth-sensor models (docs/sensors.md): Dex-Net's noise, or a structured-light camera's errors.
Sensor = Literal["dex", "structured-light"]
#: VGN's six fixed views, GIGA's one fixed side view, or one view drawn anew for every look.
Views = Literal["six", "side", "random"]
#: How a round looks before each grasp: the fixed views, or a wrist camera's arc (closed_loop.py).
Scan = Literal["fixed", "wrist"]
Selection = Literal["best", "random"]
Planner = Literal["vgn", "antipodal"]
#: The grasp options a run may leave to the service (``ClutterConfig.left_to_service``).
SERVICE_OPTIONS = ("threshold", *SWITCHES)


def looking(views: str, scan: str) -> str:
    """How a round looks at the scene, for report headers: the wrist scan chooses its own
    frames, so the fixed views it does not use are not named."""
    return "wrist scan" if scan == "wrist" else f"{views} view(s)"


@dataclass(frozen=True)
class ClutterConfig:
    """Settings of a clear-scene run; a resumed run must use the same ones."""

    scene: ClutterScene = "blocks"
    objects: str | None = None  # object set name or URDF folder; None = the scene's default
    object_count: int = 5
    rounds: int = 1
    seed: int = 1
    threshold: float | None = None  # None: the service's default (the model's operating threshold)
    # The quality the service falls back to when nothing passes the checks at its operating
    # threshold (resolve_planner records it from the service when the run names no threshold; a run
    # that names one asks for that one alone).
    fallback_threshold: float | None = None
    views: Views = "six"
    selection: Selection = "best"
    planner: Planner = "vgn"  # antipodal: the service's geometric baseline
    noise: bool = False
    renderer: Renderer = "auto"
    model: str | None = None  # id of the service's weights, recorded with the results
    # The service's network for one-frame volumes and its threshold, when it has one: it answers the
    # looks of one frame (resolve_planner records them; docs/configuration.md).
    one_view_model: str | None = None
    one_view_threshold: float | None = None
    # Ask the service to drop grasps whose approach hits observed geometry or whose fingers would
    # not meet the surface squarely, and VGN for outputs averaged over four quarter turns of the
    # grid; None: the service's default for each (resolve_planner records what that was before a
    # run starts).
    clearance: bool | None = None
    grip: bool | None = None
    turn_average: bool | None = None
    # The grasp options the run leaves to the service ("threshold" and the switches): requests leave
    # them unset, while config.json records what the service said it would use (resolve_planner) and
    # every answer is checked against that record. Not recorded itself.
    left_to_service: frozenset[str] = frozenset()
    # A depth sensor's errors on every view (``noise`` is "dex"), and per-view camera pose error.
    sensor: Sensor | None = None
    pose_error: bool = False
    # Closing the loop (closed_loop.py, disturbance.py): the share of attempts in which the aimed-at
    # object is displaced during the approach; watching and re-planning while approaching; and
    # how the scene is looked at before each grasp.
    disturb: float = 0.0
    closed_loop: bool = False
    scan: Scan = "fixed"
    # The hand that executes the grasps; the service's session plans for the same one (its clearance
    # and grip checks measure it), so the service must know it and serve it with a network.
    hand: GripperDescription = field(default_factory=default_gripper)

    @property
    def looking(self) -> str:
        """How a round looks at the scene, for report headers (:func:`looking`)."""
        return looking(self.views, self.scan)

    def __post_init__(self) -> None:
        for name, allowed in (
            ("scene", ClutterScene),
            ("views", Views),
            ("selection", Selection),
            ("planner", Planner),
            ("renderer", Renderer),
            ("scan", Scan),
        ):
            check_choice(name, getattr(self, name), allowed)
        if self.sensor is not None:
            check_choice("sensor", self.sensor, Sensor)
        check_at_least("object_count", self.object_count, 1)
        check_at_least("rounds", self.rounds, 1)
        check_fraction("threshold", self.threshold, optional=True)
        check_fraction("fallback_threshold", self.fallback_threshold, optional=True)
        check_fraction("one_view_threshold", self.one_view_threshold, optional=True)
        check_fraction("disturb", self.disturb)
        unknown = self.left_to_service - set(SERVICE_OPTIONS)
        if unknown:
            raise ValueError(f"left_to_service names no grasp option the service decides: {sorted(unknown)}")
        if self.scan == "wrist" and self.views != "six":
            raise ValueError("--scan wrist replaces the fixed views: leave --views at its default")

    def as_json(self) -> dict:
        """The settings as stored in the results folder's config.json, which a resume must match.

        ``clearance``, ``grip``, ``turn_average``, ``sensor``, ``pose_error``, ``disturb`` and
        ``closed_loop`` are recorded when on (``scan`` when not "fixed", the hand's name and
        digest as ``gripper`` and ``gripper_digest`` when it is not ``franka``); left out when off,
        so folders of runs from before these options still resume. Resolve the
        first three first (``resolve_planner``): unresolved, the service's default is recorded as
        off whatever it is."""
        settings = {
            f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("left_to_service", "hand")
        }
        if self.hand != default_gripper():
            settings |= {"gripper": self.hand.name, "gripper_digest": self.hand.digest}
        for switch in ("clearance", "grip", "turn_average", "sensor", "pose_error", "disturb", "closed_loop",
                       "fallback_threshold", "one_view_model", "one_view_threshold"):  # fmt: skip
            if not settings[switch]:
                del settings[switch]
        if settings["scan"] == "fixed":
            del settings["scan"]
        return settings

    def grasp_options(self) -> dict:
        """The options of every grasp request: those the run chose, the rest unset for the service to
        decide (a threshold sent would also switch the service's fallback off)."""
        left = self.left_to_service
        return {"planner": self.planner} | {
            name: None if name in left else getattr(self, name) for name in SERVICE_OPTIONS
        }

    def depth_noise(self) -> DepthNoise | StructuredLightNoise | None:
        """The noise model of every rendered view (``sensor`` wins over ``noise``)."""
        if self.sensor == "structured-light":
            return StructuredLightNoise(SIM_INTRINSICS)
        if self.sensor == "dex" or self.noise:
            return DepthNoise()
        return None


def camera_views(kind: str, rng: np.random.Generator | None = None) -> list[np.ndarray]:
    """The camera poses of a look: VGN's six views on a circle, one side view, or one view drawn
    from ``rng`` as data generation draws them (0.48-0.72 m from the workspace centre, up to 45
    degrees from the vertical, any azimuth)."""
    if kind == "six":
        return six_views()
    if kind == "side":
        return [side_view()]
    if kind == "random":
        if rng is None:
            raise ValueError("random views need the round's random stream")
        return random_views(rng, 1)
    raise ValueError(f"unknown views {kind!r}: use 'six', 'side' or 'random'")


class ClutterRemoval:
    """Runs rounds in one PyBullet world against one service session."""

    def __init__(
        self, config: ClutterConfig, vgn: VGNClient, results: ResultsFolder, image_dir: Path | None = None
    ) -> None:
        self.config, self.vgn, self.results = config, vgn, results
        self.world = World(renderer=config.renderer)
        self.spec = GripperSpec(hand=config.hand)
        self.gripper = Gripper(self.world, self.spec)
        self.camera = Camera(self.world, noise=config.depth_noise())
        self.pose_error = PoseError() if config.pose_error else None
        self.views = [] if config.views == "random" else camera_views(config.views)
        self.objects = object_set(config.objects or "", config.scene)
        self.image_dir = image_dir
        self.session_id = vgn.create_session(intrinsics=SIM_INTRINSICS, gripper=config.hand.name).session_id

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
        rng = self.new_scene(round_id)
        record = RoundRecord(round_id, f"{self.config.seed}-{round_id}", len(self.world.objects))
        # Disturbances draw from a stream of their own, so open and closed loop meet the same ones.
        disturber = Disturber(self.config.disturb, np.random.default_rng([self.config.seed, round_id, 7]))
        failures = aborts = 0
        withdrawn_from: Disturbance | None = None
        while self.world.objects and failures < MAX_CONSECUTIVE_FAILURES:
            observed = self.look(rng)
            if not observed.answer.grasps:
                _record_empty_look(record, observed.answer)
                break
            grasp = self._select(observed.answer.grasps, rng)
            if self.image_dir is not None:
                self._save_image(record, grasp)
            # A retry after the closed loop withdrew belongs to the same attempt: no new disturbance.
            trial, disturbance, watch = self._attempt(grasp, disturber, retry=aborts > 0)
            row = _grasp_row(record, grasp, trial, observed)
            row["contact"] = "+".join(self._body_name(body) for body in trial.contact_bodies)
            row["closed_on"] = "+".join(self._body_name(body) for body in trial.closed_on)
            # A retry after a withdrawal belongs to the disturbed attempt: it carries its disturbance.
            carried = disturbance or (withdrawn_from if aborts else None)
            row["disturbance"] = carried.kind if carried else ""
            if watch is not None:
                stopped = trial.outcome is Outcome.INTERRUPTED
                row["loop"] = "stopped" if stopped else "retried" if aborts else "kept"
                row["looks"] = watch.looks
            record.grasps.append(row)
            if trial.outcome is Outcome.INTERRUPTED:  # the closed loop withdrew: no attempt, look again
                withdrawn_from = carried
                aborts += 1
                if aborts >= MAX_STOPS_IN_A_ROW:
                    record.ended = "withdrawn"
                    break
            else:
                aborts = 0
                record.attempts += 1
                record.successes += trial.label
                failures = 0 if trial.label else failures + 1
            self.world.wait_for_rest()
            self.world.remove_objects_outside()
        record.cleared = record.successes
        record.remaining = len(self.world.objects)
        record.left = "+".join(sorted(self._body_name(body) for body in self.world.objects))
        if not record.ended:
            record.ended = "cleared" if not self.world.objects else "failures"
        record.seconds = round(time.perf_counter() - started, 3)
        if self.image_dir is not None:
            images.write_contact_sheet(self.image_dir, record)
        return record

    def new_scene(self, round_id: int) -> np.random.Generator:
        """Build the scene of (seed, ``round_id``) in a reset world; returns the round's random
        stream (camera noise and grasp choices draw from it), so that a round depends on (seed,
        round) alone, not on earlier rounds."""
        rng = np.random.default_rng([self.config.seed, round_id])
        self.camera.rng = rng
        self.world.reset()
        self.gripper = Gripper(self.world, self.spec)
        generate_scene(self.world, self.config.scene, self.objects, self.config.object_count, rng)
        return rng

    def look(self, rng: np.random.Generator) -> Observed:
        """Observe the scene afresh and plan: the fixed views, or a wrist scan that stops early.
        Its answer must have used the options the run records (:func:`check_answer`)."""
        started = time.perf_counter()
        self.session_id = fresh_session(self.vgn, self.session_id, gripper=self.config.hand.name)
        if self.config.scan == "wrist":
            arc = wrist_arc(float(rng.uniform(0.0, 2.0 * np.pi)))
            scan = wrist_scan(
                self.vgn, self.session_id, self.camera, arc, self.config.grasp_options(), self._reported_pose
            )
            observed = Observed(scan.answer, scan.frames, scan.integration_ms, elapsed_ms(started), None)
        else:
            if self.config.views == "random":
                self.views = camera_views("random", rng)
            integration_ms = self._observe()
            client_started = time.perf_counter()
            answer = self.vgn.grasps(self.session_id, **self.config.grasp_options())
            client_ms = elapsed_ms(client_started)
            observed = Observed(answer, len(self.views), integration_ms, elapsed_ms(started), client_ms)
        check_answer(self.config, observed.answer)
        return observed

    def _attempt(
        self, grasp: Grasp, disturber: Disturber, retry: bool = False
    ) -> tuple[GraspTrial, Disturbance | None, ApproachWatch | None]:
        """Execute ``grasp``; a drawn disturbance moves the aimed-at object during the approach,
        and with ``closed_loop`` the approach is watched and stopped when the grasp is gone
        (the trial is then ``INTERRUPTED``). Returns the trial, the disturbance and the watch."""
        planned = None if retry else disturber.draw()
        watch = None
        if self.config.closed_loop:  # what the fixed cameras see now, the hand out of view
            views = six_views()
            reference = [self.camera.render_depth(pose) for pose in views]
            watch = ApproachWatch(
                self.camera, views, reference, self.gripper.body, np.asarray(grasp.position)
            )
        happened: list[Disturbance | None] = []
        target = np.asarray(grasp.position)

        def on_waypoint(step: int, count: int) -> bool:
            if planned is not None and not happened and step >= planned.step(count):
                happened.append(disturber.apply(self.world, planned, target))
            return watch(step, count) if watch is not None else False

        trial = execute_grasp(self.world, self.gripper, grasp.as_matrix(), allow_contact=True,
                              on_waypoint=on_waypoint, on_contact=watch.look if watch else None)  # fmt: skip
        return trial, (happened[0] if happened else None), watch

    def _reported_pose(self, pose: np.ndarray) -> np.ndarray:
        """Where the service is told the camera was: the true pose, or one with pose error."""
        return pose if self.pose_error is None else self.pose_error.perturb(pose, self.camera.rng)

    def _observe(self) -> float:
        """Fuse the views of the current scene into a fresh volume; total integration ms."""
        total = 0.0
        for pose in self.views:
            depth = self.camera.render_depth(pose)
            # The service is told where the camera was believed to be, not where it was.
            total += self.vgn.add_frame(self.session_id, depth, self._reported_pose(pose)).integration_ms
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
            len(record.grasps),  # one picture per row, withdrawn approaches too
            grasp,
            rgb,
            self.views[0],
            self.camera.intrinsics,
            self.spec.finger_depth,
        )


@dataclass(frozen=True)
class Observed:
    """A look at the scene before a grasp: the plan, the frames fused for it, their integration
    time on the service, the time from the first frame to the plan, and the grasp request's
    own round trip (None for a scan, which plans after every frame)."""

    answer: GraspResult
    frames: int
    integration_ms: float
    first_grasp_ms: float
    client_ms: float | None


class ServiceDefaultsError(RuntimeError):
    """The service does not report the defaults a run must record (it is older than this client),
    or an answer used other options than the run records (its defaults changed meanwhile)."""


def check_answer(config: ClutterConfig, answer: GraspResult) -> None:
    """Raise ``ServiceDefaultsError`` unless ``answer`` used the threshold (or the recorded fallback)
    and the switches that ``config`` records, so that config.json stays true to every round. What
    the answer or the record does not say (an older service, an unresolved config) is not checked."""
    recorded = {"turn_average": config.turn_average if config.planner == "vgn" else None,
                "clearance": config.clearance, "grip": config.grip}  # fmt: skip
    answered = {"turn_average": answer.turn_average, "clearance": answer.clearance, "grip": answer.grip}
    differ = [
        f"{name} {answered[name]} (recorded: {recorded[name]})"
        for name in recorded
        if recorded[name] is not None and answered[name] is not None and answered[name] != recorded[name]
    ]
    main = config.one_view_model is None or answer.model != config.one_view_model
    threshold = config.threshold if main else config.one_view_threshold
    thresholds = {threshold, config.fallback_threshold} - {None}
    if threshold is not None and answer.threshold not in thresholds:
        differ.append(f"threshold {answer.threshold} (recorded: {' or '.join(map(str, sorted(thresholds)))})")
    if differ:
        raise ServiceDefaultsError(
            f"the service answered with {', '.join(differ)}: its defaults changed during the run (the "
            "finished rounds are kept); name the options to hold them fixed"
        )


def _record_empty_look(record: RoundRecord, answer: GraspResult) -> None:
    """A look offered nothing: note it and what its planner found before the checks dropped it
    (``last_candidates`` zero: the threshold or the valid region left nothing to check)."""
    record.ended = "no_grasp"
    clearance, grip, workspace = answer.clearance_dropped, answer.grip_dropped, answer.workspace_dropped
    record.last_candidates = (clearance or 0) + (grip or 0) + (workspace or 0)
    record.last_clearance_dropped = "" if clearance is None else clearance
    record.last_grip_dropped = "" if grip is None else grip
    record.last_workspace_dropped = "" if workspace is None else workspace


def _grasp_row(record: RoundRecord, grasp: Grasp, trial: GraspTrial, observed: Observed) -> dict:
    qx, qy, qz, qw = grasp.orientation
    x, y, z = grasp.position
    answer = observed.answer
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
        "integration_time": round(observed.integration_ms, 3),
        "planning_time": round(answer.planning_ms, 3),
        "client_planning_time": "" if observed.client_ms is None else observed.client_ms,
        "outcome": trial.outcome.value,
        "contact_distance": "" if trial.contact_distance is None else trial.contact_distance,
        "grasp_count": len(answer.grasps),
        "trial_time": round(trial.seconds, 4),
        "frames": observed.frames,
        "first_grasp_ms": observed.first_grasp_ms,
        "model": answer.model,
        "threshold": answer.threshold,
        "clearance_margin": "" if answer.clearance_margin is None else answer.clearance_margin,
        "fallback": "" if answer.fallback is None else int(answer.fallback),
    }
