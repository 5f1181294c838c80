"""``benchmarks.answer_signal`` on answer-labelled scenes made through a real service."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.answer_signal import auc


def test_auc_counts_the_pairs_ranked_right():
    labels = np.array([1, 0, 1, 0])
    assert auc(labels, np.array([0.9, 0.1, 0.8, 0.85])) == pytest.approx(0.75)
    assert auc(labels, np.array([0.5, 0.5, 0.5, 0.5])) == pytest.approx(0.5), "ties count half"
    assert auc(np.zeros(3), np.array([0.2, 0.4, 0.6])) is None, "no success: nothing to rank"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=600)


def test_answers_are_scored_by_each_model_and_the_checks(server, random_checkpoint: Path, tmp_path: Path):
    raw, data, out = tmp_path / "raw", tmp_path / "data", tmp_path / "out"
    made = run("-m", "client.cli", "generate-data", "--sim", "--url", server.url, "--scene", "pile", "--objects",
               "blocks", "--scenes", "3", "--points", "0", "--answer-grasps", "6", "--answer-threshold", "0",
               "--renderer", "tiny", "--out", str(raw))  # fmt: skip
    assert made.returncode == 0, made.stderr
    assert (
        run("-m", "training.data_cli", "pack", str(raw), "--source", "answers", "--out", str(data)).returncode
        == 0
    )
    rows = np.loadtxt(raw / "grasps.csv", delimiter=",", skiprows=1, usecols=range(1, 10), ndmin=2)
    scored = run("-m", "benchmarks.answer_signal", "--data", str(data), "--source", "answers", "--cache",
                 str(tmp_path / "cache"), "--every-scene", "--model", str(random_checkpoint),
                 "--model", "service/models/vgn.safetensors", "--out", str(out))  # fmt: skip
    assert scored.returncode == 0, scored.stderr
    result = json.loads((out / "answer_signal.json").read_text())
    assert result["answers"] == len(rows) and result["success"] == pytest.approx(rows[:, 8].mean(), abs=1e-4)
    first, second = result["models"].values()
    assert len(result["models"]) == 2 and first["checks"] == second["checks"], (
        "the checks read the grid alone"
    )
    assert first["plain"] != second["plain"], "each model scores with its own quality"
    for by_score in result["models"].values():
        for got in by_score.values():
            both = 0 < rows[:, 8].sum() < len(rows)
            assert (0.0 <= got["auc"] <= 1.0) if both else got["auc"] is None
            assert set(got["top_success"]) == {"20%", "40%", "60%", "80%"}
    for by_score in result["models"].values():  # the checks gate a quality: they only ever drop answers
        for quality in ("plain", "turned"):
            gated = by_score[f"{quality}_checked"]["at_threshold"]["0.5"]["count"]
            assert gated <= by_score[quality]["at_threshold"]["0.5"]["count"]
        assert "at_threshold" not in by_score["checks"], "pass or fail is no quality"
    assert (
        f"in {len(set(np.loadtxt(raw / 'grasps.csv', delimiter=',', skiprows=1, usecols=0, dtype=str)))} scenes of answers"
        in scored.stdout
    )
