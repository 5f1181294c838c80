"""Planning for a named hand: ``GET /grippers``, sessions that name a gripper over HTTP and gRPC,
refusals of unknown and unserved hands, and the checks measuring the session's own hand."""

from __future__ import annotations

import copy
import json
from collections.abc import Iterator
from pathlib import Path

import grpc
import numpy as np
import pytest
from fastapi.testclient import TestClient

from client import BadRequest
from client.grpc_client import GRPCClient
from client.http import VGNClient
from service.clearance import ClearanceConfig, approach_is_clear, clear_grasps
from service.core import PlanningService
from service.grpc.server import build_server
from service.hands import Hands
from service.http_app import create_app
from service.launch.embedded import EmbeddedService
from service.settings import PACKAGED_MODEL, Settings
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.gripper_description import BUILTIN_DIR, GripperDescription, parse_gripper
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.grpc_api.grasp_planning_pb2_grpc import GraspPlanningStub
from vgn_contract.schemas import GraspResult, GripperList, SessionCreate, SessionInfo

FRANKA = json.loads((BUILTIN_DIR / "franka.json").read_text())


def variant(name: str, change) -> dict:
    """The franka description renamed and changed by ``change(data)``."""
    data = copy.deepcopy(FRANKA) | {"name": name, "version": f"{name}-v1", "urdf": None}
    change(data)
    return data


def widen(data: dict) -> None:
    """Open to 10 cm (the palm, 20 cm wide, still holds the fingers)."""
    data["opening"]["max"] = 0.10


def deepen(data: dict) -> None:
    """Every finger box and the pads 2 cm further along the approach: 7 cm fingers."""
    data["finger_depth"] = 0.07
    for box in data["fingers"]:
        box["centre"][2] += 0.02
    data["pad"]["contact_z"] = [z + 0.02 for z in data["pad"]["contact_z"]]


def narrow(data: dict) -> None:
    """Open to 6 cm only."""
    data["opening"]["max"] = 0.06


def hand(name: str, change) -> GripperDescription:
    return parse_gripper(variant(name, change), name)


# The clearance check measures the hand it is given ------------------------------------------------
IDENTITY, ORIGIN = np.array([[0.0, 0.0, 0.0, 1.0]]), np.zeros((1, 3))
#: A block 7 cm wide along the closing axis, between the fingertips' reach (z 1-5 cm).
BLOCK = np.stack(
    np.meshgrid(np.linspace(-0.01, 0.01, 3), np.linspace(-0.035, 0.035, 8), np.linspace(0.01, 0.05, 5)),
    axis=-1,
).reshape(-1, 3)
#: A patch beyond the franka fingertips at the grasp pose, above where the +y pad comes down.
AHEAD = np.array([[0.0, 0.047, 0.06], [0.001, 0.048, 0.061], [-0.001, 0.046, 0.059]])


@pytest.mark.parametrize(
    ("points", "other"),
    [(BLOCK, hand("narrow", narrow)), (AHEAD, hand("deep", deepen))],
    ids=["narrower hand", "deeper hand"],
)
def test_a_grasp_clear_for_the_wide_open_hand_is_dropped_for_another(points, other):
    franka = parse_gripper(FRANKA)
    config = ClearanceConfig(margin=0.0, min_points=1, contact_tolerance=0.0)
    assert approach_is_clear(points, ORIGIN, IDENTITY, config, franka).all()
    assert approach_is_clear(points, ORIGIN, IDENTITY, config, hand("wide", widen)).all()
    assert not approach_is_clear(points, ORIGIN, IDENTITY, config, other).any()


# A third hand, described in a file, served ---------------------------------------------------------
@pytest.fixture(scope="module")
def core(tmp_path_factory) -> Iterator[PlanningService]:
    """The packaged network, told it also serves a hand described in a temporary file (franka's
    fingers opening to 6 cm only)."""
    path: Path = tmp_path_factory.mktemp("hands") / "narrow-jaw.json"
    path.write_text(json.dumps(variant("narrow-jaw", narrow)))
    settings = Settings(
        model=PACKAGED_MODEL,
        api_key=None,
        alternatives=False,
        grippers=[path],
        network_grippers=["franka", "narrow-jaw"],
        hand_models={"robotiq-2f85": "none"},  # its packaged network off: here it is the hand without one
    )
    service = PlanningService.from_settings(settings)
    yield service
    service.close()


@pytest.fixture(scope="module")
def http(core) -> Iterator[TestClient]:
    with TestClient(create_app(core=core)) as client:
        yield client


def fuse(http: TestClient, session_id: str) -> None:
    scene = BoxScene()
    for pose in circle_views():
        meta = {"camera_pose": {"matrix": pose.tolist()}, "intrinsics": INTRINSICS.model_dump()}
        headers = {"Content-Type": "application/octet-stream", "X-Frame-Meta": json.dumps(meta)}
        answer = http.post(
            f"/sessions/{session_id}/frames", content=scene.depth(pose).tobytes(), headers=headers
        )
        assert answer.status_code == 200, answer.text


def test_the_service_lists_its_hands_and_their_networks(http, core):
    listed = http.get("/grippers")
    assert listed.status_code == 200
    assert GripperList.model_validate(listed.json()) == core.grippers()
    body = listed.json()
    assert body["default"] == "franka"
    networks = {g["name"]: g["network"] for g in body["grippers"]}
    assert networks == {
        "franka": core.planner.model_id,
        "robotiq-2f85": None,
        "narrow-jaw": core.planner.model_id,
    }
    third = next(g for g in body["grippers"] if g["name"] == "narrow-jaw")
    assert (third["max_opening"], third["finger_depth"]) == (0.06, 0.05)


def test_a_session_for_a_hand_described_in_a_file_plans_with_its_geometry(http, core):
    created = {}
    for name in ("franka", "narrow-jaw"):
        answer = http.post("/sessions", json={"gripper": name, "intrinsics": INTRINSICS.model_dump()})
        assert answer.status_code == 201, answer.text
        created[name] = SessionInfo.model_validate(answer.json())
        assert created[name].gripper == name
        assert http.get(f"/sessions/{created[name].session_id}").json()["gripper"] == name
        fuse(http, created[name].session_id)
    third = core.hands.known["narrow-jaw"]
    session = created["narrow-jaw"].session_id
    url = f"/sessions/{session}/grasps"
    plain = GraspResult.model_validate(
        http.get(url, params={"threshold": 0.0, "clearance": "false", "grip": "false"}).json()
    )
    checked = GraspResult.model_validate(http.get(url, params={"threshold": 0.0, "grip": "false"}).json())
    assert plain.grasps and checked.clearance_dropped + checked.workspace_dropped == len(plain.grasps) - len(
        checked.grasps
    )
    with core.sessions.use(session) as s:
        surface = s.volume.surface_points()
    assert checked.grasps == clear_grasps(plain.grasps, surface, workspace=(np.eye(4), 0.3), hand=third)
    # The franka session sees the same scene and network output, and is checked with its own hand.
    franka_url = f"/sessions/{created['franka'].session_id}/grasps"
    franka_plain = http.get(
        franka_url, params={"threshold": 0.0, "clearance": "false", "grip": "false"}
    ).json()
    assert franka_plain["grasps"] == [g.model_dump(mode="json") for g in plain.grasps]
    franka_checked = GraspResult.model_validate(
        http.get(franka_url, params={"threshold": 0.0, "grip": "false"}).json()
    )
    assert franka_checked.grasps == clear_grasps(plain.grasps, surface, workspace=(np.eye(4), 0.3))
    assert franka_checked.grasps != checked.grasps  # the two hands' checks disagree on this scene
    both = http.get(url, params={"threshold": 0.0}).json()  # the grip check too: the narrow pads close
    assert both["grip_dropped"] is not None
    for info in created.values():
        assert http.delete(f"/sessions/{info.session_id}").status_code == 204


def test_unknown_and_unserved_hands_are_refused_naming_the_known_ones(http):
    unknown = http.post("/sessions", json={"gripper": "schunk-egp"})
    assert unknown.status_code == 400
    assert unknown.json()["detail"] == (
        "unknown gripper 'schunk-egp'; this service knows: franka, narrow-jaw, robotiq-2f85"
    )
    unserved = http.post("/sessions", json={"gripper": "robotiq-2f85"})
    assert unserved.status_code == 400
    assert "no network of this service is trained for the gripper 'robotiq-2f85'" in unserved.json()["detail"]
    assert "hands with a network: franka, narrow-jaw" in unserved.json()["detail"]
    assert http.post("/sessions", json={"gripper": "Not A Name"}).status_code == 422


def test_grpc_sessions_name_their_hand(core):
    server, port = build_server(core, "127.0.0.1", 0)
    try:
        with grpc.insecure_channel(f"127.0.0.1:{port}") as channel:
            stub = GraspPlanningStub(channel)
            session = stub.CreateSession(pb.CreateSessionRequest(gripper="narrow-jaw"))
            assert session.gripper == "narrow-jaw"
            assert stub.CreateSession(pb.CreateSessionRequest()).gripper == "franka"
            for name, code in (("schunk-egp", grpc.StatusCode.INVALID_ARGUMENT),
                               ("robotiq-2f85", grpc.StatusCode.FAILED_PRECONDITION)):  # fmt: skip
                with pytest.raises(grpc.RpcError) as caught:
                    stub.CreateSession(pb.CreateSessionRequest(gripper=name))
                assert caught.value.code() == code and "franka" in caught.value.details()
        with GRPCClient(f"grpc://127.0.0.1:{port}") as rpc:
            assert rpc.grippers() == core.grippers()
            assert rpc.create_session(gripper="narrow-jaw").gripper == "narrow-jaw"
            with pytest.raises(BadRequest, match="hands with a network: franka, narrow-jaw"):
                rpc.create_session(gripper="robotiq-2f85")
    finally:
        server.stop(None)


def test_a_snapshot_keeps_the_hand(core):
    info = core.create_session(SessionCreate(gripper="narrow-jaw"))
    data = core.export_session(info.session_id)
    core.delete_session(info.session_id)
    assert core.import_session(data).gripper == "narrow-jaw"
    core.delete_session(info.session_id)


def test_the_operator_s_files_are_checked_when_the_service_starts(tmp_path):
    taken = tmp_path / "taken.json"
    taken.write_text(json.dumps(FRANKA))
    with pytest.raises(ValueError, match="the gripper name 'franka' is taken"):
        Hands.build([taken])
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps(variant("broken", lambda data: data.pop("palm"))))
    with pytest.raises(ValueError, match="broken.json: palm: Field required"):
        Hands.build([broken])
    with pytest.raises(ValueError, match="VGN_NETWORK_GRIPPERS names unknown hands \\['schunk'\\]"):
        Hands.build([], ["franka", "schunk"])
    assert Hands.build().served == {"franka"}


def test_a_real_server_plans_for_a_hand_described_in_the_operators_file(tmp_path):
    """Over a socket, as a robot meets it: uvicorn started with the operator's description of a third
    hand, sessions that name it and the franka hand on the same box, and the same network grasps
    checked against each hand's own geometry (the narrow jaw's 6 cm opening hits the box's 6 cm sides)."""
    path = tmp_path / "narrow-jaw.json"
    path.write_text(json.dumps(variant("narrow-jaw", narrow)))
    env = {
        "VGN_API_KEY": "",
        "VGN_TORCH_THREADS": "1",
        "VGN_GRIPPERS": json.dumps([str(path)]),
        "VGN_NETWORK_GRIPPERS": json.dumps(["franka", "narrow-jaw"]),
    }
    plain, checked = {}, {}
    with EmbeddedService(env=env) as service, VGNClient(service.url) as client:
        assert "narrow-jaw" in [info.name for info in client.grippers().grippers]
        for name in ("franka", "narrow-jaw"):
            session = client.create_session(intrinsics=INTRINSICS, gripper=name)
            assert session.gripper == name
            for pose in circle_views():
                client.add_frame(session.session_id, BoxScene().depth(pose), pose)
            plain[name] = client.grasps(session.session_id, threshold=0.0, clearance=False, grip=False)
            checked[name] = client.grasps(session.session_id, threshold=0.0, grip=False)
    assert plain["narrow-jaw"].grasps and plain["narrow-jaw"].grasps == plain["franka"].grasps
    dropped = {name: answer.clearance_dropped + answer.workspace_dropped for name, answer in checked.items()}
    assert dropped["narrow-jaw"] > dropped["franka"]
    assert len(checked["narrow-jaw"].grasps) < len(checked["franka"].grasps)
