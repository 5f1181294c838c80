"""``/model``'s typed parts (the request defaults, the runtime) and the options every grasp answer
reports, as the client parses them from HTTP's JSON and from gRPC, older services' answers included."""

from __future__ import annotations

import json

import pytest

from vgn_contract.grpc_api import convert
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.schemas import GraspDefaults, GraspResult, ModelInfo, RuntimeInfo

DEFAULTS = GraspDefaults(turn_average=True, clearance=True, grip=False, threshold=0.8, antipodal_threshold=0.5,
                         fallback_threshold=0.5)  # fmt: skip
#: ``runtime`` as a service from before ``defaults`` reports it, the request defaults among the facts.
OLD_RUNTIME = {
    "torch_threads": 1, "usable_cores": 2, "omp_wait_policy": "PASSIVE", "omp_set_by_service": ["OMP_WAIT_POLICY"],
    "omp_applied_before_torch": True, "malloc": {"set_by_service": False, "reason": "not glibc"},
    "torch": "2.13.0", "inference": "fast", "precision": "bfloat16", "heads": "on-demand", "batch_window_ms": 0.0,
    "max_batch": 32, "lanes": 2, "batches": {"batches": 3, "grids": 6, "largest": 4, "mean": 2.0},
    "turn_average": True, "clearance": True, "grip": False, "fallback_threshold": 0.5,
}  # fmt: skip
MODEL = {"loaded": True, "model_id": "abc", "source": "vgn.safetensors", "architecture": "VGN", "parameters": 1,
         "device": "cpu", "conventions": {}, "threshold": 0.8}  # fmt: skip


def test_the_runtime_of_a_service_from_before_the_defaults_still_parses():
    """Its runtime is typed now; the defaults it carried stay readable there, deprecated."""
    info = ModelInfo.model_validate({**MODEL, "runtime": OLD_RUNTIME})
    assert info.defaults is None
    assert info.runtime is not None and info.runtime.batches.largest == 4
    assert info.runtime.malloc.reason == "not glibc"
    with pytest.deprecated_call(match="defaults.turn_average"):
        assert info.runtime.turn_average is True
    assert info.runtime.model_dump(exclude_none=True) == OLD_RUNTIME, "the same keys as before"


def test_the_defaults_that_moved_are_marked_deprecated_where_they_were():
    schema = RuntimeInfo.model_json_schema()["properties"]
    moved = set(RuntimeInfo.model_fields) & set(GraspDefaults.model_fields)
    assert moved == {"turn_average", "clearance", "grip", "fallback_threshold"}
    for name in moved:
        assert schema[name]["deprecated"] is True and f"defaults.{name}" in schema[name]["description"]
    assert not any(schema[name].get("deprecated") for name in set(schema) - moved)


def test_the_threshold_is_said_once_in_the_defaults_and_repeated_deprecated():
    """The top-level ``threshold`` is ``defaults.threshold`` again, whatever was given beside it;
    from a service older than ``defaults`` it is the one it sent."""
    info = ModelInfo.model_validate({**MODEL, "threshold": 0.3, "defaults": DEFAULTS.model_dump()})
    assert ModelInfo.model_json_schema()["properties"]["threshold"]["deprecated"] is True
    with pytest.deprecated_call(match="defaults.threshold"):
        assert info.threshold == DEFAULTS.threshold
    assert json.loads(info.model_dump_json())["threshold"] == DEFAULTS.threshold, "still on the wire"
    without = ModelInfo.model_validate(
        {k: v for k, v in MODEL.items() if k != "threshold"} | {"defaults": DEFAULTS}
    )
    assert without.model_dump()["threshold"] == DEFAULTS.threshold
    assert ModelInfo.model_validate(MODEL).model_dump()["threshold"] == MODEL["threshold"], "an older service"
    message = convert.model_info_message(without)
    assert message.threshold == DEFAULTS.threshold, "gRPC's deprecated field too"
    assert pb.ModelInfo.DESCRIPTOR.fields_by_name["threshold"].GetOptions().deprecated


def test_model_info_travels_over_grpc_typed():
    info = ModelInfo.model_validate({**MODEL, "defaults": DEFAULTS.model_dump(), "runtime": OLD_RUNTIME})
    message = convert.model_info_message(info)
    assert message.defaults.grip is False and message.defaults.antipodal_threshold == 0.5
    assert convert.model_info(message) == info
    older = pb.ModelInfo(**MODEL)  # from a service without defaults or runtime
    assert (convert.model_info(older).defaults, convert.model_info(older).runtime) == (None, None)


def test_a_grasp_answer_says_which_options_it_used_over_http_and_grpc():
    answer = GraspResult(grasps=[], planning_ms=1.0, integration_ms=2.0, frame_count=1, model="abc", threshold=0.5,
                         turn_average=True, clearance=True, grip=True, fallback=True, clearance_dropped=3)  # fmt: skip
    assert GraspResult.model_validate_json(answer.model_dump_json()) == answer
    assert convert.grasp_result(convert.grasp_result_message(answer)) == answer
    off = answer.model_copy(
        update={"clearance": False, "grip": False, "fallback": False, "clearance_dropped": None}
    )
    assert convert.grasp_result(convert.grasp_result_message(off)) == off, "off is said, not left unset"
    older = pb.GraspResult(model="abc", threshold=0.9, frame_count=1)  # from a service before these fields
    parsed = convert.grasp_result(older)
    assert (parsed.clearance, parsed.grip, parsed.fallback) == (None, None, None)
