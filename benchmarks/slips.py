"""Why grasps slip: each grasp of the default answer executed under several hands.

Most failed grasps of the clutter-removal benchmark are ``slipped`` (held after closing, lost while
lifting). This tells a bad grasp from a simulator that holds too weakly: it runs clutter-removal
rounds as ``benchmarks.grasp_outcomes`` does and, at every look, executes each grasp of the
service's default answer (what a robot asking without options executes) from the same saved state
under each hand variant, here the shipped hand and the Franka hand's rated continuous grasp force.
It watches every lift (finger normal forces, where the object's centre of mass lies relative to the
grip, how far the object turns and slides in the fingers before it is lost) and advances the round
with a random grasp of the answer, executed by the shipped hand, as the benchmark does. Each round
goes to ``OUT/roundNNNN.json`` (written atomically; a rerun resumes).

    python -m benchmarks.slips collect --objects OBJ/pile/train --rounds 20 --seed 11 --out DIR
    python -m benchmarks.slips report DIR [--write docs/results/NAME]
    python -m benchmarks.slips masses OBJ/pile/train

``masses`` lists the objects' URDF masses against their collision meshes' size and volume: whether
the weights the fingers must carry are plausible.
"""

from __future__ import annotations

import argparse
import functools
import json
import re
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from client.connect import connect
from service.launch.embedded import EmbeddedService
from sim_worker.clutter import MAX_CONSECUTIVE_FAILURES, ClutterConfig, ClutterRemoval
from sim_worker.grasping import LIFT_DISTANCE, Outcome, execute_grasp
from sim_worker.gripper import Gripper, GripperSpec
from sim_worker.results import ResultsFolder
from sim_worker.world import World
from vgn_contract.geometry import matrix_from_pose
from vgn_data.files import write_atomically

GRAVITY = 9.81
#: The Franka Emika hand's datasheet grasping force: 70 N continuous, 140 N maximum. Two opposing
#: fingers each pressing with F squeeze the object with F, so the rating is each finger's force.
FRANKA_CONTINUOUS_FORCE = 70.0
FRANKA_MAX_FORCE = 140.0
#: Torsional friction of the pads' contact patch (m): the variant the shipped hand lacks.
PAD_TORSION = 0.003
#: The hands compared; the first is the shipped one, which advances the rounds.
VARIANTS: dict[str, GripperSpec] = {
    "shipped": GripperSpec(),
    "franka-70N": replace(GripperSpec(), finger_force=FRANKA_CONTINUOUS_FORCE),
    "franka-140N": replace(GripperSpec(), finger_force=FRANKA_MAX_FORCE),
    # Rubber pressed on an object touches it over a patch, whose friction resists a turn about the
    # contact normal: about (2/3) mu a for a patch of radius a. 3 mm is a 4.5 mm patch, small for a
    # 20 x 18.5 mm pad; the shipped hand has none.
    "torsion-3mm": replace(GripperSpec(), pad_spinning_friction=PAD_TORSION),
    # Executed last: replaying a saved state is not exact (the solver's caches carry history), so a
    # borderline grasp can change outcome with no change of hand. This measures that floor.
    "shipped-again": GripperSpec(),
}
MASS_BINS = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0, np.inf)
#: kg/m³: up to water, up to aluminium (2700: denser than glass, ceramic or any plastic), beyond.
DENSITY_BINS = (0.0, 1000.0, 2700.0, np.inf)


@dataclass
class LiftWatch:
    """What a lift does to the held object, sampled after each 2 mm step of the lift.

    A slip is either a turn about the closing axis (the weight's torque about the grip beats the
    pads' friction torque: the grip is far from the centre of mass) or a slide of the grip point
    along the pads (the weight beats the friction force: the object is too heavy or held too
    weakly). ``turn_deg`` and ``slide_mm`` measure each, up to the step the object was lost."""

    world: World
    gripper: Gripper
    body: int | None = None
    start_force: float = 0.0  # N, mean over the fingers of the summed normal force, first lift step
    min_force: float = np.inf  # N, the least of that while held
    lever_mm: float = 0.0  # the weight's lever arm about the closing axis through the grip point
    weight_ratio: float = (
        0.0  # m g / (2 mu F), mu the pads' (objects have 1.0): at 1 friction just carries it
    )
    lost_at: float | None = None  # fraction of the lift done when the object left a finger
    turn_deg: float = 0.0  # the object's rotation in the hand since the first lift step
    slide_mm: float = 0.0  # how far the object's grip point moved in the hand since then
    #: Per lift step while held: forces and contact points per finger, turn, slide, the centre of
    #: mass in the grasp frame (mm).
    steps: list[dict[str, Any]] = field(default_factory=list)
    _start: np.ndarray = field(default_factory=lambda: np.eye(4))  # object in the hand
    _grip: np.ndarray = field(default_factory=lambda: np.zeros(3))  # grip point, object frame

    def __call__(self, n: int, count: int) -> None:
        """Sample after lift step ``n`` of ``count``; stops once the object left a finger."""
        if self.lost_at is not None:
            return
        if self.body is None and not self._begin():
            self.lost_at = 0.0
            return
        contacts = self._finger_contacts()
        forces = [sum(c[9] for c in points) for points in contacts]
        relative = self._object_in_hand()
        change = relative @ np.linalg.inv(self._start)
        cosine = np.clip((np.trace(change[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
        self.turn_deg = float(np.degrees(np.arccos(cosine)))
        grip_now = relative[:3, :3] @ self._grip + relative[:3, 3]
        grip_then = self._start[:3, :3] @ self._grip + self._start[:3, 3]
        self.slide_mm = float(1000 * np.linalg.norm(grip_now - grip_then))
        self.steps.append({"step": n, "of": count, "forces": [round(f, 1) for f in forces],
                           "contacts": [len(points) for points in contacts], "turn_deg": round(self.turn_deg, 1),
                           "slide_mm": round(self.slide_mm, 1), "com_mm": np.round(1000 * relative[:3, 3], 1).tolist()})  # fmt: skip
        if min(forces) <= 0.0:
            self.lost_at = n / count
            return
        self.min_force = min(self.min_force, float(np.mean(forces)))

    def _begin(self) -> bool:
        """Note the held object and how it is held; False when nothing is held."""
        held = self.gripper.bodies_between_fingers() & set(self.world.objects)
        if not held:
            return False
        self.body = min(held)
        self._start = self._object_in_hand()
        self.start_force = float(np.mean([sum(c[9] for c in points) for points in self._finger_contacts()]))
        self.min_force = self.start_force
        points = [c[5] for c in self.world.p.getContactPoints(bodyA=self.gripper.body, bodyB=self.body)]
        grip_world = np.mean(np.asarray(points), axis=0)
        hand = self.gripper.pose()
        obj = _pose(self.world, self.body)
        self._grip = np.linalg.inv(obj) @ np.append(grip_world, 1.0)
        self._grip = self._grip[:3]
        mass = self.mass()
        closing = hand[:3, 1]
        torque = np.cross(obj[:3, 3] - grip_world, np.array([0.0, 0.0, -mass * GRAVITY]))
        self.lever_mm = float(1000 * abs(torque @ closing) / (mass * GRAVITY))
        friction = self.gripper.spec.finger_friction
        self.weight_ratio = float(mass * GRAVITY / max(2 * friction * self.start_force, 1e-9))
        return True

    def mass(self) -> float:
        """The held object's mass (kg)."""
        return float(self.world.p.getDynamicsInfo(self.body, -1)[0])

    def _finger_contacts(self) -> list[tuple[Any, ...]]:
        """Each finger's contact points with the held object (PyBullet's tuples; [9] is the normal force)."""
        p = self.world.p
        return [
            p.getContactPoints(bodyA=self.gripper.body, bodyB=self.body, linkIndexA=f)
            for f in self.gripper.fingers
        ]

    def _object_in_hand(self) -> np.ndarray:
        return np.linalg.inv(self.gripper.pose()) @ _pose(self.world, self.body)

    def as_json(self) -> dict[str, Any]:
        """The watch's figures, rounded (empty where nothing was held)."""
        if self.body is None:
            return {}
        return {"start_force": round(self.start_force, 2), "min_force": round(self.min_force, 2),
                "lever_mm": round(self.lever_mm, 1), "weight_ratio": round(self.weight_ratio, 3),
                "lost_at": self.lost_at, "turn_deg": round(self.turn_deg, 1),
                "slide_mm": round(self.slide_mm, 1)}  # fmt: skip


def _pose(world: World, body: int) -> np.ndarray:
    position, orientation = world.object_pose(body)
    return matrix_from_pose(position, orientation)


#: Told of every trial: look, grasp (index in the answer), variant, its lift watch and outcome.
OnTrial = Callable[[int, int, str, "LiftWatch", Outcome], None]


def try_variants(
    episode: ClutterRemoval,
    grasp_pose: np.ndarray,
    variants: list[str],
    on_trial: Callable[..., None] | None = None,
) -> dict[str, Any]:
    """One grasp executed from the current state under each hand variant; the state is restored
    after each and the shipped hand is put back. Returns outcomes, watches and the held object;
    ``on_trial(variant, watch, outcome)`` is told of each trial."""
    world, gripper = episode.world, episode.gripper
    state = world.save_state()
    row: dict[str, Any] = {"outcomes": {}, "watch": {}}
    for name in variants:
        gripper.use_spec(VARIANTS[name])
        watch = LiftWatch(world, gripper)
        trial = execute_grasp(world, gripper, grasp_pose, remove_grasped=False, on_lift=watch)
        row["outcomes"][name] = trial.outcome.value
        row["watch"][name] = watch.as_json()
        if on_trial is not None:
            on_trial(name, watch, trial.outcome)
        if watch.body is not None and "object" not in row:
            found = world.objects[watch.body]
            row.update(object=found.urdf.stem, mass=round(watch.mass(), 4), scale=round(found.scale, 3))
        world.restore_state(state)
    world.discard_state(state)
    gripper.use_spec(VARIANTS["shipped"])
    return row


def run_round(
    episode: ClutterRemoval,
    round_id: int,
    variants: list[str],
    on_trial: OnTrial | None = None,
    last_look: int | None = None,
) -> list[dict[str, Any]]:
    """One round: at every look (up to ``last_look``), each grasp of the default answer under every
    variant. Replaying a round replays its history too, which its outcomes depend on."""
    rng = episode.new_scene(round_id)
    world, looks, failures = episode.world, [], 0
    while world.objects and failures < MAX_CONSECUTIVE_FAILURES:
        answer = episode.look(rng).answer.grasps
        rows, look = [], len(looks)
        for index, grasp in enumerate(answer):
            told = None if on_trial is None else functools.partial(on_trial, look, index)
            row = try_variants(episode, grasp.as_matrix(), variants, told)
            rows.append({"quality": round(grasp.quality, 4), "width": round(grasp.width, 4),
                         "position": [round(v, 5) for v in grasp.position],
                         "orientation": [round(v, 6) for v in grasp.orientation], **row})  # fmt: skip
        looks.append({"objects": len(world.objects), "grasps": rows})
        if not answer or look == last_look:
            break
        trial = execute_grasp(world, episode.gripper, answer[int(rng.integers(len(answer)))].as_matrix())
        failures = 0 if trial.label else failures + 1
        world.wait_for_rest()
        world.remove_objects_outside()
    return looks


def collect(args: argparse.Namespace) -> int:
    """Run the rounds not stored yet in ``args.out``."""
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    variants = ["shipped", *[v for v in args.variants if v != "shipped"]]
    # The default request: the service's threshold (with its fallback), turn-averaged, both checks.
    config = ClutterConfig(scene=args.scene, objects=args.objects, object_count=args.object_count,
                           rounds=args.rounds, seed=args.seed, selection="random", turn_average=True,
                           clearance=True, grip=True)  # fmt: skip
    with EmbeddedService(log_path=out / "service.log") as service, connect(service.url) as vgn:
        episode = ClutterRemoval(config, vgn, ResultsFolder(out / "benchmark", config.as_json()))
        try:
            for round_id in range(args.rounds):
                path = out / f"round{round_id:04d}.json"
                if path.exists():
                    continue
                looks = run_round(episode, round_id, variants)
                record = {"round": round_id, "seed": args.seed, "variants": variants, "looks": looks}
                write_atomically(path, json.dumps(record) + "\n")
                print(f"round {round_id}: {len(looks)} looks, "
                      f"{sum(len(look['grasps']) for look in looks)} grasps", flush=True)  # fmt: skip
        finally:
            episode.close()
    return 0


def trace(args: argparse.Namespace) -> int:
    """Replay a stored round up to one look and print how one grasp's lift goes under each hand."""
    record = json.loads((args.folder / f"round{args.round:04d}.json").read_text())
    stored = record["looks"][args.look]["grasps"][args.grasp]
    config = ClutterConfig(scene=args.scene, objects=args.objects, object_count=args.object_count, rounds=1,
                           seed=record["seed"], selection="random", turn_average=True, clearance=True, grip=True)  # fmt: skip
    matches = []

    def show(look: int, grasp: int, variant: str, watch: LiftWatch, outcome: Outcome) -> None:
        if (look, grasp) != (args.look, args.grasp):
            return
        matches.append(outcome.value == stored["outcomes"][variant])
        print(
            f"{variant}: {outcome.value} (stored: {stored['outcomes'][variant]}); {json.dumps(watch.as_json())}"
        )
        if watch.steps:
            print(
                "  lift mm | normal force N (fingers) | contact points | turn deg | slide mm | centre of mass in the hand mm"
            )
        for step in watch.steps:
            if step["step"] % args.every == 0 or step is watch.steps[-1] or step["step"] == 1:
                lift = 1000 * LIFT_DISTANCE * step["step"] / step["of"]
                print(f"  {lift:7.0f} | {step['forces']} | {step['contacts']} | {step['turn_deg']:8.1f} | "
                      f"{step['slide_mm']:8.1f} | {step['com_mm']}")  # fmt: skip

    print(f"round {args.round}, look {args.look}, grasp {args.grasp}: {stored.get('object', 'nothing held')}, "
          f"{stored.get('mass', 0):.3f} kg, quality {stored['quality']}, width {1000 * stored['width']:.1f} mm")  # fmt: skip
    with EmbeddedService(log_path=args.folder / "trace-service.log") as service, connect(service.url) as vgn:
        episode = ClutterRemoval(
            config, vgn, ResultsFolder(args.folder / "trace-benchmark", config.as_json())
        )
        try:
            run_round(episode, args.round, record["variants"], show, last_look=args.look)
        finally:
            episode.close()
    if not all(matches):
        print("the replay's outcomes differ from the stored ones: the service or simulator changed")
    return 0 if matches and all(matches) else 1


# Report ---------------------------------------------------------------------------------------
def load_grasps(folder: Path) -> list[dict[str, Any]]:
    """Every executed grasp of ``folder``'s rounds."""
    grasps = []
    for path in sorted(folder.glob("round*.json")):
        record = json.loads(path.read_text())
        grasps += [grasp for look in record["looks"] for grasp in look["grasps"]]
    return grasps


def tabulate(
    grasps: list[dict[str, Any]], variants: list[str], densities: dict[str, float] | None = None
) -> dict[str, Any]:
    """The figures of a report: each variant's outcomes against the shipped hand's, on the grasps
    every variant executed. With ``densities`` (kg/m³ per object at scale 1), slips are also
    counted by the density an object had in its scene (PyBullet scales the shape, not the mass)."""
    grasps = [g for g in grasps if all(v in g["outcomes"] for v in variants)]
    others = [v for v in variants if v != "shipped"]
    slipped = [g for g in grasps if g["outcomes"]["shipped"] == Outcome.SLIPPED.value]
    held = [g for g in grasps if g["outcomes"]["shipped"] == Outcome.SUCCESS.value]
    per_object: dict[str, dict[str, Any]] = {}
    for g in grasps:
        if "object" not in g:
            continue
        entry = per_object.setdefault(g["object"], {"mass": g["mass"], "held_at_close": 0, "slipped": 0,
                                                    **{f"held_{v}": 0 for v in others}})  # fmt: skip
        if densities and g["object"] in densities:
            entry["density"] = round(densities[g["object"]])
        entry["held_at_close"] += 1
        if g["outcomes"]["shipped"] == Outcome.SLIPPED.value:
            entry["slipped"] += 1
            for v in others:
                entry[f"held_{v}"] += g["outcomes"][v] == Outcome.SUCCESS.value
    held_something = [g for g in grasps if "object" in g]
    by_mass = _binned(held_something, [g["mass"] for g in held_something], MASS_BINS, variants)
    known = [g for g in held_something if densities and g["object"] in densities]
    scene_density = [densities[g["object"]] / g["scale"] ** 3 for g in known] if densities else []
    return {
        "grasps": len(grasps),
        "outcomes": {v: dict(Counter(g["outcomes"][v] for g in grasps)) for v in variants},
        "changed": {v: [[a, b, n] for (a, b), n in sorted(Counter(
            (g["outcomes"]["shipped"], g["outcomes"][v]) for g in grasps).items()) if a != b] for v in others},
        "slipped": len(slipped),
        "slipped_then": {v: dict(Counter(g["outcomes"][v] for g in slipped)) for v in others},
        "succeeded": len(held),
        "succeeded_then": {v: dict(Counter(g["outcomes"][v] for g in held)) for v in others},
        "by_mass": by_mass,
        "by_density": _binned(known, scene_density, DENSITY_BINS, variants) if densities else [],
        "objects": dict(sorted(per_object.items(), key=lambda item: (-item[1]["slipped"], item[0]))),
        "lift": {
            "succeeded (shipped)": _watch_summary(held, "shipped"),
            "slipped (shipped)": _watch_summary(slipped, "shipped"),
            **{f"slipped (shipped), under {v}": _watch_summary(slipped, v) for v in others},
        },
    }  # fmt: skip


def _binned(
    grasps: list[dict[str, Any]], values: list[float], bins: tuple[float, ...], variants: list[str]
) -> list[dict[str, Any]]:
    """Per bin of ``values`` (one per grasp): grasps held at close, and slips under each variant."""
    rows = []
    for low, high in zip(bins[:-1], bins[1:], strict=True):
        inside = [g for g, value in zip(grasps, values, strict=True) if low <= value < high]
        rows.append({"bin": [low, None if np.isinf(high) else high], "held_at_close": len(inside),
                     "slipped": {v: _count(inside, v, Outcome.SLIPPED) for v in variants}})  # fmt: skip
    return rows


def _count(grasps: Iterable[dict[str, Any]], variant: str, outcome: Outcome) -> int:
    return sum(g["outcomes"][variant] == outcome.value for g in grasps)


def _watch_summary(grasps: list[dict[str, Any]], variant: str) -> dict[str, Any]:
    """Quartiles of the lift watch's figures over ``grasps`` (those that held at the lift's start)."""
    watches = [g["watch"][variant] for g in grasps if g["watch"].get(variant)]
    summary: dict[str, Any] = {"count": len(watches)}
    for key in ("start_force", "min_force", "lever_mm", "weight_ratio", "turn_deg", "slide_mm", "lost_at"):
        values = [w[key] for w in watches if w[key] is not None and np.isfinite(w[key])]
        if values:
            summary[key] = [round(float(v), 3) for v in np.percentile(values, [25, 50, 75])]
    summary["lost"] = sum(w["lost_at"] is not None for w in watches)
    masses = [g["mass"] for g in grasps if "mass" in g]
    if masses:
        summary["mass_kg"] = [round(float(v), 4) for v in np.percentile(masses, [25, 50, 75])]
    return summary


def render(table: dict[str, Any], top: int = 15) -> str:
    """The report as markdown."""
    variants = list(table["outcomes"])
    others = variants[1:]
    row = " | ".join
    lines = [f"{table['grasps']} grasps of the default answer, each executed from the same saved state by "
             "every hand: " + ", ".join(f"{v} ({_describe(v)})" for v in variants) + ".", "",
             f"| outcome | {row(variants)} |", "| --- |" + " ---: |" * len(variants)]  # fmt: skip
    names = sorted({name for counts in table["outcomes"].values() for name in counts})
    for name in names:
        lines.append(f"| {name} | {row(str(table['outcomes'][v].get(name, 0)) for v in variants)} |")
    lines.append(f"| total | {row(str(table['grasps']) for _ in variants)} |")
    lines += ["", f"Of the {table['slipped']} grasps that slipped and the {table['succeeded']} that succeeded "
              "under the shipped hand, the outcomes under each other hand:", "",
              "| hand | slipped (shipped) then | succeeded (shipped) then | all changed outcomes |",
              "| --- | --- | --- | --- |"]  # fmt: skip
    for v in others:
        changed = ", ".join(f"{a} → {b} {n}" for a, b, n in table["changed"][v]) or "-"
        lines.append(f"| {v} | {_counts(table['slipped_then'][v])} | {_counts(table['succeeded_then'][v])} | "
                     f"{changed} |")  # fmt: skip
    for key, title, unit in (("by_mass", "mass", "mass (kg)"),
                             ("by_density", "density in its scene (URDF mass over the scaled collision mesh's "
                              "volume)", "density (kg/m³)")):  # fmt: skip
        if not table[key]:
            continue
        lines += ["", f"Slips by the held object's {title}; grasps that held something when the lift began:", "",
                  f"| {unit} | held at close | slipped: {' / '.join(variants)} |", "| --- | ---: | --- |"]  # fmt: skip
        for entry in table[key]:
            low, high = entry["bin"]
            span = f"{low:g}-{high:g}" if high is not None else f">= {low:g}"
            lines.append(f"| {span} | {entry['held_at_close']} | "
                         f"{' / '.join(str(entry['slipped'][v]) for v in variants)} |")  # fmt: skip
    lines += ["", f"Objects with the most slips under the shipped hand (of {len(table['objects'])} held at "
              "close):", "",
              f"| object | mass (kg) | density (kg/m³) | held at close | slipped | of those held by: "
              f"{' / '.join(others)} |", "| --- | ---: | ---: | ---: | ---: | --- |"]  # fmt: skip
    for name, entry in list(table["objects"].items())[:top]:
        if not entry["slipped"]:
            break
        lines.append(f"| {name[:24]} | {entry['mass']:.3f} | {entry.get('density', '-')} | "
                     f"{entry['held_at_close']} | {entry['slipped']} | "
                     f"{' / '.join(str(entry[f'held_{v}']) for v in others)} |")  # fmt: skip
    lines += ["", "The lift, quartiles (25 / 50 / 75 %): the fingers' normal force at the first lift step and "
              "its least while held (N, mean of the two fingers), the weight's lever arm about the closing "
              "axis through the grip point (mm), weight / (2 × friction × normal force), and how far the "
              "object turned (degrees) and its grip point slid (mm) in the hand until it was lost or the "
              "lift ended, and how many were lost with the share of the lift done then:", "",
              "| grasps | count | force N | least force N | lever mm | weight ratio | turn deg | slide mm "
              "| lost at | mass kg |", "| --- | ---: | --- | --- | --- | --- | --- | --- | --- | --- |"]  # fmt: skip
    keys = (
        "start_force",
        "min_force",
        "lever_mm",
        "weight_ratio",
        "turn_deg",
        "slide_mm",
        "lost_at",
        "mass_kg",
    )
    for name, summary in table["lift"].items():
        cells = " | ".join(_quartiles(summary.get(key)) for key in keys)
        cells = cells.replace(" | " + _quartiles(summary.get("lost_at")) + " | ",
                              f" | {summary['lost']}: {_quartiles(summary.get('lost_at'))} | ", 1)  # fmt: skip
        lines.append(f"| {name} | {summary['count']} | {cells} |")
    return "\n".join(lines) + "\n"


def _describe(variant: str) -> str:
    spec, shipped = VARIANTS[variant], GripperSpec()
    if variant == "shipped-again":
        return "the shipped hand once more, last: how often replaying one state alone changes an outcome"
    changed = [f"{name} {getattr(spec, name):g}" for name in ("finger_force", "finger_friction",
               "pad_contact_stiffness", "pad_contact_damping", "pad_spinning_friction")
               if getattr(spec, name) != getattr(shipped, name)]  # fmt: skip
    return ", ".join(changed) or f"finger_force {spec.finger_force:g} N"


def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{name} {n}" for name, n in sorted(counts.items(), key=lambda item: -item[1])) or "-"


def _quartiles(values: list[float] | None) -> str:
    return "-" if values is None else " / ".join(f"{v:.3g}" for v in values)


def report(args: argparse.Namespace) -> int:
    """Print the tables; with ``--write``, also store them as report.md and report.json."""
    paths = sorted(args.folder.glob("round*.json"))
    if not paths:
        print(f"no rounds in {args.folder}")
        return 1
    variants = json.loads(paths[0].read_text())["variants"]
    densities = None
    if args.objects is not None:
        densities = {row["object"]: row["density"] for row in object_masses(args.objects)}
    table = tabulate(load_grasps(args.folder), variants, densities)
    text = f"{len(paths)} rounds in {args.folder.name}.\n\n" + render(table)
    print(text, end="")
    if args.write is not None:
        args.write.mkdir(parents=True, exist_ok=True)
        write_atomically(args.write / "report.md", text)
        # The objects that never slipped under the shipped hand are left out: the file stays small.
        slipping = {name: entry for name, entry in table["objects"].items() if entry["slipped"]}
        stored = {"rounds": len(paths), **table, "objects": slipping}
        write_atomically(args.write / "report.json", json.dumps(stored, indent=1) + "\n")
    return 0


# Masses ---------------------------------------------------------------------------------------
def mesh_volume(path: Path) -> tuple[float, np.ndarray, np.ndarray]:
    """A closed OBJ mesh's volume (m³), its centroid and its bounding-box extents (m)."""
    vertices, faces = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(v) for v in line.split()[1:4]])
        elif line.startswith("f "):
            corners = [int(c.split("/")[0]) for c in line.split()[1:]]
            faces += [(corners[0], corners[i], corners[i + 1]) for i in range(1, len(corners) - 1)]
    v = np.asarray(vertices)
    f = np.asarray(faces)
    f = np.where(f > 0, f - 1, len(v) + f)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    signed = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    volume = float(signed.sum())
    centroid = (signed[:, None] * (a + b + c) / 4.0).sum(axis=0) / volume if volume else v.mean(axis=0)
    return abs(volume), centroid, v.max(axis=0) - v.min(axis=0)


def object_masses(folder: Path) -> list[dict[str, Any]]:
    """Per URDF: its mass, its collision mesh's extents, volume and the density they imply, and
    how far the mesh origin (PyBullet's centre of mass: the URDFs give no inertial origin) lies
    from the mesh's centroid."""
    rows = []
    for urdf in sorted(folder.glob("*.urdf")):
        text = urdf.read_text()
        mass = re.search(r'<mass value="([^"]+)"', text)
        mesh = re.search(r'<collision>.*?<mesh filename="([^"]+)"', text, re.S)
        if not mass or not mesh:
            continue
        volume, centroid, extents = mesh_volume(urdf.parent / mesh.group(1))
        rows.append({"object": urdf.stem, "mass": float(mass.group(1)), "extents": extents.tolist(),
                     "volume": volume, "density": float(mass.group(1)) / volume if volume else np.nan,
                     "com_offset": float(np.linalg.norm(centroid))})  # fmt: skip
    return rows


def masses(args: argparse.Namespace) -> int:
    """Print the objects' masses against their sizes."""
    rows = object_masses(args.folder)
    if not rows:
        print(f"no URDFs in {args.folder}")
        return 1
    mass = np.array([r["mass"] for r in rows])
    density = np.array([r["density"] for r in rows])
    size = np.array([max(r["extents"]) for r in rows])
    offset = np.array([r["com_offset"] for r in rows])
    print(f"{len(rows)} objects in {args.folder}")
    print("quantile | mass kg | largest extent mm | density kg/m³ | origin from centroid mm")
    for q in (0, 10, 25, 50, 75, 90, 100):
        print(f"{q:8d} | {np.percentile(mass, q):7.3f} | {1000 * np.percentile(size, q):17.0f} | "
              f"{np.nanpercentile(density, q):13.0f} | {1000 * np.percentile(offset, q):23.1f}")  # fmt: skip
    print(f"heavier than 1 kg: {int(np.sum(mass > 1))}; density above 1000 kg/m³ (water): "
          f"{int(np.sum(density > 1000))}; origin more than 10 mm from the centroid: {int(np.sum(offset > 0.01))}")  # fmt: skip
    print("heaviest: " + ", ".join(f"{r['object'][:8]} {r['mass']:.2f} kg "
                                    f"({'x'.join(f'{1000 * e:.0f}' for e in r['extents'])} mm)"
                                    for r in sorted(rows, key=lambda r: -r["mass"])[:5]))  # fmt: skip
    return 0


def main(argv: list[str] | None = None) -> int:
    """``collect``, ``report`` or ``masses``, as the arguments say."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser(
        "collect", help="execute every default grasp of clutter-removal rounds per hand"
    )
    run.add_argument("--scene", choices=["pile", "packed", "blocks"], default="pile")
    run.add_argument("--objects", help="object set or URDF folder (study on training objects)")
    run.add_argument("--object-count", type=int, default=5)
    run.add_argument("--rounds", type=int, default=20)
    run.add_argument("--seed", type=int, default=11)
    run.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    run.add_argument("--out", type=Path, required=True)
    show = commands.add_parser("report", help="the shipped hand's outcomes against another hand's")
    show.add_argument("folder", type=Path)
    show.add_argument("--objects", type=Path, help="the rounds' URDF folder: count slips by density too")
    show.add_argument("--write", type=Path, help="also write report.md and report.json into this folder")
    replay = commands.add_parser("trace", help="replay one stored grasp and print its lift step by step")
    replay.add_argument("folder", type=Path)
    replay.add_argument("--objects", help="the object set the rounds were collected on")
    replay.add_argument("--scene", choices=["pile", "packed", "blocks"], default="pile")
    replay.add_argument("--object-count", type=int, default=5)
    replay.add_argument("--round", type=int, required=True)
    replay.add_argument("--look", type=int, required=True)
    replay.add_argument("--grasp", type=int, required=True, help="index in the look's answer")
    replay.add_argument("--every", type=int, default=5, help="print every this many lift steps")
    weigh = commands.add_parser("masses", help="the objects' masses against their sizes")
    weigh.add_argument("folder", type=Path)
    args = parser.parse_args(argv)
    return {"collect": collect, "report": report, "trace": trace, "masses": masses}[args.command](args)


if __name__ == "__main__":
    raise SystemExit(main())
