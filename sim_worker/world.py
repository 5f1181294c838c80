"""The PyBullet world: physics settings, the table, and the objects on it (docs/conventions.md)."""

from __future__ import annotations

import contextlib
import ctypes
import functools
import logging
import os
import pkgutil
import sys
import tempfile
import xml.etree.ElementTree as ElementTree
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

log = logging.getLogger(__name__)

#: Height of the table top in the world; the workspace cube's corner is the world origin.
TABLE_Z = 0.05
WORKSPACE_SIZE = 0.30
#: "egl" renders on the GPU or Mesa's EGL, "tiny" on the CPU; "auto" tries EGL first.
Renderer = Literal["auto", "egl", "tiny"]


@functools.cache
def _c_library() -> ctypes.CDLL | None:
    """The C library this process runs on, for ``fflush``; None where there is none to ask."""
    try:
        return ctypes.CDLL(None)
    except (OSError, TypeError):  # Windows takes no None here
        return None


def _flush_c_stdio() -> None:
    """Write out what C code left in its stdio buffers. Into a pipe or file C's stdout is fully
    buffered, so text printed while fd 1 was silenced would otherwise reach the real stdout
    later, at the next flush or at exit."""
    library = _c_library()
    if library is not None:
        library.fflush(None)


@contextlib.contextmanager
def _quiet_native_stdout() -> Iterator[None]:
    """Silence what PyBullet's C code prints on stdout (``argv[0]=`` on connect; the EGL plugin's
    GL vendor whenever it makes its buffers, on load and exit), which would mix with a command's
    own output."""
    sys.stdout.flush()
    _flush_c_stdio()
    try:
        saved = os.dup(1)
    except OSError:  # no real stdout to silence
        yield
        return
    with open(os.devnull, "wb") as devnull:
        os.dup2(devnull.fileno(), 1)
        try:
            yield
        finally:
            _flush_c_stdio()
            os.dup2(saved, 1)
            os.close(saved)


class QuietBulletClient(BulletClient):
    """A ``BulletClient`` whose connect and renders keep stdout clean. The EGL plugin makes its
    buffers at the first render and again when a render is larger than any before it (or after a
    reset), and prints the GL vendor each time, so every render is silenced, not only the first."""

    def __init__(self, connection_mode: int = pybullet.DIRECT) -> None:
        with _quiet_native_stdout():
            super().__init__(connection_mode=connection_mode)

    def __del__(self) -> None:
        """Disconnect, silenced as ``World.close`` does, when a world is dropped without closing."""
        if getattr(self, "_client", -1) >= 0:
            with _quiet_native_stdout():
                super().__del__()

    def getCameraImage(self, *args: Any, **kwargs: Any) -> Any:
        """``pybullet.getCameraImage`` on this client, with native stdout silenced."""
        with _quiet_native_stdout():
            return pybullet.getCameraImage(*args, physicsClientId=self._client, **kwargs)


# Meshes at more than one scale ----------------------------------------------------------------
# PyBullet's EGL renderer keeps one graphics shape per mesh it draws, keyed by the mesh file's
# path as PyBullet resolved it from the URDF (and the visual's frame), not by its scale, until
# resetSimulation. A mesh loaded again at another scale (by the same URDF, a removed attempt or
# another URDF naming the same file) would be drawn at its first scale, though its collision
# shape has the right one. Each further scale of a mesh in one simulation is therefore loaded
# from a copy of the URDF that names the mesh by another path to the same file:
# ``folder/./name``, ``folder/././name``, ... TinyRenderer has no such cache.


def _drawn_meshes(robot: ElementTree.Element) -> list[ElementTree.Element]:
    """The ``<mesh>`` elements a renderer draws: each link's visual meshes, or its collision
    meshes where it has no visual (PyBullet then draws those)."""
    meshes = []
    for link in robot.iter("link"):
        kind = "visual" if link.find("visual") is not None else "collision"
        meshes += link.findall(f"{kind}/geometry/mesh")
    return meshes


def _referenced_path(urdf: Path, element: ElementTree.Element) -> str:
    """The path a ``filename`` attribute names, as PyBullet resolves it (the URDF's folder
    joined with it, unnormalised: that string is what the renderer's cache holds)."""
    return os.path.join(os.path.dirname(str(urdf)), element.get("filename", ""))


def _aliased_path(path: str, slot: int) -> str:
    """Another name for the file at ``path``: absolute, normalised, with ``slot`` ``./`` steps
    before its base name (slot 0: no step)."""
    folder, name = os.path.split(os.path.abspath(path))
    return f"{folder}/{'./' * slot}{name}"


def _write_aliased_copy(robot: ElementTree.Element, urdf: Path, slots: dict[int, int], folder: Path) -> Path:
    """A copy of the URDF in ``folder`` naming every file by its absolute path, and each drawn
    mesh (by element id) by the alias of its slot. Physics reads the same files as from the
    original."""
    for element in robot.iter():
        if "filename" in element.attrib:
            path = _referenced_path(urdf, element)
            if os.path.exists(path):
                element.set("filename", _aliased_path(path, slots.get(id(element), 0)))
    copy = folder / Path(urdf).name
    ElementTree.ElementTree(robot).write(copy, encoding="utf-8", xml_declaration=True)
    return copy


def _loads_as_is(urdf: Path, robot: ElementTree.Element, slots: dict[int, int]) -> bool:
    """Whether the URDF itself draws its meshes right: each at its file's first scale, named
    by a normalised path (an unnormalised one could equal another scale's alias)."""
    meshes = [mesh for mesh in _drawn_meshes(robot) if id(mesh) in slots]
    paths = [_referenced_path(urdf, mesh) for mesh in meshes]
    return all(slots[id(mesh)] == 0 for mesh in meshes) and all(
        path == os.path.normpath(path) for path in paths
    )


@dataclass(frozen=True)
class PhysicsConfig:
    """VGN's simulation parameters, so figures compare with the paper."""

    timestep: float = 1.0 / 240.0
    solver_iterations: int = 150
    gravity: float = -9.81
    object_friction: float = 1.0
    table_friction: float = 0.5
    rest_speed: float = 0.01  # m/s and rad/s: "at rest" below this
    rest_timeout: float = 2.0  # seconds to wait for a scene to settle
    rest_check_steps: int = 60


@dataclass
class SimObject:
    """An object in the world: its body id, the URDF it came from and its scale."""

    body: int
    urdf: Path
    scale: float


class World:
    """A PyBullet world in DIRECT mode with a table whose top is at ``TABLE_Z``.

    ``renderer``: ``"egl"`` loads PyBullet's EGL plugin (it must be loaded before any body
    exists, hence here), ``"tiny"`` uses the CPU TinyRenderer, ``"auto"`` tries EGL first.
    """

    def __init__(self, config: PhysicsConfig = PhysicsConfig(), renderer: Renderer = "auto") -> None:
        self.config = config
        self.p = QuietBulletClient(pybullet.DIRECT)
        self.egl = renderer in ("egl", "auto") and self._load_egl(required=renderer == "egl")
        self.objects: dict[int, SimObject] = {}
        #: False draws as PyBullet's EGL renderer does by itself, each mesh at the first scale it
        #: was loaded at: only to recognise observations drawn so. Change it before a reset.
        self.alias_scaled_meshes = True
        #: Per mesh file (real path): the scales it was loaded at in this simulation, in order,
        #: each as (its URDF's ``scale`` attribute, global scale); a scale's index is the alias
        #: the mesh is loaded by.
        self._mesh_scales: dict[str, list[tuple[str, float]]] = {}
        self._set_up()

    def _set_up(self) -> None:
        self.p.setPhysicsEngineParameter(
            fixedTimeStep=self.config.timestep, numSolverIterations=self.config.solver_iterations
        )
        self.p.setGravity(0.0, 0.0, self.config.gravity)
        self.objects = {}
        self._mesh_scales = {}  # a new simulation: the EGL renderer has forgotten its shapes
        self.table = self._create_table()
        self.sim_time = 0.0

    def reset(self) -> None:
        """An empty table, as in a new world (the renderer stays loaded). Removing objects alone
        is not enough for reproducible results: body ids and the solver's caches carry over and
        shift later simulations slightly, so a scene would depend on what ran before it. Bodies
        added by others (the gripper) are gone too and must be made again."""
        self.p.resetSimulation()
        self._set_up()

    def _load_egl(self, required: bool) -> bool:
        loader = pkgutil.get_loader("eglRenderer")
        try:
            if loader is None:
                raise RuntimeError("pybullet's eglRenderer module is missing")
            with _quiet_native_stdout():
                loaded = self.p.loadPlugin(loader.get_filename(), "_eglRendererPlugin") >= 0
            if not loaded:
                raise RuntimeError("pybullet could not load its EGL plugin")
            log.info("rendering with PyBullet's EGL plugin")
            return True
        except Exception as error:  # pybullet raises plain errors when EGL is unavailable
            if required:
                raise RuntimeError(f"the EGL renderer cannot be loaded: {error}") from None
            log.warning("EGL renderer unavailable (%s): rendering with the CPU TinyRenderer, slower", error)
            return False

    def _create_table(self) -> int:
        half_extents = [0.5, 0.5, 0.025]
        shape = self.p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half_extents)
        visual = self.p.createVisualShape(
            pybullet.GEOM_BOX, halfExtents=half_extents, rgbaColor=[0.8, 0.8, 0.8, 1]
        )
        table = self.p.createMultiBody(
            0.0, shape, visual, basePosition=[WORKSPACE_SIZE / 2, WORKSPACE_SIZE / 2, TABLE_Z - 0.025]
        )
        self.p.changeDynamics(table, -1, lateralFriction=self.config.table_friction)
        return table

    # Objects ------------------------------------------------------------------------------
    def add_object(
        self,
        urdf: Path,
        position: Sequence[float] | np.ndarray,
        orientation: Sequence[float] | np.ndarray = (0.0, 0.0, 0.0, 1.0),
        scale: float = 1.0,
    ) -> int:
        """Load an object URDF at a pose ([x, y, z], [x, y, z, w]) with a uniform scale. The
        object keeps ``urdf`` as its file even when it was loaded from an aliased copy."""
        with self._drawable_urdf(Path(urdf), scale) as loadable:
            body = self.p.loadURDF(str(loadable), list(position), list(orientation), globalScaling=scale)
        self.p.changeDynamics(body, -1, lateralFriction=self.config.object_friction)
        self.objects[body] = SimObject(body, Path(urdf), scale)
        return body

    @contextlib.contextmanager
    def _drawable_urdf(self, urdf: Path, scale: float) -> Iterator[Path]:
        """The URDF to load so that EGL draws each of its meshes at ``scale``: ``urdf`` itself
        where every mesh is at its first scale in this simulation, else an aliased copy that
        lives while it is loaded."""
        if not (self.egl and self.alias_scaled_meshes):
            yield urdf
            return
        robot = ElementTree.parse(urdf).getroot()
        slots = self._mesh_slots(urdf, robot, scale)
        if _loads_as_is(urdf, robot, slots):
            yield urdf
            return
        with tempfile.TemporaryDirectory(prefix="vgn-urdf-") as folder:
            yield _write_aliased_copy(robot, urdf, slots, Path(folder))

    def _mesh_slots(self, urdf: Path, robot: ElementTree.Element, scale: float) -> dict[int, int]:
        """Each drawn mesh file's alias slot (by element id) for ``scale``: the index of the
        scale among those its file was loaded at in this simulation, ``scale`` noted."""
        slots = {}
        for mesh in _drawn_meshes(robot):
            path = _referenced_path(urdf, mesh)
            if not os.path.isfile(path):  # package:// names and the like: left as they are
                continue
            scales = self._mesh_scales.setdefault(os.path.realpath(path), [])
            drawn_at = (mesh.get("scale", ""), scale)
            if drawn_at not in scales:
                scales.append(drawn_at)
            slots[id(mesh)] = scales.index(drawn_at)
        return slots

    def clear_objects(self) -> None:
        """Remove every object, keeping the table (and any gripper)."""
        for body in list(self.objects):
            self.remove_object(body)

    def remove_object(self, body: int) -> None:
        """Take one object out of the world and out of ``objects``."""
        self.p.removeBody(body)
        del self.objects[body]

    def object_pose(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        """Position (3,) and quaternion [x, y, z, w] (4,) of a body's base, world frame."""
        position, orientation = self.p.getBasePositionAndOrientation(body)
        return np.asarray(position), np.asarray(orientation)

    def aabb(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper corners of a body's axis-aligned bounding box, world frame."""
        lower, upper = self.p.getAABB(body)
        return np.asarray(lower), np.asarray(upper)

    # Physics ------------------------------------------------------------------------------
    def step(self, count: int = 1) -> None:
        """Advance physics by ``count`` fixed time steps, keeping ``sim_time``."""
        for _ in range(count):
            self.p.stepSimulation()
        self.sim_time += count * self.config.timestep

    def at_rest(self) -> bool:
        """Whether every object moves slower than ``rest_speed``, linearly and angularly."""
        for body in self.objects:
            linear, angular = self.p.getBaseVelocity(body)
            if max(np.abs(linear).max(), np.abs(angular).max()) > self.config.rest_speed:
                return False
        return True

    def wait_for_rest(self) -> bool:
        """Step until every object is at rest (checked every ``rest_check_steps`` steps, for at
        most ``rest_timeout`` seconds)."""
        steps = int(round(self.config.rest_timeout / self.config.timestep))
        for _ in range(0, steps, self.config.rest_check_steps):
            self.step(self.config.rest_check_steps)
            if self.at_rest():
                return True
        return False

    def remove_objects_outside(
        self, lower: Sequence[float] = (0.0, 0.0, 0.0), upper: Sequence[float] = (WORKSPACE_SIZE,) * 3
    ) -> list[int]:
        """Remove objects whose centre left the workspace cube (fallen off, flung away)."""
        removed = []
        for body in list(self.objects):
            position, _ = self.object_pose(body)
            if np.any(position < lower) or np.any(position > upper):
                self.remove_object(body)
                removed.append(body)
        return removed

    def save_state(self) -> int:
        """Snapshot the simulation in memory; the id is for ``restore_state`` and ``discard_state``."""
        return self.p.saveState()

    def restore_state(self, state: int) -> None:
        """Return to a snapshot, e.g. to try another grasp on the same scene."""
        self.p.restoreState(stateId=state)

    def discard_state(self, state: int) -> None:
        """Free a snapshot no longer needed (each holds a copy of the world)."""
        self.p.removeState(state)

    def close(self) -> None:
        """Disconnect from PyBullet, silencing what its native code prints on the way out."""
        with _quiet_native_stdout():
            self.p.disconnect()

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
