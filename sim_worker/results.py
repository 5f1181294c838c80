"""Clutter-removal results on disk: written atomically per round, resumable after a stop.

Layout of a results folder:
- ``config.json``: the run's settings; a resumed run must match them.
- ``rounds.csv``: one row per *finished* round (round_id, scene_id, object_count, ...).
- ``grasps.csv``: one row per attempt, VGN's columns first (round_id, scene_id, qx, qy, qz,
  qw, x, y, z, width, score, label, integration_time, planning_time) then ours.
- ``summary.json``: the metrics over all finished rounds.
A round's rows are committed together (temp file + rename), so an interrupted round leaves
no trace and is simply run again.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from vgn_data.files import check_settings, remove_stale_temporaries, write_atomically

ROUND_COLUMNS = [
    "round_id",
    "scene_id",
    "object_count",
    "cleared",
    "attempts",
    "successes",
    "seconds",
    # why the round ended (ROUND_ENDINGS), how many objects were left and which; when the last look
    # offered nothing, what its planner found before the checks and what each check dropped
    "ended",
    "remaining",
    "left",
    "last_candidates",
    "last_clearance_dropped",
    "last_grip_dropped",
    "last_workspace_dropped",
]
#: Why a round ends: the table is empty; two attempts in a row failed; a look offered no grasp
#: while objects remained; the closed loop withdrew too often in a row.
ROUND_ENDINGS = ("cleared", "failures", "no_grasp", "withdrawn")
GRASP_COLUMNS = [
    "round_id",
    "scene_id",
    "qx",
    "qy",
    "qz",
    "qw",
    "x",
    "y",
    "z",
    "width",
    "score",
    "label",
    "integration_time",
    "planning_time",
    # ours, after VGN's
    "client_planning_time",
    "outcome",
    "grasp_count",
    "trial_time",
    # where the approach stopped on contact: what it touched, how far (m) before the grasp pose
    "contact",
    "contact_distance",
    # the look before the grasp: frames fused, ms from the first frame to the plan
    "frames",
    "first_grasp_ms",
    # closing the loop: "push"/"drop" when the object moved; what the closed loop did, its looks
    "disturbance",
    "loop",
    "looks",
    # what answered the look: the weights' id or "antipodal" (the surface's pairs), at which threshold,
    # cleared for how wide a hand (m grown on every side; empty without the clearance check)
    "model",
    "threshold",
    "clearance_margin",
    # whether nothing passed at the operating threshold and the service answered below it; the
    # objects the closed hand touched (empty when it never closed)
    "fallback",
    "closed_on",
]


#: Columns that measure time: they differ between two runs of the same rounds, all else is equal.
TIMING_COLUMNS = frozenset(
    {"seconds", "integration_time", "planning_time", "client_planning_time", "trial_time", "first_grasp_ms"}
)


@dataclass
class RoundRecord:
    """One clutter-removal round: its scene, how many objects it started with and cleared, its attempts and
    successes, and a row per grasp."""

    round_id: int
    scene_id: str
    object_count: int
    cleared: int = 0
    attempts: int = 0
    successes: int = 0
    seconds: float = 0.0
    ended: str = ""
    remaining: int = 0
    left: str = ""  # the remaining objects' file names, "+"-joined
    last_candidates: int | str = ""
    last_clearance_dropped: int | str = ""
    last_grip_dropped: int | str = ""
    last_workspace_dropped: int | str = ""
    grasps: list[dict[str, Any]] = field(default_factory=list)


def _csv_text(columns: list[str], rows: list[dict[str, Any]]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows({c: row.get(c, "") for c in columns} for row in rows)
    return buffer.getvalue()


def read_csv(path: Path) -> list[dict[str, str]]:
    """The rows of a results CSV (``rounds.csv``, ``grasps.csv``); none where the file is missing."""
    if not path.exists():
        return []
    with path.open(newline="") as stream:
        return list(csv.DictReader(stream))


class ResultsFolder:
    """Reads what a previous run finished and commits each new round atomically."""

    def __init__(self, path: Path, config: dict[str, Any]) -> None:
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)
        check_settings(self.path / "config.json", config, may_change=("rounds",))
        remove_stale_temporaries(self.path)
        self.rounds = read_csv(self.path / "rounds.csv")
        finished = {row["round_id"] for row in self.rounds}
        # Rows of a round that never finished are dropped: that round runs again.
        self.grasps = [row for row in read_csv(self.path / "grasps.csv") if row["round_id"] in finished]

    def finished_rounds(self) -> set[int]:
        """Round ids already committed: a resumed run skips them."""
        return {int(row["round_id"]) for row in self.rounds}

    def commit(self, record: RoundRecord) -> None:
        """Add a finished round: grasps first, then the round row that makes them count."""
        round_row = {k: v for k, v in asdict(record).items() if k != "grasps"}
        self.grasps.extend(record.grasps)
        write_atomically(self.path / "grasps.csv", _csv_text(GRASP_COLUMNS, self.grasps))
        self.rounds.append(round_row)
        write_atomically(self.path / "rounds.csv", _csv_text(ROUND_COLUMNS, self.rounds))

    def write_summary(self, summary: dict[str, Any]) -> None:
        """Replace summary.json (atomically) with the summary over every finished round."""
        write_atomically(self.path / "summary.json", json.dumps(summary, indent=2) + "\n")
