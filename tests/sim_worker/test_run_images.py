"""Pictures of clear-scene runs: the grasp drawn where the camera sees it, and contact sheets."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from sim_worker.images import (
    FAILURE_COLOUR,
    GRASP_COLOUR,
    SUCCESS_COLOUR,
    TILE_SIZE,
    project,
    save_attempt_image,
    write_contact_sheet,
)
from sim_worker.results import RoundRecord
from tests.helpers.scenes import INTRINSICS
from vgn_contract.geometry import look_at
from vgn_contract.schemas import Grasp

CAMERA = look_at(np.array([0.15, 0.15, 0.6]), np.array([0.15, 0.15, 0.0]), up=(0, 1, 0))
TOP_DOWN = Grasp(
    position=(0.15, 0.15, 0.1), orientation=(1, 0, 0, 0), approach=(0, 0, -1), width=0.06, quality=0.9
)


def test_projection_follows_the_pinhole_model() -> None:
    centre = project(np.array([[0.15, 0.15, 0.0]]), CAMERA, INTRINSICS)[0]
    np.testing.assert_allclose(centre, [INTRINSICS.cx, INTRINSICS.cy], atol=1e-6)
    # 0.06 m across at 0.5 m depth is fx * 0.06 / 0.5 pixels.
    ends = project(np.array([[0.12, 0.15, 0.1], [0.18, 0.15, 0.1]]), CAMERA, INTRINSICS)
    assert np.linalg.norm(ends[1] - ends[0]) == pytest.approx(INTRINSICS.fx * 0.06 / 0.5)
    assert np.isnan(project(np.array([[0.15, 0.15, 1.0]]), CAMERA, INTRINSICS)).all()  # behind the camera


def magenta(image: np.ndarray) -> np.ndarray:
    return np.all(np.abs(image.astype(int) - GRASP_COLOUR) < 30, axis=-1)


def test_grasp_is_drawn_where_the_camera_sees_it(tmp_path: Path) -> None:
    grey = np.full((INTRINSICS.height, INTRINSICS.width, 3), 128, np.uint8)
    path = save_attempt_image(tmp_path, 3, 0, TOP_DOWN, grey, CAMERA, INTRINSICS)
    assert path.name == "round0003_attempt00.png"
    drawn = magenta(np.asarray(Image.open(path)))
    rows, cols = np.nonzero(drawn)
    # Seen from above, the palm spans the grasp width (0.06 m at 0.5 m: 65 px) along the closing
    # axis, world y, which is the image's vertical here; the fingers point at the camera.
    assert abs(cols.mean() - INTRINSICS.cx) < 3 and abs(rows.mean() - INTRINSICS.cy) < 3
    assert rows.max() - rows.min() == pytest.approx(INTRINSICS.fx * 0.06 / 0.5, abs=6)
    assert cols.max() - cols.min() < 8
    assert not drawn[:, : int(INTRINSICS.cx) - 60].any()  # nothing far from the grasp


def test_contact_sheet_frames_attempts_by_outcome(tmp_path: Path) -> None:
    grey = np.full((INTRINSICS.height, INTRINSICS.width, 3), 128, np.uint8)
    labels = [1, 0, 1]
    for attempt in range(len(labels)):
        save_attempt_image(tmp_path, 0, attempt, TOP_DOWN, grey, CAMERA, INTRINSICS)
    rows = [
        {"score": 0.9, "label": label, "outcome": "success" if label else "nothing_held"} for label in labels
    ]
    record = RoundRecord(0, "1-0", 4, cleared=2, attempts=3, successes=2, grasps=rows)
    sheet = np.asarray(Image.open(write_contact_sheet(tmp_path, record)))
    tile_w, tile_h = TILE_SIZE
    assert sheet.shape[1] == 3 * (tile_w + 8)  # one row of three framed tiles
    for index, label in enumerate(labels):
        frame = sheet[40, index * (tile_w + 8) + 1]  # a pixel of the tile's frame
        assert tuple(frame) == (SUCCESS_COLOUR if label else FAILURE_COLOUR)
    empty = RoundRecord(1, "1-1", 4)
    assert Image.open(write_contact_sheet(tmp_path, empty)).size[1] > 0
