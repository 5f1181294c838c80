"""A fleet of real processes on loopback: two service replicas behind HAProxy, clients over HTTP
and gRPC, and one replica killed with SIGKILL while they work. Every session ends with the
grasps a single process plans from the same frames; the clients see no error, only slower
calls for the sessions they rebuilt."""

from __future__ import annotations

import os
import shutil
import signal
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from client import GRPCClient, VGNClient
from client.http import encode_depth
from client.recovery import Replay
from service.core import PlanningService
from service.launch.embedded import free_port
from service.launch.fleet import Fleet, FleetConfig
from service.settings import Settings
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views
from vgn_contract.schemas import FrameMeta, GraspQuery, Pose, SessionCreate

if shutil.which("haproxy") is None and not os.environ.get("CI"):
    pytest.skip(
        "HAProxy is not installed (apt-get install haproxy; install.sh --dev does)", allow_module_level=True
    )

SESSIONS = 32
FRAMES_PER_SESSION = 3
VIEWS = circle_views(6)
#: Each view as the 16-bit PNG (millimetres) the clients send.
FRAMES = [encode_depth(np.round(BoxScene().depth(pose) * 1000).astype(np.uint16))[0] for pose in VIEWS]
#: Plain VGN grasps: the random test weights have every grasp dropped by the clearance check.
QUERY = {"threshold": 0.0, "max_grasps": 10, "clearance": False, "grip": False, "turn_average": False}
ENV = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1", "VGN_MAX_SESSIONS": "64"}


def views_of(session: int) -> list[int]:
    """The views a session fuses: six different sets across the sessions."""
    return [(session + k) % len(VIEWS) for k in range(FRAMES_PER_SESSION)]


@pytest.fixture(scope="module")
def fleet(random_checkpoint: Path) -> Iterator[Fleet]:
    config = FleetConfig(replicas=2, http_port=free_port(), grpc_port=free_port(), model=random_checkpoint,
                         env=ENV, restart=False, check_interval_ms=500)  # fmt: skip
    with Fleet(config) as running:
        yield running


@pytest.fixture(scope="module")
def reference(random_checkpoint: Path) -> dict[tuple[int, ...], list]:
    """The grasps one process plans from each set of views, fused from the same PNG bytes."""
    core = PlanningService.from_settings(Settings(model=random_checkpoint, api_key=None))
    try:
        answers = {}
        for first in range(len(VIEWS)):
            views = tuple(views_of(first))
            session_id = f"reference-{first}"
            core.create_session(SessionCreate(session_id=session_id, intrinsics=INTRINSICS))
            for view in views:
                meta = FrameMeta(camera_pose=Pose.from_matrix(VIEWS[view]))
                core.add_encoded_frame(session_id, FRAMES[view], "image/png", meta)
            answers[views] = core.plan(session_id, GraspQuery(**QUERY)).grasps
        return answers
    finally:
        core.close()


def assert_same_grasps(got: list, expected: list, session: int) -> None:
    """Same grasps as the single process: positions and orientations to float precision; the
    qualities within what a different batching of the forward pass can change."""
    assert len(got) == len(expected) > 0, f"session {session}: {len(got)} grasps, expected {len(expected)}"
    for a, b in zip(got, expected, strict=True):
        np.testing.assert_allclose(a.position, b.position, atol=1e-6, err_msg=f"session {session}")
        np.testing.assert_allclose(a.orientation, b.orientation, atol=1e-3, err_msg=f"session {session}")
        assert a.quality == pytest.approx(b.quality, abs=1e-3) and a.width == pytest.approx(b.width, abs=1e-4)


@dataclass
class Run:
    """What the client threads share: progress, the kill signal and what they got."""

    frames_posted: int = 0
    halfway: threading.Event = field(default_factory=threading.Event)
    killed: threading.Event = field(default_factory=threading.Event)
    grasps: dict[int, list] = field(default_factory=dict)
    errors: list[BaseException] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def posted(self) -> None:
        with self.lock:
            self.frames_posted += 1
            if self.frames_posted >= SESSIONS * FRAMES_PER_SESSION // 2:
                self.halfway.set()


def work(client: VGNClient | GRPCClient, sessions: list[int], run: Run) -> None:
    """Open the sessions, fuse their frames one round at a time, and plan on each."""
    try:
        ids = {s: client.create_session(intrinsics=INTRINSICS).session_id for s in sessions}
        for round_ in range(FRAMES_PER_SESSION):
            for session in sessions:
                view = views_of(session)[round_]
                client.add_frame(ids[session], FRAMES[view], VIEWS[view])
                run.posted()
        run.killed.wait(30)  # some sessions planned before the kill, most after
        for session in sessions:
            run.grasps[session] = client.grasps(ids[session], **QUERY).grasps
    except BaseException as error:  # reported by the test, with the thread's traceback
        run.errors.append(error)


def test_sessions_survive_a_replica_killed_mid_run(fleet: Fleet, reference) -> None:
    run = Run()
    replay = Replay(backoff_s=0.2)
    clients = [VGNClient(fleet.url, replay=replay), VGNClient(fleet.url, replay=replay),
               GRPCClient(fleet.grpc_url, replay=replay), GRPCClient(fleet.grpc_url, replay=replay)]  # fmt: skip
    share = SESSIONS // len(clients)
    threads = [
        threading.Thread(target=work, args=(client, list(range(i * share, (i + 1) * share)), run))
        for i, client in enumerate(clients)
    ]
    started = time.monotonic()
    for thread in threads:
        thread.start()
    assert run.halfway.wait(120), "the clients never got halfway"
    victim = fleet.replicas[0]
    os.kill(victim.pid, signal.SIGKILL)
    run.killed.set()
    for thread in threads:
        thread.join(120)
    for client in clients:
        client.close()
    assert not run.errors, f"{len(run.errors)} calls failed, first: {run.errors[0]!r}"
    assert sorted(run.grasps) == list(range(SESSIONS))
    for session, grasps in run.grasps.items():
        assert_same_grasps(grasps, reference[tuple(views_of(session))], session)
    assert fleet.server_states() == {"r0": "DOWN", "r1": "UP"}
    rebuilt = sum(client.rebuilds for client in clients)
    assert 0 < rebuilt <= SESSIONS, "the killed replica's sessions were rebuilt"
    # The proxy answered 5xx only for requests in flight on the killed replica (one per client at most).
    failed = sum(int(row["hrsp_5xx"] or 0) for row in fleet.stats() if row["svname"] == "FRONTEND")
    assert failed <= len(clients), failed
    print(
        f"{rebuilt} sessions rebuilt, {failed} answers 5xx from the proxy, {time.monotonic() - started:.1f} s"
    )
    assert time.monotonic() - started < 90
