"""The structured-light depth model and camera pose error, on depth images whose truth is known."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim_worker.sensors import PoseError, StructuredLightNoise, shadowed
from vgn_contract.schemas import Intrinsics

K = Intrinsics(width=320, height=240, fx=270.0, fy=270.0, cx=160.0, cy=120.0)


def plane(z: float) -> np.ndarray:
    return np.full((K.height, K.width), z, dtype=np.float32)


def box_before_plane() -> np.ndarray:
    depth = plane(0.8)
    depth[90:150, 130:190] = 0.6  # a square 20 cm nearer, in the middle of the image
    return depth


def test_axial_noise_grows_with_the_square_of_the_distance():
    model = StructuredLightNoise(K, steep_start_deg=90.0, steep_end_deg=91.0, quantum=1e-6)
    spreads = []
    for z in (0.5, 1.0, 1.5):
        noisy = model.apply(plane(z), np.random.default_rng(0))
        centre = noisy[60:180, 120:300]  # clear of the band the projector does not see
        assert np.all(centre > 0)
        spreads.append(np.std(centre - z))
        assert spreads[-1] == pytest.approx(float(model.sigma(np.array(z))), rel=0.05)
    # Nguyen et al.: 1.2 mm + 1.9 mm/m^2 (z - 0.4 m)^2
    np.testing.assert_allclose(
        spreads, [0.0012 + 0.0019 * (z - 0.4) ** 2 for z in (0.5, 1.0, 1.5)], rtol=0.05
    )


def test_depth_is_quantised_and_reproducible():
    model = StructuredLightNoise(K)
    first = model.apply(box_before_plane(), np.random.default_rng(3))
    np.testing.assert_array_equal(first, model.apply(box_before_plane(), np.random.default_rng(3)))
    readings = first[first > 0].astype(np.float64)
    np.testing.assert_allclose(readings * 1000, np.rint(readings * 1000), atol=1e-3)


def test_the_projector_casts_a_shadow_beside_an_object_on_the_far_side():
    mask = shadowed(box_before_plane().astype(np.float64), K, baseline=0.05)
    # The projector sits at +x: the box hides from it the plane just left of the box (columns
    # 125-129 here: a 5 cm baseline, box at 0.6 m, plane at 0.8 m), nothing on the right.
    assert mask[95:145, 125:130].mean() > 0.9
    assert not mask[95:145, 100:122].any() and not mask[95:145, 190:220].any()
    assert not mask[95:145, 135:185].any()  # the box itself is lit
    assert mask[:, :15].all()  # the image edge the projector cannot see at all (270 px x 5 cm / 0.8 m)


def test_steep_surfaces_lose_their_readings():
    model = StructuredLightNoise(K, baseline=0.0, edge_dropout=0.0, flying_pixel=0.0)
    tilt = np.radians(80.0)  # a plane whose normal is 80 degrees off the optical axis at the centre
    normal = np.array([np.sin(tilt), 0.0, -np.cos(tilt)])
    u, v = np.meshgrid(np.arange(K.width), np.arange(K.height))
    rays = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(u.shape)], axis=-1)
    facing = rays @ normal
    depth = np.where(facing < -0.05, -0.8 * np.cos(tilt) / np.minimum(facing, -1e-9), 0.0)
    angle = np.degrees(np.arccos(np.abs(facing) / np.linalg.norm(rays, axis=-1)))
    noisy = model.apply(depth.astype(np.float32), np.random.default_rng(1))
    kept = noisy > 0
    assert kept[(depth > 0) & (angle > 86.0)].mean() < 0.05
    assert kept[(depth > 0) & (angle < 68.0)].mean() > 0.99
    assert (model.apply(plane(0.8), np.random.default_rng(1))[:, 20:] > 0).all()  # a frontal plane keeps all


def test_edges_drop_or_smear_pixels_between_the_two_surfaces():
    model = StructuredLightNoise(K, baseline=0.0, sigma_base=0.0, sigma_quadratic=0.0, quantum=1e-6)
    noisy = model.apply(box_before_plane(), np.random.default_rng(5))
    border = np.zeros((K.height, K.width), dtype=bool)
    border[89:151, 129:191] = True
    border[91:149, 131:189] = False
    values = noisy[border]
    assert (values == 0).any()  # dropped at the discontinuity
    assert ((values > 0.605) & (values < 0.795)).any()  # flying pixels between box and plane
    inside = noisy[95:145, 135:185]
    np.testing.assert_allclose(inside, 0.6, atol=1e-5)  # away from edges nothing changes


def test_pose_error_has_the_asked_spread():
    error = PoseError(position_sigma=0.005, rotation_sigma_deg=1.0)
    rng = np.random.default_rng(0)
    truth = np.eye(4)
    reported = [error.perturb(truth, rng) for _ in range(4000)]
    shifts = np.array([r[:3, 3] for r in reported])
    angles = np.degrees([np.linalg.norm(Rotation.from_matrix(r[:3, :3]).as_rotvec()) for r in reported])
    assert np.std(shifts, axis=0) == pytest.approx([0.005] * 3, rel=0.1)
    assert np.sqrt(np.mean(angles**2)) == pytest.approx(1.0, rel=0.1)
    assert all(np.allclose(r[:3, :3] @ r[:3, :3].T, np.eye(3), atol=1e-9) for r in reported[:10])
