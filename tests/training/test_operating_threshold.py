"""A model's operating threshold: its card says which quality threshold it was validated at,
and grasp requests that give none use it (VGN's 0.9 for weights without a card)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from service.vgn.checkpoint import card_path, weights_id
from tests.helpers.apps import serve
from tests.helpers.frames import open_fused_session
from vgn_contract.schemas import ANTIPODAL_DEFAULT_THRESHOLD, VGN_DEFAULT_THRESHOLD


def operating_threshold(model: dict) -> float:
    """``/model``'s operating threshold, which its deprecated top-level ``threshold`` repeats."""
    assert model["threshold"] == model["defaults"]["threshold"]
    return model["defaults"]["threshold"]


def test_weights_without_a_card_use_vgns_threshold(random_checkpoint: Path):
    with serve(random_checkpoint) as http:
        assert operating_threshold(http.get("/model").json()) == VGN_DEFAULT_THRESHOLD
        session = open_fused_session(http)
        # Without the checks there is no fallback below the operating threshold to report instead.
        unchecked = {"clearance": "false", "grip": "false"}
        answer = http.get(f"/sessions/{session}/grasps", params=unchecked).json()
        assert answer["threshold"] == VGN_DEFAULT_THRESHOLD


def test_the_cards_threshold_is_the_default_and_a_request_overrides_it(
    random_checkpoint: Path, tmp_path: Path
):
    weights = tmp_path / "vgn.safetensors"
    shutil.copy(random_checkpoint, weights)
    card = {"threshold": 0.0, "model": {"weights_id": weights_id(weights)}, "datasets": [], "epochs": 3}
    card_path(weights).write_text(json.dumps(card))
    with serve(weights) as http:
        model = http.get("/model").json()
        assert (
            operating_threshold(model) == 0.0
            and model["card"]["threshold"] == 0.0
            and model["card"]["matches_weights"]
        )
        session = open_fused_session(http)
        plain = {"clearance": "false", "grip": "false"}  # the random model's grasps would all hit the surface
        default = http.get(f"/sessions/{session}/grasps", params=plain).json()
        explicit = http.get(f"/sessions/{session}/grasps", params={**plain, "threshold": 0.0}).json()
        assert default["threshold"] == 0.0 and default["grasps"], (
            "threshold 0 lets the random model's grasps through"
        )
        assert default["grasps"] == explicit["grasps"]
        strict = http.get(f"/sessions/{session}/grasps", params={**plain, "threshold": 0.99}).json()
        assert strict["threshold"] == 0.99 and all(g["quality"] >= 0.99 for g in strict["grasps"])
        assert len(strict["grasps"]) < len(default["grasps"])
        baseline = http.get(f"/sessions/{session}/grasps", params={"planner": "antipodal"}).json()
        assert baseline["threshold"] == ANTIPODAL_DEFAULT_THRESHOLD, (
            "the model's threshold is not the baseline's"
        )


def test_a_card_threshold_outside_0_1_is_ignored(random_checkpoint: Path, tmp_path: Path):
    weights = tmp_path / "vgn.safetensors"
    shutil.copy(random_checkpoint, weights)
    card_path(weights).write_text(json.dumps({"threshold": 7, "model": {}}))
    with serve(weights) as http:
        assert operating_threshold(http.get("/model").json()) == VGN_DEFAULT_THRESHOLD
