"""``benchmarks.slips``: the hand variants, the lift watch on a box of known weight, the report's
tabulation on a synthetic record and the mesh volumes behind the mass check."""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import numpy as np
import pybullet
import pytest
from scipy.spatial.transform import Rotation

from benchmarks import slips
from sim_worker.grasping import Outcome, execute_grasp
from sim_worker.gripper import Gripper, GripperSpec
from sim_worker.world import TABLE_Z, SimObject, World
from vgn_contract.geometry import matrix_from_pose


def test_each_variant_differs_from_the_shipped_hand_only_where_it_says():
    shipped = GripperSpec()
    assert slips.VARIANTS["shipped"] == shipped == slips.VARIANTS["shipped-again"]
    changed = {
        name: {f.name for f in fields(GripperSpec) if getattr(spec, f.name) != getattr(shipped, f.name)}
        for name, spec in slips.VARIANTS.items()
    }
    assert changed["franka-70N"] == changed["franka-140N"] == {"finger_force"}
    assert changed["torsion-3mm"] == {"pad_spinning_friction"}
    assert slips.VARIANTS["franka-70N"].finger_force == 70.0
    assert slips.VARIANTS["franka-140N"].finger_force == 140.0


@pytest.mark.parametrize("variant, force", [("shipped", 20.0), ("franka-70N", 70.0)])
def test_a_variant_squeezes_with_its_force_and_the_watch_measures_it(variant, force):
    with World(renderer="tiny") as world:
        half = 0.025
        shape = world.p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[half] * 3)
        box = world.p.createMultiBody(0.1, shape, -1, [0.15, 0.15, TABLE_Z + half + 0.001])
        world.p.changeDynamics(box, -1, lateralFriction=world.config.object_friction)
        world.objects[box] = SimObject(box, Path("box.urdf"), 1.0)
        world.wait_for_rest()
        gripper = Gripper(world)
        gripper.use_spec(slips.VARIANTS[variant])
        watch = slips.LiftWatch(world, gripper)
        pose = matrix_from_pose(np.array([0.15, 0.15, TABLE_Z + 2 * half + 0.02]),
                                Rotation.from_euler("x", np.pi).as_quat())  # fmt: skip
        trial = execute_grasp(world, gripper, pose, remove_grasped=False, on_lift=watch)
    assert trial.outcome is Outcome.SUCCESS
    assert watch.body == box and watch.lost_at is None
    assert watch.start_force == pytest.approx(force, rel=0.15), "two fingers each pressing F squeeze with F"
    assert watch.weight_ratio == pytest.approx(0.1 * 9.81 / (2 * watch.start_force), rel=1e-6)
    assert watch.lever_mm < 3.0 and watch.turn_deg < 2.0, (
        "a box grasped over its centre neither tilts nor turns"
    )


def grasp_row(outcomes: dict[str, str], mass: float | None = 0.1, name: str = "can") -> dict:
    watch = {"start_force": 18.0, "min_force": 17.0, "lever_mm": 10.0, "weight_ratio": 0.03, "lost_at": None,
             "turn_deg": 5.0, "slide_mm": 1.0}  # fmt: skip
    row = {"quality": 0.9, "width": 0.05, "outcomes": outcomes, "watch": {v: watch for v in outcomes}}
    if mass is not None:
        row.update(object=name, mass=mass, scale=1.0)
    return row


SYNTHETIC = [
    grasp_row({"shipped": "slipped", "franka-70N": "success"}, mass=1.5, name="heavy"),
    grasp_row({"shipped": "slipped", "franka-70N": "slipped"}, mass=0.05, name="light"),
    grasp_row({"shipped": "success", "franka-70N": "slipped"}, mass=0.05, name="light"),
    grasp_row({"shipped": "success", "franka-70N": "success"}, mass=0.3, name="can"),
    grasp_row({"shipped": "approach_contact", "franka-70N": "approach_contact"}, mass=None),
]


def test_the_report_tabulates_each_hand_against_the_shipped_one():
    table = slips.tabulate(SYNTHETIC, ["shipped", "franka-70N"])
    assert table["grasps"] == 5
    assert table["outcomes"]["shipped"] == {"slipped": 2, "success": 2, "approach_contact": 1}
    assert table["slipped"] == 2 and table["slipped_then"]["franka-70N"] == {"success": 1, "slipped": 1}
    assert table["succeeded"] == 2 and table["succeeded_then"]["franka-70N"] == {"slipped": 1, "success": 1}
    assert table["changed"]["franka-70N"] == [["slipped", "success", 1], ["success", "slipped", 1]]
    assert list(table["objects"]) == ["heavy", "light", "can"], "most slips first, then by name"
    assert table["objects"]["light"] == {"mass": 0.05, "held_at_close": 2, "slipped": 1, "held_franka-70N": 0}
    bins = {tuple(b["bin"]): b for b in table["by_mass"]}
    assert bins[(0.0, 0.1)]["held_at_close"] == 2 and bins[(0.0, 0.1)]["slipped"] == {
        "shipped": 1,
        "franka-70N": 2,
    }
    assert bins[(1.0, 2.0)]["slipped"] == {"shipped": 1, "franka-70N": 0}
    assert sum(b["held_at_close"] for b in table["by_mass"]) == 4, "a grasp that held nothing has no mass"
    assert table["lift"]["slipped (shipped)"]["count"] == 2
    text = slips.render(table)
    assert "| slipped | 2 | 2 |" in text and "| total | 5 | 5 |" in text


def test_report_writes_its_tables(tmp_path: Path, capsys):
    record = {"round": 0, "seed": 1, "variants": ["shipped", "franka-70N"], "looks": [{"objects": 5,
              "grasps": SYNTHETIC}]}  # fmt: skip
    (tmp_path / "round0000.json").write_text(json.dumps(record))
    out = tmp_path / "docs"
    assert slips.main(["report", str(tmp_path), "--write", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("1 rounds in") and (out / "report.md").read_text() == printed
    assert json.loads((out / "report.json").read_text())["slipped"] == 2


def test_mesh_volume_of_a_cube(tmp_path: Path):
    corners = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    quads = [(1, 3, 4, 2), (5, 6, 8, 7), (1, 2, 6, 5), (3, 7, 8, 4), (1, 5, 7, 3), (2, 4, 8, 6)]
    obj = tmp_path / "cube.obj"
    obj.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in corners) + "".join(
        "f " + " ".join(f"{i}//{i}" for i in quad) + "\n" for quad in quads))  # fmt: skip
    volume, centroid, extents = slips.mesh_volume(obj)
    assert volume == pytest.approx(1.0) and np.allclose(centroid, 0.5) and np.allclose(extents, 1.0)
