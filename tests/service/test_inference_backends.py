"""The runtime comparison (benchmarks/inference_backends.py) runs what it claims to: its exportable
form computes the fast form's function, and every form it times is checked against the reference."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from benchmarks import inference_backends
from benchmarks.inference_backends import ExportableFastVGN, export_onnx
from service.settings import PACKAGED_MODEL
from service.vgn.checkpoint import load_vgn
from service.vgn.fast import FastVGN
from tests.helpers.grids import recorded_grids


def test_the_exportable_form_computes_what_the_fast_form_computes():
    fast = FastVGN.from_vgn(load_vgn(PACKAGED_MODEL))
    grid = torch.from_numpy(np.stack([g for _, g in recorded_grids()[:2]]))[:, None]
    with torch.inference_mode():
        for expected, actual in zip(fast(grid), ExportableFastVGN(fast)(grid), strict=True):
            assert actual.shape == expected.shape
            assert torch.allclose(actual, expected, atol=1e-6)


def test_onnx_runtime_runs_the_exported_form_to_the_same_outputs(tmp_path):
    ort = pytest.importorskip("onnxruntime")
    pytest.importorskip("onnx")
    fast = FastVGN.from_vgn(load_vgn(PACKAGED_MODEL))
    export_onnx(fast, tmp_path / "vgn.onnx")
    session = ort.InferenceSession(str(tmp_path / "vgn.onnx"), providers=["CPUExecutionProvider"])
    _, grid = recorded_grids()[0]
    with torch.inference_mode():
        expected = fast(torch.from_numpy(grid)[None, None])
    actual = session.run(None, {session.get_inputs()[0].name: grid[None, None]})
    for e, a in zip(expected, actual, strict=True):
        assert np.abs(e.numpy() - a).max() < 1e-4


def test_the_comparison_checks_and_times_every_form(tmp_path, capsys):
    out = tmp_path / "runtimes.json"
    assert (
        inference_backends.main(["--repeats", "2", "--warmup", "0", "--skip-compile", "--json", str(out)])
        == 0
    )
    results = json.loads(out.read_text())
    names = [form["name"] for form in results["forms"]]
    assert names[0] == inference_backends.REFERENCE and "torch fast form float32" in names
    for form in results["forms"]:
        assert len(form["samples_ms"]) == 2 and form["p50_ms"] > 0
        assert form["disagreements"] == [], form["name"]  # every form here computes VGN's grasps
    assert "torch fast form float32" in capsys.readouterr().out
