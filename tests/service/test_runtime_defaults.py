"""The service picks its own thread count and OpenMP settings, in time for torch to use
them, and says so in ``GET /model``."""

from __future__ import annotations

import platform

import httpx

from service.launch.embedded import EmbeddedService
from service.runtime import (
    MALLOC_SETTINGS,
    MALLOC_VARIABLES,
    WAIT_POLICY,
    configured_threads,
    default_threads,
    prepare_environment,
    tune_malloc,
)

OPERATOR_VARIABLES = (
    "OMP_WAIT_POLICY",
    "OMP_NUM_THREADS",
    "VGN_TORCH_THREADS",
    "VGN_LANES",
    "GOMP_SPINCOUNT",
    *MALLOC_VARIABLES,
)
ON_GLIBC = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"


def test_default_threads_leave_cores_to_the_rest_of_the_service():
    assert [default_threads(cores) for cores in (1, 2, 3, 4, 16, 64)] == [1, 1, 1, 2, 8, 8]
    assert configured_threads({"VGN_TORCH_THREADS": "3"}) == 3
    assert configured_threads({"VGN_TORCH_THREADS": "zero"}) == configured_threads({})


def test_the_operator_s_openmp_settings_win():
    environ = {"OMP_WAIT_POLICY": "ACTIVE"}
    report = prepare_environment(environ)
    assert environ["OMP_WAIT_POLICY"] == "ACTIVE" and report["set_by_service"] == []
    environ = {}
    assert prepare_environment(environ)["set_by_service"] == ["OMP_WAIT_POLICY"]
    assert environ["OMP_WAIT_POLICY"] == WAIT_POLICY


def test_malloc_is_tuned_on_glibc_unless_the_operator_tuned_it():
    assert tune_malloc({"MALLOC_MMAP_THRESHOLD_": "65536"}) == {
        "set_by_service": False,
        "reason": "set by the operator's variables",
    }
    report = tune_malloc({})
    if ON_GLIBC:
        assert report == {
            "set_by_service": True,
            **{name: value for name, (_, value) in MALLOC_SETTINGS.items()},
        }
    else:
        assert report["set_by_service"] is False


def test_a_plain_start_sets_openmp_before_torch_and_reports_it(random_checkpoint):
    """``uvicorn service.app:app`` with none of the variables set, as the embedded service
    (and an operator) starts it."""
    with EmbeddedService(
        model=random_checkpoint, env={"VGN_API_KEY": ""}, unset=OPERATOR_VARIABLES
    ) as service:
        runtime = httpx.get(f"{service.url}/model").json()["runtime"]
    assert runtime["omp_wait_policy"] == WAIT_POLICY
    assert runtime["omp_set_by_service"] == ["OMP_WAIT_POLICY"]
    assert runtime["omp_applied_before_torch"] is True
    assert runtime["torch_threads"] == default_threads(runtime["usable_cores"])
    assert runtime["inference"] == "fast" and runtime["precision"] in ("bfloat16", "float32")
    assert runtime["heads"] == "on-demand"  # on a CPU
    assert runtime["malloc"]["set_by_service"] is ON_GLIBC


def test_the_operator_s_lane_count_is_used_and_reported(random_checkpoint):
    """``VGN_LANES`` overrides the lanes the service would choose (the cores over the torch threads)."""
    with EmbeddedService(model=random_checkpoint, env={"VGN_API_KEY": "", "VGN_LANES": "3"}) as service:
        runtime = httpx.get(f"{service.url}/model").json()["runtime"]
    assert runtime["lanes"] == 3
