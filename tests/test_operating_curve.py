"""``benchmarks.operating_curve`` on small synthetic result files: a curve per model, request and
scenario measured at two or more thresholds, the newest run at each, tabled and drawn."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks import operating_curve, report
from tests.test_docs_report import ROW, clutter_results


def point(threshold: float, success: float, cleared: float, **changes) -> dict:
    return {**ROW, "planner": "vgn", "threshold": threshold, "success_rate": success,
            "success_rate_ci95": [success - 5, success + 5], "percent_cleared": cleared,
            "percent_cleared_ci95": [cleared - 4, cleared + 4], **changes}  # fmt: skip


def test_curves_group_by_model_request_and_scenario_and_keep_the_newest(tmp_path: Path):
    later = {**ROW["measured"], "time": "20:00:00"}
    clutter_results(tmp_path / "t08", [point(0.8, 61.6, 49.3), point(0.8, 90.0, 60.0, planner="vgn+turns")])
    clutter_results(tmp_path / "t09", [point(0.9, 75.6, 36.2)])
    clutter_results(tmp_path / "t09-again", [point(0.9, 74.0, 37.0, measured=later)])
    clutter_results(tmp_path / "other-model", [point(0.7, 70.9, 43.8, model="fedcba987654")])
    clutter_results(
        tmp_path / "noisy", [point(0.85, 40.0, 30.0), point(0.9, 30.0, 20.0)], settings="seed 1, depth noise"
    )
    control = clutter_results(tmp_path / "control", [point(0.85, 40.0, 30.0)])
    (control / "variant.md").write_text("changed code\n")
    newest = {**ROW["measured"], "time": "23:00:00"}
    clutter_results(tmp_path / "seed-3", [point(0.9, 99.0, 10.0, measured=newest)], settings="seed 3")
    curves = report.operating_curves(tmp_path)
    assert list(curves) == [(ROW["model"], "vgn", "pile-5"), (ROW["model"], "vgn", "pile-5, depth noise")], (
        "one threshold (the other model, the other request) is no curve; other sensing is another curve"
    )
    points = curves[ROW["model"], "vgn", "pile-5"]
    assert [p.threshold for p in points] == [0.8, 0.9], "the variant's 0.85 is left out"
    assert points[1].row["success_rate"] == 74.0, "the newest run at a threshold, of the default seed"

    page = report.curves_page(tmp_path)
    assert f"#### `{ROW['model']}`, `vgn`, pile-5" in page
    assert "| 0.8 | 61.6 (56.6-66.6) | 49.3 (45.3-53.3) | 386 | 72 / 7 / 90 / 0 | `t08` |" in page
    assert "2031-02-03, Example CPU 9000 (2 cores)" in page
    assert "two thresholds" in report.curves_page(tmp_path / "t08")


def test_the_figure_is_drawn_for_a_scenario_with_curves(tmp_path: Path):
    pytest.importorskip("matplotlib")
    results = tmp_path / "results"
    clutter_results(results / "a", [point(0.8, 61.6, 49.3)])
    clutter_results(results / "b", [point(0.9, 75.6, 36.2)])
    out = operating_curve.draw(report.operating_curves(results), "pile-5", tmp_path / "curve.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000
    with pytest.raises(ValueError, match="no curve of 'packed-5'"):
        operating_curve.draw(report.operating_curves(results), "packed-5", tmp_path / "x.png")


def test_the_generated_pages_include_the_curves(tmp_path: Path):
    clutter_results(tmp_path / "a", [point(0.8, 61.6, 49.3)])
    clutter_results(tmp_path / "b", [point(0.9, 75.6, 36.2)])
    outputs = report.render_all(tmp_path, out=tmp_path / "generated", readme=None)
    assert "| 0.9 | 75.6" in outputs[tmp_path / "generated" / "operating-curves.md"]
