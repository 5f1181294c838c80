"""The latency benchmark times the request a plain client sends, with the weights users get."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks import latency
from service.settings import PACKAGED_MODEL


def test_default_request_is_timed_with_the_packaged_model_and_returns_grasps(tmp_path: Path) -> None:
    """With grasps to return, the default request's clearance and grip checks run while timed
    (random weights return none, so those checks would cost nothing)."""
    out = tmp_path / "latency.json"
    argv = [
        "--repeats",
        "2",
        "--warmup",
        "0",
        "--concurrent-requests",
        "0",
        "--skip-grpc",
        "--json",
        str(out),
    ]
    assert latency.main(argv) == 0
    report = json.loads(out.read_text())
    env = report["environment"]
    assert env["random_weights"] is False and Path(env["weights"]) == PACKAGED_MODEL
    assert env["threshold"] == 0.8, "the packaged model card's operating threshold"
    assert report["grasps"]["http"] > 0 and report["grasps"]["in_process"] == report["grasps"]["http"]


def test_random_weights_and_a_model_exclude_each_other(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        latency.parse_args(["--random-weights", "--model", "x.safetensors"])
    assert exit_.value.code == 2
    assert "exclude each other" in capsys.readouterr().err
