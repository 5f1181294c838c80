"""Generated shapes: a source of training objects that is neither VGN's meshes nor pybullet_data's.

A network trained on one family of meshes learns that family; shapes drawn here from a seed
(boxy, round and pointed solids, random polytopes, flat plates, and two- or three-part bodies
such as ells, tees, handles and dumbbells) widen what it sees. Every part is convex, so each is its
own collision mesh and no decomposition is needed. Masses follow a plausible density
(:data:`DENSITY_RANGE`), unlike some URDF masses of VGN's sets (docs/slips.md).

The set is a pure function of its index and :data:`SHAPES_VERSION`: a recipe naming
``shapes:shape_0042.urdf`` is rebuilt on any machine by writing the set again, and the files'
sha256 in the recipe proves it is the same shape. Sizes are metres before a scene's scale.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from sim_worker.objects import (
    MAX_GRASP_EXTENT,
    ObjectSet,
    default_cache_dir,
    mesh_mass_properties,
    obj_text,
    rigid_urdf,
    shifted_inertia,
    write_atomic,
)

#: Bump when any rule below changes: recipes made with other shapes are then refused by hash.
SHAPES_VERSION = 1
#: How many shapes the set holds.
SHAPE_COUNT = 400
#: Household objects: packaging, plastics and wood (kg/m³, solid bodies).
DENSITY_RANGE = (150.0, 900.0)
#: Every extent of a shape lies in this range (m); its smallest is at most MAX_GRASP_EXTENT.
EXTENT_RANGE = (0.02, 0.16)
#: Surface samples per convex part (longitude × latitude) before the hull.
_SAMPLES = (20, 12)
FAMILIES = ("solid", "polytope", "flat", "compound")


@dataclass(frozen=True)
class Part:
    """A convex part: hull vertices (V, 3) and outward triangles (F, 3) in the shape's frame."""

    vertices: np.ndarray
    faces: np.ndarray


def _hull(points: np.ndarray) -> Part:
    """The convex hull of ``points`` with its triangles turned outward."""
    hull = ConvexHull(points)
    used = np.unique(hull.simplices)
    index = np.full(len(points), -1)
    index[used] = np.arange(len(used))
    vertices, faces = points[used], index[hull.simplices]
    centre = vertices.mean(axis=0)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a - centre) > 0
    faces[~outward] = faces[~outward][:, [0, 2, 1]]
    return Part(vertices, faces)


def _superquadric(half: np.ndarray, e_lat: float, e_lon: float) -> np.ndarray:
    """Surface points of a superellipsoid with half extents ``half``: exponents near 0 give a box,
    1 an ellipsoid, 2 a double pyramid (convex for exponents up to 2)."""
    lon = np.linspace(-np.pi, np.pi, _SAMPLES[0], endpoint=False)
    lat = np.linspace(-np.pi / 2, np.pi / 2, _SAMPLES[1])
    lat, lon = np.meshgrid(lat, lon)

    def power(x: np.ndarray, e: float) -> np.ndarray:
        return np.sign(x) * np.abs(x) ** e

    x = power(np.cos(lat), e_lat) * power(np.cos(lon), e_lon)
    y = power(np.cos(lat), e_lat) * power(np.sin(lon), e_lon)
    z = power(np.sin(lat), e_lat)
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()]) * half


def _solid(rng: np.random.Generator, half: np.ndarray, pointed: bool = True) -> Part:
    """A superellipsoid; ``pointed`` allows exponents above 1 (ridges and tips)."""
    lat = [0.1, 0.3, 0.6, 1.0, 1.5] if pointed else [0.1, 0.3, 0.6]
    lon = [0.1, 0.4, 1.0, 1.6] if pointed else [0.1, 0.4, 1.0]
    return _hull(_superquadric(half, rng.choice(lat), rng.choice(lon)))


def _polytope(rng: np.random.Generator, half: np.ndarray) -> Part:
    """A random polytope: the hull of points on the box's faces, at least one on each face, so it
    keeps the box's extents."""
    count = int(rng.integers(8, 24))
    points = rng.uniform(-1.0, 1.0, size=(count, 3))
    axis = np.r_[0, 0, 1, 1, 2, 2, rng.integers(3, size=count - 6)]
    sign = np.r_[-1.0, 1.0, -1.0, 1.0, -1.0, 1.0, rng.choice([-1.0, 1.0], size=count - 6)]
    points[np.arange(count), axis] = sign
    return _hull(points * half)


def _extents(rng: np.random.Generator, thin: tuple[float, float]) -> np.ndarray:
    """Full extents: one at most the hand's grasp limit, the others up to the largest extent."""
    narrow = rng.uniform(*thin)
    others = rng.uniform(max(narrow, EXTENT_RANGE[0]), EXTENT_RANGE[1], size=2)
    return rng.permutation(np.r_[narrow, others])


def _compound(rng: np.random.Generator) -> list[Part]:
    """Two or three convex parts that touch: a bar with a post (ell or tee), a body with a handle, or
    two knobs on a bar (dumbbell)."""
    kind = rng.choice(["ell", "tee", "handle", "dumbbell"])
    bar = np.array([rng.uniform(0.07, 0.14), rng.uniform(0.02, 0.045), rng.uniform(0.02, 0.045)]) / 2
    parts = [_solid(rng, bar)]
    if kind in ("ell", "tee"):
        post = np.array([rng.uniform(0.02, 0.04), bar[1] * 2, rng.uniform(0.03, 0.07)]) / 2
        x = bar[0] - post[0] if kind == "ell" else 0.0
        on_top = _solid(rng, post)
        parts.append(Part(on_top.vertices + [x, 0.0, bar[2] + post[2] * 0.9], on_top.faces))
    elif kind == "handle":
        body = np.array([rng.uniform(0.025, 0.035)] * 2 + [rng.uniform(0.03, 0.06)])
        grip = np.array([rng.uniform(0.012, 0.02), 0.008, body[2] * 0.7])
        parts = [
            _solid(rng, body),
            _hull(_superquadric(grip, 0.3, 0.3) + [body[0] + grip[0] * 0.8, 0.0, 0.0]),
        ]
    else:
        knob = np.full(3, rng.uniform(0.02, 0.03))
        for side in (-1.0, 1.0):
            parts.append(_hull(_superquadric(knob, 1.0, 1.0) + [side * bar[0], 0.0, 0.0]))
    return parts


def shape_parts(index: int) -> tuple[str, list[Part]]:
    """The family and convex parts of shape ``index`` (deterministic)."""
    rng = np.random.default_rng([SHAPES_VERSION, index])
    family = FAMILIES[index % len(FAMILIES)]
    if family == "solid":
        return family, [_solid(rng, _extents(rng, (0.025, MAX_GRASP_EXTENT - 0.01)) / 2)]
    if family == "polytope":
        return family, [_polytope(rng, _extents(rng, (0.025, MAX_GRASP_EXTENT - 0.01)) / 2)]
    if family == "flat":  # 1.2-2.5 cm thick: staplers, packs and bars are what piles leave behind
        half = np.r_[rng.uniform(0.05, 0.14), rng.uniform(0.04, 0.10), rng.uniform(0.012, 0.025)] / 2
        # Rounded or boxy edges: a knife-thin rim is not what a pack or a bar has.
        return family, [_polytope(rng, half) if rng.random() < 0.3 else _solid(rng, half, pointed=False)]
    return family, _compound(rng)


def shape_urdf(index: int, directory: Path) -> Path:
    """Write shape ``index``'s meshes and URDF into ``directory`` (meshes first, so a URDF never
    names a missing file); the link origin is the centre of mass."""
    name = f"shape_{index:04d}"
    family, parts = shape_parts(index)
    rng = np.random.default_rng([SHAPES_VERSION, index, 1])
    density = rng.uniform(*DENSITY_RANGE)
    properties = [mesh_mass_properties(p.vertices, p.faces, density) for p in parts]
    masses = np.array([m for m, _, _ in properties])
    com = sum(m * c for m, c, _ in properties) / masses.sum()
    inertia = sum(shifted_inertia(m, own, c - com) for m, c, own in properties)
    elements = []
    for k, part in enumerate(parts):
        mesh = f"{name}_{k}.obj"
        write_atomic(directory / mesh, obj_text(part.vertices - com, part.faces))
        elements.append((f'<mesh filename="{mesh}"/>', np.zeros(3)))
    rgba = (*np.round(rng.uniform(0.15, 0.95, size=3), 3), 1.0)
    path = directory / f"{name}.urdf"
    write_atomic(path, rigid_urdf(name, rgba, elements, float(masses.sum()), inertia))
    return path


def write_shapes(directory: Path, count: int = SHAPE_COUNT) -> list[Path]:
    """Write the first ``count`` shapes into ``directory`` (files already right are left alone)."""
    directory = Path(directory)
    stamp = directory / "VERSION"
    if stamp.exists() and stamp.read_text().strip() == f"{SHAPES_VERSION} {count}":
        return [directory / f"shape_{i:04d}.urdf" for i in range(count)]
    paths = [shape_urdf(i, directory) for i in range(count)]
    write_atomic(stamp, f"{SHAPES_VERSION} {count}\n")
    return paths


def shapes_set(cache_dir: Path | None = None, count: int = SHAPE_COUNT) -> ObjectSet:
    """The first ``count`` generated shapes, written to ``cache_dir`` (default
    ``default_cache_dir() / "shapes"``) when missing or made by another version, reused otherwise."""
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir() / "shapes"
    return ObjectSet("shapes", write_shapes(directory, count))
