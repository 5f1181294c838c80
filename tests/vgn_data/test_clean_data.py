import argparse

import numpy as np

from vgn_contract.schemas import Intrinsics
from vgn_data.clean_data import run
from vgn_data.dataset import DatasetSetup, RawDataset, SceneViews


def _args(source, destination) -> argparse.Namespace:
    return argparse.Namespace(source=str(source), destination=str(destination), seed=0)


def _raw(root):
    intrinsics = Intrinsics(width=8, height=6, fx=10.0, fy=10.0, cx=4.0, cy=3.0)
    raw = RawDataset(root, DatasetSetup(intrinsics=intrinsics))
    inside = [0.15, 0.15, 0.10]
    rows = [[0, 0, 0, 1, *inside, 0.04, 1], [0, 0, 0, 1, *inside, 0.04, 0], [0, 0, 0, 1, *inside, 0.04, 0]]
    raw.add_scene("s0-0", SceneViews(np.full((1, 6, 8), 0.5, np.float32), np.eye(4)[None]), np.array(rows))
    return raw


def test_run_writes_the_cleaned_folder(tmp_path, capsys):
    _raw(tmp_path / "raw")
    assert run(_args(tmp_path / "raw", tmp_path / "clean")) == 0
    assert "2 grasps" in capsys.readouterr().out
    _, grasps = RawDataset(tmp_path / "clean").grasps()
    assert sorted(grasps[:, 8]) == [0.0, 1.0]


def test_run_refuses_to_clean_in_place(tmp_path, capsys):
    _raw(tmp_path / "raw")
    assert run(_args(tmp_path / "raw", tmp_path / "raw")) == 2
    assert "other than the source" in capsys.readouterr().err
