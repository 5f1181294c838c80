"""The simulated camera: rendered depth against known geometry, renderers, views, noise.

Scene: the World's table (top at z = 0.05) and one box standing on it, checked against
the analytic ray caster of ``tests/helpers/scenes.py``. Frames and units as docs/conventions.md.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pybullet
import pytest
from scipy.spatial.transform import Rotation

from sim_worker.camera import (
    SIM_INTRINSICS,
    TINY_SAMPLE_OFFSET,
    Camera,
    DepthNoise,
    bilinear_upsample,
    camera_on_sphere,
    column_major,
    metric_depth,
    opengl_projection,
    opengl_view,
    random_views,
    side_view,
    six_views,
)
from sim_worker.world import TABLE_Z, World
from tests.helpers.scenes import BoxScene
from vgn_contract.geometry import check_rigid_matrix, invert, look_at

K = SIM_INTRINSICS
BOX_CENTRE = (0.13, 0.16)  # x, y of the box's centre, metres
BOX_HALF = (0.03, 0.0213, 0.04)  # half extents: 6.0 × 4.26 × 8.0 cm, top at z = 0.13
BOX_TOP = TABLE_Z + 2 * BOX_HALF[2]
BOX = BoxScene(
    lower=(BOX_CENTRE[0] - BOX_HALF[0], BOX_CENTRE[1] - BOX_HALF[1], TABLE_Z),
    upper=(BOX_CENTRE[0] + BOX_HALF[0], BOX_CENTRE[1] + BOX_HALF[1], BOX_TOP),
)
CAMERA_HEIGHT = 0.60
#: Straight above the box's top centre, image right = world +x, image down = world -y.
TOP_DOWN = look_at((*BOX_CENTRE, CAMERA_HEIGHT), (*BOX_CENTRE, 0.0), up=(0.0, 1.0, 0.0))


# Scene ------------------------------------------------------------------------------------
def _add_box(world: World) -> int:
    half = list(BOX_HALF)
    shape = world.p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
    visual = world.p.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=[0.9, 0.1, 0.1, 1])
    return world.p.createMultiBody(0.0, shape, visual, basePosition=[*BOX_CENTRE, TABLE_Z + BOX_HALF[2]])


def _scene(renderer: str) -> Iterator[tuple[Camera, int]]:
    try:
        world = World(renderer=renderer)
    except RuntimeError as error:
        pytest.skip(f"renderer {renderer!r} unavailable here: {error}")
    with world:
        yield Camera(world), _add_box(world)


@pytest.fixture(scope="module")
def tiny_scene() -> Iterator[tuple[Camera, int]]:
    yield from _scene("tiny")


@pytest.fixture(scope="module")
def egl_scene() -> Iterator[tuple[Camera, int]]:
    yield from _scene("egl")


@pytest.fixture(params=["tiny", "egl"])
def scene(request: pytest.FixtureRequest) -> tuple[Camera, int]:
    """The box scene under each renderer (EGL skips where it cannot load)."""
    return request.getfixturevalue(f"{request.param}_scene")


def _back_project(depth: np.ndarray, camera_pose: np.ndarray) -> np.ndarray:
    """(n, 3) world points of the valid pixels of ``depth`` seen from ``camera_pose``."""
    v, u = np.nonzero(depth > 0)
    z = depth[v, u].astype(np.float64)
    points = np.stack([(u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z, np.ones_like(z)], axis=-1)
    return (points @ camera_pose.T)[:, :3]


def _project(point: np.ndarray, camera_pose: np.ndarray) -> tuple[float, float, float]:
    """``(u, v, z)`` of a world point in the image of ``camera_pose``."""
    x, y, z, _ = invert(camera_pose) @ np.append(point, 1.0)
    return K.fx * x / z + K.cx, K.fy * y / z + K.cy, z


# Matrices -----------------------------------------------------------------------------------
def test_projection_matrix_agrees_with_pinhole() -> None:
    """Points in the OpenCV camera frame land at the OpenCV pixel, depth survives the z-buffer."""
    near, far = 0.1, 2.0
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-0.3, 0.3, (50, 2)), rng.uniform(0.2, 1.9, 50)])
    projection = opengl_projection(K, near, far)
    clip = (projection @ np.diag([1.0, -1.0, -1.0, 1.0]) @ np.column_stack([points, np.ones(50)]).T).T
    ndc = clip[:, :3] / clip[:, 3:]
    # OpenGL pixel i spans NDC [2i/w - 1, 2(i+1)/w - 1]; row 0 is the top (NDC y = +1).
    column = (ndc[:, 0] + 1.0) / 2.0 * K.width - 0.5
    row = (1.0 - ndc[:, 1]) / 2.0 * K.height - 0.5
    np.testing.assert_allclose(column, K.fx * points[:, 0] / points[:, 2] + K.cx, atol=1e-9)
    np.testing.assert_allclose(row, K.fy * points[:, 1] / points[:, 2] + K.cy, atol=1e-9)
    depth = metric_depth((ndc[:, 2] + 1.0) / 2.0, near, far)
    np.testing.assert_allclose(depth, points[:, 2], rtol=1e-6)
    assert metric_depth(np.ones((2, 2)), near, far).tolist() == [[0.0, 0.0], [0.0, 0.0]]


def test_tiny_offset_moves_the_principal_point() -> None:
    shifted = opengl_projection(K, 0.1, 2.0, TINY_SAMPLE_OFFSET)
    moved = K.model_copy(update={"cx": K.cx - 0.5, "cy": K.cy + 0.5})
    np.testing.assert_allclose(shifted, opengl_projection(moved, 0.1, 2.0))


def test_view_matrix_matches_pybullet() -> None:
    """Our column-major view matrix equals PyBullet's own for the same eye, target and up."""
    eye, target, up = np.array([0.4, -0.2, 0.5]), np.array([0.15, 0.15, 0.0]), np.array([0.0, 0.0, 1.0])
    ours = column_major(opengl_view(look_at(eye, target, up)))
    theirs = pybullet.computeViewMatrix(eye.tolist(), target.tolist(), up.tolist())
    np.testing.assert_allclose(ours, theirs, atol=1e-6)


# Depth against geometry ---------------------------------------------------------------------
def test_top_down_depth_matches_heights(tiny_scene: tuple[Camera, int]) -> None:
    camera, _ = tiny_scene
    depth = camera.render_depth(TOP_DOWN)
    assert depth.shape == (K.height, K.width) and depth.dtype == np.float32
    assert depth[K.height // 2, K.width // 2] == pytest.approx(CAMERA_HEIGHT - BOX_TOP, abs=0.003)
    assert depth[10, 10] == pytest.approx(CAMERA_HEIGHT - TABLE_Z, abs=0.003)
    assert depth[-10, -10] == pytest.approx(CAMERA_HEIGHT - TABLE_Z, abs=0.003)


def test_box_outline_lands_on_predicted_pixels(scene: tuple[Camera, int]) -> None:
    """From above, the box top covers exactly the pixels whose centres its outline encloses:
    checks cx, cy, the row order, image axes and the half-pixel convention (to < 0.5 px)."""
    camera, box = scene
    _, segmentation = camera.render(TOP_DOWN)
    rows, columns = np.nonzero(segmentation == box)
    scale = K.fx / (CAMERA_HEIGHT - BOX_TOP)  # pixels per metre on the top face
    u0, u1 = K.cx - BOX_HALF[0] * scale, K.cx + BOX_HALF[0] * scale  # world +x = image right
    v0, v1 = K.cy - BOX_HALF[1] * scale, K.cy + BOX_HALF[1] * scale
    for edge in (u0, u1, v0, v1):  # outline well between pixel centres, so no ties
        assert 0.3 < edge % 1.0 < 0.7
    assert (columns.min(), columns.max()) == (np.ceil(u0), np.floor(u1))
    assert (rows.min(), rows.max()) == (np.ceil(v0), np.floor(v1))


def test_oblique_view_points_lie_on_the_surfaces(scene: tuple[Camera, int]) -> None:
    camera, _ = scene
    pose = six_views()[1]
    depth = camera.render_depth(pose)
    valid = depth > 0
    assert valid.mean() > 0.99  # the 1 m table fills this view
    distance = BOX.distance_to_surface(_back_project(depth, pose))
    assert np.percentile(distance, 95) < 0.003
    assert np.percentile(distance, 99.5) < 0.005
    expected = BOX.depth(pose, K)
    assert np.mean(np.abs(depth - expected)[valid] > 0.003) < 0.01  # only silhouette edges differ


def test_box_top_centre_at_its_projected_pixel(scene: tuple[Camera, int]) -> None:
    camera, box = scene
    pose = six_views()[3]
    depth, segmentation = camera.render(pose)
    u, v, z = _project(np.array([*BOX_CENTRE, BOX_TOP]), pose)
    row, column = int(round(v)), int(round(u))
    assert segmentation[row, column] == box
    assert depth[row, column] == pytest.approx(z, abs=0.003)


def test_background_and_segmentation(scene: tuple[Camera, int]) -> None:
    """Past the table's edge there is no reading: depth 0 and segmentation -1."""
    camera, box = scene
    depth, segmentation = camera.render(side_view())
    background = segmentation == -1
    assert 0.05 < background.mean() < 0.9
    assert np.all(depth[background] == 0) and np.all(depth[~background] > 0)
    assert depth.max() < camera.far
    assert set(np.unique(segmentation)) == {-1, camera.world.table, box}


def test_render_rgb(tiny_scene: tuple[Camera, int]) -> None:
    camera, _ = tiny_scene
    rgb = camera.render_rgb(TOP_DOWN)
    assert rgb.shape == (K.height, K.width, 3) and rgb.dtype == np.uint8
    red, green, _ = rgb[K.height // 2, K.width // 2].astype(int)
    assert red > green + 50  # the red box top at the centre


def test_egl_and_tiny_agree(tiny_scene: tuple[Camera, int], egl_scene: tuple[Camera, int]) -> None:
    """The same scene under both renderers (EGL here is Mesa's software llvmpipe)."""
    tiny, _ = tiny_scene
    egl, _ = egl_scene
    assert egl.world.egl and not tiny.world.egl
    for pose in [*six_views()[::2], side_view(), TOP_DOWN]:
        a, b = tiny.render_depth(pose), egl.render_depth(pose)
        assert np.mean(np.abs(a - b) > 0.005) < 0.01
        assert np.mean((a > 0) != (b > 0)) < 0.01


def test_camera_applies_noise(tiny_scene: tuple[Camera, int]) -> None:
    camera, _ = tiny_scene
    clean = camera.render_depth(side_view())
    noisy = Camera(camera.world, noise=DepthNoise(), rng=np.random.default_rng(3)).render_depth(side_view())
    assert np.array_equal(noisy == 0, clean == 0)
    assert not np.array_equal(noisy, clean)


# Views ------------------------------------------------------------------------------------
def _tilt_deg(pose: np.ndarray, centre: np.ndarray) -> float:
    offset = pose[:3, 3] - centre
    return float(np.degrees(np.arccos(offset[2] / np.linalg.norm(offset))))


def _assert_looks_at(pose: np.ndarray, centre: np.ndarray) -> None:
    check_rigid_matrix(pose)
    assert np.isclose(np.linalg.det(pose[:3, :3]), 1.0)
    towards = (centre - pose[:3, 3]) / np.linalg.norm(centre - pose[:3, 3])
    np.testing.assert_allclose(pose[:3, 2], towards, atol=1e-9)


def test_six_views() -> None:
    centre = np.array([0.15, 0.15, 0.0])
    poses = six_views()
    assert len(poses) == 6
    azimuths = []
    for pose in poses:
        _assert_looks_at(pose, centre)
        assert np.linalg.norm(pose[:3, 3] - centre) == pytest.approx(0.6)
        assert _tilt_deg(pose, centre) == pytest.approx(30.0)
        np.testing.assert_allclose(pose, look_at(pose[:3, 3], centre, up=(0.0, 0.0, 1.0)), atol=1e-9)
        azimuths.append(np.degrees(np.arctan2(*(pose[1::-1, 3] - centre[1::-1]))))
    np.testing.assert_allclose(np.diff(np.unwrap(np.radians(azimuths))), np.radians(60.0), atol=1e-9)


def test_world_up_is_image_up() -> None:
    pose = six_views()[2]
    _, v_centre, _ = _project(np.array([0.15, 0.15, 0.0]), pose)
    _, v_above, _ = _project(np.array([0.15, 0.15, 0.1]), pose)
    assert v_above < v_centre


def test_side_view() -> None:
    centre = np.array([0.15, 0.15, 0.10])
    pose = side_view()
    _assert_looks_at(pose, centre)
    np.testing.assert_allclose(pose[:3, 3], [0.15, 0.15 - 0.6 * np.sin(np.pi / 3), 0.4], atol=1e-9)
    assert _tilt_deg(pose, centre) == pytest.approx(60.0)


def test_random_views_in_range_and_reproducible() -> None:
    centre = np.array([0.15, 0.15, 0.0])
    poses = random_views(np.random.default_rng(7), 200)
    assert len(poses) == 200
    distances = [np.linalg.norm(pose[:3, 3] - centre) for pose in poses]
    tilts = [_tilt_deg(pose, centre) for pose in poses]
    assert min(distances) >= 0.48 and max(distances) <= 0.72 and max(distances) - min(distances) > 0.2
    assert min(tilts) >= 0.0 and max(tilts) <= 45.0 + 1e-9 and max(tilts) - min(tilts) > 40.0
    for pose in poses:
        _assert_looks_at(pose, centre)
    again = random_views(np.random.default_rng(7), 200)
    assert all(np.array_equal(a, b) for a, b in zip(poses, again, strict=True))
    other = random_views(np.random.default_rng(8), 200)
    assert not np.allclose(poses[0], other[0])


def test_straight_down_view_is_defined() -> None:
    """Tilt 0 (possible in random_views) has no look_at up vector; the pose is still rigid."""
    centre = np.array([0.15, 0.15, 0.0])
    for azimuth in (0.0, 1.0, 4.0):
        pose = camera_on_sphere(centre, 0.5, 0.0, azimuth)
        _assert_looks_at(pose, centre)
        np.testing.assert_allclose(pose[:3, 3], [0.15, 0.15, 0.5], atol=1e-12)
    (pose,) = random_views(np.random.default_rng(0), 1, tilt_deg=(0.0, 0.0))
    _assert_looks_at(pose, centre)


def test_camera_on_sphere_matches_look_at() -> None:
    centre = np.array([0.1, 0.2, 0.05])
    for tilt in np.radians([1.0, 20.0, 45.0, 89.0]):
        for azimuth in np.radians([0.0, 75.0, 200.0, 330.0]):
            pose = camera_on_sphere(centre, 0.6, tilt, azimuth)
            np.testing.assert_allclose(pose, look_at(pose[:3, 3], centre), atol=1e-9)


def test_rolled_camera_depth_has_no_subpixel_shift(scene: tuple[Camera, int]) -> None:
    """The table seen by a rolled, tilted camera: depth at every pixel matches the ray through
    its centre (a half-pixel shift would cost ~0.15 mm on average here)."""
    camera, _ = scene
    roll = np.eye(4)
    roll[:3, :3] = Rotation.from_euler("z", 35.0, degrees=True).as_matrix()
    pose = camera_on_sphere((0.45, 0.45, TABLE_Z), 0.4, np.radians(50.0), np.radians(30.0)) @ roll
    depth = camera.render_depth(pose)
    valid = depth > 0
    error = np.abs(depth - BOX.depth(pose, K))[valid]
    edges = error > 0.001  # the box's silhouette, if in view
    assert valid.mean() > 0.8 and edges.mean() < 0.01
    assert np.mean(error[~edges]) < 3e-5


# Noise ------------------------------------------------------------------------------------
def test_noise_keeps_missing_pixels_missing() -> None:
    depth = np.full((48, 64), 0.6, dtype=np.float32)
    depth[:10] = 0.0
    depth[10, :5] = np.nan
    noisy = DepthNoise(field_probability=1.0).apply(depth, np.random.default_rng(0))
    assert noisy.dtype == np.float32 and noisy.shape == depth.shape
    assert np.all(noisy[:10] == 0) and np.all(noisy[10, :5] == 0)
    assert np.all(noisy[11:] > 0)


def test_noise_is_small_and_unbiased() -> None:
    depth = np.full((48, 64), 0.6, dtype=np.float32)
    noise = DepthNoise()
    rng = np.random.default_rng(1)
    ratios = np.array([noise.apply(depth, rng) / depth for _ in range(300)])
    assert abs(ratios.mean() - 1.0) < 0.005
    assert np.abs(ratios - 1.0).max() < 0.2
    assert 0.02 < ratios.mean(axis=(1, 2)).std() < 0.045  # per-frame scale, 1/√1000 ≈ 0.032


def test_noise_field_is_smooth() -> None:
    depth = np.full((120, 160), 0.6, dtype=np.float32)
    noise = DepthNoise(gamma_shape=1e12, field_sigma=0.005, field_probability=1.0)
    added = noise.apply(depth, np.random.default_rng(2)).astype(np.float64) - depth
    assert 0.4 * 0.005 < added.std() < 1.1 * 0.005
    # Neighbours differ by ~σ·1.13/4 (4 px cells); white noise of the same σ would give ~1.1σ.
    assert np.abs(np.diff(added, axis=1)).mean() < 0.4 * 0.005
    assert np.abs(np.diff(added, axis=0)).mean() < 0.4 * 0.005


def test_noise_reproducible_per_seed() -> None:
    depth = np.random.default_rng(0).uniform(0.4, 0.8, (48, 64)).astype(np.float32)
    noise = DepthNoise(field_probability=1.0)
    a = noise.apply(depth, np.random.default_rng(5))
    assert np.array_equal(a, noise.apply(depth, np.random.default_rng(5)))
    assert not np.array_equal(a, noise.apply(depth, np.random.default_rng(6)))


def test_bilinear_upsample() -> None:
    assert np.allclose(bilinear_upsample(np.full((3, 4), 2.5), (30, 40)), 2.5)
    ramp = bilinear_upsample(np.arange(4.0)[None, :].repeat(3, axis=0), (6, 16))
    assert ramp.shape == (6, 16)
    np.testing.assert_allclose(np.diff(ramp[0, 2:14]), 0.25)  # linear between cell centres
