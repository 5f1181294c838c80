"""Clutter removal: results files, resume, metrics, and short runs through a real service."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks import failures
from service.clearance import FALLBACK_MARGIN, ClearanceConfig
from sim_worker.camera import WORKSPACE_CENTRE
from sim_worker.clutter import camera_views
from sim_worker.metrics import failure_breakdown, summarize, wilson_interval
from sim_worker.results import GRASP_COLUMNS, ResultsFolder, RoundRecord
from tests.helpers.runs import check_results, clear_scene, read_csv
from vgn_contract.gripper_description import builtin_gripper
from vgn_contract.schemas import (
    ANTIPODAL_DEFAULT_THRESHOLD,
    GraspDefaults,
    GraspResult,
    ModelInfo,
    OneViewModel,
)

VGN_COLUMNS = ["round_id", "scene_id", "qx", "qy", "qz", "qw", "x", "y", "z", "width", "score", "label",
               "integration_time", "planning_time"]  # fmt: skip


def record(round_id: int, labels: list[int], objects: int = 5) -> RoundRecord:
    rows = [{"round_id": round_id, "scene_id": f"s{round_id}", "label": label, "planning_time": 10.0}
            for label in labels]  # fmt: skip
    return RoundRecord(round_id, f"s{round_id}", objects, cleared=sum(labels), attempts=len(labels),
                       successes=sum(labels), seconds=1.0, grasps=rows)  # fmt: skip


def test_grasps_csv_starts_with_vgn_columns():
    assert GRASP_COLUMNS[: len(VGN_COLUMNS)] == VGN_COLUMNS


def test_rounds_commit_atomically_and_resume(tmp_path: Path):
    config = {"scene": "blocks", "rounds": 3, "seed": 1}
    folder = ResultsFolder(tmp_path, config)
    folder.commit(record(0, [1, 0, 1]))
    # An interrupted round 1 left grasp rows but no round row: they must not count.
    with (tmp_path / "grasps.csv").open("a") as stream:
        stream.write("1,s1,0,0,0,1,0.1,0.1,0.1,0.05,0.95,1,1.0,10.0,,,,\n")
    resumed = ResultsFolder(tmp_path, {**config, "rounds": 5})  # more rounds may be asked for
    assert resumed.finished_rounds() == {0}
    assert [row["round_id"] for row in resumed.grasps] == ["0", "0", "0"]
    resumed.commit(record(1, [0, 0]))
    assert [row["round_id"] for row in read_csv(tmp_path / "rounds.csv")] == ["0", "1"]
    assert len(read_csv(tmp_path / "grasps.csv")) == 5
    assert not list(tmp_path.glob(".*.tmp")), "no temporary files left behind"


def test_resume_with_other_settings_is_refused(tmp_path: Path):
    ResultsFolder(tmp_path, {"scene": "blocks", "seed": 1, "rounds": 1})
    with pytest.raises(ValueError, match="seed"):
        ResultsFolder(tmp_path, {"scene": "blocks", "seed": 2, "rounds": 1})


def test_metrics_follow_the_paper():
    rounds = [{"object_count": 5, "cleared": 4, "attempts": 5, "successes": 4, "seconds": 2.0},
              {"object_count": 5, "cleared": 1, "attempts": 3, "successes": 1, "seconds": 4.0}]  # fmt: skip
    grasps = [
        {"planning_time": t, "integration_time": 5.0, "client_planning_time": t + 1} for t in (10, 20, 30)
    ]
    summary = summarize(rounds, grasps)
    assert summary["success_rate"] == pytest.approx(62.5)  # 5 successes / 8 attempts
    assert summary["percent_cleared"] == pytest.approx(50.0)  # 5 removed / 10 placed
    assert summary["planning_ms"] == {"mean": 20.0, "p50": 20.0}
    low, high = summary["success_rate_ci95"]
    assert low < 62.5 < high


def test_outcomes_are_counted_by_failure_class():
    grasps = [{"outcome": o} for o in
              ["success", "approach_contact", "approach_contact", "nothing_held", "slipped", "pregrasp_collision"]]  # fmt: skip
    counts = summarize([], grasps)["outcomes"]
    assert counts == {"success": 1, "approach_contact": 2, "nothing_held": 1, "slipped": 1, "collision": 1}
    assert failure_breakdown({"outcomes": counts}) == (
        "approach contact 2, nothing held 1, slipped 1, collision 1"
    )


def test_wilson_interval_known_values():
    assert wilson_interval(0, 0) == (0.0, 0.0)
    assert wilson_interval(50, 100) == (40.4, 59.6)
    low, high = wilson_interval(10, 10)
    assert high == 100.0 and 69 < low < 73


#: The clearance and grip checks drop every grasp of the random weights the test services load,
#: so runs that must execute grasps turn them off.
UNCHECKED = ("--no-clearance", "--no-grip")


def test_short_run_through_a_real_service_and_resume(server, tmp_path: Path):
    results = tmp_path / "run"
    common = ["--url", server.url, "--object-count", "3", "--threshold", "0.5", *UNCHECKED,
              "--results", str(results)]  # fmt: skip
    first = clear_scene(*common, "--rounds", "1")
    assert first.returncode == 0, first.stderr
    assert "success rate" in first.stdout and "percent cleared" in first.stdout
    assert check_results(results, 1)["attempts"] > 0
    rounds_before = (results / "rounds.csv").read_text()
    second = clear_scene(*common, "--rounds", "2")
    assert second.returncode == 0, second.stderr
    assert "1 of 2 rounds already done" in second.stderr
    check_results(results, 2)
    assert (results / "rounds.csv").read_text().startswith(rounds_before), "round 0 was kept, not rerun"


def test_embedded_service_run_with_images(random_checkpoint: Path, tmp_path: Path):
    results = tmp_path / "embedded"
    run = clear_scene("--model", str(random_checkpoint), "--rounds", "1", "--object-count", "2",
                      "--threshold", "0.5", *UNCHECKED, "--results", str(results), "--save-images")  # fmt: skip
    assert run.returncode == 0, run.stderr
    summary = check_results(results, 1)
    assert summary["attempts"] > 0
    assert len(list((results / "images").glob("round*_attempt*.png"))) == summary["attempts"]
    assert (results / "images" / "round0000_sheet.png").exists()


def test_without_a_model_the_run_explains_itself(tmp_path: Path, monkeypatch):
    monkeypatch.setenv("VGN_MODEL", "none")  # the packaged default is not loaded either
    run = clear_scene("--rounds", "1", "--results", str(tmp_path / "r"))
    assert run.returncode == 2
    assert "no model is configured" in run.stderr and "--model" in run.stderr


@pytest.mark.slow
@pytest.mark.parametrize("scene, extra", [("pile", ["--object-count", "10", "--noise"]),
                                          ("packed", ["--views", "side", "--selection", "random"])])  # fmt: skip
def test_longer_runs(server, tmp_path: Path, scene: str, extra: list[str]):
    results = tmp_path / scene
    run = clear_scene("--url", server.url, "--scene", scene, "--rounds", "3", "--threshold", "0.5", *UNCHECKED,
                      "--results", str(results), *extra)  # fmt: skip
    assert run.returncode == 0, run.stderr
    check_results(results, 3)


def test_baseline_planner_needs_no_model(tmp_path: Path, monkeypatch):
    """clear-scene with the service's antipodal baseline runs on an embedded service without weights."""
    monkeypatch.setenv("VGN_MODEL", "none")
    results = tmp_path / "baseline"
    run = clear_scene(
        "--planner", "antipodal", "--rounds", "1", "--object-count", "2", "--results", str(results)
    )
    assert run.returncode == 0, run.stderr
    summary = check_results(results, 1)
    assert json.loads((results / "config.json").read_text())["model"] == "antipodal"
    assert summary["rounds"] == 1


def test_benchmark_table_next_to_the_paper(tmp_path: Path):
    """The plain planner (no clearance or grip check), as the paper measures it, beside the paper's rows."""
    from benchmarks.clutter import main

    out = tmp_path / "bench"
    assert main(["--planners", "antipodal", "--selections", "best", "--scenarios", "blocks-5", "--rounds", "1",
                 "--renderer", "tiny", "--no-clearance", "--no-grip", "--out", str(out)]) == 0  # fmt: skip
    rows = json.loads((out / "table.json").read_text())
    assert [(r["planner"], r["scenario"], r["rounds"]) for r in rows] == [("antipodal", "blocks-5", 1)]
    assert "| antipodal | best | 0.5 | blocks-5 | 1 |" in (out / "table.md").read_text()
    table = (out / "table.md").read_text()
    assert "approach contact / nothing held / slipped / collision" in table
    outcomes = rows[0]["outcomes"]
    failures = " / ".join(
        str(outcomes[k]) for k in ("approach_contact", "nothing_held", "slipped", "collision")
    )
    assert f"| {failures} |" in table, "the failure breakdown is in the row"
    assert "87.6 / 90.1" in table and "88.6 / 39.4" in table, "the paper's Table 1 rows stand beside ours"
    assert (out / "antipodal-best-blocks-5" / "rounds.csv").exists()
    (out / "table.md").unlink()
    assert main(["--report", "--no-clearance", "--no-grip", "--out", str(out)]) == 0, (
        "the table again, running nothing"
    )
    assert "| antipodal | best | 0.5 | blocks-5 | 1 |" in (out / "table.md").read_text()


@pytest.mark.parametrize(
    ("options", "averaged", "checked"),
    [
        ((), True, (True, True)),
        (("--no-turn-average", "--no-clearance", "--no-grip"), False, (False, False)),
        (("--no-clearance",), True, (False, True)),
        (("--no-grip",), True, (True, False)),
    ],
)
def test_clear_scene_records_the_services_defaults_or_the_choice(
    server, tmp_path: Path, options: tuple[str, ...], averaged: bool, checked: tuple[bool, bool]
):
    """Without an option the service's default applies (all on here) and is recorded as such;
    an option turned off is left out of config.json, as in folders from before the options.
    ``checked``: (clearance, grip)."""
    results = tmp_path / "run"
    run = clear_scene("--url", server.url, "--rounds", "1", "--object-count", "2", "--threshold", "0.5",
                      *options, "--results", str(results))  # fmt: skip
    assert run.returncode == 0, run.stderr
    check_results(results, 1)
    config = json.loads((results / "config.json").read_text())
    recorded = (config.get("turn_average", False), config.get("clearance", False), config.get("grip", False))
    assert recorded == (averaged, *checked)
    said = ("turn averaging" in run.stdout, "clearance check" in run.stdout, "grip check" in run.stdout)
    assert said == (averaged, *checked)


def test_a_run_that_names_no_threshold_leaves_it_and_the_fallback_to_the_service(server, tmp_path: Path):
    """With the checks on and no threshold named, config.json records the service's operating threshold
    and its fallback as ``/model`` reports them, and every answer (a fallen-back one too) agrees."""
    from client.http import VGNClient

    results = tmp_path / "run"
    run = clear_scene("--url", server.url, "--rounds", "1", "--object-count", "2", "--results", str(results))
    assert run.returncode == 0, run.stderr
    check_results(results, 1)
    with VGNClient(server.url) as vgn:
        defaults = vgn.model().defaults
    assert defaults is not None and defaults.fallback_threshold < defaults.threshold
    config = json.loads((results / "config.json").read_text())
    assert (config["threshold"], config["fallback_threshold"]) == (
        defaults.threshold,
        defaults.fallback_threshold,
    )
    assert (config["turn_average"], config["clearance"], config["grip"]) == (True, True, True)


#: A service whose operator turned every switch off, and one that left them on.
OFF = GraspDefaults(turn_average=False, clearance=False, grip=False, threshold=0.8, antipodal_threshold=0.4,
                    fallback_threshold=0.5)  # fmt: skip
BEST = OFF.model_copy(update={"turn_average": True, "clearance": True, "grip": True})


class ServiceDefaults:
    """Stands in for a client of a service whose ``/model`` reports ``defaults``."""

    def __init__(self, defaults: GraspDefaults | None, one_view: OneViewModel | None = None) -> None:
        self.defaults = defaults
        self.one_view = one_view

    def model(self) -> ModelInfo:
        return ModelInfo(loaded=True, model_id="m", source=None, architecture="VGN", parameters=1, device="cpu",
                         conventions={}, threshold=0.8, defaults=self.defaults, one_view=self.one_view)  # fmt: skip


@pytest.mark.parametrize(
    "defaults",
    [BEST, OFF, BEST.model_copy(update={"grip": False}), OFF.model_copy(update={"turn_average": True})],
)
def test_the_planner_is_resolved_to_the_services_defaults(defaults: GraspDefaults):
    """What the run leaves unset is recorded as the service reports it will be done, and left to the
    service in every request; a choice is recorded and sent as it is."""
    from sim_worker.clear_scene import resolve_planner
    from sim_worker.clutter import ClutterConfig

    vgn = ServiceDefaults(defaults)
    expected = (defaults.turn_average, defaults.clearance, defaults.grip)
    resolved = resolve_planner(ClutterConfig(), vgn)
    assert (resolved.turn_average, resolved.clearance, resolved.grip) == expected
    assert (resolved.model, resolved.threshold) == ("m", 0.8)
    checked = defaults.clearance or defaults.grip
    assert resolved.fallback_threshold == (0.5 if checked else None), "the floor applies only with a check"
    assert resolved.left_to_service == {"threshold", "turn_average", "clearance", "grip"}
    sent = resolved.grasp_options()
    assert sent == {
        "planner": "vgn",
        "threshold": None,
        "turn_average": None,
        "clearance": None,
        "grip": None,
    }
    recorded = resolved.as_json()
    assert "left_to_service" not in recorded and recorded["threshold"] == 0.8
    assert (recorded.get("turn_average", False), recorded.get("clearance", False)) == expected[:2]
    for choice in (True, False):  # a choice is kept whatever the default
        chosen = resolve_planner(ClutterConfig(turn_average=choice, clearance=choice, grip=choice), vgn)
        assert (chosen.turn_average, chosen.clearance, chosen.grip) == (choice, choice, choice)
        assert chosen.left_to_service == {"threshold"}
        assert chosen.grasp_options() == {"planner": "vgn", "threshold": None, "turn_average": choice,
                                          "clearance": choice, "grip": choice}  # fmt: skip
    named = resolve_planner(ClutterConfig(threshold=0.3), vgn)
    assert (named.threshold, named.fallback_threshold, named.grasp_options()["threshold"]) == (0.3, None, 0.3)
    baseline = resolve_planner(ClutterConfig(planner="antipodal"), vgn)
    assert (baseline.turn_average, baseline.clearance, baseline.grip) == (False, *expected[1:]), (
        "checks apply too"
    )
    assert (baseline.model, baseline.threshold, baseline.grasp_options()["threshold"]) == (
        "antipodal",
        0.4,
        None,
    )


def test_a_service_that_does_not_report_its_defaults_is_refused():
    from sim_worker.clear_scene import resolve_planner
    from sim_worker.clutter import ClutterConfig, ServiceDefaultsError

    with pytest.raises(ServiceDefaultsError, match="older than this client"):
        resolve_planner(ClutterConfig(), ServiceDefaults(None))


def test_an_answer_that_used_other_options_than_the_record_stops_the_run():
    """The answers must agree with config.json: the threshold, or the recorded fallback, and the switches."""
    from sim_worker.clear_scene import resolve_planner
    from sim_worker.clutter import ClutterConfig, ServiceDefaultsError, check_answer

    config = resolve_planner(ClutterConfig(), ServiceDefaults(BEST))
    answer = GraspResult(grasps=[], planning_ms=1.0, integration_ms=1.0, frame_count=6, model="m", threshold=0.8,
                         turn_average=True, clearance=True, grip=True, fallback=False)  # fmt: skip
    check_answer(config, answer)
    check_answer(config, answer.model_copy(update={"threshold": 0.5, "fallback": True}))
    check_answer(config, answer.model_copy(update={"clearance": None, "grip": None}))  # an older service
    for changed in ({"turn_average": False}, {"grip": False}, {"threshold": 0.7}):
        with pytest.raises(ServiceDefaultsError, match=next(iter(changed))):
            check_answer(config, answer.model_copy(update=changed))
    baseline = resolve_planner(ClutterConfig(planner="antipodal"), ServiceDefaults(BEST))
    check_answer(baseline, answer.model_copy(update={"threshold": 0.4, "turn_average": None}))


def test_the_one_view_network_is_recorded_and_its_answers_checked_against_its_threshold():
    """One-frame looks are answered by the service's one-view network at its own threshold."""
    from sim_worker.clear_scene import resolve_planner
    from sim_worker.clutter import ClutterConfig, ServiceDefaultsError, check_answer

    one_view = OneViewModel(model_id="o", source="o.safetensors", threshold=0.65, gripper="franka")
    config = resolve_planner(ClutterConfig(views="side"), ServiceDefaults(BEST, one_view))
    assert (config.one_view_model, config.one_view_threshold) == ("o", 0.65)
    assert config.as_json()["one_view_model"] == "o"
    answer = GraspResult(grasps=[], planning_ms=1.0, integration_ms=1.0, frame_count=1, model="o", threshold=0.65,
                         turn_average=True, clearance=True, grip=True, fallback=False)  # fmt: skip
    check_answer(config, answer)
    check_answer(config, answer.model_copy(update={"model": "m", "threshold": 0.8, "frame_count": 2}))
    for changed in ({"threshold": 0.8}, {"model": "m"}):
        with pytest.raises(ServiceDefaultsError, match="threshold"):
            check_answer(config, answer.model_copy(update=changed))
    named = resolve_planner(ClutterConfig(threshold=0.7), ServiceDefaults(BEST, one_view))
    assert named.one_view_threshold == 0.7
    assert "one_view_model" not in resolve_planner(ClutterConfig(), ServiceDefaults(BEST)).as_json()
    other_hand = ClutterConfig(views="side", hand=builtin_gripper("robotiq-2f85"))
    assert "one_view_model" not in resolve_planner(other_hand, ServiceDefaults(BEST, one_view)).as_json(), (
        "it answers the default hand's sessions only"
    )


def test_benchmark_runs_with_turn_averaging_are_kept_apart_and_labelled(tmp_path: Path):
    """Only VGN runs take the option: their folders end in -turns and their rows read vgn+turns."""
    from benchmarks.clutter import combinations, parse_args, scenario_config, table_row, with_service_defaults
    from sim_worker.clutter import ClutterConfig

    args = with_service_defaults(
        parse_args(["--planners", "vgn", "antipodal", "--selections", "random", "--scenarios", "pile-5",
                    "--turn-average", "--clearance", "--out", str(tmp_path)]),
        OFF,
    )  # fmt: skip
    runs = {planner: folder.name for planner, _, _, folder in combinations(args)}
    assert runs == {
        "vgn": "vgn-random-pile-5-turns-clearance",
        "antipodal": "antipodal-random-pile-5-clearance",
    }
    vgn, antipodal = (scenario_config(args, planner, "random", "pile-5") for planner in ("vgn", "antipodal"))
    assert vgn.turn_average and not antipodal.turn_average
    assert vgn.left_to_service == {"grip"}, "only the switch left out is left to the service"
    assert "turn_average" not in ClutterConfig().as_json()
    assert table_row("vgn", "random", "pile-5", vgn.as_json(), {})["planner"] == "vgn+turns+clearance"
    assert (
        table_row("antipodal", "random", "pile-5", antipodal.as_json(), {})["planner"]
        == "antipodal+clearance"
    )
    unsaid = parse_args(["--planners", "vgn", "--scenarios", "pile-5", "--selections", "random"])
    assert (unsaid.turn_average, unsaid.clearance) == (None, None), "left to the service"
    for defaults, folder in ((OFF, "vgn-random-pile-5"), (BEST, "vgn-random-pile-5-turns-clearance-grip")):
        resolved = with_service_defaults(unsaid, defaults)
        assert [f.name for *_, f in combinations(resolved)] == [folder], defaults
        config = scenario_config(resolved, "vgn", "random", "pile-5")
        assert (config.turn_average, config.clearance, config.grip) == (
            defaults.turn_average, defaults.clearance, defaults.grip
        )  # fmt: skip
        assert config.left_to_service == {"turn_average", "clearance", "grip"}
        sent = config.grasp_options()
        assert (sent["turn_average"], sent["clearance"], sent["grip"]) == (None, None, None)
    chosen = with_service_defaults(
        parse_args(["--no-turn-average", "--clearance"]), BEST.model_copy(update={"clearance": False})
    )
    assert (chosen.turn_average, chosen.clearance) == (False, True), "a choice beats the default"


def test_configs_without_the_checks_keep_their_recorded_form():
    """Off, an option is left out of config.json, so results folders from before it still resume."""
    from sim_worker.clutter import ClutterConfig

    assert "clearance" not in ClutterConfig().as_json() and "grip" not in ClutterConfig().as_json()
    assert ClutterConfig(clearance=True).as_json()["clearance"] is True
    assert ClutterConfig(grip=True).as_json()["grip"] is True


def test_benchmark_rows_with_the_clearance_check_are_labelled(tmp_path: Path, monkeypatch):
    """The benchmark follows the embedded service's default (the check on) and says so."""
    from benchmarks.clutter import main

    for switch in ("VGN_CLEARANCE", "VGN_GRIP", "VGN_TURN_AVERAGE"):
        monkeypatch.delenv(switch, raising=False)
    out = tmp_path / "bench"
    assert main(["--planners", "antipodal", "--selections", "best", "--scenarios", "blocks-5", "--rounds", "1",
                 "--renderer", "tiny", "--out", str(out)]) == 0  # fmt: skip
    rows = json.loads((out / "table.json").read_text())
    assert [(r["planner"], r["scenario"]) for r in rows] == [("antipodal+clearance+grip", "blocks-5")]
    assert "| antipodal+clearance+grip | best | 0.5 | blocks-5 | 1 |" in (out / "table.md").read_text()
    folder = out / "antipodal-best-blocks-5-clearance-grip"
    config = json.loads((folder / "config.json").read_text())
    assert config["clearance"] is True and config["grip"] is True
    assert main(["--report", "--out", str(out)]) == 0
    assert "| antipodal+clearance+grip |" in (out / "table.md").read_text()
    # Without a check the report finds no run of its own kind: it says so and keeps the table.
    assert main(["--report", "--no-clearance", "--out", str(out)]) == 1
    assert main(["--report", "--no-grip", "--out", str(out)]) == 1
    assert "| antipodal+clearance+grip |" in (out / "table.md").read_text()
    assert json.loads((out / "table.json").read_text()) == rows


@pytest.mark.slow
def test_a_structured_light_sensor_with_pose_error_is_run_and_recorded(tmp_path: Path, monkeypatch):
    """clear-scene through the structured-light model and reported-pose error: both reach the
    service (the baseline plans on what the sensor saw) and config.json records them."""
    monkeypatch.setenv("VGN_MODEL", "none")
    results = tmp_path / "sensor"
    run = clear_scene("--planner", "antipodal", "--rounds", "1", "--object-count", "2", "--sensor",
                      "structured-light", "--pose-error", "--results", str(results))  # fmt: skip
    assert run.returncode == 0, run.stderr
    check_results(results, 1)
    config = json.loads((results / "config.json").read_text())
    assert config["sensor"] == "structured-light" and config["pose_error"] is True
    refused = clear_scene(
        "--planner", "antipodal", "--rounds", "1", "--object-count", "2", "--results", str(results)
    )
    assert refused.returncode != 0  # the same folder without the sensor is another run


def test_sensor_options_make_their_own_benchmark_folders():
    from benchmarks.clutter import combinations, parse_args

    args = parse_args(["--planners", "antipodal", "--selections", "best", "--scenarios", "pile-5",
                       "--sensor", "structured-light", "--pose-error", "--no-turn-average", "--no-clearance"])  # fmt: skip
    ((_, _, _, folder),) = combinations(args)
    assert folder.name == "antipodal-best-pile-5-structured-light-pose"


def test_a_random_view_is_drawn_anew_for_every_look(tmp_path: Path, monkeypatch):
    """``--views random``: one frame per look, from a camera drawn from the round's own stream, so
    that the same seed sees the same views and two looks see the scene from two places."""
    rng_a, rng_b = np.random.default_rng([1, 0]), np.random.default_rng([1, 0])
    first, second = camera_views("random", rng_a)[0], camera_views("random", rng_a)[0]
    assert np.allclose(first, camera_views("random", rng_b)[0]) and not np.allclose(first, second)
    centre = np.asarray(WORKSPACE_CENTRE)
    for pose in (first, second):
        offset = pose[:3, 3] - centre
        assert 0.48 <= np.linalg.norm(offset) <= 0.72 and offset[2] > 0  # above the table
    monkeypatch.setenv("VGN_MODEL", "none")
    results = tmp_path / "random-view"
    run = clear_scene("--planner", "antipodal", "--views", "random", "--rounds", "1", "--object-count", "2",
                      "--results", str(results))  # fmt: skip
    assert run.returncode == 0, run.stderr
    check_results(results, 1)
    rows = read_csv(results / "grasps.csv")
    assert {row["frames"] for row in rows} <= {"1"}
    # Each attempt says what answered its look, at which threshold: the baseline's own here.
    assert rows and {(row["model"], row["threshold"]) for row in rows} == {
        ("antipodal", str(ANTIPODAL_DEFAULT_THRESHOLD))
    }
    # ... cleared for the service's hand, or its narrower fallback hand where that left nothing.
    assert {row["clearance_margin"] for row in rows} <= {str(ClearanceConfig().margin), str(FALLBACK_MARGIN)}
    # The baseline never answers below its threshold; a held object was closed on, by name.
    assert {row["fallback"] for row in rows} == {"0"}
    assert all(row["closed_on"] for row in rows if row["outcome"] == "success")
    assert failures.main([str(results)]) == 0, "the run's failures can be listed by object"
    assert json.loads((results / "config.json").read_text())["views"] == "random"
