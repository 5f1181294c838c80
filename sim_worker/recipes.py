"""Scene recipes: what a labelled scene *is* (its objects and their settled poses), not what one
camera happened to see of it.

A recipe keeps the facts a label depends on (a few hundred bytes), so any number of
observations can be rendered from it later without labelling again; it also keeps the scene's
original observation (camera poses, the depth noise's generator state), which is how it is
checked against the grid that was labelled. Poses are world frame, metres, ``[x, y, z, qx, qy,
qz, qw]`` (docs/conventions.md). Objects are named by a *reference* ``"<root>:<path>"``
(``vgn:``, ``pybullet_data:``, ``builtin:``, ``shapes:`` or ``file:<absolute path>``), so a recipe does
not depend on where a machine keeps its meshes (:func:`object_roots`; data/README.md).
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim_worker.camera import Camera, DepthNoise
from sim_worker.world import World

#: The bit generator whose state a recipe stores for its original depth noise.
NOISE_BIT_GENERATOR = "PCG64"
#: Mesh files a URDF refers to: ``filename="..."`` attributes.
_MESH_REFERENCE = re.compile(rb'filename\s*=\s*"([^"]+)"')


class RecipeError(Exception):
    """A recipe cannot be rebuilt here: an object file is missing or is not the file it names."""


# Object files -------------------------------------------------------------------------------
@dataclass(frozen=True)
class ObjectFile:
    """One object's identity: its reference and the sha256 of its URDF and of its meshes
    (the meshes the URDF names, in order; empty for primitives)."""

    ref: str
    urdf_sha256: str
    mesh_sha256: str


def object_roots(vgn_objects: Path | str | None = None) -> dict[str, Path]:
    """Where each reference root lives on this machine: ``vgn`` from the argument or
    ``$VGN_OBJECTS`` (absent when neither is set), ``pybullet_data``, ``builtin`` (the blocks) and
    ``shapes`` (the generated shapes)."""
    import pybullet_data

    from sim_worker.objects import default_cache_dir

    roots = {
        "pybullet_data": Path(pybullet_data.getDataPath()),
        "builtin": default_cache_dir() / "blocks",
        "shapes": default_cache_dir() / "shapes",
    }
    vgn = vgn_objects or os.environ.get("VGN_OBJECTS")
    if vgn:
        roots["vgn"] = Path(vgn).expanduser()
    return roots


def object_ref(urdf: Path, roots: dict[str, Path]) -> str:
    """The reference of the URDF at ``urdf`` (symbolic links followed: a split folder of links
    names the original files)."""
    resolved = Path(urdf).resolve()
    for name, root in roots.items():
        try:
            return f"{name}:{resolved.relative_to(root.resolve()).as_posix()}"
        except ValueError:
            continue
    return f"file:{resolved.as_posix()}"


def resolve_ref(ref: str, roots: dict[str, Path]) -> Path:
    """The URDF path of a reference on this machine."""
    name, _, relative = ref.partition(":")
    if name == "file":
        path = Path(relative)
        if not path.is_file():
            raise RecipeError(f"object {ref!r}: {path} does not exist")
        return path
    if name not in roots:
        hint = " (set VGN_OBJECTS to the folder of VGN's object sets)" if name == "vgn" else ""
        raise RecipeError(f"object {ref!r}: root {name!r} is not known here{hint}")
    path = roots[name] / relative
    if name == "builtin" and not path.exists():
        from sim_worker.objects import write_blocks

        write_blocks(roots[name])
    if name == "shapes" and not path.exists():
        from sim_worker.shapes import write_shapes

        write_shapes(roots[name])
    if not path.is_file():
        raise RecipeError(f"object {ref!r}: {path} does not exist")
    return path


def file_hashes(urdf: Path) -> tuple[str, str]:
    """sha256 of the URDF and of the mesh files it names (concatenated, in order)."""
    text = Path(urdf).read_bytes()
    meshes = hashlib.sha256()
    for name in _MESH_REFERENCE.findall(text):
        mesh = Path(urdf).resolve().parent / name.decode()
        if mesh.is_file():
            meshes.update(mesh.read_bytes())
    has_meshes = bool(_MESH_REFERENCE.search(text))
    return hashlib.sha256(text).hexdigest(), meshes.hexdigest() if has_meshes else ""


@dataclass
class ObjectTable:
    """The object files seen so far, each hashed once; scenes refer to rows of it."""

    roots: dict[str, Path]
    files: list[ObjectFile] = field(default_factory=list)
    _rows: dict[str, int] = field(default_factory=dict)

    def row(self, urdf: Path) -> int:
        """The row of ``urdf``, added (and hashed) the first time it is seen."""
        ref = object_ref(urdf, self.roots)
        if ref not in self._rows:
            self._rows[ref] = len(self.files)
            self.files.append(ObjectFile(ref, *file_hashes(urdf)))
        return self._rows[ref]


# Recipes ------------------------------------------------------------------------------------
@dataclass
class SceneRecipe:
    """One scene: ``objects`` (O,) object references, ``scales`` (O,), ``poses`` (O, 7) world,
    ``views`` (V, 7) camera → world of its original observation, ``noise_state`` (6,) uint64,
    the PCG64 state its original depth noise was drawn from (``None``: no noise), and the
    ``renderer`` that drew it ("egl" or "tiny": their images differ by a fraction of a pixel)."""

    scene_id: str
    objects: list[str]
    scales: np.ndarray
    poses: np.ndarray
    views: np.ndarray
    noise_state: np.ndarray | None = None
    side_view: bool = False
    renderer: str = "egl"

    @property
    def noisy(self) -> bool:
        """Whether the original observation carried depth noise."""
        return self.noise_state is not None


def pose_vector(matrix: np.ndarray) -> np.ndarray:
    """A 4×4 pose as ``[x, y, z, qx, qy, qz, qw]`` (float64)."""
    from scipy.spatial.transform import Rotation

    matrix = np.asarray(matrix, dtype=np.float64)
    return np.r_[matrix[:3, 3], Rotation.from_matrix(matrix[:3, :3]).as_quat()]


def pose_matrix(vector: np.ndarray) -> np.ndarray:
    """The 4×4 pose of ``[x, y, z, qx, qy, qz, qw]``."""
    from scipy.spatial.transform import Rotation

    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat(vector[3:7]).as_matrix()
    matrix[:3, 3] = vector[:3]
    return matrix


def rng_state(rng: np.random.Generator) -> np.ndarray:
    """The state of a PCG64 generator as six uint64 (state and increment as high/low words, the
    buffered 32-bit draw flag and value), enough to draw the same numbers again."""
    state = rng.bit_generator.state
    if state["bit_generator"] != NOISE_BIT_GENERATOR:
        raise ValueError(
            f"only {NOISE_BIT_GENERATOR} generators can be recorded, got {state['bit_generator']}"
        )
    inner = state["state"]
    words = [
        inner["state"] >> 64,
        inner["state"] & (2**64 - 1),
        inner["inc"] >> 64,
        inner["inc"] & (2**64 - 1),
    ]
    return np.array([*words, state["has_uint32"], state["uinteger"]], dtype=np.uint64)


def rng_from_state(words: np.ndarray) -> np.random.Generator:
    """The generator :func:`rng_state` recorded, ready to draw where it left off."""
    w = [int(x) for x in np.asarray(words, dtype=np.uint64)]
    bit_generator = np.random.PCG64()
    bit_generator.state = {
        "bit_generator": NOISE_BIT_GENERATOR,
        "state": {"state": (w[0] << 64) | w[1], "inc": (w[2] << 64) | w[3]},
        "has_uint32": w[4],
        "uinteger": w[5],
    }
    return np.random.Generator(bit_generator)


def record_recipe(
    world: World,
    scene_id: str,
    table: ObjectTable,
    camera_poses: Sequence[np.ndarray],
    noise_rng: np.random.Generator | None,
    side_view: bool = False,
) -> SceneRecipe:
    """The recipe of the scene now in ``world``: every object's reference, scale and base pose,
    and the original observation (``camera_poses``; ``noise_rng`` as it stands *before* the
    first view is rendered, ``None`` for clean depth). Object references are registered in
    ``table``."""
    bodies = sorted(world.objects)
    refs, scales, poses = [], [], []
    for body in bodies:
        obj = world.objects[body]
        refs.append(table.files[table.row(obj.urdf)].ref)
        scales.append(obj.scale)
        position, orientation = world.object_pose(body)
        poses.append(np.r_[position, orientation])
    return SceneRecipe(
        scene_id=scene_id,
        objects=refs,
        scales=np.asarray(scales, dtype=np.float64),
        poses=np.asarray(poses, dtype=np.float64).reshape(-1, 7),
        views=np.stack([pose_vector(p) for p in camera_poses]).reshape(-1, 7),
        noise_state=None if noise_rng is None else rng_state(noise_rng),
        side_view=side_view,
        renderer="egl" if world.egl else "tiny",
    )


def rebuild(world: World, recipe: SceneRecipe, roots: dict[str, Path]) -> list[int]:
    """Put the recipe's objects into an emptied ``world`` at their recorded poses, without a
    physics step (the poses are already settled). Returns the body ids, in recipe order."""
    world.reset()
    bodies = []
    for ref, scale, pose in zip(recipe.objects, recipe.scales, recipe.poses, strict=True):
        body = world.add_object(resolve_ref(ref, roots), pose[:3], pose[3:], float(scale))
        # loadURDF places the URDF link frame; the recorded pose is the base (inertial) frame.
        world.p.resetBasePositionAndOrientation(body, pose[:3].tolist(), pose[3:].tolist())
        bodies.append(body)
    return bodies


def render_views(
    camera: Camera,
    camera_poses: Sequence[np.ndarray],
    noise: DepthNoise | None = None,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """(V, H, W) float32 depth of the scene now in the camera's world from each pose, with
    ``noise`` drawn from ``rng`` view after view (as data generation draws it)."""
    camera.noise, camera.rng = noise, rng if rng is not None else np.random.default_rng()
    try:
        return np.stack([camera.render_depth(pose) for pose in camera_poses])
    finally:
        camera.noise = None


def render_original(camera: Camera, recipe: SceneRecipe) -> np.ndarray:
    """The depth images of the recipe's original observation, noise included, bit for bit as
    they were rendered when the scene was labelled (same renderer assumed)."""
    poses = [pose_matrix(v) for v in recipe.views]
    if recipe.noise_state is None:
        return render_views(camera, poses)
    return render_views(camera, poses, DepthNoise(), rng_from_state(recipe.noise_state))


# Storage --------------------------------------------------------------------------------------
def recipe_arrays(recipe: SceneRecipe, table: ObjectTable) -> dict[str, np.ndarray]:
    """A recipe as named arrays (a raw dataset's ``recipes/<id>.npz``), object files with their
    hashes, so the file stands alone."""
    files = {f.ref: f for f in table.files}
    return {
        "objects": np.asarray(recipe.objects, dtype=str),
        "urdf_sha256": np.asarray([files[ref].urdf_sha256 for ref in recipe.objects], dtype=str),
        "mesh_sha256": np.asarray([files[ref].mesh_sha256 for ref in recipe.objects], dtype=str),
        "scales": recipe.scales,
        "poses": recipe.poses,
        "views": recipe.views,
        "noise_state": recipe.noise_state if recipe.noise_state is not None else np.zeros(0, np.uint64),
        "side_view": np.asarray(recipe.side_view),
        "renderer": np.asarray(recipe.renderer),
    }


def recipe_from_arrays(scene_id: str, arrays: dict[str, np.ndarray]) -> tuple[SceneRecipe, list[ObjectFile]]:
    """The recipe stored by :func:`recipe_arrays` and its objects' files."""
    objects = [str(ref) for ref in arrays["objects"]]
    files = [ObjectFile(ref, str(u), str(m))
             for ref, u, m in zip(objects, arrays["urdf_sha256"], arrays["mesh_sha256"], strict=True)]  # fmt: skip
    noise = np.asarray(arrays["noise_state"], dtype=np.uint64)
    recipe = SceneRecipe(scene_id, objects, np.asarray(arrays["scales"], np.float64),
                         np.asarray(arrays["poses"], np.float64).reshape(-1, 7),
                         np.asarray(arrays["views"], np.float64).reshape(-1, 7),
                         noise if noise.size else None, bool(arrays["side_view"]),
                         str(arrays["renderer"]) if "renderer" in arrays else "egl")  # fmt: skip
    return recipe, files
