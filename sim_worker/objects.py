"""Object sets for the simulated scenes: what can be dropped on the table (docs/conventions.md).

An :class:`ObjectSet` is a list of URDFs (one rigid object each) plus the scale that the
scene generators multiply their random scale by. Three sources: :func:`blocks_set`
(geometric primitives generated here, scaled by 1.67 as VGN's "blocks" scenes do),
:func:`pybullet_data_set` (the rigid objects of ``pybullet_data`` that fit the gripper,
vetted once and cached) and :func:`urdf_folder_set` (any folder of URDFs in the VGN layout).

All lengths are metres, masses kilograms. Object frames are the URDF's link frame; for the
generated blocks it is the centre of mass, with z up in the upright pose of packed scenes.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from vgn_data.files import write_atomically

if TYPE_CHECKING:
    from pybullet_utils.bullet_client import BulletClient

#: VGN's global scale for its block set (``{"blocks": 1.67}`` in its simulation).
BLOCKS_SCALE = 1.67
#: An object is graspable when some horizontal extent is at most this: a margin under the
#: ``franka`` hand's 0.08 m opening (vgn_contract/grippers/franka.json), which the object sets are sized for.
MAX_GRASP_EXTENT = 0.07
#: Named pybullet_data objects that are too wide are scaled down to this horizontal extent.
RESCALE_TARGET = 0.065
#: Every extent of a kept pybullet_data object lies in [MIN_EXTENT, MAX_EXTENT].
MIN_EXTENT = 0.02
MAX_EXTENT = 0.25
#: Heavier objects cannot be lifted by two fingers at ~20 N and friction 1 with margin.
MAX_MASS = 1.0

#: Block density (kg/m³): light wood, as VGN's blocks (a 3 cm cube of 20 g).
BLOCK_DENSITY = 700.0
#: Rolling and spinning friction of the blocks (Bullet's coefficient, metres). VGN's blocks
#: have none, so a cylinder still rolling below the "at rest" speed rolls off the table once
#: the pile's box is removed; 1 mm stops it within millimetres and barely changes grasping.
BLOCK_ROLLING_FRICTION = 0.001


@dataclass
class ObjectSet:
    """A named list of object URDFs.

    ``scale_factor`` multiplies the scale that scene generators draw (VGN: 1.67 for blocks,
    1.0 otherwise); ``object_scales`` (same length as ``urdfs``, or empty for all 1.0) is an
    extra per-object factor that makes an oversized object fit the gripper.
    """

    name: str
    urdfs: list[Path]
    scale_factor: float = 1.0
    object_scales: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.urdfs = [Path(urdf) for urdf in self.urdfs]
        if not self.urdfs:
            raise ValueError(f"object set {self.name!r} is empty")
        if self.object_scales and len(self.object_scales) != len(self.urdfs):
            raise ValueError("object_scales must have one entry per URDF")

    def __len__(self) -> int:
        return len(self.urdfs)

    def base_scale(self, index: int) -> float:
        """``scale_factor`` × the per-object scale of ``urdfs[index]``."""
        extra = self.object_scales[index] if self.object_scales else 1.0
        return self.scale_factor * extra

    def sample(self, rng: np.random.Generator) -> tuple[Path, float]:
        """One URDF drawn uniformly, with its base scale (see :meth:`base_scale`)."""
        index = int(rng.integers(len(self.urdfs)))
        return self.urdfs[index], self.base_scale(index)


# Cache and atomic writes ---------------------------------------------------------------------
def default_cache_dir() -> Path:
    """``$VGN_CACHE_DIR``, else ``$XDG_CACHE_HOME/vgn-service`` (``~/.cache/vgn-service``);
    a per-user folder under the temp directory when that is not writable."""
    if os.environ.get("VGN_CACHE_DIR"):
        return Path(os.environ["VGN_CACHE_DIR"])
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "vgn-service"
    try:
        base.mkdir(parents=True, exist_ok=True)
        if os.access(base, os.W_OK):
            return base
    except OSError:
        pass
    user = os.getuid() if hasattr(os, "getuid") else os.environ.get("USERNAME", "user")
    return Path(tempfile.gettempdir()) / f"vgn-service-{user}"


def write_atomic(path: Path, text: str) -> bool:
    """Write ``text`` to ``path`` via a temp file + rename, unless it already holds exactly
    that text. Returns whether the file was (re)written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        if path.read_text() == text:
            return False
    except (OSError, UnicodeDecodeError):
        pass
    write_atomically(path, text)
    return True


# Blocks --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Box:
    """A box of full side lengths ``size`` (x, y, z) centred at ``center`` (block parts are
    shifted together so that the block's centre of mass is its link origin)."""

    size: tuple[float, float, float]
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Cylinder:
    """A cylinder along z, centred at the origin."""

    radius: float
    length: float


@dataclass(frozen=True)
class Prism:
    """A convex polygon (counter-clockwise xy vertices) extruded along z by ``length``."""

    polygon: tuple[tuple[float, float], ...]
    length: float


@dataclass(frozen=True)
class Block:
    """A procedural block: its parts (boxes, or one cylinder or prism) and colour, before scaling."""

    name: str
    parts: tuple[Box, ...] | Cylinder | Prism
    rgba: tuple[float, float, float, float]


def _regular_polygon(sides: int, across_flats: float) -> tuple[tuple[float, float], ...]:
    radius = across_flats / 2 / np.cos(np.pi / sides)
    angles = np.pi / sides + 2 * np.pi * np.arange(sides) / sides
    return tuple((float(radius * np.cos(a)), float(radius * np.sin(a))) for a in angles)


#: The generated blocks, sizes before scaling (× 1.67 × U(0.8, 1.0) in scenes, so every
#: block has a dimension of at most 0.04 × 1.67 = 0.067 m across which it can be grasped).
#: z is the upright axis; every block is stable standing on its z-bottom.
BLOCKS: tuple[Block, ...] = (
    Block("cube", (Box((0.03, 0.03, 0.03)),), (0.85, 0.25, 0.2, 1.0)),
    Block("cuboid", (Box((0.025, 0.035, 0.05)),), (0.2, 0.45, 0.85, 1.0)),
    Block("cylinder", Cylinder(radius=0.015, length=0.05), (0.2, 0.7, 0.3, 1.0)),
    Block("disc", Cylinder(radius=0.02, length=0.018), (0.9, 0.75, 0.2, 1.0)),
    Block("triangular_prism", Prism(((0.0, 0.0), (0.04, 0.0), (0.0, 0.04)), 0.025), (0.6, 0.3, 0.75, 1.0)),
    Block("hexagonal_prism", Prism(_regular_polygon(6, 0.03), 0.04), (0.95, 0.5, 0.15, 1.0)),
    # An "L": a 5 cm bar with a 2.5 cm post on one end (two boxes: not convex).
    Block(
        "ell",
        (Box((0.05, 0.02, 0.02), (0.0, 0.0, 0.01)), Box((0.02, 0.02, 0.025), (-0.015, 0.0, 0.0325))),
        (0.3, 0.75, 0.8, 1.0),
    ),
)


def _prism_mesh(prism: Prism) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and outward counter-clockwise triangles (F, 3) of a prism."""
    polygon = np.asarray(prism.polygon, dtype=float)
    n = len(polygon)
    half = prism.length / 2
    vertices = np.vstack([np.c_[polygon, np.full(n, -half)], np.c_[polygon, np.full(n, half)]])
    faces = []
    for i in range(1, n - 1):
        faces.append((0, i + 1, i))  # bottom, facing -z
        faces.append((n, n + i, n + i + 1))  # top, facing +z
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, j, n + j), (i, n + j, n + i)]
    return vertices, np.asarray(faces)


def mesh_mass_properties(
    vertices: np.ndarray, faces: np.ndarray, density: float
) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, centre of mass (3,) and inertia tensor (3, 3) about the centre of mass of a
    closed, outward-oriented triangle mesh (sum of signed tetrahedra from the origin)."""
    canonical = np.array([[2.0, 1.0, 1.0], [1.0, 2.0, 1.0], [1.0, 1.0, 2.0]]) / 120.0
    volume, moment, covariance = 0.0, np.zeros(3), np.zeros((3, 3))
    for face in faces:
        a = vertices[face].T  # columns: the triangle's corners
        det = float(np.linalg.det(a))
        volume += det / 6.0
        moment += det / 6.0 * a.sum(axis=1) / 4.0
        covariance += det * a @ canonical @ a.T
    com = moment / volume
    covariance = density * (covariance - volume * np.outer(com, com))
    inertia = np.trace(covariance) * np.eye(3) - covariance
    inertia[np.abs(inertia) < 1e-12 * np.abs(inertia).max()] = 0.0  # round-off
    return density * volume, com, inertia


def shifted_inertia(mass: float, inertia: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """A part's inertia tensor (about its own centre of mass) about a point ``offset`` away from it:
    the parallel-axis rule, for bodies made of several parts."""
    return inertia + mass * (offset @ offset * np.eye(3) - np.outer(offset, offset))


def _box_inertia(mass: float, size: Sequence[float]) -> np.ndarray:
    x, y, z = size
    return mass / 12.0 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])


def obj_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    """Wavefront OBJ text of a triangle mesh, one flat normal per face."""
    lines = ["# generated by vgn-service sim_worker/objects.py"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    for k, (a, b, c) in enumerate(faces, start=1):
        normal = np.cross(vertices[b] - vertices[a], vertices[c] - vertices[a])
        normal /= np.linalg.norm(normal)
        lines.append(f"vn {normal[0]:.6f} {normal[1]:.6f} {normal[2]:.6f}")
        lines.append(f"f {a + 1}//{k} {b + 1}//{k} {c + 1}//{k}")
    return "\n".join(lines) + "\n"


def _fmt(values: Sequence[float]) -> str:
    return " ".join(f"{v:.6g}" for v in values)


def _geometry_xml(block: Block) -> tuple[list[tuple[str, np.ndarray]], float, np.ndarray]:
    """Geometry elements with their origins (shifted so the link origin is the centre of
    mass), the mass, and the inertia tensor about the centre of mass."""
    shape = block.parts
    if isinstance(shape, Cylinder):
        mass = BLOCK_DENSITY * np.pi * shape.radius**2 * shape.length
        side = mass * (3 * shape.radius**2 + shape.length**2) / 12.0
        inertia = np.diag([side, side, mass * shape.radius**2 / 2.0])
        return (
            [(f'<cylinder radius="{shape.radius:.6g}" length="{shape.length:.6g}"/>', np.zeros(3))],
            mass,
            inertia,
        )
    if isinstance(shape, Prism):
        mass, _, inertia = mesh_mass_properties(*_prism_mesh(shape), BLOCK_DENSITY)
        return [(f'<mesh filename="{block.name}.obj"/>', np.zeros(3))], mass, inertia
    masses = np.array([BLOCK_DENSITY * float(np.prod(box.size)) for box in shape])
    centers = np.array([box.center for box in shape], dtype=float)
    centers -= masses @ centers / masses.sum()
    inertia = np.zeros((3, 3))
    for m, box, c in zip(masses, shape, centers, strict=True):
        inertia += shifted_inertia(m, _box_inertia(m, box.size), c)
    elements = [(f'<box size="{_fmt(box.size)}"/>', c) for box, c in zip(shape, centers, strict=True)]
    return elements, float(masses.sum()), inertia


def block_urdf(block: Block) -> str:
    """URDF text of a block: primitive (or prism mesh) geometry, mass from ``BLOCK_DENSITY``."""
    elements, mass, inertia = _geometry_xml(block)
    return rigid_urdf(block.name, block.rgba, elements, mass, inertia)


def rigid_urdf(
    name: str,
    rgba: Sequence[float],
    elements: Sequence[tuple[str, np.ndarray]],
    mass: float,
    inertia: np.ndarray,
) -> str:
    """URDF text of one rigid link whose origin is its centre of mass: each geometry element (at its
    origin) is both visual and collision, friction 1.0 as VGN's objects, a little rolling friction
    (see ``BLOCK_ROLLING_FRICTION``)."""
    r, g, b, a = rgba
    geometry = []
    for element, center in elements:
        origin = f'<origin xyz="{_fmt(np.asarray(center) + 0.0)}" rpy="0 0 0"/>'
        geometry.append(
            f"    <visual>\n      {origin}\n      <geometry>{element}</geometry>\n"
            f'      <material name="{name}"><color rgba="{r} {g} {b} {a}"/></material>\n    </visual>\n'
            f"    <collision>\n      {origin}\n      <geometry>{element}</geometry>\n    </collision>\n"
        )
    i = inertia
    return (
        '<?xml version="1.0"?>\n'
        f'<robot name="{name}">\n  <link name="base_link">\n'
        '    <contact>\n      <lateral_friction value="1.0"/>\n'
        f'      <rolling_friction value="{BLOCK_ROLLING_FRICTION}"/>\n'
        f'      <spinning_friction value="{BLOCK_ROLLING_FRICTION}"/>\n'
        '      <contact_cfm value="0.0"/>\n      <contact_erp value="1.0"/>\n    </contact>\n'
        f'    <inertial>\n      <origin xyz="0 0 0" rpy="0 0 0"/>\n      <mass value="{mass:.6g}"/>\n'
        f'      <inertia ixx="{i[0, 0]:.6g}" ixy="{i[0, 1]:.6g}" ixz="{i[0, 2]:.6g}" '
        f'iyy="{i[1, 1]:.6g}" iyz="{i[1, 2]:.6g}" izz="{i[2, 2]:.6g}"/>\n    </inertial>\n'
        + "".join(geometry)
        + "  </link>\n</robot>\n"
    )


def _centred_prism_mesh(prism: Prism) -> tuple[np.ndarray, np.ndarray]:
    vertices, faces = _prism_mesh(prism)
    _, com, _ = mesh_mass_properties(vertices, faces, 1.0)
    return vertices - com, faces


def write_blocks(directory: Path) -> list[Path]:
    """Write every block's URDF (and prism OBJ) into ``directory``, atomically, skipping
    files that already hold the right content. Returns the URDF paths, in ``BLOCKS`` order."""
    urdfs = []
    for block in BLOCKS:
        if isinstance(block.parts, Prism):
            vertices, faces = _centred_prism_mesh(block.parts)
            # Meshes first, so a URDF never points at a missing mesh.
            write_atomic(directory / f"{block.name}.obj", obj_text(vertices, faces))
        path = directory / f"{block.name}.urdf"
        write_atomic(path, block_urdf(block))
        urdfs.append(path)
    return urdfs


def blocks_set(cache_dir: Path | None = None) -> ObjectSet:
    """The generated blocks (see ``BLOCKS``), written to ``cache_dir`` (default
    ``default_cache_dir() / "blocks"``) when missing or stale, reused otherwise."""
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir() / "blocks"
    return ObjectSet("blocks", write_blocks(directory), scale_factor=BLOCKS_SCALE)


# pybullet_data ---------------------------------------------------------------------------------
#: Named single-link objects of pybullet_data worth trying (relative to its data path); these
#: may be scaled down to fit the gripper. ``random_urdfs/*/*.urdf`` (1000 random blobs, 0.1 kg)
#: are also tried, but only kept at their own scale, so the set's sizes stay varied.
#:
#: With pybullet 3.2.7 the vetting keeps 341 objects (about 3 s, then cached):
#:
#: - cube_small (5 cm cube), sphere_small (6 cm ball), lego (3.4 × 3.4 × 2.5 cm brick),
#:   jenga (15 × 5 × 3 cm block) at scale 1; duck_vhacd (× 0.76), teddy_vhacd (× 0.77) and
#:   objects/mug (× 0.74, 1 kg) shrunk so their narrower horizontal side is 6.5 cm;
#: - 334 of the 1000 random blobs (654 are wider than 7 cm both ways, 12 smaller than 2 cm).
#:
#: Skipped: block (1.8 cm thin rod), domino (6 mm thick), sphere_1cm (1 cm), soccerball
#: (10 kg). Robots, planes, trays, tables and the soft-body torus were never candidates.
PYBULLET_NAMED = (
    "block.urdf",
    "cube_small.urdf",
    "domino/domino.urdf",
    "duck_vhacd.urdf",
    "jenga/jenga.urdf",
    "lego/lego.urdf",
    "objects/mug.urdf",
    "soccerball.urdf",
    "sphere_1cm.urdf",
    "sphere_small.urdf",
    "teddy_vhacd.urdf",
)
PYBULLET_RANDOM_GLOB = "random_urdfs/*/*.urdf"
#: Bump when the vetting rules change, so caches are rebuilt.
_VETTING_VERSION = 1


@dataclass(frozen=True)
class VettedObject:
    """A pybullet_data candidate: ``urdf`` relative to the data path, the ``scale`` it is
    kept at (1.0 unless it was shrunk), its AABB ``extents`` at scale 1 (x, y, z, metres),
    and ``reason`` it was skipped (``None`` when kept)."""

    urdf: str
    scale: float
    extents: tuple[float, float, float] | None
    reason: str | None = None


def _measure(p: BulletClient, path: Path) -> tuple[tuple[float, float, float] | None, float, str | None]:
    """AABB extents and mass of a URDF loaded at scale 1, or the reason it is unusable."""
    try:
        body = p.loadURDF(str(path))
    except Exception:  # pybullet raises a bare error for unparsable files and missing meshes
        return None, 0.0, "does not load"
    try:
        if p.getNumJoints(body) > 0:
            return None, 0.0, "articulated (has joints)"
        if not p.getCollisionShapeData(body, -1):
            return None, 0.0, "no collision shape"
        mass = float(p.getDynamicsInfo(body, -1)[0])
        lower, upper = p.getAABB(body)
        extents = np.subtract(upper, lower)
        if not np.all(np.isfinite(extents)) or extents.min() < 1e-3:
            return None, mass, "empty or degenerate mesh"
        return (float(extents[0]), float(extents[1]), float(extents[2])), mass, None
    finally:
        p.removeBody(body)


def _fit(extents: tuple[float, float, float], mass: float, rescale: bool) -> tuple[float, str | None]:
    """The scale at which an object fits the gripper, or why it cannot."""
    if mass <= 0.0:
        return 1.0, "static (mass 0)"
    if mass > MAX_MASS:
        return 1.0, f"too heavy ({mass:g} kg > {MAX_MASS:g} kg)"
    horizontal = min(extents[0], extents[1])
    scale = 1.0
    if rescale:
        scale = min(1.0, RESCALE_TARGET / horizontal, MAX_EXTENT / max(extents))
    sized = np.asarray(extents) * scale
    if min(sized[0], sized[1]) > MAX_GRASP_EXTENT:
        return scale, f"too wide for the gripper (smallest horizontal extent {horizontal:.3f} m)"
    if sized.min() < MIN_EXTENT:
        return scale, f"too thin or small (smallest extent {sized.min():.3f} m at scale {scale:.2f})"
    if sized.max() > MAX_EXTENT:
        return scale, f"too large (largest extent {sized.max():.3f} m)"
    return round(scale, 4), None


def vet_pybullet_data(data_path: Path | None = None) -> list[VettedObject]:
    """Load every candidate in a scratch DIRECT client and decide whether it fits the gripper.

    Kept: single-link bodies with a collision shape, 0 < mass ≤ ``MAX_MASS`` kg, whose
    smallest horizontal AABB extent is ≤ ``MAX_GRASP_EXTENT`` and whose extents all lie in
    [``MIN_EXTENT``, ``MAX_EXTENT``] at the kept scale. Named objects that are too wide are
    shrunk to ``RESCALE_TARGET``. Takes a few seconds, hence the cache."""
    import pybullet
    import pybullet_data

    from sim_worker.world import QuietBulletClient

    root = Path(data_path or pybullet_data.getDataPath())
    candidates = [(name, True) for name in PYBULLET_NAMED if (root / name).exists()]
    candidates += [
        (path.relative_to(root).as_posix(), False) for path in sorted(root.glob(PYBULLET_RANDOM_GLOB))
    ]
    p = QuietBulletClient(pybullet.DIRECT)  # connecting prints to stdout
    try:
        vetted = []
        for name, rescale in candidates:
            extents, mass, reason = _measure(p, root / name)
            scale = 1.0
            if reason is None:
                scale, reason = _fit(extents, mass, rescale)
            vetted.append(VettedObject(name, scale, extents, reason))
        return vetted
    finally:
        p.disconnect()


def _vetting_key(root: Path) -> dict:
    import pybullet

    return {"version": _VETTING_VERSION, "data_path": str(root), "pybullet_api": pybullet.getAPIVersion()}


def pybullet_data_set(cache_dir: Path | None = None) -> ObjectSet:
    """The objects shipped with ``pybullet_data`` that fit the gripper (see
    :func:`vet_pybullet_data`), with their per-object scales.

    The vetted list is cached as JSON in ``cache_dir`` (default :func:`default_cache_dir`),
    keyed by the data path and pybullet's API version.
    """
    import pybullet_data

    root = Path(pybullet_data.getDataPath())
    cache = Path(cache_dir or default_cache_dir()) / "pybullet_data_set.json"
    key = _vetting_key(root)
    vetted = None
    try:
        stored = json.loads(cache.read_text())
        if stored.get("key") == key:
            vetted = [
                VettedObject(o["urdf"], o["scale"], tuple(o["extents"] or ()) or None, o["reason"])
                for o in stored["objects"]
            ]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    if vetted is None:
        vetted = vet_pybullet_data(root)
        objects = [
            {"urdf": o.urdf, "scale": o.scale, "extents": o.extents, "reason": o.reason} for o in vetted
        ]
        write_atomic(cache, json.dumps({"key": key, "objects": objects}, indent=1) + "\n")
    kept = [o for o in vetted if o.reason is None]
    return ObjectSet("pybullet", [root / o.urdf for o in kept], 1.0, [o.scale for o in kept])


# Folders and names ----------------------------------------------------------------------------
def urdf_folder_set(path: Path, scale_factor: float = 1.0) -> ObjectSet:
    """Every ``*.urdf`` in ``path`` (VGN layout: one URDF per object, meshes beside it), or
    in its immediate subfolders when it has none at the top, sorted for reproducibility."""
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"object folder {path} does not exist or is not a directory")
    urdfs = sorted(path.glob("*.urdf")) or sorted(path.glob("*/*.urdf"))
    if not urdfs:
        raise ValueError(f"object folder {path} holds no .urdf files (expected one URDF per object)")
    return ObjectSet(path.name, urdfs, scale_factor)


#: Default object set per scene kind, as the CLIs use it.
DEFAULT_OBJECT_SET = {"blocks": "blocks", "pile": "pybullet", "packed": "pybullet"}


def object_set(name_or_dir: str | Path | None, scene: str) -> ObjectSet:
    """Resolve ``--objects``: ``"blocks"``, ``"shapes"`` (generated, ``sim_worker.shapes``),
    ``"pybullet"`` (the pybullet_data set) or a folder of URDFs; ``None`` or ``""`` picks the default for ``scene`` (blocks for
    "blocks", the pybullet_data set for "pile" and "packed"). A folder named ``blocks``
    gets VGN's block scale 1.67, as VGN does for its ``blocks`` folder."""
    if scene not in DEFAULT_OBJECT_SET:
        raise ValueError(f"unknown scene {scene!r}; expected one of {sorted(DEFAULT_OBJECT_SET)}")
    name = str(name_or_dir) if name_or_dir else DEFAULT_OBJECT_SET[scene]
    if name == "blocks":
        return blocks_set()
    if name == "shapes":
        from sim_worker.shapes import shapes_set

        return shapes_set()
    if name == "pybullet":
        return pybullet_data_set()
    path = Path(name).expanduser()
    if not path.is_dir():
        raise ValueError(
            f"--objects {name!r} is neither 'blocks', 'shapes', 'pybullet' nor a folder of URDFs"
        )
    return urdf_folder_set(path, BLOCKS_SCALE if path.resolve().name == "blocks" else 1.0)
