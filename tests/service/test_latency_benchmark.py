"""The latency benchmark times the request a plain client sends, with the weights users get."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks import latency
from service.settings import PACKAGED_MODEL
from service.vgn.checkpoint import card_path, weights_id


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
    env, grasps = report["environment"], report["grasps"]
    assert env["random_weights"] is False and Path(env["weights"]) == Path("service/models/vgn.safetensors")
    assert env["weights_id"] == weights_id(PACKAGED_MODEL), "the result file names its weights by content"
    card = json.loads(card_path(PACKAGED_MODEL).read_text())
    assert env["threshold"] == card["threshold"], "the packaged model card's operating threshold"
    assert grasps["http"] > 0 and grasps["in_process"] == grasps["http"]
    assert grasps["http_timed_median"] > 0, "most timed default requests had grasps to check"


def test_random_weights_and_a_model_exclude_each_other(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        latency.parse_args(["--random-weights", "--model", "x.safetensors"])
    assert exit_.value.code == 2
    assert "exclude each other" in capsys.readouterr().err
