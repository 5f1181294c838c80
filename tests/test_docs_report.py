"""``python -m benchmarks.report`` on small synthetic result files: the tables carry the intervals
and the date and machine of every figure, the README's block is replaced only where results exist,
and ``--check`` tells a stale page from a current one."""

from __future__ import annotations

import json
from pathlib import Path

from benchmarks import report

ROW = {
    "planner": "vgn+turns+clearance", "selection": "random", "scenario": "pile-5", "threshold": 0.8,
    "model": "0123456789ab", "rounds": 100, "attempts": 386, "successes": 217, "success_rate": 56.2,
    "success_rate_ci95": [51.2, 61.1], "objects_placed": 489, "objects_cleared": 217, "percent_cleared": 44.4,
    "percent_cleared_ci95": [40.0, 48.8],
    "outcomes": {"success": 217, "approach_contact": 72, "nothing_held": 7, "slipped": 90, "collision": 0},
    "planning_ms": {"mean": 10.2, "p50": 9.9},
    "measured": {"date": "2031-02-03", "cpu": "Example CPU 9000", "cores": 2},
}  # fmt: skip
README = "# x\n\nintro\n\n<!-- results:begin -->\nold table\n<!-- results:end -->\n\nafter\n"


def clutter_results(
    folder: Path, rows: list[dict], settings: str = "seed 1, rounds per scenario 100, six view(s)"
) -> Path:
    """A result folder as ``benchmarks.clutter`` publishes it: its table, under the results root."""
    folder.mkdir(parents=True)
    (folder / "table.json").write_text(json.dumps(rows))
    (folder / "table.md").write_text(f"{settings}\n\n| planner | ... |\n")
    return folder


def test_clutter_table_has_intervals_failures_and_where_it_was_measured(tmp_path: Path, monkeypatch):
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    clutter_results(tmp_path / "bench-a", [ROW])
    page = report.clutter_page(tmp_path)
    assert "#### `bench-a`" in page
    assert "seed 1, rounds per scenario 100, six view(s)" in page and "`0123456789ab`" in page
    line = next(line for line in page.splitlines() if line.startswith("| vgn+turns+clearance"))
    assert "56.2 (51.2-61.1)" in line and "44.4 (40.0-48.8)" in line
    assert "| 72 / 7 / 90 / 0 |" in line and "| 10 |" in line and "62.3 / 46.4" in line
    assert "2031-02-03, Example CPU 9000 (2 cores)" in line


def test_a_row_without_a_record_takes_the_folders_measured_json(tmp_path: Path, monkeypatch):
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    row = {key: value for key, value in ROW.items() if key != "measured"}
    folder = clutter_results(tmp_path / "bench-a", [row])
    assert "date and machine not recorded" in report.clutter_page(tmp_path)
    (folder / "measured.json").write_text(json.dumps({"date": "2031-05-06", "cpu": "Other CPU", "cores": 16}))
    assert "2031-05-06, Other CPU (16 cores)" in report.clutter_page(tmp_path)


def test_headline_table_and_readme_block(tmp_path: Path, monkeypatch):
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    noisy = tmp_path / "noise"
    clutter_results(tmp_path / "bench-a", [ROW, {**ROW, "scenario": "blocks-5", "planner": "vgn"}])
    clutter_results(noisy, [ROW], settings="seed 1, rounds per scenario 100, six view(s), depth noise")
    table = report.headline_table(tmp_path)
    assert "| scenario | `vgn` | `vgn+turns+clearance` | paper's VGN |" in table, (
        "plain first, then by options"
    )
    lines = table.splitlines()
    assert lines.index("| blocks-5 | 56.2 / 44.4 / - | - | 87.6 / 90.1 |") < lines.index(
        "| pile-5 | - | 56.2 / 44.4 / - | 62.3 / 46.4 |"
    ), "the paper's order of scenarios"
    assert "| pile-5, depth noise | - | 56.2 / 44.4 / - | - |" in lines
    assert "2031" not in table, "the README's table carries no dates (the benchmark page does)"
    updated = report.readme_with_headline(README, table)
    assert "old table" not in updated and table in updated and updated.endswith("after\n")
    assert report.readme_with_headline(README, None) == README


def test_latency_table_with_date_and_machine(tmp_path: Path):
    folder = tmp_path / "latency-a"
    folder.mkdir()
    (folder / "latency.json").write_text(json.dumps({
        "environment": {"cpu_count": 2, "device": "cpu", "repeats": 40, "torch": "2.13.0"},
        "targets": [{"name": "grasp request p50 <= 25 ms", "value": 10.6, "passed": True}],
        "results": [{"name": "grasp request over HTTP", "p50_ms": 10.58, "p95_ms": 13.3}],
        "grpc": {"targets": [], "results": [{"name": "gRPC frame upload", "p50_ms": 5.2, "p95_ms": 6.0}]},
    }))  # fmt: skip
    assert "date and machine not recorded" in report.latency_page(tmp_path)
    assert report.main(["--stamp", str(folder)]) == 0
    page = report.latency_page(tmp_path)
    stamp = json.loads((folder / "measured.json").read_text())
    assert f"measured on {stamp['date']}, {stamp['cpu']} (" in page
    assert (
        "| grasp request over HTTP | 10.58 | 13.30 |" in page
        and "| gRPC frame upload | 5.20 | 6.00 |" in page
    )
    assert "| grasp request p50 <= 25 ms | 10.6 | pass |" in page


def test_latency_page_reads_each_runs_grasp_request_against_its_own_naive_pass(tmp_path: Path):
    runs = {
        "slow": ("2031-01-02", 126.0, 25.2),
        "fast": ("2031-01-01", 64.0, 16.0),
        "partial": ("2031-01-03", None, 9.0),
    }
    for name, (date, naive, grasps) in runs.items():
        rows = [{"name": report.DEFAULT_GRASPS_ROW, "p50_ms": grasps, "p95_ms": grasps * 1.2}]
        if naive is not None:
            rows.append({"name": report.NAIVE_FORWARD_ROW, "p50_ms": naive, "p95_ms": naive})
        (tmp_path / name).mkdir()
        (tmp_path / name / "latency.json").write_text(
            json.dumps({"environment": {"date": date, "cpu": "x"}, "results": rows})
        )
    lines = report.latency_page(tmp_path).splitlines()
    fast, slow = (
        lines.index("| `fast` | 2031-01-01 | 64.0 | 16.0 | - | 4.0× |"),
        lines.index("| `slow` | 2031-01-02 | 126.0 | 25.2 | - | 5.0× |"),
    )
    assert fast < slow, "oldest first"
    assert not any(line.startswith("| `partial`") for line in lines), (
        "a run without the naive pass has nothing to be read against"
    )
    for name in ("slow", "fast"):
        (tmp_path / name / "latency.json").unlink()
    assert "naive / request" not in report.latency_page(tmp_path)


def test_latency_table_says_which_weights_and_how_many_grasps(tmp_path: Path):
    runs = {"packaged": ({"random_weights": False, "weights": "service/models/vgn.safetensors",
                          "weights_id": "0123456789ab", "threshold": 0.8}, 2),
            "random": ({"random_weights": True, "weights": "/tmp/random-vgn.safetensors", "threshold": 0.9}, 0)}  # fmt: skip
    for name, (env, grasps) in runs.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "latency.json").write_text(json.dumps({
            "environment": env, "grasps": {"direct": grasps, "in_process": grasps, "http": grasps,
                                           "http_timed_median": grasps, "http_timed_min": grasps},
            "results": [{"name": "grasp request over HTTP", "p50_ms": 20.0, "p95_ms": 22.0}],
        }))  # fmt: skip
    page = report.latency_page(tmp_path)
    assert "weights `0123456789ab`; 2 grasps a request on the fused scene at threshold 0.8 (the timed" in page
    assert "default requests: median 2, least 2)" in page
    assert "random-initialised weights; 0 grasps a request on the fused scene at threshold 0.9 (" in page


def test_no_results_say_how_to_add_them(tmp_path: Path):
    assert "No clutter-removal result files" in report.clutter_page(tmp_path)
    # A run's per-scenario folder is not published (docs/results/.gitignore): its table is not read.
    clutter_results(tmp_path / "run" / "vgn-random-pile-5", [ROW])
    assert "No clutter-removal result files" in report.clutter_page(tmp_path)
    assert "No latency result files" in report.latency_page(tmp_path)
    assert report.headline_table(tmp_path) is None


def test_the_command_writes_then_checks(tmp_path: Path, monkeypatch):
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    results, out, readme = tmp_path / "results", tmp_path / "generated", tmp_path / "README.md"
    clutter_results(results / "bench-a", [ROW])
    readme.write_text(README)
    argv = [str(results), "--out", str(out), "--readme", str(readme)]
    assert report.main([*argv, "--check"]) == 1, "nothing generated yet"
    assert report.main(argv) == 0
    assert {p.name for p in out.iterdir()} == {"clutter.md", "latency.md", "configuration.md", "http-endpoints.md",
                                               "model-card.md", "training-data.md", "fleet.md", "device-planning.md",
                                               "operating-curves.md", "clear-scene-options.md", "experiments.md",
                                               "failures-by-object.md"}  # fmt: skip
    assert "| `vgn+turns+clearance` |" in readme.read_text()
    assert "| `--views` six\\|side\\|random | `six` |" in (out / "clear-scene-options.md").read_text()
    assert "`VGN_TURN_AVERAGE`" in (out / "configuration.md").read_text()
    assert "### `GET /sessions/{session_id}/grasps`" in (out / "http-endpoints.md").read_text()
    assert report.main([*argv, "--check"]) == 0
    (out / "clutter.md").write_text("edited by hand\n")
    assert report.main([*argv, "--check"]) == 1


def test_the_clutter_benchmark_records_date_and_machine(tmp_path: Path):
    from benchmarks.clutter import measured_on

    folder = tmp_path / "vgn-random-pile-5"
    folder.mkdir()
    assert measured_on(folder) == {"date": None, "cpu": None, "cores": None}
    recorded = measured_on(folder, record=True)
    now = report.this_machine()
    assert {k: v for k, v in recorded.items() if k != "time"} == {k: v for k, v in now.items() if k != "time"}
    assert recorded["cpu"] and recorded["cores"] and len(recorded["time"].split(":")) == 3
    assert measured_on(folder) == recorded, "read back by --report"


def test_the_machine_is_named_with_its_cpus_family_and_model(tmp_path: Path):
    """A virtual machine's bare "AMD EPYC" covers generations that differ twofold in speed."""
    cpuinfo = tmp_path / "cpuinfo"
    core = "processor\t: {}\nvendor_id\t: AuthenticAMD\ncpu family\t: 25\nmodel\t\t: 17\nmodel name\t: AMD EPYC\n\n"
    cpuinfo.write_text(core.format(0) + core.format(1))
    assert report.cpu_model(cpuinfo) == "AMD EPYC family 25 model 17"
    cpuinfo.write_text("processor\t: 0\nmodel name\t: Some CPU 9000\n")
    assert report.cpu_model(cpuinfo) == "Some CPU 9000"


def test_the_readme_table_shows_the_packaged_weights_only(tmp_path: Path, monkeypatch):
    monkeypatch.setattr(report, "shipped_model_id", lambda: "shipped00000")
    clutter_results(tmp_path / "bench-a", [ROW, {**ROW, "model": "shipped00000", "scenario": "packed-5"}])
    table = report.headline_table(tmp_path)
    assert (
        "| packed-5 | 56.2 / 44.4 / - |" in table and "pile-5" not in table
    )  # ROW's weights are an experiment's


def test_paired_comparison_rows_per_arm_and_columns_per_setting(tmp_path: Path):
    clutter_results(tmp_path / "bench-a", [ROW])  # not a paired-<arm> folder: left out
    noisy = "seed 1, rounds per scenario 100, six view(s), depth noise"
    for arm, rate in (("fixed", 25.7), ("fresh", 40.0)):
        for suffix, settings in (("", "seed 1, rounds per scenario 100, six view(s)"), ("-noise", noisy)):
            folder = tmp_path / f"paired-{arm}{suffix}"
            folder.mkdir()
            (folder / "table.json").write_text(
                json.dumps([{**ROW, "success_rate": rate + (0 if suffix else 20)}])
            )
            (folder / "table.md").write_text(f"{settings}\n\n| planner | ... |\n")
    plain = tmp_path / "paired-fixed-default"  # the same arm asked with another request: its own row
    plain.mkdir()
    (plain / "table.json").write_text(json.dumps([{**ROW, "planner": "vgn", "success_rate": 30.0}]))
    (plain / "table.md").write_text("seed 1, rounds per scenario 100, six view(s)\n\n| planner | ... |\n")
    header, _, *rows = [line for line in report.paired_comparison(tmp_path) if line.startswith("| ")]
    assert header == "| training observations | request | pile-5 | pile-5, depth noise | measured |"
    assert rows[0].startswith(
        "| fixed | `vgn+turns+clearance` | 45.7 (51.2-61.1), 100 rounds | 25.7 (51.2-61.1), 100 rounds |"
    )
    assert rows[1].startswith("| fixed | `vgn` | 30.0 (51.2-61.1), 100 rounds | - |")
    assert (
        rows[2].startswith("| fresh | `vgn+turns+clearance` | 60.0")
        and "2031-02-03" in rows[2]
        and len(rows) == 3
    )


def test_runs_under_other_sensors_get_their_own_rows(tmp_path: Path, monkeypatch):
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    clutter_results(tmp_path / "clean", [ROW])
    clutter_results(tmp_path / "sl", [{**ROW, "success_rate": 41.0}],
                    settings="seed 1, rounds per scenario 100, six view(s), structured-light sensor, camera pose error")  # fmt: skip
    clutter_results(
        tmp_path / "side",
        [{**ROW, "success_rate": 33.0}],
        settings="seed 1, rounds per scenario 100, side view(s)",
    )
    lines = report.headline_table(tmp_path).splitlines()
    assert "| pile-5 | 56.2 / 44.4 / - | 62.3 / 46.4 |" in lines
    assert any(
        line.startswith("| pile-5, structured-light sensor, camera pose error | 41.0") for line in lines
    )
    assert any(line.startswith("| pile-5, one side view | 33.0") for line in lines)


def test_a_variant_is_named_on_the_page_and_left_out_of_the_readme(tmp_path: Path, monkeypatch):
    """A control run on changed code (``variant.md``) is tabled with what it changed, and the
    README's table, which shows what the package does, keeps the shipped code's figures."""
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    clutter_results(tmp_path / "a-shipped", [ROW])
    control = clutter_results(tmp_path / "b-control", [{**ROW, "success_rate": 41.0}])
    (control / "variant.md").write_text("the grip check\nwithout its preference.\n")
    assert "| pile-5 | 56.2 / 44.4 / - | 62.3 / 46.4 |" in report.headline_table(tmp_path).splitlines()
    assert "variant:" not in report.clutter_page(tmp_path)
    page = report.experiments_page(tmp_path)
    assert "variant: the grip check without its preference." in page
    assert page.count("variant:") == 1


def test_of_two_runs_on_one_day_the_readme_shows_the_later(tmp_path: Path, monkeypatch):
    """Folder names say nothing of order: the time a run was measured decides, and a record
    from before times were kept counts as the earliest of its day."""
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    day = ROW["measured"]["date"]
    clutter_results(tmp_path / "a-later", [{**ROW, "measured": {**ROW["measured"], "time": "18:00:00"}}])
    clutter_results(tmp_path / "b-earlier", [{**ROW, "success_rate": 41.0,
                                              "measured": {**ROW["measured"], "time": "09:30:00"}}])  # fmt: skip
    clutter_results(tmp_path / "c-untimed", [{**ROW, "success_rate": 42.0}])
    lines = report.headline_table(tmp_path).splitlines()
    assert "| pile-5 | 56.2 / 44.4 / - | 62.3 / 46.4 |" in lines
    assert report.measured_at({"date": day}) < report.measured_at({"date": day, "time": "00:00:00"})
    assert report.measured_at(None) == ""


def test_a_later_run_of_another_seed_stays_out_of_the_readme(tmp_path: Path, monkeypatch):
    """The README's table shows the benchmark's default seed: a repeat on another draw of scenes,
    however new, is tabled on its own page and leaves the README's cell as it was."""
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    day = ROW["measured"]["date"]
    clutter_results(tmp_path / "a-seed-1", [{**ROW, "measured": {**ROW["measured"], "time": "09:30:00"}}])
    clutter_results(tmp_path / "b-seed-2", [{**ROW, "success_rate": 41.0, "measured": {"date": day, "time": "18:00:00"}}],
                    settings="seed 2, rounds per scenario 100, six view(s)")  # fmt: skip
    assert "| pile-5 | 56.2 / 44.4 / - | 62.3 / 46.4 |" in report.headline_table(tmp_path).splitlines()
    assert report.run_seed(tmp_path / "b-seed-2") == 2
    assert report.run_seed(tmp_path / "a-seed-1") == report.HEADLINE_SEED


def test_the_readme_table_keeps_the_operating_threshold(tmp_path: Path, monkeypatch):
    """A run of the packaged weights at another threshold is another operating point: newer or
    not, it stays out of the README's table (the operating curves table it)."""
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    monkeypatch.setattr(report, "shipped_threshold", lambda: 0.8)
    later = {**ROW["measured"], "time": "23:00:00"}
    clutter_results(tmp_path / "a", [ROW])
    clutter_results(tmp_path / "b", [{**ROW, "threshold": 0.9, "success_rate": 75.6, "measured": later}])
    assert "| pile-5 | 56.2 / 44.4 / - | 62.3 / 46.4 |" in report.headline_table(tmp_path).splitlines()


def test_the_share_of_rounds_that_offered_no_grasp_stands_beside_success_and_cleared(
    tmp_path: Path, monkeypatch
):
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    recorded = {**ROW, "no_grasp_rate": 37.0}
    clutter_results(tmp_path / "bench-a", [recorded])
    line = next(line for line in report.clutter_page(tmp_path).splitlines() if line.startswith("| vgn+"))
    assert "44.4 (40.0-48.8) | 37 | 72 / 7 / 90 / 0 |" in line
    assert "| pile-5 | 56.2 / 44.4 / 37 | 62.3 / 46.4 |" in report.headline_table(tmp_path).splitlines()


def test_runs_on_objects_of_another_source_get_their_own_row(tmp_path: Path, monkeypatch):
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    clutter_results(tmp_path / "heldout", [ROW], settings="seed 1, six view(s), pile objects heldout")
    other = {**ROW, "success_rate": 70.0, "measured": {"date": "2031-02-04"}}
    clutter_results(tmp_path / "xsrc", [other], settings="seed 1, six view(s), pile objects pybullet_data")
    lines = report.headline_table(tmp_path).splitlines()
    assert "| pile-5 | 56.2 / 44.4 / - | 62.3 / 46.4 |" in lines, (
        "the newer cross-source run does not replace it"
    )
    assert "| pile-5, cross-source objects | 70.0 / 44.4 / - | - |" in lines


def test_the_benchmark_page_holds_the_shipped_model_and_experiments_their_own_page(
    tmp_path: Path, monkeypatch
):
    """The benchmark page tables the folders the README's table is made of; every other folder goes
    to the experiments page, under its name prefix's question, and one no prefix names under
    "Other runs"."""
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    clutter_results(tmp_path / "shipped-default", [ROW])
    clutter_results(tmp_path / "paired-fresh", [{**ROW, "model": "fedcba987654"}])
    clutter_results(tmp_path / "paired-fixed", [{**ROW, "model": "fedcba987654"}])
    clutter_results(tmp_path / "new-idea", [{**ROW, "model": "fedcba987654"}])
    benchmark = report.clutter_page(tmp_path)
    assert "#### `shipped-default`" in benchmark and "paired-" not in benchmark
    assert "56.2 (51.2-61.1)" in benchmark, "intervals stay"
    assert "The other 3 result folders" in benchmark and "(experiments.md)" in benchmark
    experiments = report.experiments_page(tmp_path)
    assert "shipped-default" not in experiments
    question = dict(report.EXPERIMENT_GROUPS)["paired-"]
    assert f"## `paired-*`\n\n{question} (2 result folders)" in experiments
    assert "### `paired-fresh`" in experiments and "### `paired-fixed`" in experiments
    assert (
        experiments.index("## `paired-*`")
        < experiments.index("## Other runs")
        < experiments.index("new-idea")
    )


def test_repeats_on_other_seeds_are_pooled_with_the_readmes_run(tmp_path: Path, monkeypatch):
    """A folder named ``seed-N-NAME`` that ran seed N is pooled with NAME's run, planner by planner:
    sums over the seeds, not a mean of rates; a repeat with a ``variant.md`` or a settings line of
    another seed is left out."""
    monkeypatch.setattr(report, "shipped_model_id", lambda: ROW["model"])
    baseline = {
        **ROW,
        "planner": "antipodal+clearance",
        "model": "antipodal",
        "successes": 300,
        "success_rate": 77.7,
    }
    clutter_results(
        tmp_path / "xsrc", [ROW, baseline], settings="seed 1, six view(s), pile objects pybullet_data"
    )
    again = {**ROW, "attempts": 100, "successes": 90, "success_rate": 90.0, "objects_placed": 100,
             "objects_cleared": 90, "rounds": 20, "no_grasp_rate": 10.0}  # fmt: skip
    clutter_results(
        tmp_path / "seed-2-xsrc", [again], settings="seed 2, six view(s), pile objects pybullet_data"
    )
    clutter_results(
        tmp_path / "seed-3-xsrc", [again], settings="seed 3, six view(s), pile objects pybullet_data"
    )
    (tmp_path / "seed-3-xsrc" / "variant.md").write_text("A changed service.\n")
    clutter_results(
        tmp_path / "seed-4-xsrc", [again], settings="seed 5, six view(s), pile objects pybullet_data"
    )
    page = report.clutter_page(tmp_path)
    assert "#### Seeds pooled" in page
    line = next(line for line in page.splitlines() if line.startswith("| pile-5, cross-source objects | vgn"))
    low, high = report.wilson_interval(217 + 90, 386 + 100)
    assert f"| 2 | 120 | 63.2 ({low:.1f}-{high:.1f}) |" in line, (
        "successes summed over attempts, seeds 1 and 2 only"
    )
    assert "| 52.1 (" in line and line.endswith("| - | 1: 56.2, 2: 90.0 |"), (
        "one seed without no-grasp shares: -"
    )
    assert not any(
        line.startswith("| pile-5, cross-source objects | antipodal") for line in page.splitlines()
    ), "a planner no other seed ran has nothing to pool"
    alone = tmp_path / "alone"
    clutter_results(
        alone / "xsrc", [ROW, baseline], settings="seed 1, six view(s), pile objects pybullet_data"
    )
    assert "Seeds pooled" not in report.clutter_page(alone), "no repeats: no section"
