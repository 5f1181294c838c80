"""The default request is the service's best answer: a grasp request that does not say is
turn-averaged, clearance-checked and grip-checked, ``turn_average=false&clearance=false&grip=false``
is VGN's plain answer, and the operator's ``VGN_TURN_AVERAGE`` / ``VGN_CLEARANCE`` / ``VGN_GRIP``
move the default; checked against real servers on loopback, over HTTP, gRPC and the CLI."""

from __future__ import annotations

import json
from collections.abc import Iterator

import grpc
import httpx
import pytest

from client.grpc_client import GRPCClient
from client.http import VGNClient
from service.clearance import ClearanceConfig
from service.launch.embedded import EmbeddedService
from service.settings import PACKAGED_MODEL
from service.vgn.checkpoint import card_path
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.grpc_api import convert
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.grpc_api.grasp_planning_pb2_grpc import GraspPlanningStub
from vgn_contract.schemas import GraspDefaults, GraspResult

SCENE = BoxScene()
SWITCHES = ("VGN_TURN_AVERAGE", "VGN_CLEARANCE", "VGN_GRIP")
ENV = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1"}
PLAIN = {"turn_average": False, "clearance": False, "grip": False}
BEST = {"turn_average": True, "clearance": True, "grip": True}


def serve(**switches: str) -> EmbeddedService:
    """HTTP and gRPC over the shipped model (a random network's grasps on the box scene all hit
    the table or the box); ``switches`` are the operator's ``VGN_*`` defaults, none inherited
    from this process."""
    return EmbeddedService(model=PACKAGED_MODEL, env={**ENV, **switches}, unset=SWITCHES, grpc=True)


@pytest.fixture(scope="module")
def default() -> Iterator[EmbeddedService]:
    """A service as it starts when the operator says nothing."""
    with serve() as running:
        yield running


@pytest.fixture(scope="module")
def plain() -> Iterator[EmbeddedService]:
    """A service whose operator turned every option off."""
    with serve(VGN_TURN_AVERAGE="false", VGN_CLEARANCE="false", VGN_GRIP="false") as running:
        yield running


def fused_session(service: EmbeddedService) -> str:
    """A session of ``service`` with the box scene fused from six views."""
    with VGNClient(service.url) as vgn:
        session = vgn.create_session(intrinsics=INTRINSICS).session_id
        for pose in circle_views(6):
            vgn.add_frame(session, SCENE.depth(pose), pose)
    return session


def answers(service: EmbeddedService, session: str, **options: bool) -> list[GraspResult]:
    """The same request over HTTP and gRPC."""
    with VGNClient(service.url) as http, GRPCClient(service.grpc_url) as rpc:
        return [client.grasps(session, threshold=0.0, **options) for client in (http, rpc)]


def bare_grpc_grasps(service: EmbeddedService, session: str) -> pb.GraspResult:
    """A gRPC ``GetGrasps`` with only the session set: every option left to the service."""
    with grpc.insecure_channel(service.grpc_url.removeprefix("grpc://")) as channel:
        return GraspPlanningStub(channel).GetGrasps(pb.GraspQuery(session_id=session))


def same_answer(a: GraspResult, b: GraspResult) -> bool:
    """Equal grasps, and the same account of what was done (timings apart)."""
    keys = ("grasps", "threshold", "model", "turn_average", "clearance", "grip", "fallback", "clearance_dropped",
            "grip_dropped", "clearance_margin")  # fmt: skip
    return all(getattr(a, key) == getattr(b, key) for key in keys)


def test_a_request_that_does_not_say_is_turn_averaged_and_clearance_and_grip_checked(default):
    session = fused_session(default)
    bare = httpx.get(f"{default.url}/sessions/{session}/grasps")  # no query parameters at all
    assert bare.status_code == 200, bare.text
    over_http = GraspResult.model_validate(bare.json())
    over_grpc = convert.grasp_result(bare_grpc_grasps(default, session))
    for result in (over_http, over_grpc):
        assert result.turn_average is True and result.clearance_dropped is not None
        assert result.grip_dropped is not None
        assert (result.clearance, result.grip, result.fallback) == (True, True, False), "each answer says"
        assert result.clearance_margin == ClearanceConfig().margin, "the wider hand cleared these"
    assert same_answer(over_http, over_grpc)
    # As asked for explicitly, and the check did drop some of the averaged grasps here.
    for result, explicit in zip(answers(default, session), answers(default, session, **BEST), strict=True):
        assert result.grasps and result.clearance_dropped > 0
        assert same_answer(result, explicit)
    kept = answers(default, session)[0].grasps
    for switch in ("clearance", "grip"):
        unchecked = answers(default, session, **{switch: False})[0]
        assert unchecked.turn_average is True and getattr(unchecked, f"{switch}_dropped") is None
        assert (unchecked.clearance_margin is None) == (switch == "clearance")
        # The checks keep or re-pose the unchecked grasps: never more of them, each at one's quality.
        assert len(kept) <= len(unchecked.grasps)
        assert {g.quality for g in kept} <= {g.quality for g in unchecked.grasps}


def test_both_off_is_the_plain_answer_an_operator_default_off_gives(default, plain):
    """``turn_average=false&clearance=false&grip=false`` on a default service is what a service
    started with ``VGN_TURN_AVERAGE=false VGN_CLEARANCE=false VGN_GRIP=false`` answers to a request
    that does not say; and the other way round, all on there is the default here."""
    here, there = fused_session(default), fused_session(plain)
    for asked_off, plain_default in zip(answers(default, here, **PLAIN), answers(plain, there), strict=True):
        assert asked_off.grasps and asked_off.turn_average is False and asked_off.clearance_dropped is None
        assert asked_off.grip_dropped is None and (asked_off.clearance, asked_off.grip) == (False, False)
        assert same_answer(asked_off, plain_default)
    for best_default, asked_on in zip(answers(default, here), answers(plain, there, **BEST), strict=True):
        assert same_answer(best_default, asked_on)


def test_the_model_reports_the_defaults_the_operator_chose(default, plain):
    """As typed ``defaults``, over HTTP and gRPC alike; for clients that read them under ``runtime``
    there too, for one release."""
    operating = json.loads(card_path(PACKAGED_MODEL).read_text())["threshold"]
    for service, expected in ((default, True), (plain, False)):
        with VGNClient(service.url) as http, GRPCClient(service.grpc_url) as rpc:
            said = [http.model().defaults, rpc.model().defaults]
            assert said[0] == said[1] == GraspDefaults(
                turn_average=expected, clearance=expected, grip=expected, threshold=operating,
                antipodal_threshold=0.5, fallback_threshold=0.5,
            )  # fmt: skip
        body = httpx.get(f"{service.url}/model").json()
        assert body["defaults"] == said[0].model_dump()
        assert body["threshold"] == operating, "the deprecated copy of defaults.threshold"
        repeated = {
            key: body["runtime"][key] for key in ("turn_average", "clearance", "grip", "fallback_threshold")
        }
        assert repeated == said[0].model_dump(exclude={"threshold", "antipodal_threshold"})


def test_the_cli_leaves_the_default_to_the_service_or_turns_either_off(default, capsys):
    from client.cli import main

    session = fused_session(default)
    results = {}
    for options in ((), ("--no-turn-average", "--no-clearance", "--no-grip"),
                    ("--turn-average", "--clearance", "--grip")):  # fmt: skip
        assert main(["grasps", session, "--url", default.url, "--threshold", "0", *options, "--json"]) == 0
        results[options] = GraspResult.model_validate_json(capsys.readouterr().out)
    best, off, on = results.values()
    assert best.turn_average is True and best.clearance_dropped is not None and best.grip_dropped is not None
    assert same_answer(best, on)
    assert off.turn_average is False and off.clearance_dropped is None and off.grip_dropped is None
    assert off.grasps == answers(default, session, **PLAIN)[0].grasps[:10]
