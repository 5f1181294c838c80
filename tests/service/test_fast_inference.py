"""The fast inference path gives the grasps of VGN as trained: folded weights, fused heads
and bfloat16 are checked against the float32 eager network on recorded cluttered scenes."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from service.planner import GraspPlanner, InferenceOptions, native_bf16
from service.settings import PACKAGED_MODEL
from service.vgn.agreement import Tolerance, disagreements, network_outputs, voxelwise_disagreements
from service.vgn.checkpoint import load_vgn
from service.vgn.detection import DetectionConfig, detect_grasps
from service.vgn.fast import (
    FastVGN,
    pixel_shuffle_3d,
    polyphase_weights,
    space_to_depth,
    space_to_depth_weights,
)
from service.vgn.network import VGN
from service.vgn.outputs import ComputedHeads, HeadsOnDemand
from tests.helpers.grids import recorded_grids
from vgn_contract.schemas import Grasp, GraspQuery

VOXEL = 0.3 / 40
#: Low enough that the recorded scenes offer most of their grasps (after non-maximum suppression a
#: scene has 8-15 with the packaged model), so the top 10 are compared where there are 10.
THRESHOLD = 0.3


def grasps_of(network: torch.nn.Module, grid: np.ndarray):
    quality, rotation, width = network_outputs(network, grid)
    return detect_grasps(
        grid, quality, rotation, width, VOXEL, np.eye(4), DetectionConfig(threshold=THRESHOLD)
    )


def test_a_folded_convolution_equals_convolving_the_upsampled_input():
    torch.manual_seed(0)
    for kernel in (3, 5):
        conv = torch.nn.Conv3d(3, 2, kernel, padding=kernel // 2).double()
        x = torch.rand(1, 3, 4, 5, 6, dtype=torch.float64)
        expected = conv(torch.nn.functional.interpolate(x, scale_factor=2))
        weight, bias = polyphase_weights(conv.weight, conv.bias)
        folded = pixel_shuffle_3d(torch.nn.functional.conv3d(x, weight, bias, padding=1))
        assert torch.allclose(folded, expected, atol=1e-12)


def test_a_strided_convolution_equals_a_convolution_over_the_parity_channels():
    torch.manual_seed(1)
    for kernel in (3, 5):
        conv = torch.nn.Conv3d(2, 3, kernel, stride=2, padding=kernel // 2).double()
        x = torch.rand(2, 2, 8, 10, 12, dtype=torch.float64)
        weight = space_to_depth_weights(conv.weight)
        folded = torch.nn.functional.conv3d(space_to_depth(x), weight, conv.bias, padding=1)
        assert torch.allclose(folded, conv(x), atol=1e-12)
    assert torch.equal(pixel_shuffle_3d(space_to_depth(x)), x)


@pytest.mark.parametrize("resolution", [40, 48])
def test_fast_float32_matches_the_network_voxel_for_voxel(resolution):
    torch.manual_seed(3)
    network = VGN().eval()
    fast = FastVGN.from_vgn(network)
    grid = torch.rand(2, 1, resolution, resolution, resolution)
    with torch.inference_mode():
        for expected, actual in zip(network(grid), fast(grid), strict=True):
            assert actual.shape == expected.shape
            assert torch.allclose(actual, expected, atol=1e-4)


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16], ids=["fp32", "bf16"])
def test_fast_top10_grasps_agree_with_the_reference_on_recorded_scenes(dtype):
    if dtype == torch.bfloat16 and not native_bf16(torch.device("cpu")):
        pytest.skip("this CPU has no native bfloat16; the service uses float32 here")
    reference = load_vgn(PACKAGED_MODEL)
    fast = FastVGN.from_vgn(reference, dtype)
    tolerance = Tolerance(position_m=VOXEL, angle_deg=5.0, quality=0.02)
    compared = 0
    for name, grid in recorded_grids():
        expected, actual = grasps_of(reference, grid), grasps_of(fast, grid)
        assert len(expected) >= 5, f"{name}: the recorded scene should offer grasps to compare"
        # Where two neighbouring voxels nearly tie, NMS may keep the other one: the lists then
        # differ by a voxel, and the outputs must agree voxel by voxel for that to be a tie.
        assert disagreements(expected, actual, tolerance, neighbour_swaps=True) == [], name
        outputs = [network_outputs(network, grid) for network in (reference, fast)]
        graspable = outputs[0][0] >= 0.5
        assert voxelwise_disagreements(*outputs, graspable, tolerance) == [], name
        compared += min(len(expected), 10)
    assert compared >= 35, "the recorded scenes should offer enough grasps to compare"


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
def test_the_planners_grasps_agree_with_the_reference_plain_and_turn_averaged(precision):
    """The planner's own path (quality head alone, rotation and width where detection reads
    them) gives the reference network's top-10 grasps, for plain and turn-averaged requests."""
    if precision == "bf16" and not native_bf16(torch.device("cpu")):
        pytest.skip("this CPU has no native bfloat16; the service uses float32 here")
    fast = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", InferenceOptions(precision=precision))
    reference = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", InferenceOptions(form="reference"))
    tolerance = Tolerance(position_m=VOXEL, angle_deg=5.0, quality=0.02)
    query = GraspQuery(threshold=THRESHOLD, turn_average=False)
    for turn_average in (False, True):
        for name, grid in recorded_grids():
            expected, actual = (
                planner.detect(grid, planner.infer(grid, turn_average), VOXEL, np.eye(4), query)
                for planner in (reference, fast)
            )
            assert len(expected) >= 5, name
            assert disagreements(expected, actual, tolerance, neighbour_swaps=True) == [], (
                name,
                turn_average,
            )


def test_the_agreement_check_notices_a_different_network():
    """The check above can fail: weights of another network disagree on the same scenes."""
    reference = load_vgn(PACKAGED_MODEL)
    other = load_vgn(PACKAGED_MODEL)
    with torch.no_grad():
        other.conv_qual.bias.add_(0.3)  # a slightly different quality head
    tolerance = Tolerance(position_m=VOXEL)
    name, grid = recorded_grids()[0]
    assert disagreements(grasps_of(reference, grid), grasps_of(FastVGN.from_vgn(other), grid), tolerance)
    outputs = [network_outputs(network, grid) for network in (reference, FastVGN.from_vgn(other))]
    assert voxelwise_disagreements(*outputs, outputs[0][0] >= 0.5, tolerance)


def test_a_neighbour_swap_is_excused_only_one_voxel_apart_at_equal_quality():
    def grasp(y: float, quality: float, turn_deg: float) -> Grasp:
        orientation = Rotation.from_euler("z", turn_deg, degrees=True).as_quat().tolist()
        return Grasp(
            position=[0.1, y, 0.1], orientation=orientation, approach=[0, 0, 1], width=0.04, quality=quality
        )

    tolerance = Tolerance(position_m=VOXEL)
    reference = [grasp(0.1, 0.95, 0.0), grasp(0.2, 0.9, 0.0)]
    for neighbour, excused in ((grasp(0.1 + VOXEL, 0.95, 30.0), True), (grasp(0.1 + 2 * VOXEL, 0.95, 30.0), False),
                               (grasp(0.1 + VOXEL, 0.91, 30.0), False)):  # fmt: skip
        candidate = [neighbour, grasp(0.2, 0.9, 0.0)]
        assert disagreements(reference, candidate, tolerance), "a 30-degree turn is no match"
        assert (disagreements(reference, candidate, tolerance, neighbour_swaps=True) == []) is excused


def test_the_planner_runs_the_fast_form_by_default_and_the_reference_on_request():
    fast = GraspPlanner.from_path(PACKAGED_MODEL, "cpu")
    reference = GraspPlanner.from_path(PACKAGED_MODEL, "cpu", InferenceOptions(form="reference"))
    assert fast.runtime()["inference"] == "fast" and reference.runtime()["precision"] == "float32"
    _, grid = recorded_grids()[1]
    a, b = fast.infer(grid), reference.infer(grid)
    assert np.abs(a.quality - b.quality).max() < 0.02
    # Turn-averaged, the fast form runs its turned grids for quality alone and the reference
    # form runs them whole: the grasps detection reads agree all the same.
    fast_averaged, reference_averaged = (
        fast.infer(grid, turn_average=True),
        reference.infer(grid, turn_average=True),
    )
    assert isinstance(reference_averaged.turned_rotations[1], ComputedHeads)
    assert isinstance(fast_averaged.turned_rotations[1], HeadsOnDemand)
    assert np.abs(fast_averaged.quality - reference_averaged.quality).max() < 0.02
    where = fast_averaged.quality > 0.5
    assert 0 < where.sum() < 4096
    agreement = np.abs(
        np.einsum(
            "q...,q...->...", fast_averaged.rotation_where(where), reference_averaged.rotation_where(where)
        )
    )
    assert np.percentile(agreement[where], 5) > 0.9999, (
        "orientations agree (up to sign) at 95 % of the voxels"
    )


def test_each_head_alone_and_the_heads_at_a_few_voxels_match_the_fused_heads():
    """Quality alone, rotation and width alone, and the two evaluated voxel by voxel (what
    detection reads) equal what the fused heads give; voxels on every face are included, where
    the neighbourhood reaches into the padding."""
    fast = FastVGN.from_vgn(load_vgn(PACKAGED_MODEL))
    _, grid = recorded_grids()[0]
    n = grid.shape[0]
    with torch.inference_mode():
        tensor = torch.from_numpy(np.ascontiguousarray(grid))[None, None]
        quality, rotation, width = fast(tensor)
        features = fast.features(tensor)
        torch.testing.assert_close(fast.quality_from(features), quality, atol=1e-6, rtol=0)
        rotation_alone, width_alone = fast.rotation_and_width_from(features)
        torch.testing.assert_close(rotation_alone, rotation, atol=1e-6, rtol=0)
        torch.testing.assert_close(width_alone, width, atol=1e-5, rtol=1e-6)
        rng = np.random.default_rng(0)
        voxels = rng.integers(0, n, size=(300, 3))
        voxels[:6] = [
            [0, 0, 0],
            [n - 1, n - 1, n - 1],
            [0, n - 1, 7],
            [n - 1, 0, 8],
            [5, 0, n - 1],
            [n - 1, 3, 0],
        ]
        at, width_at = fast.heads_at(fast.padded_features(features[0]), voxels)
    expected = rotation[0].numpy()[:, voxels[:, 0], voxels[:, 1], voxels[:, 2]]
    np.testing.assert_allclose(width_at, width[0, 0].numpy()[tuple(voxels.T)], atol=1e-4, rtol=1e-5)
    np.testing.assert_allclose(at, expected, atol=1e-5)
    none = fast.heads_at(fast.padded_features(features[0]), voxels[:0])
    assert none[0].shape == (4, 0) and none[1].shape == (0,)
