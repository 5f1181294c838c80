"""Make examples/sample_scene.npz: a few recorded depth frames of a simulated table, for the
README's Python example and the tests that run it.

    python examples/make_sample_scene.py [--out examples/sample_scene.npz] [--seed 3] [--views 4]

A pile of the procedural blocks (``sim_worker``'s "blocks" set, no mesh files needed) is dropped
on the simulated table and seen from ``--views`` of VGN's evaluation views (0.6 m from the
workspace centre, 30° from vertical), rendered with PyBullet's CPU TinyRenderer, so the file is the
same on every machine.

The frames are stored as a robot would record them, in a world frame whose origin is on the
table top (the table surface is z = 0), not in the simulator's frame (table top at z = 0.05 m):
the example then has to place the workspace the way a real table needs it (corner 5 cm below
the surface). Contents, compressed with ``np.savez_compressed``:

- ``depth_mm``: (V, H, W) uint16, depth in millimetres (0 = no reading);
- ``intrinsics``: (6,) float64, ``width, height, fx, fy, cx, cy`` in pixels (OpenCV pinhole);
- ``camera_poses``: (V, 4, 4) float64, camera → world (OpenCV optical frame), metres;
- ``table_height``: () float64, z of the table top in that world frame (0.0).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

#: The simulator's table top in its own frame (docs/conventions.md); the file's world frame is
#: the simulator's moved down by this much, so that the table top is z = 0 there.
SIM_TABLE_TOP = 0.05


def render(seed: int, views: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depth (V, H, W) float32 metres, camera → simulator-world poses (V, 4, 4) and intrinsics (6,)
    of a seeded pile of blocks."""
    from sim_worker.camera import SIM_INTRINSICS, Camera, six_views
    from sim_worker.objects import object_set
    from sim_worker.scenes import generate_scene
    from sim_worker.world import World

    world = World(renderer="tiny")
    try:
        generate_scene(world, "blocks", object_set("", "blocks"), 5, np.random.default_rng(seed))
        camera = Camera(world)
        poses = six_views(count=views)  # evenly spaced around the table
        depth = np.stack([camera.render_depth(pose) for pose in poses])
    finally:
        world.close()
    k = SIM_INTRINSICS
    intrinsics = np.array([k.width, k.height, k.fx, k.fy, k.cx, k.cy], dtype=np.float64)
    return depth, np.stack(poses), intrinsics


def main(argv: list[str] | None = None) -> None:
    """Render the scene and write the compressed file."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path(__file__).with_name("sample_scene.npz"))
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--views", type=int, default=4, help="how many of the six views to keep (default 4)")
    args = parser.parse_args(argv)
    depth, poses, intrinsics = render(args.seed, args.views)
    depth_mm = np.round(np.nan_to_num(depth, nan=0.0, posinf=0.0) * 1000.0).clip(0, 65535).astype(np.uint16)
    poses = poses.copy()
    poses[:, 2, 3] -= SIM_TABLE_TOP  # into the frame whose origin is on the table top
    np.savez_compressed(
        args.out, depth_mm=depth_mm, intrinsics=intrinsics, camera_poses=poses, table_height=np.float64(0.0)
    )
    print(f"wrote {args.out}: {len(depth_mm)} frames {depth_mm.shape[2]}x{depth_mm.shape[1]}, "
          f"{args.out.stat().st_size // 1024} KiB")  # fmt: skip


if __name__ == "__main__":
    main()
