"""Sessions that survive a lost service: the service is restarted on the same ports (a new
process that never held the sessions, as a replica taking over a dead one's sessions), and the
clients rebuild what they kept, within their bounds, over HTTP (sync and async) and gRPC."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from client import AsyncVGNClient, GRPCClient, NotFound, VGNClient
from client.recovery import Replay, is_lost
from service.launch.embedded import EmbeddedService
from tests.helpers.scenes import INTRINSICS, TABLE_Z, BoxScene, circle_views

VIEWS = circle_views(3)
DEPTHS = [BoxScene().depth(pose) for pose in VIEWS]
QUERY = {"threshold": 0.0, "max_grasps": 10, "clearance": False, "grip": False, "turn_average": False}
ENV = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1"}


class Restartable:
    """A service that can be replaced by a fresh process on the same HTTP and gRPC ports."""

    def __init__(self, model: Path) -> None:
        self.model = model
        self.service = EmbeddedService(model=model, env=ENV, grpc=True).start()

    def restart(self) -> None:
        port, grpc_port = self.service.port, self.service.grpc_port
        self.service.stop()
        self.service = EmbeddedService(model=self.model, env=ENV, port=port, grpc=True, grpc_port=grpc_port)
        self.service.start()


@pytest.fixture(scope="module")
def restartable(random_checkpoint: Path) -> Iterator[Restartable]:
    running = Restartable(random_checkpoint)
    yield running
    running.service.stop()


def fuse(client: VGNClient | GRPCClient, session_id: str, count: int = 3) -> None:
    for depth, pose in zip(DEPTHS[:count], VIEWS[:count], strict=True):
        client.add_frame(session_id, depth, pose)


def test_sessions_are_rebuilt_after_the_service_is_replaced(restartable: Restartable) -> None:
    url, grpc_url = restartable.service.url, restartable.service.grpc_url
    with (
        VGNClient(url) as http,
        GRPCClient(grpc_url) as rpc,
        VGNClient(url, replay=Replay(max_frames=2)) as small,
    ):
        fused = http.create_session(intrinsics=INTRINSICS).session_id
        fuse(http, fused)
        streamed = rpc.create_session(intrinsics=INTRINSICS).session_id
        rpc.stream_frames(streamed, zip(DEPTHS, VIEWS, strict=True))
        emptied = http.create_session(intrinsics=INTRINSICS).session_id
        fuse(http, emptied)
        http.reset_session(emptied)
        moved = http.import_session(http.snapshot(fused), session_id="moved").session_id
        http.add_frame(moved, DEPTHS[0], VIEWS[0])
        too_big = small.create_session(intrinsics=INTRINSICS).session_id
        fuse(small, too_big)
        before = {sid: http.grasps(sid, **QUERY).grasps for sid in (fused, streamed, moved)}
        grid = http.tsdf(fused)

        restartable.restart()

        assert http.grasps(fused, **QUERY).grasps == before[fused]
        np.testing.assert_array_equal(http.tsdf(fused), grid)
        assert rpc.grasps(streamed, **QUERY).grasps == before[streamed]
        assert http.session(emptied).frame_count == 0
        assert http.grasps(moved, **QUERY).grasps == before[moved] and http.session(moved).frame_count == 4
        with pytest.raises(NotFound, match="does not exist"):  # past its bounds: the original error
            small.grasps(too_big, **QUERY)
        assert (http.rebuilds, rpc.rebuilds, small.rebuilds) == (3, 1, 0)


def test_a_forgetting_session_is_rebuilt_in_the_order_its_frames_came(restartable: Restartable) -> None:
    """With ``decay`` the order of the frames matters: the box moved, and the volume follows its
    latest place. A rebuild that replayed the frames in another order would show the old place."""
    moved = BoxScene(lower=(0.05, 0.05, TABLE_Z), upper=(0.11, 0.11, TABLE_Z + 0.08))
    frames = [(BoxScene().depth(pose), pose) for pose in VIEWS] + [
        (moved.depth(pose), pose) for pose in VIEWS
    ]
    with VGNClient(restartable.service.url) as http:
        kept = http.create_session(intrinsics=INTRINSICS, decay=0.5).session_id
        reversed_order = http.create_session(intrinsics=INTRINSICS, decay=0.5).session_id
        for depth, pose in frames:
            http.add_frame(kept, depth, pose)
        for depth, pose in reversed(frames):
            http.add_frame(reversed_order, depth, pose)
        grid, other = http.tsdf(kept), http.tsdf(reversed_order)
        assert np.abs(grid - other).max() > 0.5  # the order shows in the volume, beyond rounding

        restartable.restart()

        np.testing.assert_allclose(http.tsdf(kept), grid, atol=1e-5)


def test_a_session_that_ended_is_not_rebuilt(restartable: Restartable) -> None:
    with VGNClient(restartable.service.url) as http:
        session_id = http.create_session(intrinsics=INTRINSICS).session_id
        fuse(http, session_id, 1)
        httpx.delete(f"{restartable.service.url}/sessions/{session_id}")  # another client deletes it
        with pytest.raises(NotFound) as gone:
            http.session(session_id)
        assert gone.value.ended == "deleted" and not is_lost(gone.value) and http.rebuilds == 0


def test_the_async_client_rebuilds_too(restartable: Restartable) -> None:
    async def scenario() -> None:
        async with AsyncVGNClient(restartable.service.url) as vgn:
            session_id = (await vgn.create_session(intrinsics=INTRINSICS)).session_id
            for depth, pose in zip(DEPTHS, VIEWS, strict=True):
                await vgn.add_frame(session_id, depth, pose)
            before = (await vgn.grasps(session_id, **QUERY)).grasps
            await asyncio.to_thread(restartable.restart)
            assert (await vgn.grasps(session_id, **QUERY)).grasps == before and vgn.rebuilds == 1

    asyncio.run(scenario())


def test_a_client_names_its_sessions_and_routes_every_call_by_them(restartable: Restartable) -> None:
    seen: list[httpx.Request] = []
    transport = httpx.Client(base_url=restartable.service.url, event_hooks={"request": [seen.append]})
    with VGNClient(restartable.service.url, http=transport) as http:
        session_id = http.create_session(intrinsics=INTRINSICS).session_id
        assert len(session_id) == 32 and int(session_id, 16) >= 0  # a uuid4 hex the client chose
        http.add_frame(session_id, DEPTHS[0], VIEWS[0])
        http.grasps(session_id, **QUERY)
        http.reset_session(session_id)
        http.delete_session(session_id)
    assert [request.headers.get("X-Session-Id") for request in seen] == [session_id] * 5
