"""Cost of labelling one grasp point (all 6 yaws) on pile scenes, fast vs naive execution.

    python -m benchmarks.labelling [--scenes 4] [--points 30] [--objects DIR ...]

Both executions label the *same* grasp points from the same saved scene states in one
run, so the ratio is fair and the labels can be compared: fast execution must agree with
the naive one (VGN's protocol: dynamic approach, fixed 0.5 s close, full lift). The point
sampling uses the scene's fused surface like data generation, but from the simulator's own
ground truth cloud (no service needed): the benchmark measures physics, not HTTP.
Target: <= 0.25 s per labelled point per core, on average.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial.transform import Rotation

from sim_worker.camera import Camera, random_views
from sim_worker.datagen import MIN_NORMAL_Z, grasp_frame, merged_object_set
from sim_worker.grasping import execute_grasp
from sim_worker.gripper import Gripper
from sim_worker.scenes import generate_scene, poisson_object_count
from sim_worker.world import World


def surface_points(camera: Camera, rng: np.random.Generator, count: int) -> np.ndarray:
    """(count, 6) points with normals on visible surfaces, from a rendered depth image
    (normals from neighbouring pixels), standing in for the service's cloud."""
    pose = random_views(rng, 1)[0]
    depth = camera.render_depth(pose)
    i = camera.intrinsics
    v, u = np.mgrid[0 : i.height, 0 : i.width]
    rays = np.stack([(u - i.cx) / i.fx, (v - i.cy) / i.fy, np.ones(u.shape)], axis=-1)
    points = (rays * depth[..., None]) @ pose[:3, :3].T + pose[:3, 3]
    normals = np.cross(np.gradient(points, axis=1), np.gradient(points, axis=0))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True) + 1e-12
    normals *= -np.sign(
        np.sum(normals * (points - pose[:3, 3]), axis=-1, keepdims=True)
    )  # towards the camera
    valid = (depth > 0) & (normals[..., 2] > MIN_NORMAL_Z) & (points[..., 2] > 0.055)
    cloud = np.concatenate([points, normals], axis=-1)[valid]
    return cloud[rng.integers(len(cloud), size=count)]


def label(
    world: World, gripper: Gripper, state: int, point: np.ndarray, rng_depth: float, fast: bool
) -> tuple[list[int], float, int]:
    """Try the point's six yaws from the saved ``state``: their
    labels, the seconds taken and the simulation steps."""
    normal = point[3:]
    position = point[:3] + normal * rng_depth
    labels, started, steps = [], time.perf_counter(), 0
    for yaw in np.arange(6) * np.pi / 6:
        world.restore_state(state)
        pose = np.eye(4)
        pose[:3, :3] = (grasp_frame(normal) * Rotation.from_euler("z", yaw)).as_matrix()
        pose[:3, 3] = position
        trial = execute_grasp(world, gripper, pose, allow_contact=False, remove_grasped=False, fast=fast)
        labels.append(trial.label)
        steps += trial.sim_steps
    return labels, time.perf_counter() - started, steps


def main() -> None:
    """Label the same points fast and naively, then print the
    costs, the speed-up and how well the labels agree."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scenes", type=int, default=4)
    parser.add_argument("--points", type=int, default=30, help="grasp points per scene")
    parser.add_argument(
        "--objects", action="append", help="object sets or URDF folders (default: pybullet set)"
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    objects = merged_object_set(tuple(args.objects or ()), "pile")
    totals = {True: [0.0, 0], False: [0.0, 0]}
    agree = compared = positives = 0
    with World(renderer="auto") as world:
        gripper, camera = Gripper(world), Camera(world)
        for scene in range(args.scenes):
            rng = np.random.default_rng([args.seed, scene])
            world.clear_objects()
            generate_scene(world, "pile", objects, poisson_object_count(rng), rng)
            points = surface_points(camera, rng, args.points)
            depths = rng.uniform(-0.005, 0.055, size=len(points))
            state = world.save_state()
            for point, depth in zip(points, depths, strict=True):
                results = {}
                for fast in (True, False):
                    labels, seconds, steps = label(world, gripper, state, point, depth, fast)
                    results[fast] = labels
                    totals[fast][0] += seconds
                    totals[fast][1] += steps
                compared += 6
                agree += sum(a == b for a, b in zip(results[True], results[False], strict=True))
                positives += sum(results[False])
            world.discard_state(state)
            print(f"scene {scene}: {len(world.objects)} objects, {len(points)} points", flush=True)

    points = args.scenes * args.points
    fast_s, naive_s = totals[True][0] / points, totals[False][0] / points
    print(
        f"\nobjects: {objects.name} ({len(objects)}), {args.scenes} pile scenes, {points} grasp points x 6 yaws"
    )
    print(f"{'execution':<10} {'s/point':>8} {'steps/point':>12}")
    print(f"{'naive':<10} {naive_s:8.3f} {totals[False][1] / points:12.0f}")
    print(f"{'fast':<10} {fast_s:8.3f} {totals[True][1] / points:12.0f}")
    print(f"speed-up {naive_s / fast_s:.1f}x; trial labels agree {agree}/{compared} ({100 * agree / compared:.1f} %); "
          f"positive trials {positives}/{compared}")  # fmt: skip
    verdict = "PASS" if fast_s <= 0.25 else "MISS"
    print(f"target <= 0.25 s per labelled point per core: {verdict} ({fast_s:.3f} s)")


if __name__ == "__main__":
    main()
