"""Soak: thousands of sessions created, fed and expired against a real server, and its memory
is flat afterwards.

The server keeps at most ``MAX_SESSIONS`` sessions with a one-second TTL, so almost every
session is evicted or expires while the next ones arrive. The server's resident memory
(VmRSS from /proc) is read after a warm-up (allocator pools, Open3D and numpy caches filled),
sampled throughout for the peak, and read again once every session has expired; it is
printed (run with ``-s``) and must not have grown by more than ``GROWTH_BOUND_MB``.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from client.http import NotFound, VGNClient
from service.launch.embedded import EmbeddedService
from tests.helpers.scenes import BoxScene, circle_views
from vgn_contract.schemas import Intrinsics

MAX_SESSIONS = 16
TTL_S = 1.0
SESSIONS = 8000
WARM_UP = 400
CLIENTS = 4
#: Generous: leaking one session in fifty (each holds a 40³ grid and a queued 80×60 frame,
#: every 50th a 120³ cloud volume too) would exceed it; allocator noise stays well under.
GROWTH_BOUND_MB = 64.0
SMALL = Intrinsics(width=80, height=60, fx=67.5, fy=67.5, cx=39.5, cy=29.5)
POSE = circle_views(1)[0]
DEPTH = BoxScene().depth(POSE, SMALL)


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for process {pid}")


def churn(url: str, count: int, seed: int) -> int:
    """Create, feed and abandon ``count`` sessions; every third one is deleted, the rest are
    evicted or expire; every 50th also has its cloud read (which builds the session's finer
    volume, the largest thing it holds). Returns how many frames were fused."""
    fused = 0
    rng = np.random.default_rng(seed)
    with VGNClient(url) as vgn:
        for n in range(count):
            session = vgn.create_session(intrinsics=SMALL).session_id
            try:
                vgn.add_frame(session, DEPTH, POSE)
                fused += 1
                if n % 50 == 0:
                    assert len(vgn.cloud(session)) > 0
                if n % 3 == 0:
                    vgn.delete_session(session)
            except NotFound:
                pass  # evicted by another client's session in between: what the limit is for
            if rng.random() < 0.01:
                time.sleep(TTL_S * 1.2)  # let this client's last sessions expire idle
    return fused


@pytest.mark.slow
def test_thousands_of_sessions_leave_memory_flat():
    env = {"VGN_MODEL": "none", "VGN_MAX_SESSIONS": str(MAX_SESSIONS), "VGN_SESSION_TTL_S": str(TTL_S),
           "VGN_TORCH_THREADS": "1"}  # fmt: skip
    with EmbeddedService(env=env) as service:
        assert service.pid is not None
        churn(service.url, WARM_UP, seed=0)
        before = rss_mb(service.pid)
        peak = before
        done = threading.Event()

        def sample() -> None:
            nonlocal peak
            while not done.wait(0.2):
                peak = max(peak, rss_mb(service.pid))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        started = time.monotonic()
        with ThreadPoolExecutor(CLIENTS) as pool:
            shares = [
                pool.submit(churn, service.url, SESSIONS // CLIENTS, seed) for seed in range(1, CLIENTS + 1)
            ]
            fused = sum(share.result() for share in shares)
        seconds = time.monotonic() - started
        time.sleep(TTL_S * 1.5)
        with VGNClient(service.url) as vgn:
            assert vgn.sessions().sessions == [], "every session expired"
            time.sleep(0.5)
            assert vgn.health()["status"] == "ok"
        done.set()
        sampler.join()
        after = rss_mb(service.pid)
    print(
        f"\nsoak: {SESSIONS} sessions ({fused} frames fused) by {CLIENTS} clients in {seconds:.0f} s, "
        f"VGN_MAX_SESSIONS={MAX_SESSIONS}, TTL {TTL_S:g} s; server RSS before {before:.1f} MB, "
        f"peak {peak:.1f} MB, after {after:.1f} MB"
    )
    assert fused >= SESSIONS // 2, "most sessions got their frame before being evicted"
    assert after - before <= GROWTH_BOUND_MB, f"RSS grew {after - before:.1f} MB over {SESSIONS} sessions"
