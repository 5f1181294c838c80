"""The learning-curve tool: nested training subsets, resumable phases, the fit and its report."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from benchmarks.learning_curve import CurvePoint, fit_log_curve, main, parse_args, weights_path
from tests.helpers.datasets import make_dataset

PACKAGED = Path(__file__).resolve().parents[2] / "service" / "models" / "vgn.safetensors"


def point(scenes: int, success: float, half_width: float = 5.0) -> CurvePoint:
    return CurvePoint(
        requested_scenes=scenes,
        train_scenes=scenes,
        steps=scenes,
        best_epoch=1,
        val_balanced_loss=0.4,
        rounds=100,
        success_rate=success,
        success_rate_ci95=(success - half_width, success + half_width),
        percent_cleared=success,
        percent_cleared_ci95=(success - half_width, success + half_width),
        outcomes={},
    )


def test_the_fit_recovers_a_line_on_a_log_axis_and_extrapolates_to_the_target():
    points = [point(n, 10.0 + 20.0 * math.log10(n)) for n in (100, 300, 1000)]
    fit = fit_log_curve(points, target=90.0)
    assert fit is not None
    assert fit.intercept == pytest.approx(10.0) and fit.slope == pytest.approx(20.0)
    assert fit.scenes_for_target == pytest.approx(10_000.0, rel=1e-6)


def test_the_fit_weighs_short_runs_less():
    """A wide interval (few rounds) pulls the line less than a narrow one."""
    points = [point(100, 30.0, 2.0), point(1000, 50.0, 2.0), point(10_000, 10.0, 40.0)]
    fit = fit_log_curve(points, target=70.0)
    assert fit is not None and fit.slope > 10.0, "the outlier with a wide interval barely counts"


def test_a_flat_curve_predicts_no_size():
    """A slope well inside the points' intervals is no evidence that more data helps."""
    fit = fit_log_curve([point(250, 38.7), point(700, 42.4), point(2111, 38.8)], target=62.3)
    assert fit is not None and fit.slope_ci95[0] < 0 < fit.slope_ci95[1]
    assert fit.scenes_for_target is None


def test_no_fit_from_one_size_and_no_target_from_a_falling_line():
    assert fit_log_curve([point(100, 30.0)], target=60.0) is None
    falling = fit_log_curve([point(100, 40.0), point(1000, 30.0)], target=60.0)
    assert falling is not None and falling.slope < 0 and falling.scenes_for_target is None


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--sizes", "10", "--out", "x"], "vgn-train options after --"),
        (
            ["--sizes", "10", "--out", "x", "--", "--data", "d", "--out", "w.safetensors"],
            "must not hold --out",
        ),
        (["--sizes", "10", "--out", "x", "--", "--data", "d", "--train-scenes", "3"], "must not hold"),
        (["--sizes", "0", "--out", "x", "--phase", "report"], "positive"),
    ],
)
def test_options_refuse(argv: list[str], needle: str, capsys: pytest.CaptureFixture):
    with pytest.raises(SystemExit):
        parse_args(argv)
    assert needle in capsys.readouterr().err


def test_train_phase_trains_each_size_on_a_nested_subset_and_resumes(tmp_path: Path):
    data = make_dataset(tmp_path / "raw", scenes=8).root
    out = tmp_path / "curve"
    train = ["--data", str(data), "--epochs", "1", "--batch-scenes", "2", "--val-fraction", "0.2"]
    train += ["--cache", str(tmp_path / "cache"), "--no-progress", "--threads", "1"]
    argv = ["--sizes", "5", "2", "--out", str(out), "--phase", "train", "--", *train]
    assert main(argv) == 0
    cards = {n: json.loads(weights_path(out, n).with_suffix(".card.json").read_text()) for n in (2, 5)}
    assert [cards[n]["training"]["train_scenes"] for n in (2, 5)] == [2, 5]
    assert cards[2]["training"]["val_scenes"] == cards[5]["training"]["val_scenes"], "validation unchanged"
    assert "Not measured yet: 2, 5 scenes" in (out / "curve.md").read_text()
    assert json.loads((out / "curve.json").read_text())["points"] == []
    weights = weights_path(out, 5).read_bytes()
    assert main(argv) == 0, "a finished size resumes: nothing is trained again"
    assert weights_path(out, 5).read_bytes() == weights


@pytest.mark.slow
def test_a_whole_curve_trains_benchmarks_and_reports(tmp_path: Path):
    data = make_dataset(tmp_path / "raw", scenes=8).root
    out = tmp_path / "curve"
    train = ["--data", str(data), "--epochs", "1", "--batch-scenes", "2", "--no-progress", "--threads", "1"]
    train += ["--init", str(PACKAGED), "--lr", "1e-5"]  # a model that grasps, barely moved by the boxes
    argv = ["--sizes", "3", "6", "--scenario", "blocks-5", "--rounds", "2", "--threshold", "0.5"]
    assert main([*argv, "--out", str(out), "--", *train]) == 0
    report = json.loads((out / "curve.json").read_text())
    assert [p["train_scenes"] for p in report["points"]] == [3, 6]
    assert all(p["rounds"] == 2 and p["success_rate"] is not None for p in report["points"])
    assert "| 3 |" in (out / "curve.md").read_text() and (out / "curve.png").stat().st_size > 1000
