"""The clutter benchmark's report draws its table as a bar chart beside the paper's rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from benchmarks.chart import chart_series
from benchmarks.clutter import PAPER_GPD, PAPER_TABLE_1, combinations, main, markdown_table, parse_args
from sim_worker.clutter import ClutterConfig
from sim_worker.results import ResultsFolder, RoundRecord


def finished_round(round_id: int, labels: list[int], objects: int = 5) -> RoundRecord:
    rows = [{"round_id": round_id, "scene_id": f"1-{round_id}", "label": label, "planning_time": 12.0}
            for label in labels]  # fmt: skip
    return RoundRecord(round_id, f"1-{round_id}", objects, cleared=sum(labels), attempts=len(labels),
                       successes=sum(labels), seconds=1.0, grasps=rows)  # fmt: skip


def test_report_writes_the_chart(tmp_path: Path, capsys) -> None:
    outcomes = {("vgn", "blocks-5"): [1, 0, 1, 1], ("antipodal", "blocks-5"): [1, 1, 1, 1, 1],
                ("vgn", "pile-5"): [0, 1]}  # fmt: skip
    for (planner, scenario), labels in outcomes.items():
        scene, count = scenario.split("-")
        config = ClutterConfig(scene=scene, object_count=int(count), planner=planner, model="m").as_json()
        ResultsFolder(tmp_path / f"{planner}-best-{scenario}", config).commit(finished_round(0, labels))
    argv = ["--report", "--out", str(tmp_path), "--selections", "best", "--scenarios", "blocks-5", "pile-5",
            "--no-turn-average", "--no-clearance", "--no-grip"]  # fmt: skip
    assert main(argv) == 0
    assert f"chart: {tmp_path / 'table.png'}" in capsys.readouterr().out
    chart = np.asarray(Image.open(tmp_path / "table.png").convert("RGB"))
    assert chart.shape[0] > 300 and len(np.unique(chart.reshape(-1, 3), axis=0)) > 50


def test_series_pair_measured_runs_with_the_paper() -> None:
    rows = [
        {"planner": "vgn", "selection": "best", "scenario": "pile-5", "success_rate": 50.0,
         "success_rate_ci95": (30.0, 70.0), "percent_cleared": 40.0, "percent_cleared_ci95": (20.0, 60.0)},
        {"planner": "antipodal", "selection": "best", "scenario": "blocks-5", "success_rate": None,
         "success_rate_ci95": (0.0, 0.0), "percent_cleared": 0.0, "percent_cleared_ci95": (0.0, 10.0)},
    ]  # fmt: skip
    scenarios, series = chart_series(rows, PAPER_TABLE_1, PAPER_GPD)
    assert scenarios == ["pile-5", "blocks-5"]
    assert [s.label for s in series] == ["vgn (best)", "antipodal (best)", "paper VGN ε=0.9", "paper GPD"]
    assert series[0].success == [(50.0, 30.0, 70.0), None] and series[1].success == [None, None]
    assert series[1].cleared == [None, (0.0, 0.0, 10.0)]
    assert series[2].success == [(62.3,) * 3, (87.6,) * 3] and series[3].cleared[0] == (26.1,) * 3


def test_table_header_names_the_frames_a_round_used() -> None:
    fixed = markdown_table([], parse_args(["--views", "side", "--noise"])).splitlines()[0]
    wrist = markdown_table([], parse_args(["--scan", "wrist"])).splitlines()[0]
    assert "side view(s), depth noise" in fixed
    assert "wrist scan" in wrist and "view(s)" not in wrist
    assert ClutterConfig(scene="pile", object_count=5, scan="wrist").looking == "wrist scan"
    assert ClutterConfig(scene="pile", object_count=5, views="side").looking == "side view(s)"


def test_the_settings_line_names_the_objects_of_the_scenes_run() -> None:
    def settings(*argv: str) -> str:
        return markdown_table([], parse_args(list(argv))).splitlines()[0]

    assert settings("--scenarios", "pile-5").endswith("six view(s), pile objects pybullet_data")
    assert settings("--scenarios", "pile-5", "packed-5", "--pile-objects", "/x/heldout").endswith(
        "pile objects heldout, packed objects pybullet_data"
    )
    assert settings("--scenarios", "pile-5", "--pile-objects", "pybullet").endswith(
        "pile objects pybullet_data"
    ), "the pybullet set by name reads as by default: the report tells cross-source rows by it"
    assert settings("--scenarios", "pile-5", "--pile-objects", "shapes").endswith("pile objects shapes")
    assert "objects" not in settings("--scenarios", "blocks-5")


def test_one_random_view_gets_its_own_folders_and_rows() -> None:
    args = parse_args(
        ["--views", "random", "--scenarios", "pile-5", "--planners", "vgn", "--selections", "random"]
    )
    folders = [folder.name for *_, folder in combinations(args)]
    assert folders == ["vgn-random-pile-5-random"]
    assert "random view(s)" in markdown_table([], args).splitlines()[0]
