"""Record the network inputs of a few simulated cluttered scenes for the fast-inference
agreement test (``tests/service/test_fast_inference.py``) and the batching test, which
read them through ``tests/helpers/grids.py``.

    PYTHONPATH=. python -m tests.data.record_grids --out tests/data/recorded_grids.npz

Each grid is a 40³ TSDF fused (by the service's ``TSDFVolume``) from VGN's six views of a
pile or packed scene built by the simulator, so the test sees real clutter, not analytic
boxes. The grids are stored as float16 (the TSDF values need no more) in one compressed
``.npz``; regenerating them with the same seeds gives the same scenes.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from service.tsdf import TSDFVolume
from sim_worker.camera import Camera, six_views
from sim_worker.objects import object_set
from sim_worker.scenes import generate_scene
from sim_worker.world import World

SIZE, RESOLUTION = 0.3, 40
SCENES = (
    ("pile", "pybullet", 5, 1),
    ("packed", "pybullet", 4, 2),
    ("pile", "blocks", 6, 3),
    ("packed", "pybullet", 5, 4),
)


def record(kind: str, objects: str, count: int, seed: int) -> np.ndarray:
    """The fused grid of one scene."""
    rng = np.random.default_rng(seed)
    with World(renderer="tiny") as world:
        generate_scene(world, kind, object_set(objects, kind), count, rng)
        camera = Camera(world)
        volume = TSDFVolume(SIZE, RESOLUTION)
        for pose in six_views():
            volume.integrate(camera.render_depth(pose), camera.intrinsics, pose, 2.0)
        return volume.grid()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "recorded_grids.npz")
    args = parser.parse_args()
    grids = np.stack([record(*scene) for scene in SCENES]).astype(np.float16)
    names = np.array([f"{kind}-{objects}-{count}-seed{seed}" for kind, objects, count, seed in SCENES])
    np.savez_compressed(args.out, grids=grids, names=names)
    print(f"{args.out}: {grids.shape}, {args.out.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
