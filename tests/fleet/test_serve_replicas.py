"""``vgn-client serve --replicas N``: one command starts N service processes and HAProxy, serves
HTTP and gRPC through the proxy, and a SIGTERM (or a SIGKILL of the command) leaves no process
behind."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import httpx
import pytest

from client import GRPCClient, VGNClient
from service.launch.embedded import free_port
from tests.helpers.processes import alive, wait_until_gone

if shutil.which("haproxy") is None and not os.environ.get("CI"):
    pytest.skip(
        "HAProxy is not installed (apt-get install haproxy; install.sh --dev does)", allow_module_level=True
    )

REPO = Path(__file__).resolve().parents[2]


def descendants(pid: int) -> set[int]:
    """Every process below ``pid`` (Linux ``/proc``)."""
    found, frontier = set(), [pid]
    while frontier:
        parent = frontier.pop()
        for task in Path(f"/proc/{parent}/task").glob("*"):
            try:
                children = {int(c) for c in (task / "children").read_text().split()}
            except OSError:
                continue
            frontier += children - found
            found |= children
    return found


def serve_fleet(model: Path, port: int, grpc_port: int) -> subprocess.Popen:
    command = [sys.executable, "-m", "client.cli", "serve", "--replicas", "2", "--port", str(port),
               "--grpc-port", str(grpc_port), "--model", str(model)]  # fmt: skip
    env = {**os.environ, "VGN_TORCH_THREADS": "1", "VGN_API_KEY": ""}
    return subprocess.Popen(
        command, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def wait_until_serving(process: subprocess.Popen, url: str) -> str:
    """The command's output up to the line saying it serves (it prints it once the proxy counts
    every replica ready), checked against the proxy."""
    assert process.stderr is not None
    lines = []
    while not lines or "serving HTTP on" not in lines[-1]:
        lines.append(process.stderr.readline())
        assert lines[-1], "".join(lines) + process.communicate()[1]  # it ended without serving
    lines += [process.stderr.readline() for _ in range(2)]  # each replica's own URLs
    assert httpx.get(f"{url}/readyz", timeout=5.0).status_code == 200
    return "".join(lines)


@pytest.mark.parametrize("stop", [signal.SIGTERM, pytest.param(signal.SIGKILL, marks=pytest.mark.slow)],
                         ids=["sigterm", "sigkill"])  # fmt: skip
def test_one_command_serves_a_fleet_and_stops_it_whole(random_checkpoint: Path, stop: signal.Signals) -> None:
    port, grpc_port = free_port(), free_port()
    process = serve_fleet(random_checkpoint, port, grpc_port)
    try:
        output = wait_until_serving(process, f"http://127.0.0.1:{port}")
        assert output.count(" (pid ") == 2, output  # each replica's own URLs
        children = descendants(process.pid)
        assert len(children) >= 3, children  # two replicas and HAProxy
        with (
            VGNClient(f"http://127.0.0.1:{port}") as http,
            GRPCClient(f"grpc://127.0.0.1:{grpc_port}") as rpc,
        ):
            created = http.create_session()
            assert rpc.session(created.session_id).session_id == created.session_id  # routed alike
            assert rpc.ready().ready
        process.send_signal(stop)
        process.wait(30)
        assert not wait_until_gone(children, timeout=15), "processes outlived the fleet"
        if stop == signal.SIGTERM:
            assert process.returncode == 0, process.communicate()[1]
    finally:
        if alive(process.pid):
            process.kill()
