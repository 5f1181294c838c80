"""Pictures of clear-scene runs: each attempt's camera image with the planned grasp drawn in,
and one contact sheet per round, so a run can be judged at a glance instead of from CSV rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from sim_worker.results import RoundRecord
from vgn_contract.geometry import gripper_outline, invert
from vgn_contract.schemas import Grasp, Intrinsics

GRASP_COLOUR = (255, 0, 200)
SUCCESS_COLOUR = (30, 160, 60)
FAILURE_COLOUR = (200, 40, 40)
TILE_SIZE = (320, 240)
SHEET_COLUMNS = 4


def attempt_image_name(round_id: int, attempt: int) -> str:
    """The PNG of one attempt, named so that a folder lists in round and attempt order."""
    return f"round{round_id:04d}_attempt{attempt:02d}.png"


def project(points: np.ndarray, camera_pose: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(N, 2) pixel coordinates (u, v) of world points seen from ``camera_pose`` (camera → world,
    OpenCV optical frame); NaN for points that are not in front of the camera."""
    world_to_camera = invert(camera_pose)
    camera = points @ world_to_camera[:3, :3].T + world_to_camera[:3, 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        in_front = camera[:, 2] > 1e-6
        u = intrinsics.fx * camera[:, 0] / camera[:, 2] + intrinsics.cx
        v = intrinsics.fy * camera[:, 1] / camera[:, 2] + intrinsics.cy
    return np.where(in_front[:, None], np.stack([u, v], axis=1), np.nan)


def _font(size: int) -> ImageFont.ImageFont:
    return ImageFont.load_default(size=size)


def _strokes(pixels: np.ndarray) -> list[list[tuple[float, float]]]:
    """Polyline pieces between NaN rows (pen up), each with at least two points."""
    strokes, current = [], []
    for u, v in pixels:
        if np.isfinite(u) and np.isfinite(v):
            current.append((float(u), float(v)))
            continue
        strokes.append(current)
        current = []
    strokes.append(current)
    return [stroke for stroke in strokes if len(stroke) > 1]


def draw_grasp(
    rgb: np.ndarray,
    grasp: Grasp,
    camera_pose: np.ndarray,
    intrinsics: Intrinsics,
    caption: str,
    finger_depth: float | None = None,
) -> Image.Image:
    """The camera image with the gripper outline at ``grasp`` (dark halo, so it reads on any
    background; fingers ``finger_depth`` long, default the default hand's) and a caption bar."""
    image = Image.fromarray(rgb).convert("RGB")
    draw = ImageDraw.Draw(image)
    pixels = project(gripper_outline(grasp.as_matrix(), grasp.width, finger_depth), camera_pose, intrinsics)
    for colour, width in (((0, 0, 0), 6), (GRASP_COLOUR, 3)):
        for stroke in _strokes(pixels):
            draw.line(stroke, fill=colour, width=width, joint="curve")
    font = _font(16)
    draw.rectangle((0, 0, image.width, 24), fill=(0, 0, 0))
    draw.text((6, 3), caption, fill=(255, 255, 255), font=font)
    return image


def save_attempt_image(
    image_dir: Path,
    round_id: int,
    attempt: int,
    grasp: Grasp,
    rgb: np.ndarray,
    camera_pose: np.ndarray,
    intrinsics: Intrinsics,
    finger_depth: float | None = None,
) -> Path:
    """Write one attempt's picture (the planned grasp drawn into the camera image, with fingers
    ``finger_depth`` long)."""
    image_dir.mkdir(parents=True, exist_ok=True)
    caption = f"round {round_id}  attempt {attempt + 1}  quality {grasp.quality:.3f}  width {1000 * grasp.width:.1f} mm"
    path = image_dir / attempt_image_name(round_id, attempt)
    draw_grasp(rgb, grasp, camera_pose, intrinsics, caption, finger_depth).save(path)
    return path


def contact_sheet(
    tiles: list[Image.Image], captions: list[str], successes: list[bool], title: str
) -> Image.Image:
    """Tiles in a grid under a title, each framed green (success) or red (failure) with its caption."""
    tile_w, tile_h = TILE_SIZE
    caption_h, title_h, border = 22, 34, 4
    columns = max(1, min(SHEET_COLUMNS, len(tiles)))
    rows = max(1, -(-len(tiles) // columns))
    cell_w, cell_h = tile_w + 2 * border, tile_h + 2 * border + caption_h
    sheet = Image.new("RGB", (columns * cell_w, title_h + rows * cell_h), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    draw.text((8, 7), title, fill=(0, 0, 0), font=_font(18))
    if not tiles:
        draw.text(
            (8, title_h + 8), "no attempt: the planner found no grasp", fill=(90, 90, 90), font=_font(16)
        )
    for index, (tile, caption, success) in enumerate(zip(tiles, captions, successes, strict=True)):
        x, y = (index % columns) * cell_w, title_h + (index // columns) * cell_h
        colour = SUCCESS_COLOUR if success else FAILURE_COLOUR
        draw.rectangle((x, y, x + cell_w - 1, y + tile_h + 2 * border - 1), fill=colour)
        sheet.paste(tile.convert("RGB").resize(TILE_SIZE), (x + border, y + border))
        draw.text((x + border, y + tile_h + 2 * border + 2), caption, fill=colour, font=_font(15))
    return sheet


def write_contact_sheet(image_dir: Path, record: RoundRecord) -> Path:
    """The round's attempts on one page, captioned with their score and outcome."""
    tiles, captions, successes = [], [], []
    for attempt, row in enumerate(record.grasps):  # rows of grasps.csv, in attempt order
        path = image_dir / attempt_image_name(record.round_id, attempt)
        if not path.exists():  # a resumed run may lack pictures of earlier attempts
            continue
        with Image.open(path) as picture:
            tiles.append(picture.copy())
        notes = " ".join(str(row[key]) for key in ("disturbance", "loop") if row.get(key))
        captions.append(
            f"#{attempt + 1}  q {float(row['score']):.2f}  {row.get('outcome', '')}  {notes}".rstrip()
        )
        successes.append(bool(int(row["label"])))
    title = (
        f"round {record.round_id} (scene {record.scene_id}): {record.cleared}/{record.object_count} objects "
        f"cleared, {record.successes}/{record.attempts} grasps succeeded"
    )
    image_dir.mkdir(parents=True, exist_ok=True)
    path = image_dir / f"round{record.round_id:04d}_sheet.png"
    contact_sheet(tiles, captions, successes, title).save(path)
    return path
