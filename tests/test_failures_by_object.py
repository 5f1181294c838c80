"""The per-object failure tables (``benchmarks.failures``) over clutter runs' ``grasps.csv``."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from benchmarks import failures
from benchmarks.report import render_all
from sim_worker.results import GRASP_COLUMNS, ROUND_COLUMNS, read_csv


def write_run(
    folder: Path, attempts: list[tuple[str, str, str, str]], columns: list[str] = GRASP_COLUMNS
) -> Path:
    """A results folder whose grasps.csv holds ``attempts`` as (closed_on, outcome, model, fallback)."""
    folder.mkdir(parents=True)
    with (folder / "grasps.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for closed_on, outcome, model, fallback in attempts:
            writer.writerow(
                {"closed_on": closed_on, "outcome": outcome, "model": model, "fallback": fallback}
            )
    table = [{"planner": "vgn+turns+clearance+grip", "scenario": "pile-5", "rounds": 3,
              "measured": {"date": "2026-11-29", "cpu": "AMD EPYC", "cores": 2}}]  # fmt: skip
    (folder / "table.json").write_text(json.dumps(table))
    return folder


ATTEMPTS = [
    ("bowl", "nothing_held", "antipodal", "1"),
    ("bowl", "slipped", "antipodal", "0"),
    ("box", "success", "091fde649204", "0"),
    ("box", "slipped", "091fde649204", "1"),
    ("", "nothing_held", "antipodal", "0"),
    ("cup+box", "success", "091fde649204", "0"),
]


def test_failures_are_counted_per_object_most_first(tmp_path: Path):
    rows = read_csv(write_run(tmp_path / "run", ATTEMPTS) / "grasps.csv")
    entries = failures.by_object(rows)
    assert [(entry.name, entry.failures, entry.attempts) for entry in entries] == [
        ("bowl", 2, 2), ("box", 1, 2), (failures.NO_OBJECT, 1, 1), ("cup+box", 0, 1),
    ]  # fmt: skip
    bowl = entries[0]
    assert bowl.outcomes == {"nothing held": 1, "slipped": 1}
    assert bowl.answers == {"pairs below threshold": 1, "pairs": 1}
    assert entries[1].answers == {"network below threshold": 1}
    table = failures.failures_table(rows)
    assert "| bowl | 2 / 2 |" in table and "cup+box" not in table, "objects that never failed are left out"
    assert (
        "4 of 6 attempts failed, on 3 objects or groups; the two with the most failures hold 3 of them. "
        "Closed on two objects or more: 1 attempts, 0 failed." in table
    )


def test_the_objects_rounds_left_are_counted_with_how_those_rounds_ended(tmp_path: Path):
    folder = write_run(tmp_path / "run", ATTEMPTS)
    rounds = [("bowl+box", "failures"), ("bowl", "no_grasp"), ("", "cleared")]
    with (folder / "rounds.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=ROUND_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows({"left": left, "ended": ended} for left, ended in rounds)
    text = failures.folder_tables(folder, read_csv(folder / "grasps.csv"))
    assert "| bowl | 2 | failures 1, no grasp 1 |" in text and "| box | 1 | failures 1 |" in text
    assert text.index("| bowl | 2 |") < text.index("| box | 1 |"), "most often left first"
    assert "No round of 1 left" in failures.left_table([{"left": "", "ended": "cleared"}])


def test_the_page_lists_runs_that_name_objects_and_the_command_refuses_older_ones(tmp_path: Path, capsys):
    named = write_run(tmp_path / "results" / "named", ATTEMPTS)
    older = [column for column in GRASP_COLUMNS if column != "closed_on"]
    old = write_run(tmp_path / "results" / "old", ATTEMPTS, older)
    page = failures.failures_page(tmp_path / "results")
    assert "`named`: vgn+turns+clearance+grip, pile-5, 3 rounds, measured 2026-11-29 on AMD EPYC" in page
    assert "`old`" not in page
    assert failures.main([str(named)]) == 0
    assert "| bowl | 2 / 2 |" in capsys.readouterr().out
    assert failures.main([str(old)]) == 2
    assert "predates the closed_on column" in capsys.readouterr().err
    assert failures.main([str(tmp_path / "missing")]) == 2


def test_only_the_files_a_result_folder_publishes_are_read(tmp_path: Path):
    """A run's per-scenario folder stays out of the repository (docs/results/.gitignore): a page
    that read it would differ between where the run was made and a fresh clone."""
    write_run(tmp_path / "results" / "named" / "vgn-random-pile-5", ATTEMPTS)
    assert "No result folder holds" in failures.failures_page(tmp_path / "results")


def test_the_report_writes_the_page(tmp_path: Path):
    write_run(tmp_path / "results" / "named", ATTEMPTS)
    outputs = render_all(tmp_path / "results", tmp_path / "generated", readme=None)
    assert "| bowl | 2 / 2 |" in outputs[tmp_path / "generated" / "failures-by-object.md"]
