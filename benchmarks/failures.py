"""Which objects a clutter run's failed grasps were on: per object, the attempts that closed on it,
how they failed and what answered them; and, from ``rounds.csv`` beside it, the objects rounds left
on the table and how those rounds ended. A success rate hides whether its failures are spread over
the objects or piled on the few the hand cannot hold, which decide where effort goes.

    python -m benchmarks.failures RUN_FOLDER [RUN_FOLDER ...]   # the tables of each folder with grasps.csv

``benchmarks.report`` puts the tables of every ``docs/results/*/grasps.csv`` that names the objects
(``closed_on``, recorded since that column exists) on the benchmark page.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from benchmarks.published import published
from sim_worker.results import read_csv

#: How an attempt that closed on no object is listed.
NO_OBJECT = "(no object between the fingers)"


@dataclass
class ObjectAttempts:
    """The attempts whose closed hand touched one object (or several, named together)."""

    name: str
    attempts: int = 0
    failures: int = 0
    outcomes: Counter[str] = field(default_factory=Counter)
    answers: Counter[str] = field(default_factory=Counter)


def names_objects(rows: list[dict[str, str]]) -> bool:
    """Whether the run recorded the objects each attempt closed on (older runs did not)."""
    return bool(rows) and "closed_on" in rows[0]


def answered_by(row: dict[str, str]) -> str:
    """What answered an attempt's look: the network or the surface's pairs, and whether below the
    operating threshold (the service's fallback)."""
    source = "pairs" if row["model"] == "antipodal" else "network"
    return f"{source} below threshold" if row.get("fallback") == "1" else source


def by_object(rows: list[dict[str, str]]) -> list[ObjectAttempts]:
    """Per object the closed hand touched, its attempts, failures, failures' outcomes and what
    answered them; most failures first."""
    objects: dict[str, ObjectAttempts] = {}
    for row in rows:
        name = row["closed_on"] or NO_OBJECT
        entry = objects.setdefault(name, ObjectAttempts(name))
        entry.attempts += 1
        if row["outcome"] != "success":
            entry.failures += 1
            entry.outcomes[row["outcome"].replace("_", " ")] += 1
            entry.answers[answered_by(row)] += 1
    return sorted(objects.values(), key=lambda entry: (-entry.failures, -entry.attempts, entry.name))


def _counts(counter: Counter[str]) -> str:
    return ", ".join(f"{name} {count}" for name, count in counter.most_common())


def failures_table(rows: list[dict[str, str]]) -> str:
    """A Markdown table of the objects with a failure, and a line on how the failures spread and how
    the attempts fared that closed on neighbours together (the hand squeezes them apart)."""
    entries = [entry for entry in by_object(rows) if entry.failures]
    failed = sum(entry.failures for entry in entries)
    if not failed:
        return f"No failed attempt in {len(rows)}.\n"
    lines = [
        "| object the hand closed on | failed / attempts | how | answered by |",
        "| --- | ---: | --- | --- |",
        *(
            f"| {entry.name.replace('|', '/')} | {entry.failures} / {entry.attempts} | {_counts(entry.outcomes)} "
            f"| {_counts(entry.answers)} |"
            for entry in entries
        ),
    ]
    worst = sum(entry.failures for entry in entries[:2])
    together = [row for row in rows if "+" in row["closed_on"]]
    summary = (
        f"\n{failed} of {len(rows)} attempts failed, on {len(entries)} objects or groups; the two with the "
        f"most failures hold {worst} of them. Closed on two objects or more: {len(together)} attempts, "
        f"{sum(row['outcome'] != 'success' for row in together)} failed.\n"
    )
    return "\n".join(lines) + "\n" + summary


def left_table(rounds: list[dict[str, str]], most: int = 6) -> str:
    """A Markdown table of the ``most`` objects rounds left on the table most often, and how those
    rounds ended (``ended`` of ``rounds.csv``): two objects no planner removes read alike in cleared,
    while one planner's rounds end on two failures and the other's with nothing offered."""
    left: dict[str, Counter[str]] = {}
    for row in rounds:
        for name in filter(None, row["left"].split("+")):
            left.setdefault(name, Counter())[row["ended"].replace("_", " ")] += 1
    if not left:
        return f"No round of {len(rounds)} left an object on the table.\n"
    ranked = sorted(left.items(), key=lambda item: (-item[1].total(), item[0]))[:most]
    lines = [
        "| object left on the table | rounds | how those rounds ended |",
        "| --- | ---: | --- |",
        *(
            f"| {name.replace('|', '/')} | {endings.total()} | {_counts(endings)} |"
            for name, endings in ranked
        ),
    ]
    return "\n".join(lines) + "\n"


def folder_tables(folder: Path, attempts: list[dict[str, str]]) -> str:
    """The failures table of a folder's ``attempts`` (its ``grasps.csv``) and, where ``rounds.csv``
    is beside it, the objects its rounds left."""
    text = failures_table(attempts)
    rounds = read_csv(folder / "rounds.csv")
    return text + "\n" + left_table(rounds) if rounds else text


def run_title(folder: Path) -> str:
    """The folder's name with the planner, scenario, rounds and measuring date of its ``table.json``
    where there is one."""
    table = folder / "table.json"
    if not table.is_file():
        return folder.name
    row = json.loads(table.read_text())[0]
    title = f"`{folder.name}`: {row['planner']}, {row['scenario']}, {row['rounds']} rounds"
    measured = row.get("measured") or {}
    if measured.get("date"):
        title += f", measured {measured['date']} on {measured.get('cpu', 'an unrecorded CPU')}"
    return title


def failures_page(results: Path) -> str:
    """The table of every results folder under ``results`` whose ``grasps.csv`` names the objects."""
    sections = []
    for path in published(results, "grasps.csv"):
        rows = read_csv(path)
        if names_objects(rows):
            sections.append(f"**{run_title(path.parent)}**\n\n{folder_tables(path.parent, rows)}")
    if not sections:
        return "No result folder holds a `grasps.csv` that names the objects closed on yet.\n"
    return "\n".join(sections)


def main(argv: list[str] | None = None) -> int:
    """Print the table of each folder; 2 when one holds no grasps.csv that names the objects."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("folders", nargs="+", type=Path, help="clutter results folders (holding grasps.csv)")
    args = parser.parse_args(argv)
    status = 0
    for folder in args.folders:
        path = folder / "grasps.csv"
        if not path.is_file():
            print(f"{folder}: no grasps.csv there", file=sys.stderr)
            status = 2
            continue
        rows = read_csv(path)
        if not names_objects(rows):
            print(
                f"{folder}: its grasps.csv predates the closed_on column; run the benchmark again",
                file=sys.stderr,
            )
            status = 2
            continue
        print(f"{run_title(folder)}\n\n{folder_tables(folder, rows)}")
    return status


if __name__ == "__main__":
    sys.exit(main())
