"""Clear-scene runs as a user starts them (``vgn-client clear-scene --sim``), and the checks
every finished run's results folder must pass."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

from sim_worker.results import ROUND_ENDINGS, TIMING_COLUMNS


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as stream:
        return list(csv.DictReader(stream))


def rows_without_timings(path: Path) -> list[dict[str, str]]:
    """The rows of a results CSV without the columns that hold wall-clock times, which differ
    between any two runs of the same rounds."""
    return [{k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in read_csv(path)]


def check_results(results: Path, rounds: int) -> dict:
    summary = json.loads((results / "summary.json").read_text())
    round_rows = read_csv(results / "rounds.csv")
    grasp_rows = read_csv(results / "grasps.csv")
    assert len(round_rows) == summary["rounds"] == rounds
    # A closed loop's withdrawn approaches have rows too, but are no attempts.
    attempted = [g for g in grasp_rows if g.get("outcome") != "interrupted"]
    assert len(attempted) == summary["attempts"] == sum(int(r["attempts"]) for r in round_rows)
    assert summary["successes"] == sum(int(g["label"]) for g in grasp_rows)
    outcomes = summary["outcomes"]
    assert sum(outcomes.values()) == summary["attempts"], "every attempt falls in one outcome class"
    assert outcomes["success"] == summary["successes"]
    for g in grasp_rows:  # a contact stop names what it touched and how far before the grasp pose
        assert bool(g["contact"]) == (g["contact_distance"] != "")
        if g["outcome"] == "approach_contact":
            assert g["contact"] and 0 <= float(g["contact_distance"]) <= 0.05
    for r in round_rows:  # each round ends: table clear, no grasp found, or 2 failures in a row
        labels = [int(g["label"]) for g in attempted if g["round_id"] == r["round_id"]]
        assert "0,0" not in ",".join(map(str, labels[:-1])), "no attempt after two failures in a row"
        assert int(r["cleared"]) <= int(r["object_count"])
        # ... and says which, with the objects it left and, for a look that offered nothing, its drops
        assert r["ended"] in ROUND_ENDINGS
        assert (r["ended"] == "cleared") == (int(r["remaining"]) == 0)
        assert len(r["left"].split("+")) == int(r["remaining"]) if r["left"] else int(r["remaining"]) == 0
        assert (r["ended"] == "failures") == (labels[-2:] == [0, 0] and int(r["remaining"]) > 0)
        if r["ended"] == "no_grasp":
            stages = ("last_workspace_dropped", "last_clearance_dropped", "last_grip_dropped")
            dropped = sum(int(r[key] or 0) for key in stages)
            assert int(r["last_candidates"]) == dropped
    endings = summary["endings"]
    assert sum(endings[key] for key in ROUND_ENDINGS) == rounds
    stages = ("threshold", "workspace", "clearance", "grip")
    assert sum(endings[stage] for stage in stages) == endings["no_grasp"]
    for g in grasp_rows:
        assert float(g["planning_time"]) > 0
        if g["client_planning_time"]:  # a wrist scan plans after every frame: no single request
            assert float(g["client_planning_time"]) >= float(g["planning_time"])
        assert float(g["integration_time"]) > 0
    return summary


def clear_scene(*args: str) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "client.cli", "clear-scene", "--sim", "--renderer", "tiny", *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


def assert_same_results(expected: Path, got: Path) -> None:
    """Two results folders hold the same rounds and attempts, timing columns apart."""
    for name in ("rounds.csv", "grasps.csv"):
        rows = rows_without_timings(expected / name)
        assert rows, f"{name} holds rows"
        assert rows_without_timings(got / name) == rows, name
