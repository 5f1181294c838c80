"""The HTTP contract, fuzzed: schemathesis generates requests from the app's OpenAPI document
and sends them to a live uvicorn server on loopback, checking every answer against the
document (status codes, content types, headers, response schemas, Allow headers) and that
nothing is a server error. Seeded and derandomized, so the cases are the same from run to run.

The short run is ~130 requests; ``VGN_FUZZ_EXAMPLES=500 python3 -m pytest -m slow
tests/service/test_http_contract.py`` runs a larger one (see docs/development.md).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, seed, settings
from hypothesis import strategies as st
from hypothesis.errors import Flaky
from schemathesis.checks import (
    allow_header_conformance,
    content_type_conformance,
    ensure_resource_availability,
    missing_required_header,
    negative_data_rejection,
    not_a_server_error,
    positive_data_acceptance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
    unsupported_method,
    use_after_free,
)
from schemathesis.openapi.checks import RejectedPositiveData

from service.launch.embedded import EmbeddedService
from service.snapshot import Snapshot, encode
from vgn_contract import snapshot
from vgn_contract.schemas import Workspace

SEED = 20261123
SHORT_EXAMPLES = 8
SHORT_WORKFLOWS = 6
SLOW_EXAMPLES = int(os.environ.get("VGN_FUZZ_EXAMPLES", "200"))
FRAMES_OPERATION = "POST /sessions/{session_id}/frames"
CREATE_OPERATION = "POST /sessions"
IMPORT_OPERATION = "PUT /sessions/{session_id}/snapshot"
#: Snapshot bodies: an empty session's (valid), and bytes that are none.
EMPTY_SNAPSHOT = encode(
    Snapshot("fuzz", Workspace(resolution=16), None, 0, 0.0, np.zeros((16**3, 2), np.float32), None)
)
schemathesis.openapi.media_type(
    snapshot.MEDIA_TYPE, st.sampled_from([EMPTY_SNAPSHOT, b"", b"PK\x03\x04 not a zip", EMPTY_SNAPSHOT[:100]])
)
#: The rules of the wire schemas that JSON Schema cannot state, each documented in the field's
#: description, as their messages word them. A schema-valid request may be refused by these only.
RULES_BEYOND_SCHEMA = (
    "quaternion must have unit length",
    "must be below crop_max",
    "approach and max_approach_angle must be given together",
    "approach must be a non-zero direction",
    "must lie inside the",  # the principal point, inside the image
    "exceeds the largest image",
    "must be three finite comma-separated numbers",  # a number past a double's range
)


def valid_but_beyond_schema(
    ctx: schemathesis.CheckContext, response: schemathesis.Response, case: schemathesis.Case
) -> None:
    """Schema-valid requests are accepted, except where a documented rule that JSON Schema
    cannot state refuses them with a clear message: a custom rule of the wire schemas (unit
    quaternions, crop_min below crop_max, approach with max_approach_angle, a principal point
    inside the image: ``RULES_BEYOND_SCHEMA``) answers 422 whose every field error names one; a
    frame whose depth bytes cannot be used (their size, encoding, or missing intrinsics), bytes
    that are not a snapshot, or a session for a gripper the service does not serve 400."""
    try:
        positive_data_acceptance(ctx, response, case)
    except RejectedPositiveData:
        try:
            detail = response.json().get("detail")
        except (ValueError, AttributeError):
            raise RejectedPositiveData(
                operation=case.operation.label,
                message="a refused valid request must say why as JSON {detail}",
                status_code=response.status_code,
                allowed_statuses=[],
            ) from None
        field_errors = detail if response.status_code == 422 and isinstance(detail, list) else []
        if field_errors and all(
            e.get("type") == "value_error" and any(rule in e.get("msg", "") for rule in RULES_BEYOND_SCHEMA)
            for e in field_errors
        ):
            return
        if (
            response.status_code == 400
            and case.operation.label in (FRAMES_OPERATION, IMPORT_OPERATION)
            and detail
        ):
            return
        if (
            response.status_code == 400
            and case.operation.label == CREATE_OPERATION
            and "gripper" in str(detail)
        ):
            return
        raise


CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    negative_data_rejection,
    valid_but_beyond_schema,
    missing_required_header,
    unsupported_method,
    allow_header_conformance,
    use_after_free,
    ensure_resource_availability,
]


@pytest.fixture(scope="module")
def contract_server(random_checkpoint: Path) -> Iterator[EmbeddedService]:
    """A server of its own, so fuzzed sessions never evict or delete another test's."""
    env = {"VGN_MAX_FRAME_BYTES": str(1024 * 1024), "VGN_API_KEY": "", "VGN_TORCH_THREADS": "1"}
    with EmbeddedService(model=random_checkpoint, env=env) as service:
        yield service


def loaded_schema(server: EmbeddedService, *, coverage: bool) -> schemathesis.BaseSchema:
    """The live document; the coverage phase (every boundary and missing-part case the schema
    defines, ~1,000 requests) only in the long run."""
    config = schemathesis.Config.from_dict(
        {"seed": SEED, "phases": {"coverage": {"enabled": coverage}, "examples": {"enabled": coverage}}}
    )
    return schemathesis.openapi.from_url(f"{server.url}/openapi.json", config=config)


@pytest.fixture(scope="module")
def live_schema(contract_server: EmbeddedService) -> schemathesis.BaseSchema:
    return loaded_schema(contract_server, coverage=False)


@pytest.fixture(scope="module")
def live_schema_full(contract_server: EmbeddedService) -> schemathesis.BaseSchema:
    return loaded_schema(contract_server, coverage=True)


schema = schemathesis.pytest.from_fixture("live_schema")
full_schema = schemathesis.pytest.from_fixture("live_schema_full")
FUZZ_SETTINGS = {
    "derandomize": True,
    "database": None,
    "deadline": None,
    "suppress_health_check": list(HealthCheck),
}


@schema.parametrize()
@settings(max_examples=SHORT_EXAMPLES, **FUZZ_SETTINGS)
def test_http_contract(case: schemathesis.Case) -> None:
    case.call_and_validate(checks=CHECKS)


def run_workflows(live: schemathesis.BaseSchema, examples: int, steps: int, rounds: int = 1) -> None:
    """Chains of calls along the document's links (create a session, then use, reset and
    delete it): catches what single calls cannot, e.g. a duplicate id's 409 or a deleted
    session still answering."""
    failures: list[Exception] = []

    class Workflows(live.as_state_machine()):
        def validate_response(self, response, case, additional_checks=None, **kwargs) -> None:
            try:
                case.validate_response(response, checks=CHECKS)
            except Exception as failure:
                failures.append(failure)
                raise

    # As schemathesis runs its own workflows: seeded, generation only. Replaying a chain (to
    # shrink it) meets a server whose state moved on, which Hypothesis reports as a flaky
    # strategy; like schemathesis, that counts only through the contract failures it met.
    workflow_settings = settings(
        max_examples=examples,
        stateful_step_count=steps,
        phases=[Phase.generate],
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
    )
    for round_ in range(rounds):  # a flaky replay ends a round early; the next starts afresh
        try:
            seed(SEED + round_)(Workflows).run(settings=workflow_settings)
        except Flaky:
            if failures:
                raise failures[0] from None


def test_http_workflows(live_schema: schemathesis.BaseSchema) -> None:
    run_workflows(live_schema, examples=SHORT_WORKFLOWS, steps=4)


@pytest.mark.slow
@full_schema.parametrize()
@settings(max_examples=SLOW_EXAMPLES, **FUZZ_SETTINGS)
def test_http_contract_long(case: schemathesis.Case) -> None:
    case.call_and_validate(checks=CHECKS)


@pytest.mark.slow
def test_http_workflows_long(live_schema_full: schemathesis.BaseSchema) -> None:
    run_workflows(live_schema_full, examples=SLOW_EXAMPLES, steps=10, rounds=5)
