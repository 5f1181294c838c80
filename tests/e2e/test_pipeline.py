"""The whole learning loop in small: data generated through a real service, one short
training epoch, the weights loaded by a service that then plans grasps."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from client.http import VGNClient
from service.launch.embedded import EmbeddedService
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views


def test_generate_train_load_plan(server, tmp_path: Path):
    data, weights = tmp_path / "data", tmp_path / "model" / "vgn.safetensors"
    generated = subprocess.run(
        [sys.executable, "-m", "client.cli", "generate-data", "--sim", "--url", server.url, "--scene", "packed",
         "--objects", "blocks", "--scenes", "2", "--points", "6", "--renderer", "tiny", "--out", str(data)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert generated.returncode == 0, generated.stderr
    trained = subprocess.run(
        [sys.executable, "-m", "training.cli", "--data", str(data), "--epochs", "1", "--out", str(weights),
         "--threads", "1", "--no-progress", "--val-fraction", "0.5"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert trained.returncode == 0, trained.stdout + trained.stderr
    assert weights.exists() and weights.with_name("vgn.card.json").exists()
    with EmbeddedService(model=weights) as service, VGNClient(service.url) as vgn:
        model = vgn.model()
        assert model.loaded and model.source == str(weights)
        assert model.card is not None, "the service tells which data and command made its weights"
        assert model.card["matches_weights"] and model.card["scenes"] == 2 and model.card["epochs"] == 1
        assert model.card["command"].startswith("vgn-train --data")
        session = vgn.create_session(intrinsics=INTRINSICS).session_id
        for pose in circle_views(3):
            vgn.add_frame(session, BoxScene().depth(pose), pose)
        result = vgn.grasps(session, threshold=0.0)
        assert result.model == model.model_id and result.frame_count == 3
