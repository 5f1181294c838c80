"""Labelled grasp data through the service (VGN's data generation, docs/conventions.md).

Per scene: build a pile or packed scene, render 1-6 random views, post them to a session,
read the fused grid and the point cloud with normals back, and label 120 grasp points by
trying 6 yaws each in simulation; the output is VGN's raw layout (vgn_data.dataset).
``answer_grasps`` also labels the service's own plain answers, so the network's mistakes
become negatives exactly where it makes them. A share of scenes, drawn from the seed alone,
can be observed as a real sensor sees them (``noise_fraction``: Dex-Net depth noise;
``side_view_fraction``: one view from the side), so a model trained on the data survives them.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from client.http import VGNClient
from sim_worker.camera import SIM_INTRINSICS, Camera, DepthNoise, random_views
from sim_worker.grasping import execute_grasp
from sim_worker.gripper import Gripper, GripperSpec
from sim_worker.objects import ObjectSet, object_set
from sim_worker.recipes import (
    ObjectTable,
    SceneRecipe,
    object_roots,
    recipe_arrays,
    record_recipe,
    render_views,
)
from sim_worker.scenes import generate_scene, poisson_object_count
from sim_worker.service_session import fresh_session
from sim_worker.settings_checks import check_at_least, check_choice, check_fraction
from sim_worker.world import WORKSPACE_SIZE, Renderer, World
from vgn_contract.gripper_description import GripperDescription, default_gripper
from vgn_data.dataset import VALID_LOWER, VALID_UPPER, DatasetSetup, RawDataset, SceneViews

#: Normals must point at least this much upwards: grasps from below the table are pointless.
MIN_NORMAL_Z = -0.1
#: Single side views look from this far off vertical (degrees), like a robot's head camera.
SIDE_VIEW_TILT_DEG = (45.0, 65.0)
#: Labelled scenes: blocks are kept for benchmarks that no model trains on.
DataScene = Literal["pile", "packed"]


@dataclass(frozen=True)
class DataGenConfig:
    """Settings of a generate-data run; all but the renderer and the hand are recorded in the dataset's
    generation.json, which a resumed run must match (the hand is recorded by ``generate_data``)."""

    scene: DataScene = "pile"
    objects: tuple[str, ...] = ()  # object set names or URDF folders; () = the scene's default
    seed: int = 0
    points_per_scene: int = 120
    yaws: int = 6
    max_views: int = 6
    noise: bool = False  # every scene noisy (same as noise_fraction=1)
    noise_fraction: float = 0.0  # share of scenes rendered with depth noise
    side_view_fraction: float = 0.0  # share of scenes seen from one side view only
    answer_grasps: int = 0  # of the service's plain answers per scene, labelled as answered
    answer_threshold: float = 0.5  # the quality those answers must reach
    answer_model: str | None = None  # weights id of the model expected to answer
    renderer: Renderer = "auto"
    hand: GripperDescription = field(default_factory=default_gripper)  # the hand that labels

    def __post_init__(self) -> None:
        check_choice("scene", self.scene, DataScene)
        check_choice("renderer", self.renderer, Renderer)
        for name in ("yaws", "max_views"):
            check_at_least(name, getattr(self, name), 1)
        check_at_least("answer_grasps", self.answer_grasps, 0)
        # Answer-only scenes (no random points) are allowed: the network's answers are the labels.
        check_at_least("points_per_scene", self.points_per_scene, 0 if self.answer_grasps else 1)
        for name in ("noise_fraction", "side_view_fraction", "answer_threshold"):
            check_fraction(name, getattr(self, name))

    def recorded(self) -> dict:
        """The settings a resumed run must match (generation.json); the answer-labelling ones only
        when it is on, so folders made before it existed still resume."""
        settings = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                    if f.name not in ("renderer", "hand")}  # fmt: skip
        settings["objects"] = list(settings["objects"])
        if not self.answer_grasps:
            del settings["answer_grasps"], settings["answer_threshold"], settings["answer_model"]
        return settings

    def scene_conditions(self, index: int) -> tuple[bool, bool]:
        """(noisy, side view) for scene ``index``: drawn from the seed alone, so a scene is
        the same whichever worker labels it and whatever else changes."""
        draws = np.random.default_rng([self.seed, index, 7]).random(2)
        noisy = self.noise or bool(draws[0] < self.noise_fraction)
        return noisy, bool(draws[1] < self.side_view_fraction)


def merged_object_set(names: tuple[str, ...], scene: str) -> ObjectSet:
    """One set from several (``--objects`` may repeat); each object keeps its own scale."""
    sets = [object_set(name, scene) for name in (names or ("",))]
    if len(sets) == 1:
        return sets[0]
    urdfs = [urdf for s in sets for urdf in s.urdfs]
    scales = [s.base_scale(i) for s in sets for i in range(len(s))]
    return ObjectSet("+".join(s.name for s in sets), urdfs, 1.0, scales)


def in_valid_region(points: np.ndarray) -> np.ndarray:
    """(M,) bool: which of the (M, 3) world points lie where grasps are labelled."""
    return np.all((points >= VALID_LOWER) & (points <= VALID_UPPER), axis=1)


def scene_id(seed: int, index: int) -> str:
    """Deterministic ids, so a resumed run knows which scenes are done."""
    return f"s{seed}-{index:07d}"


def grasp_frame(normal: np.ndarray) -> Rotation:
    """Grasp orientation at yaw 0 for a surface normal: z = -normal (approach into the
    surface), x chosen along world x where possible."""
    z_axis = -normal / np.linalg.norm(normal)
    x_axis = np.array([1.0, 0.0, 0.0])
    if abs(x_axis @ z_axis) > 1.0 - 1e-4:
        x_axis = np.array([0.0, 1.0, 0.0])
    y_axis = np.cross(z_axis, x_axis)
    y_axis /= np.linalg.norm(y_axis)
    x_axis = np.cross(y_axis, z_axis)
    return Rotation.from_matrix(np.column_stack([x_axis, y_axis, z_axis]))


def middle_of_widest_run(successes: np.ndarray) -> int | None:
    """Index in the middle of the longest run of consecutive successes (first on ties)."""
    best: tuple[int, int] | None = None
    start = None
    for i, ok in enumerate([*successes, False]):
        if ok and start is None:
            start = i
        elif not ok and start is not None:
            if best is None or i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    return None if best is None else (best[0] + best[1] - 1) // 2


@dataclass
class BuiltScene:
    """A data-generation scene standing in the builder's world, with its original observation
    drawn: ``rng`` continues the scene's stream (its next draws are the depth noise, when
    ``noisy``, then the labelling's)."""

    index: int
    rng: np.random.Generator
    camera_poses: list[np.ndarray]
    noisy: bool
    side_view: bool


class SceneBuilder:
    """One simulated world that builds data-generation scenes from (seed, index) alone: the
    same scene whichever process builds it and whatever it built before."""

    def __init__(self, config: DataGenConfig) -> None:
        self.config = config
        self.world = World(renderer=config.renderer)
        self.camera = Camera(self.world)
        self.objects = merged_object_set(config.objects, config.scene)
        self.spec = GripperSpec(hand=config.hand)
        self.gripper = Gripper(self.world, self.spec)

    def build(self, index: int) -> BuiltScene | None:
        """Scene ``index`` settled in the world and its views drawn; None when it came out empty."""
        rng = np.random.default_rng([self.config.seed, index])
        self.world.reset()  # the scene depends on (seed, index) alone, not on earlier scenes
        self.gripper = Gripper(self.world, self.spec)
        generate_scene(self.world, self.config.scene, self.objects, poisson_object_count(rng), rng)
        if not self.world.objects:
            return None
        noisy, side = self.config.scene_conditions(index)
        if side:
            poses = random_views(rng, 1, tilt_deg=SIDE_VIEW_TILT_DEG)
        else:
            poses = random_views(rng, int(rng.integers(1, self.config.max_views + 1)))
        return BuiltScene(index, rng, poses, noisy, side)

    def recipe(self, built: BuiltScene, table: ObjectTable) -> SceneRecipe:
        """The recipe of the scene just built; call it before :meth:`render`, which draws the noise."""
        return record_recipe(self.world, scene_id(self.config.seed, built.index), table, built.camera_poses,
                             built.rng if built.noisy else None, built.side_view)  # fmt: skip

    def render(self, built: BuiltScene) -> np.ndarray:
        """(V, H, W) depth of the original observation, noise drawn from the scene's stream."""
        return render_views(self.camera, built.camera_poses, DepthNoise() if built.noisy else None, built.rng)

    def close(self) -> None:
        """Close the simulator."""
        self.world.close()


class SceneLabeller:
    """One scene builder and one service session, reused scene after scene."""

    def __init__(self, vgn: VGNClient, config: DataGenConfig, table: ObjectTable | None = None) -> None:
        self.vgn, self.config = vgn, config
        self.builder = SceneBuilder(config)
        self.world = self.builder.world
        self.table = table if table is not None else ObjectTable(object_roots())
        # Fusing views and reading the cloud need no hand, and no network serves a hand before data
        # made with it exists: a session names the hand only when its network's answers are labelled.
        self.hand_name = config.hand.name if config.answer_grasps else None
        self.session_id = vgn.create_session(intrinsics=SIM_INTRINSICS, gripper=self.hand_name).session_id
        self.trial_seconds = 0.0
        self.trials = 0

    @property
    def gripper(self) -> Gripper:
        """The hand of the scene being labelled (made anew with every scene)."""
        return self.builder.gripper

    def close(self) -> None:
        """Delete the service session and close the simulator, even when the first fails."""
        try:
            self.vgn.delete_session(self.session_id)
        finally:
            self.builder.close()

    def label_scene(self, index: int) -> tuple[SceneViews, np.ndarray, SceneRecipe] | None:
        """Views, grasp rows (qx, qy, qz, qw, x, y, z, width, label) and recipe of scene
        ``index``, or None when the scene came out empty."""
        built = self.builder.build(index)
        if built is None:
            return None
        recipe = self.builder.recipe(built, self.table)
        views = self._observe(built)
        if not np.any(self.vgn.tsdf(self.session_id) > 0.5):
            return None  # the fused grid holds no observed surface: nothing to label
        cloud = self.vgn.cloud(self.session_id)
        candidates = cloud[in_valid_region(cloud[:, :3]) & (cloud[:, 5] > MIN_NORMAL_Z)]
        if not len(candidates):
            return None
        rng = built.rng
        state = self.world.save_state()
        try:
            rows = [self._label_point(candidates[int(rng.integers(len(candidates)))], rng, state)
                    for _ in range(self.config.points_per_scene)]  # fmt: skip
            rows += self._label_answers(rng, state)
        finally:
            self.world.discard_state(state)
        if not rows:
            return None  # answer-only and the network answered nothing: no labels
        return views, np.asarray(rows), recipe

    def _observe(self, built: BuiltScene) -> SceneViews:
        self.session_id = fresh_session(self.vgn, self.session_id, gripper=self.hand_name)
        depths = self.builder.render(built)
        for depth, pose in zip(depths, built.camera_poses, strict=True):
            self.vgn.add_frame(self.session_id, depth, pose)
        return SceneViews(depths, np.stack(built.camera_poses))

    def _label_answers(self, rng: np.random.Generator, state: int) -> list[np.ndarray]:
        """Rows for up to ``answer_grasps`` of the service's plain answers, drawn at random among all
        that reach ``answer_threshold`` (as a randomly selecting robot would), each tried once with the
        orientation answered; a failure keeps the maximum opening as its width, like point labels."""
        if not self.config.answer_grasps:
            return []
        answer = self.vgn.grasps(self.session_id, threshold=self.config.answer_threshold, turn_average=False,
                                 clearance=False, grip=False)  # fmt: skip
        if self.config.answer_model is not None and answer.model != self.config.answer_model:
            raise RuntimeError(f"the service answers with model {answer.model}, but this run labels the "
                               f"answers of {self.config.answer_model}; restart it with those weights")  # fmt: skip
        positions = np.array([g.position for g in answer.grasps]).reshape(-1, 3)
        inside = [g for g, ok in zip(answer.grasps, in_valid_region(positions), strict=True) if ok]
        count = min(self.config.answer_grasps, len(inside))
        rows = []
        for i in rng.permutation(len(inside))[:count]:
            pose = inside[int(i)].as_matrix()
            self.world.restore_state(state)
            trial = execute_grasp(self.world, self.gripper, pose, allow_contact=False, remove_grasped=False,
                                  fast=True)  # fmt: skip
            self.trial_seconds += trial.seconds
            self.trials += 1
            width = trial.width if trial.label else self.gripper.spec.max_opening
            quaternion = Rotation.from_matrix(pose[:3, :3]).as_quat()
            rows.append(np.r_[quaternion, pose[:3, 3], width, trial.label])
        return rows

    def _label_point(self, point_normal: np.ndarray, rng: np.random.Generator, state: int) -> np.ndarray:
        spec: GripperSpec = self.gripper.spec
        normal = point_normal[3:] / np.linalg.norm(point_normal[3:])
        depth = rng.uniform(-0.1 * spec.finger_depth, 1.1 * spec.finger_depth)
        position = point_normal[:3] + normal * depth
        frame = grasp_frame(normal)
        yaws = np.arange(self.config.yaws) * np.pi / self.config.yaws  # [0, π)
        labels, widths = [], []
        for yaw in yaws:
            self.world.restore_state(state)
            pose = np.eye(4)
            pose[:3, :3] = (frame * Rotation.from_euler("z", yaw)).as_matrix()
            pose[:3, 3] = position
            trial = execute_grasp(self.world, self.gripper, pose, allow_contact=False, remove_grasped=False,
                                  fast=True)  # fmt: skip
            self.trial_seconds += trial.seconds
            self.trials += 1
            labels.append(trial.label)
            widths.append(trial.width)
        best = middle_of_widest_run(np.asarray(labels, dtype=bool))
        chosen = 0 if best is None else best
        quaternion = (frame * Rotation.from_euler("z", yaws[chosen])).as_quat()
        width = spec.max_opening if best is None else widths[best]
        return np.r_[quaternion, position, width, int(best is not None)]


def dataset_setup(hand: GripperDescription | None = None) -> DatasetSetup:
    """The dataset's setup.json: the simulated workspace, camera and gripper (``hand``, default ``franka``)."""
    hand = hand or default_gripper()
    return DatasetSetup(size=WORKSPACE_SIZE, intrinsics=SIM_INTRINSICS, max_opening_width=hand.max_opening,
                        finger_depth=hand.finger_depth)  # fmt: skip


def generate(
    vgn: VGNClient,
    dataset: RawDataset,
    config: DataGenConfig,
    indices: list[int],
    report: Callable[[str, int, float], object] | None = None,
) -> None:
    """Label the scenes ``indices`` not yet in ``dataset``; ``report(scene_id, grasps, seconds)``
    is called after each scene is stored."""
    done = dataset.done_scene_ids()
    labeller = SceneLabeller(vgn, config)
    try:
        for index in indices:
            sid = scene_id(config.seed, index)
            if sid in done:
                continue
            started = time.perf_counter()
            labelled = labeller.label_scene(index)
            if labelled is None:
                dataset.mark_empty(sid)
                if report:
                    report(sid, 0, time.perf_counter() - started)
                continue
            views, rows, recipe = labelled
            dataset.add_scene(sid, views, rows, recipe_arrays(recipe, labeller.table))
            if report:
                report(sid, len(rows), time.perf_counter() - started)
    finally:
        labeller.close()
