"""TSDF grids of cluttered simulated scenes, recorded once (``python -m tests.data.record_grids``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

RECORDED = Path(__file__).resolve().parents[1] / "data" / "recorded_grids.npz"


def recorded_grids() -> list[tuple[str, np.ndarray]]:
    """(scene name, 40³ float32 TSDF grid) of each recorded scene."""
    data = np.load(RECORDED)
    return [
        (str(name), grid.astype(np.float32)) for name, grid in zip(data["names"], data["grids"], strict=True)
    ]
