"""The device benchmark times the default request's planning steps on a recorded volume, and
its figures reach the performance page."""

from __future__ import annotations

import json
from pathlib import Path

from benchmarks import device_planning, report


def test_recorded_volume_is_timed_and_tabled(tmp_path: Path) -> None:
    volume = tmp_path / "volume.npz"
    assert device_planning.main(["record", "--out", str(volume)]) == 0
    out = tmp_path / "results" / "cpu-run" / "device_planning.json"
    argv = ["time", str(volume), "--device", "cpu", "--repeats", "3", "--concurrent", "2", "--json", str(out),
            "--heads", "auto", "--heads", "whole"]  # fmt: skip
    assert device_planning.main(argv) == 0

    run, whole = json.loads(out.read_text())["runs"]
    assert (run["device"], run["heads"], whole["heads"]) == ("cpu", "on-demand", "whole")
    assert whole["requests"]["default request"]["grasps"] == run["requests"]["default request"]["grasps"]
    requests, steps = run["requests"], run["steps"]
    assert requests["default request"]["grasps"] > 0, "the packaged model finds grasps on the box scene"
    assert requests["default request"]["grasps"] <= requests["plain request"]["grasps"] + 2
    assert set(steps) == {
        "forward (1 grid)",
        "detection",
        "forward (4 turns)",
        "detection (turn-averaged)",
        "clearance check",
        "grip check",
    }
    # Every step of the default request was timed inside it, so they cannot add up to more.
    default_steps = [steps[name]["p50_ms"] for name in list(steps)[2:]]
    assert sum(default_steps) <= requests["default request"]["p50_ms"] * 1.5
    assert run["concurrent"]["n"] == 2 * 10 and run["concurrent"]["requests_per_s"] > 0

    page = report.device_planning_page(out.parent.parent)
    assert "#### `cpu-run`" in page and "**default request**" in page and "heads whole" in page
    assert f"{requests['default request']['p50_ms']:.2f}" in page
