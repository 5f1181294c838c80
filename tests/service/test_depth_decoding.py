"""Decoding and compacting depth images: the fast paths give exactly what the plain numpy ones did."""

from __future__ import annotations

import numpy as np
import pytest

from service.depth import RAW_MEDIA_TYPE, decode_depth
from service.errors import InvalidInput
from service.tsdf import compact_depth
from vgn_contract.schemas import Intrinsics

INTRINSICS = Intrinsics(width=4, height=3, fx=5.0, fy=5.0, cx=2.0, cy=1.5)
EDGES = [0.0, 0.5, 1.999, 65504.0, 65520.0, 1e30, np.inf, -np.inf, np.nan, 3e-8, -0.0, 2.0]


def test_raw_depth_keeps_readings_and_zeroes_non_finite_ones():
    depth = np.array(EDGES, dtype=np.float32).reshape(3, 4)
    decoded = decode_depth(depth.astype("<f4").tobytes(), RAW_MEDIA_TYPE, INTRINSICS, 1000.0)
    expected = np.where(np.isfinite(depth), depth, 0.0).astype(np.float32)
    assert decoded.dtype == np.float32 and decoded.flags.writeable
    np.testing.assert_array_equal(decoded, expected)


def test_negative_raw_depth_is_counted_among_non_finite_readings():
    depth = np.full((3, 4), np.nan, dtype=np.float32)
    depth[0, :3] = [-0.1, -np.inf, 0.4]
    depth[2, 3] = -2.0
    with pytest.raises(InvalidInput, match="holds 2 negative values"):
        decode_depth(depth.tobytes(), RAW_MEDIA_TYPE, INTRINSICS, 1000.0)


def test_compact_depth_equals_numpys_float16_cast():
    rng = np.random.default_rng(0)
    depth = np.concatenate([np.array(EDGES, np.float32), rng.uniform(0, 3, 10_000).astype(np.float32)])
    with np.errstate(over="ignore"):
        expected = depth.astype(np.float16)
    compact = compact_depth(depth)
    assert compact.dtype == np.float16
    np.testing.assert_array_equal(compact, expected)  # NaN where NaN, inf where it overflows
    strided = np.arange(24, dtype=np.float32).reshape(4, 6)[:, ::2]  # not contiguous
    np.testing.assert_array_equal(compact_depth(strided), strided.astype(np.float16))
