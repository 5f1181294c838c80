"""Scene generators: "pile", "packed" and "blocks", as VGN builds them (docs/conventions.md).

Frames and units: positions are world coordinates in metres (the workspace cube's corner
is the world origin, the table top is the plane z = ``TABLE_Z``); orientations are
quaternions ``[x, y, z, w]``. Every random choice is drawn from the ``numpy`` Generator
passed in, in a fixed order, so a seed reproduces a scene exactly in a fresh
:class:`~sim_worker.world.World`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim_worker.objects import ObjectSet
from sim_worker.world import TABLE_Z, World

SCENE_KINDS = ("blocks", "pile", "packed")

# Pile (VGN): drop into a box, then remove the box.
PILE_DROP_Z = 0.25  # world z of the dropped object's origin
PILE_XY_RANGE = (0.1, 0.2)  # world x, y of the drop, uniform
PILE_SCALE_RANGE = (0.8, 1.0)  # × the object set's scale
BOX_INNER = (0.02, 0.28)  # inner faces of the box walls, world x and y
BOX_WALL_THICKNESS = 0.01
BOX_WALL_HEIGHT = 0.15  # above the table: lower than the drop height

# Packed (VGN): upright, random yaw, no collisions at placement.
PACKED_XY_RANGE = (0.08, 0.22)
PACKED_SCALE_RANGE = (0.7, 0.9)
PACKED_CLEARANCE = 0.002  # gap between the object's AABB bottom and the table when placed
PACKED_MIN_GAP = 0.0  # a placement closer than this to another body is rejected


def random_quaternion(rng: np.random.Generator) -> np.ndarray:
    """A rotation drawn uniformly from SO(3), as a unit quaternion [x, y, z, w]."""
    q = rng.normal(size=4)
    while np.linalg.norm(q) < 1e-9:  # measure zero, but never divide by 0
        q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def yaw_quaternion(yaw: float) -> np.ndarray:
    """The rotation by ``yaw`` radians about the world z axis, as [x, y, z, w]."""
    return np.array([0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)])


def poisson_object_count(rng: np.random.Generator, mean: float = 4.0) -> int:
    """Objects per data-generation scene: Poisson(``mean``) + 1, as VGN."""
    return int(rng.poisson(mean)) + 1


# Pile --------------------------------------------------------------------------------------
def create_box(world: World) -> list[int]:
    """Four static walls on the table whose inner faces bound world x, y ∈ ``BOX_INNER``.
    The walls are plain bodies, not scene objects (not in ``world.objects``)."""
    low, high = BOX_INNER
    t, h = BOX_WALL_THICKNESS, BOX_WALL_HEIGHT
    mid, length = (low + high) / 2, high - low + 2 * t
    z = TABLE_Z + h / 2
    walls = [  # (centre, half extents)
        ((low - t / 2, mid, z), (t / 2, length / 2, h / 2)),
        ((high + t / 2, mid, z), (t / 2, length / 2, h / 2)),
        ((mid, low - t / 2, z), (length / 2, t / 2, h / 2)),
        ((mid, high + t / 2, z), (length / 2, t / 2, h / 2)),
    ]
    p = world.p
    bodies = []
    for center, half_extents in walls:
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half_extents)
        bodies.append(p.createMultiBody(0.0, shape, -1, basePosition=center))
    return bodies


def drop_object(world: World, object_set: ObjectSet, rng: np.random.Generator) -> int:
    """Load one random object at z = ``PILE_DROP_Z`` above a random x, y ∈ ``PILE_XY_RANGE``
    with a uniformly random orientation and scale U(0.8, 1.0) × its base scale, then wait
    for the scene to come to rest. Returns the body id."""
    urdf, base_scale = object_set.sample(rng)
    orientation = random_quaternion(rng)
    x, y = rng.uniform(*PILE_XY_RANGE, size=2)
    scale = rng.uniform(*PILE_SCALE_RANGE) * base_scale
    body = world.add_object(urdf, (x, y, PILE_DROP_Z), orientation, scale)
    world.wait_for_rest()
    return body


def generate_pile(world: World, object_set: ObjectSet, count: int, rng: np.random.Generator) -> list[int]:
    """VGN's "pile": drop ``count`` objects one by one into a box on the table, remove the
    box, let the pile settle and remove what left the workspace cube.

    Returns the ids of the dropped bodies still in the world (possibly fewer than
    ``count`` when an object rolled out of the workspace).
    """
    walls = create_box(world)
    bodies = [drop_object(world, object_set, rng) for _ in range(count)]
    for wall in walls:
        world.p.removeBody(wall)
    world.wait_for_rest()
    world.remove_objects_outside()
    return [body for body in bodies if body in world.objects]


# Packed ------------------------------------------------------------------------------------
def place_upright(world: World, urdf: Path, scale: float, x: float, y: float, yaw: float) -> int:
    """Load an object upright (its URDF z axis along world z) rotated by ``yaw`` about z,
    at world x, y, lifted so that its AABB bottom is ``PACKED_CLEARANCE`` above the table.
    No physics step is taken. Returns the body id."""
    orientation = yaw_quaternion(yaw)
    body = world.add_object(urdf, (x, y, TABLE_Z + 0.5), orientation, scale)
    lower, _ = world.aabb(body)
    position, _ = world.object_pose(body)
    position[2] += TABLE_Z + PACKED_CLEARANCE - lower[2]
    world.p.resetBasePositionAndOrientation(body, position.tolist(), orientation.tolist())
    return body


def overlaps(world: World, body: int, gap: float = PACKED_MIN_GAP) -> bool:
    """Whether ``body`` is closer than ``gap`` (metres; 0 = touching or penetrating) to any
    other body in the world except the table."""
    p = world.p
    for index in range(p.getNumBodies()):
        other = p.getBodyUniqueId(index)
        if other in (body, world.table):
            continue
        if p.getClosestPoints(bodyA=body, bodyB=other, distance=gap):
            return True
    return False


def place_packed_object(
    world: World, object_set: ObjectSet, rng: np.random.Generator, max_attempts: int
) -> int | None:
    """Try up to ``max_attempts`` random upright placements (x, y ∈ ``PACKED_XY_RANGE``,
    yaw U(0, 2π), scale U(0.7, 0.9) × base scale) and keep the first that overlaps nothing.
    Returns the body id, or ``None`` when every attempt collided."""
    for _ in range(max_attempts):
        urdf, base_scale = object_set.sample(rng)
        x, y = rng.uniform(*PACKED_XY_RANGE, size=2)
        yaw = rng.uniform(0.0, 2.0 * np.pi)
        scale = rng.uniform(*PACKED_SCALE_RANGE) * base_scale
        body = place_upright(world, urdf, scale, x, y, yaw)
        if not overlaps(world, body):
            return body
        world.remove_object(body)
    return None


def generate_packed(
    world: World, object_set: ObjectSet, count: int, rng: np.random.Generator, max_attempts: int = 12
) -> list[int]:
    """VGN's "packed": ``count`` objects standing upright side by side, each placed where it
    collides with nothing (up to ``max_attempts`` tries per object, skipped after that),
    the scene settled after each placement.

    Returns the ids of the placed bodies still in the world (fewer than ``count`` when the
    table got too crowded or an object fell out of the workspace).
    """
    bodies = []
    for _ in range(count):
        body = place_packed_object(world, object_set, rng, max_attempts)
        if body is not None:
            bodies.append(body)
            world.wait_for_rest()
    world.remove_objects_outside()
    return [body for body in bodies if body in world.objects]


# Dispatch ----------------------------------------------------------------------------------
def generate_scene(
    world: World, kind: str, object_set: ObjectSet, count: int, rng: np.random.Generator
) -> list[int]:
    """Build a scene of ``kind`` ("pile", "packed", or "blocks" = a pile, meant for the
    blocks set as in VGN) in ``world``; returns the ids of the objects in it."""
    if kind in ("pile", "blocks"):
        return generate_pile(world, object_set, count, rng)
    if kind == "packed":
        return generate_packed(world, object_set, count, rng)
    raise ValueError(f"unknown scene kind {kind!r}; expected one of {SCENE_KINDS}")
