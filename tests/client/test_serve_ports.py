"""``vgn-client serve`` on a port another service holds says so in one line and exits, before it
loads anything; with free ports it serves as before."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from service.launch.embedded import EmbeddedService, free_port

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def running() -> Iterator[EmbeddedService]:
    """A real service holding an HTTP and a gRPC port on loopback."""
    env = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1", "VGN_MODEL": "none"}
    with EmbeddedService(env=env, grpc=True) as service:
        yield service


def serve(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """A second ``vgn-client serve``; one that starts serving runs into the timeout."""
    command = [sys.executable, "-m", "client.cli", "serve", *args]
    env = {**os.environ, "VGN_MODEL": "none"}
    env.pop("VGN_GRPC_PORT", None)
    return subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=timeout)


def assert_one_line_error(result: subprocess.CompletedProcess, *words: str) -> None:
    assert result.returncode != 0
    assert "Traceback" not in result.stderr and not result.stdout
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ")
    for word in words:
        assert word in lines[0], lines[0]


def test_http_port_in_use(running: EmbeddedService) -> None:
    started = time.monotonic()
    result = serve("--port", str(running.port), "--grpc-port", str(free_port()))
    assert_one_line_error(result, f"port {running.port} is in use", "127.0.0.1", "--port")
    assert time.monotonic() - started < 30, "it should stop before loading the service"
    assert httpx.get(f"{running.url}/healthz").status_code == 200, "the first one still serves"


def test_grpc_port_in_use(running: EmbeddedService) -> None:
    result = serve("--port", str(free_port()), "--grpc-port", str(running.grpc_port))
    assert_one_line_error(result, f"gRPC port {running.grpc_port} is in use", "--grpc-port 0")


def test_serves_on_free_ports() -> None:
    port, grpc_port = free_port(), free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "client.cli", "serve", "--port", str(port), "--grpc-port", str(grpc_port)],
        cwd=REPO,
        env={**os.environ, "VGN_MODEL": "none"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and process.poll() is None:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=1.0).status_code == 200:
                    break
            except httpx.TransportError:
                time.sleep(0.2)
        assert process.poll() is None, process.communicate()[1]
        assert httpx.get(f"http://127.0.0.1:{port}/healthz").status_code == 200
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.communicate()


def test_an_address_that_cannot_be_had() -> None:
    result = serve("--host", "192.0.2.1", "--port", str(free_port()), "--grpc-port", "0")
    assert_one_line_error(result, "cannot listen on 192.0.2.1:")
