"""Start the service in its own process on a free loopback port, for when no URL is given.

It imports none of the server: it runs ``python -m uvicorn service.app:app`` in a child
process, which needs the ``service`` extra installed, and keeps this process free of torch and
open3d, so the light client, the simulator and the tests start one alike.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

from service.launch.lifetime import ending_with_this_process


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago: the OS picks it, the probe socket lets it go."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind((host, 0))
        return probe.getsockname()[1]


def bind_error(host: str, port: int) -> OSError | None:
    """Why a server could not listen on ``host:port`` now (in use, not ours to take, no such
    address), or None. Binds as uvicorn and gRPC do, with ``SO_REUSEADDR``, so a port that
    only holds connections closing down (TIME_WAIT) counts as free, as it is for them."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind((host.strip("[]"), port))
    except OSError as error:
        return error
    return None


class EmbeddedService:
    """A uvicorn child process serving ``service.app:app``; a context manager that stops it.

    ``env`` adds ``VGN_*`` settings (e.g. ``{"VGN_MODEL": path}``) to the child's environment;
    ``unset`` names variables of this process the child must not inherit.
    With ``grpc=True`` the child also serves gRPC on ``grpc_port`` or another free port (``grpc_url``); without,
    it serves none, so embedded services running side by side never contend for a port.
    """

    def __init__(
        self,
        model: Path | str | None = None,
        env: dict[str, str] | None = None,
        host: str = "127.0.0.1",
        port: int | None = None,
        startup_timeout: float = 120.0,
        log_path: Path | None = None,
        unset: tuple[str, ...] = (),
        grpc: bool = False,
        grpc_port: int | None = None,
    ) -> None:
        self.host, self.port = host, port or free_port(host)
        self.url = f"http://{host}:{self.port}"
        self.grpc_port = (grpc_port or free_port(host)) if grpc else None
        self.grpc_url = f"grpc://{host}:{self.grpc_port}" if grpc else None
        self._env = {name: value for name, value in os.environ.items() if name not in unset} | (env or {})
        self._env["VGN_GRPC_PORT"] = str(self.grpc_port or 0)
        self._env["VGN_GRPC_HOST"] = host
        if model is not None:
            self._env["VGN_MODEL"] = str(model)
        self._startup_timeout = startup_timeout
        self._log_path = log_path
        self._process: subprocess.Popen | None = None

    def start(self) -> EmbeddedService:
        """Start the child and wait for ``/healthz``; a child that
        exits or never answers is stopped and reported with its log."""
        self.launch()
        self.wait_until_up()
        return self

    def launch(self) -> EmbeddedService:
        """Start the child without waiting for it (several start side by side, then each is waited for)."""
        command = [
            sys.executable,
            "-m",
            "uvicorn",
            "service.app:app",
            "--host",
            self.host,
            "--port",
            str(self.port),
            "--log-level",
            "warning",
        ]
        # The service ends with this process, even one killed with SIGKILL (ending_with_this_process).
        # A file, not a pipe: a pipe nobody reads would block a chatty child.
        self._log = open(self._log_path, "a+b") if self._log_path else tempfile.TemporaryFile()  # noqa: SIM115
        env = ending_with_this_process(self._env)
        self._process = subprocess.Popen(command, env=env, stdout=self._log, stderr=self._log)
        return self

    def wait_until_up(self) -> None:
        """Wait for ``/healthz`` (the model is loaded by then); a child that exits or never
        answers is stopped and reported with its log."""
        try:
            self._wait_until_up()
        except BaseException:
            self.stop()
            raise

    @property
    def running(self) -> bool:
        """Whether the child was started and has not exited."""
        return self._process is not None and self._process.poll() is None

    @property
    def pid(self) -> int | None:
        """The service process's id while it runs (to watch its memory or signal it)."""
        return self._process.pid if self._process is not None else None

    def _wait_until_up(self) -> None:
        assert self._process is not None
        deadline = time.monotonic() + self._startup_timeout
        while time.monotonic() < deadline:
            if self._process.poll() is not None:
                raise RuntimeError(
                    f"the embedded service exited with code {self._process.returncode}:\n{self._log_tail()}"
                )
            try:
                if httpx.get(f"{self.url}/healthz", timeout=1.0).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.1)
        raise TimeoutError(f"the embedded service did not answer within {self._startup_timeout:g} s")

    def _log_tail(self, size: int = 4000) -> str:
        self._log.flush()
        self._log.seek(max(0, self._log.seek(0, os.SEEK_END) - size))
        return self._log.read().decode(errors="replace")

    def stop(self) -> None:
        """Terminate the child (killing it if it outlives a grace period) and close its log; a no-op once stopped."""
        if self._process is None:
            return
        if self._process.poll() is None:
            self._process.terminate()
            try:
                self._process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
        self._log.close()
        self._process = None

    def __enter__(self) -> EmbeddedService:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
