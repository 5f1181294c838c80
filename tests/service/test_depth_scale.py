"""A frame whose depth is off by a factor is scaled back onto the volume's surface before fusion,
so that frames with drifting scale errors fuse one surface instead of several."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from service.core import PlanningService
from service.depth_scale import SETTLING_FRAMES, SceneScale, depth_scale
from service.settings import PACKAGED_MODEL, Settings
from service.tsdf import TSDFVolume
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.schemas import SessionCreate

#: Each view's depth error, as a factor: none exact, the first too, averaging to none.
FACTORS = (1.04, 0.97, 1.03, 0.96, 1.01, 0.995)


@pytest.fixture(scope="module")
def volume() -> tuple[np.ndarray, float]:
    """(N, N, N, 2) tsdf and weight of the box fused exactly from three views; the voxel size."""
    fused = TSDFVolume(0.3, 40)
    for pose in circle_views(6)[:3]:
        fused.integrate(BoxScene().depth(pose), INTRINSICS, pose, max_depth=2.0)
    return fused.state().reshape(40, 40, 40, 2), fused.voxel_size


@pytest.mark.parametrize("factor", [1.0, 0.93, 0.96, 1.04, 1.08])
def test_a_frames_scale_error_is_found_against_the_volume(volume, factor):
    tsdf, voxel_size = volume
    pose = circle_views(6)[4]  # a view the volume was not fused from
    scale = depth_scale(BoxScene().depth(pose) * factor, INTRINSICS, pose, tsdf, voxel_size, 2.0)
    if factor == 1.0:
        assert scale == 1.0  # an exact frame is fused as it came
    else:
        assert abs(scale * factor - 1.0) < 0.003


def test_a_frame_that_sees_nothing_the_volume_observed_is_left_alone(volume):
    tsdf, voxel_size = volume
    pose = circle_views(6)[4]
    empty = np.zeros_like(tsdf)
    assert depth_scale(BoxScene().depth(pose) * 1.05, INTRINSICS, pose, empty, voxel_size, 2.0) == 1.0
    nothing = np.zeros((480, 640), np.float32)
    assert depth_scale(nothing, INTRINSICS, pose, tsdf, voxel_size, 2.0) == 1.0


def test_frames_with_drifting_scale_errors_fuse_one_surface():
    """Six views of the box, five of them off by 3-5 %: with registration the fine cloud lies on the
    box and table (as the exact frames' does), without it it smears across centimetres."""
    scene, poses = BoxScene(), circle_views(6)
    spread = {}
    for register in (True, False):
        service = PlanningService.from_settings(
            Settings(model=PACKAGED_MODEL, api_key=None, depth_scale_registration=register)
        )
        try:
            for name, factors in (("exact", (1.0,) * 6), ("drifting", FACTORS)):
                session = service.create_session(SessionCreate(intrinsics=INTRINSICS)).session_id
                for pose, factor in zip(poses, factors, strict=True):
                    service.add_frame(session, scene.depth(pose) * factor, pose)
                cloud = service.cloud(session)
                spread[register, name] = np.percentile(np.abs(scene.distance_to_surface(cloud[:, :3])), 90)
        finally:
            service.close()
    assert spread[True, "exact"] == spread[False, "exact"]  # exact frames are fused as they came
    assert spread[True, "drifting"] < 1.5 * spread[True, "exact"] + 0.001
    assert spread[False, "drifting"] > 3 * spread[True, "drifting"]


@dataclass(frozen=True)
class Frame:
    name: str
    scale: float = 1.0


def test_the_scenes_scale_is_the_geometric_mean_of_its_first_frames():
    """Each first frame is measured against the first one's scale; all are scaled by their mean's
    inverse, and given back to be fused again whenever that mean moves; later frames take their own."""
    scene = SceneScale()
    assert scene.add(Frame("a"), 1.0) == [Frame("a", 1.0)]
    again = scene.add(Frame("b"), 0.96)  # b reads 4 % far against a: the mean moves to sqrt(0.96)
    assert [f.name for f in again] == ["a", "b"]
    np.testing.assert_allclose([f.scale for f in again], [1 / np.sqrt(0.96), np.sqrt(0.96)])
    # c agrees with the volume as it stands (the mean scale): nothing moves, c alone is fused.
    assert scene.add(Frame("c"), 1.0) == [Frame("c", 1.0)]
    for name in "def":
        last = scene.add(Frame(name), 1.02)
    assert len(last) == SETTLING_FRAMES and last[0] != Frame("a")
    np.testing.assert_allclose(np.prod([f.scale for f in last]), 1.0)  # errors that average to none
    assert scene.settled and scene.add(Frame("g"), 0.99) == [Frame("g", 0.99)]
    assert SceneScale(settled=True).add(Frame("a"), 1.03) == [Frame("a", 1.03)]  # a restored volume
