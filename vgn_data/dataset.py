"""VGN's raw dataset layout (docs/conventions.md), shared by data generation and training.

    DIR/setup.json           size, intrinsics, max_opening_width, finger_depth
    DIR/grasps.csv           scene_id,qx,qy,qz,qw,x,y,z,width,label  (metres, workspace frame)
    DIR/scenes/<id>.npz      depth_imgs (n, H, W) float32, extrinsics (n, 7) [qx,qy,qz,qw,tx,ty,tz] world→camera
    DIR/recipes/<id>.npz     (ours, optional) the scene's recipe: objects, poses, original views

Public VGN/GIGA raw datasets use the same layout, so they read and train here unchanged.
Every write is atomic (temp file + rename) so an interrupted writer never leaves a torn
file; grasps are appended per scene *after* the scene file exists, and a scene counts as
done once it has rows in grasps.csv, so a resumed run skips it and repeats nothing.
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from vgn_contract.geometry import invert, matrix_from_pose, pose_from_matrix
from vgn_contract.gripper_description import default_gripper
from vgn_contract.schemas import Intrinsics
from vgn_data.files import atomic_writer, crash_now, crash_point, write_atomically

GRASP_COLUMNS = ["scene_id", "qx", "qy", "qz", "qw", "x", "y", "z", "width", "label"]


@dataclass(frozen=True)
class DatasetSetup:
    """The dataset's setup.json: workspace size, camera intrinsics and gripper dimensions, in VGN's
    layout; the gripper's default to the default gripper description's (``franka``)."""

    size: float = 0.30
    intrinsics: Intrinsics = field(
        default_factory=lambda: Intrinsics(width=640, height=480, fx=540.0, fy=540.0, cx=320.0, cy=240.0)
    )
    max_opening_width: float = field(default_factory=lambda: default_gripper().max_opening)
    finger_depth: float = field(default_factory=lambda: default_gripper().finger_depth)

    def to_json(self) -> dict:
        """The content of setup.json, intrinsics as VGN writes them (a flattened 3×3 ``K``)."""
        i = self.intrinsics
        return {
            "size": self.size,
            "intrinsic": {
                "width": i.width,
                "height": i.height,
                "K": [i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0],
            },
            "max_opening_width": self.max_opening_width,
            "finger_depth": self.finger_depth,
        }

    @classmethod
    def from_json(cls, data: dict) -> DatasetSetup:
        """The setup read back from the content of setup.json."""
        k = data["intrinsic"]["K"]
        intrinsics = Intrinsics(width=data["intrinsic"]["width"], height=data["intrinsic"]["height"],
                                fx=k[0], fy=k[4], cx=k[2], cy=k[5])  # fmt: skip
        return cls(size=data["size"], intrinsics=intrinsics, max_opening_width=data["max_opening_width"],
                   finger_depth=data["finger_depth"])  # fmt: skip


@dataclass
class SceneViews:
    """Depth images (n, H, W) metres and their camera poses (n, 4, 4) camera → world."""

    depth: np.ndarray
    camera_poses: np.ndarray

    def extrinsics(self) -> np.ndarray:
        """(n, 7) world → camera as [qx, qy, qz, qw, tx, ty, tz] (VGN's storage)."""
        rows = []
        for pose in self.camera_poses:
            translation, quaternion = pose_from_matrix(invert(pose))
            rows.append(np.r_[quaternion, translation])
        return np.asarray(rows, dtype=np.float64).reshape(-1, 7)

    @classmethod
    def from_extrinsics(cls, depth: np.ndarray, extrinsics: np.ndarray) -> SceneViews:
        """Views from a scene file's depth images and VGN's stored world → camera extrinsics."""
        poses = [invert(matrix_from_pose(row[4:7], row[0:4])) for row in np.asarray(extrinsics)]
        return cls(np.asarray(depth, dtype=np.float32), np.asarray(poses).reshape(-1, 4, 4))


def _whole_scenes(text: str) -> str:
    """``text`` of grasps.csv without an unfinished last line (a writer killed mid-write) and
    without the rows of the scene it belonged to: a scene counts only with all its rows. The
    header, line 0, always stays."""
    if not text or text.endswith("\n"):
        return text
    cut = text.rfind("\n") + 1
    lines, fragment = text[:cut].splitlines(keepends=True), text[cut:]
    fragment_id = fragment.split(",")[0]
    last_id = lines[-1].split(",")[0] if len(lines) > 1 else None
    # The fragment names its scene, or it was torn inside the id: then it may be the last scene's.
    torn_id = (
        fragment_id if "," in fragment else last_id if last_id and last_id.startswith(fragment_id) else None
    )
    while len(lines) > 1 and lines[-1].split(",")[0] == torn_id:
        lines.pop()
    return "".join(lines)


def _heal_torn_tail(stream: TextIO) -> None:
    """Cut an unfinished last line and the rows of the scene it belonged to from the file."""
    stream.seek(0)
    text = stream.read()
    whole = _whole_scenes(text)
    if whole != text:
        stream.seek(0)
        stream.truncate()
        stream.write(whole)


def _csv_lines(scene_ids: Iterable[str], rows: np.ndarray) -> str:
    """grasps.csv lines for rows (qx, qy, qz, qw, x, y, z, width, label)."""
    return "".join(
        f"{sid}," + ",".join(f"{v:.6f}" for v in row[:8]) + f",{int(row[8])}\n"
        for sid, row in zip(scene_ids, rows, strict=True)
    )


class RawDataset:
    """A raw dataset folder: create or open, add scenes with their labelled grasps, read back.

    Several processes may add scenes to one folder at once: appends to ``grasps.csv`` are
    single ``write`` calls of whole lines under an exclusive file lock.
    """

    def __init__(self, root: Path, setup: DatasetSetup | None = None) -> None:
        self.root = Path(root)
        self.scenes_dir = self.root / "scenes"
        self.recipes_dir = self.root / "recipes"
        setup_path = self.root / "setup.json"
        if setup_path.exists():
            self.setup = DatasetSetup.from_json(json.loads(setup_path.read_text()))
            if setup is not None and setup != self.setup:
                raise ValueError(
                    f"{self.root} holds a dataset with another setup ({self.setup}); use another folder"
                )
        else:
            if setup is None:
                raise FileNotFoundError(f"{setup_path} does not exist: not a raw VGN dataset")
            self.scenes_dir.mkdir(parents=True, exist_ok=True)
            self.setup = setup
            write_atomically(setup_path, json.dumps(setup.to_json(), indent=2))
        self.grasps_path = self.root / "grasps.csv"
        if not self.grasps_path.exists():
            write_atomically(self.grasps_path, ",".join(GRASP_COLUMNS) + "\n")

    def generation(self) -> dict[str, Any]:
        """The settings the data generator recorded (generation.json), the hand that labelled the
        scenes among them (``gripper``: its version); empty for a dataset made elsewhere."""
        path = self.root / "generation.json"
        return json.loads(path.read_text()) if path.is_file() else {}

    def add_scene(
        self,
        scene_id: str,
        views: SceneViews,
        grasps: np.ndarray,
        recipe: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Store a scene and its grasps: rows (qx, qy, qz, qw, x, y, z, width, label) in the
        workspace frame, and its recipe (``recipes/<id>.npz``: the arrays of
        ``sim_worker.recipes.recipe_arrays``) when given. The files land first; the grasp rows
        make the scene count."""
        if not scene_id.replace("-", "").replace("_", "").isalnum():
            raise ValueError(f"scene id {scene_id!r} must be alphanumeric (with - or _)")
        arrays = {"depth_imgs": views.depth.astype(np.float32), "extrinsics": views.extrinsics()}
        with atomic_writer(self.scenes_dir / f"{scene_id}.npz") as stream:
            np.savez_compressed(stream, **arrays)
        if recipe is not None:
            with atomic_writer(self.recipes_dir / f"{scene_id}.npz") as stream:
                np.savez(stream, **recipe)
        rows = np.asarray(grasps, dtype=np.float64).reshape(-1, 9)
        self._append(_csv_lines([scene_id] * len(rows), rows))

    def mark_empty(self, scene_id: str) -> None:
        """Record a scene that produced no grasps (nothing on the table, nothing seen), so a
        resumed run does not rebuild it."""
        self._append(f"{scene_id}\n", self.root / "empty_scenes.txt")

    def _append(self, text: str, path: Path | None = None) -> None:
        """Append whole lines under an exclusive lock. A torn last line (a writer killed
        mid-write) is cut first, with the rows of its scene, which then counts as not done."""
        import fcntl

        path = path or self.grasps_path
        with path.open("a+") as stream:
            fcntl.flock(stream, fcntl.LOCK_EX)
            try:
                _heal_torn_tail(stream)
                if crash_point(path):  # crash tests: die with half the lines written
                    stream.write(text[: len(text) // 2])
                    stream.flush()
                    crash_now()
                stream.write(text)
                stream.flush()
                os.fsync(stream.fileno())
            finally:
                fcntl.flock(stream, fcntl.LOCK_UN)

    def _rows(self) -> list[list[str]]:
        """Rows of grasps.csv as lists of fields. A torn last line (a writer killed mid-write)
        is skipped with the rest of its scene's rows, as the next append will cut them: else a
        resumed run would take that scene as done and keep it incomplete. Plain lists keep 2 M
        rows affordable."""
        with self.grasps_path.open(newline="") as stream:
            reader = csv.reader(io.StringIO(_whole_scenes(stream.read())))
            next(reader, None)
            return [row for row in reader if len(row) == len(GRASP_COLUMNS) and row[-1]]

    def grasp_rows(self) -> list[dict[str, str]]:
        """Rows of grasps.csv as dicts (convenient for small datasets)."""
        return [dict(zip(GRASP_COLUMNS, row, strict=True)) for row in self._rows()]

    def grasps(self) -> tuple[list[str], np.ndarray]:
        """Scene ids and an (M, 9) array (qx, qy, qz, qw, x, y, z, width, label)."""
        rows = self._rows()
        values = np.array([row[1:] for row in rows], dtype=np.float64).reshape(-1, 9)
        return [row[0] for row in rows], values

    def done_scene_ids(self) -> set[str]:
        """Scenes whose grasps were written, or that came out empty: never generated again."""
        empty_path = self.root / "empty_scenes.txt"
        empty = set(empty_path.read_text().split()) if empty_path.exists() else set()
        return {row[0] for row in self._rows()} | empty

    def scene_ids(self) -> list[str]:
        """Scenes with grasps."""
        return sorted({row[0] for row in self._rows()})

    def read_recipe(self, scene_id: str) -> dict[str, np.ndarray] | None:
        """The arrays of a scene's recipe, or None when the scene was stored without one."""
        path = self.recipes_dir / f"{scene_id}.npz"
        if not path.is_file():
            return None
        with np.load(path) as data:
            return {name: data[name] for name in data.files}

    def read_scene(self, scene_id: str) -> SceneViews:
        """The depth images and camera poses of one scene file."""
        with np.load(self.scenes_dir / f"{scene_id}.npz") as data:
            return SceneViews.from_extrinsics(data["depth_imgs"], data["extrinsics"])


#: VGN's valid grasp region (workspace frame, metres): labels outside it are dropped by cleaning.
VALID_LOWER = (0.02, 0.02, 0.055)
VALID_UPPER = (0.28, 0.28, 0.30)


def clean_and_balance(source: Path, destination: Path, seed: int = 0) -> int:
    """Write a new dataset with the grasps of ``source`` inside the valid region and at most
    as many negatives as positives (surplus negatives dropped at random). Scene files are hard-linked (copied
    where links are impossible); ``source`` is left unchanged. Returns the grasps kept."""
    src = RawDataset(source)
    if Path(destination).resolve() == Path(source).resolve():
        raise ValueError("clean-data writes a new folder: give a destination other than the source")
    dst = RawDataset(destination, src.setup)
    if dst.scene_ids():
        raise ValueError(f"{destination} already holds grasps: choose an empty folder")
    ids, grasps = src.grasps()
    ids = np.asarray(ids)
    inside = np.all((grasps[:, 4:7] >= VALID_LOWER) & (grasps[:, 4:7] <= VALID_UPPER), axis=1)
    ids, grasps = ids[inside], grasps[inside]
    positives, negatives = np.flatnonzero(grasps[:, 8] == 1), np.flatnonzero(grasps[:, 8] == 0)
    rng = np.random.default_rng(seed)
    if len(negatives) > len(positives):
        negatives = rng.choice(negatives, len(positives), replace=False)
    keep = np.sort(np.concatenate([positives, negatives]))
    for sid in sorted(set(ids[keep])):
        target = dst.scenes_dir / f"{sid}.npz"
        if not target.exists():
            try:
                os.link(src.scenes_dir / f"{sid}.npz", target)
            except OSError:
                import shutil

                shutil.copyfile(src.scenes_dir / f"{sid}.npz", target)
    dst._append(_csv_lines(ids[keep], grasps[keep]))
    return len(keep)
