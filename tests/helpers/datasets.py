"""Small raw VGN datasets made by ray casting boxes: training and packing tests need real
files in the dataset layout, without a simulator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from tests.helpers.scenes import TABLE_Z, BoxScene, circle_views
from vgn_contract.schemas import Intrinsics
from vgn_data.dataset import DatasetSetup, RawDataset, SceneViews

N = 40
VOXEL = 0.3 / N
#: A small camera keeps the analytic ray casting and the fusion fast.
SMALL = Intrinsics(width=160, height=120, fx=135.0, fy=135.0, cx=79.5, cy=59.5)
TOP_DOWN = Rotation.from_euler("x", np.pi)  # grasp z (approach) pointing down


def scene_grasps(box: BoxScene, rng: np.random.Generator) -> np.ndarray:
    """Rows (qx, qy, qz, qw, x, y, z, width, label): top-down positives over the box, negatives
    in the table and in empty air, and one grasp outside the grid (dropped on load)."""
    centre = (np.asarray(box.lower) + np.asarray(box.upper)) / 2
    rows = []
    for _ in range(3):
        yaw = Rotation.from_euler("z", rng.uniform(0, np.pi))
        position = np.r_[centre[:2] + rng.uniform(-0.01, 0.01, 2), box.upper[2] + 0.01]
        rows.append([*(yaw * TOP_DOWN).as_quat(), *position, 0.06, 1])
    for _ in range(3):
        position = np.r_[rng.uniform(0.02, 0.28, 2), rng.choice([TABLE_Z - 0.02, 0.27])]
        rows.append([*Rotation.random(random_state=rng.integers(1 << 31)).as_quat(), *position, 0.0, 0])
    rows.append([0, 0, 0, 1, 0.35, 0.1, 0.1, 0.04, 1])  # outside the 0.3 m cube
    rows = np.asarray(rows, dtype=np.float64)
    rows[:, 4:7] = np.round(rows[:, 4:7] / VOXEL) * VOXEL  # VGN stores grasps at voxel positions
    return rows


def make_dataset(root: Path, scenes: int, views: int = 2, seed: int = 0) -> RawDataset:
    """A raw dataset of ``scenes`` boxes of random size and place, each seen from ``views`` cameras."""
    dataset = RawDataset(root, DatasetSetup(size=0.3, intrinsics=SMALL))
    rng = np.random.default_rng(seed)
    for n in range(scenes):
        corner = rng.uniform(0.08, 0.16, 2)
        extent = rng.uniform(0.04, 0.08, 3)
        box = BoxScene(lower=(*corner, TABLE_Z), upper=(*(corner + extent[:2]), TABLE_Z + extent[2]))
        poses = circle_views(views, tilt_deg=float(rng.uniform(15, 40)))
        depth = np.stack([box.depth(pose, SMALL) for pose in poses])
        dataset.add_scene(f"scene{n:03d}", SceneViews(depth, np.stack(poses)), scene_grasps(box, rng))
    return dataset
