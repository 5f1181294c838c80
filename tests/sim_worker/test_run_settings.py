"""Run settings check themselves on construction: each bad field is refused by name with what
is allowed, and the defaults are valid."""

from __future__ import annotations

from typing import Any

import pytest

from sim_worker.clutter import ClutterConfig
from sim_worker.datagen import DataGenConfig


def test_the_defaults_are_valid():
    ClutterConfig()
    DataGenConfig()


@pytest.mark.parametrize(
    ("field", "value", "needle"),
    [
        ("scene", "heap", "'blocks', 'pile', 'packed'"),
        ("views", "top", "'six', 'side'"),
        ("selection", "first", "'best', 'random'"),
        ("planner", "gpd", "'vgn', 'antipodal'"),
        ("renderer", "opengl", "'auto', 'egl', 'tiny'"),
        ("object_count", 0, ">= 1"),
        ("object_count", 2.5, ">= 1"),
        ("rounds", 0, ">= 1"),
        ("threshold", 1.5, "[0, 1]"),
        ("threshold", -0.1, "[0, 1]"),
    ],
)
def test_clutter_settings_refuse(field: str, value: Any, needle: str):
    with pytest.raises(ValueError, match=field) as error:
        ClutterConfig(**{field: value})
    assert needle in str(error.value) and repr(value) in str(error.value)


@pytest.mark.parametrize(
    ("field", "value", "needle"),
    [
        ("scene", "blocks", "'pile', 'packed'"),
        ("renderer", "gl", "'auto', 'egl', 'tiny'"),
        ("points_per_scene", 0, ">= 1"),
        ("yaws", 0, ">= 1"),
        ("max_views", 0, ">= 1"),
        ("max_views", True, ">= 1"),
        ("noise_fraction", 1.2, "[0, 1]"),
        ("side_view_fraction", -0.5, "[0, 1]"),
    ],
)
def test_data_generation_settings_refuse(field: str, value: Any, needle: str):
    with pytest.raises(ValueError, match=field) as error:
        DataGenConfig(**{field: value})
    assert needle in str(error.value) and repr(value) in str(error.value)


@pytest.mark.parametrize("threshold", [None, 0.0, 0.9, 1.0])
def test_clutter_thresholds_in_range_are_kept(threshold: float | None):
    assert ClutterConfig(threshold=threshold).threshold == threshold
