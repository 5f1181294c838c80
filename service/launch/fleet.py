"""A fleet on one machine: N service processes behind HAProxy, started, watched and stopped
together (``vgn-client serve --replicas N``).

Each replica is a uvicorn child (``service.launch.embedded``) on loopback ports of its own,
HTTP and gRPC; HAProxy (``service.launch.haproxy``) listens on the fleet's ports and routes each
session to one replica. Every child ends with this process, however it ends
(``service.launch.lifetime``): HAProxy is started through a Python shim that asks for that and
then becomes HAProxy. A replica that
dies is started again on its ports (unless ``restart`` is off); its sessions move to the other
replicas meanwhile and back once it is up, rebuilt each time by their clients.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx

from service.launch.embedded import EmbeddedService, bind_error, free_port
from service.launch.haproxy import ProxyConfig, Replica, render
from service.launch.lifetime import ending_with_this_process

#: Runs a program so that it ends with this process: asks the kernel first, then becomes it.
EXEC_ENDING_WITH_PARENT = (
    "import os, sys; from service.launch.lifetime import end_with_parent_if_asked; "
    "end_with_parent_if_asked(); os.execvp(sys.argv[1], sys.argv[1:])"
)


class FleetError(RuntimeError):
    """The fleet cannot start: HAProxy is missing, a port is taken, or a process failed."""


@dataclass(frozen=True)
class FleetConfig:
    """How many replicas, where the proxy listens, and what each replica runs with."""

    replicas: int = 2
    host: str = "127.0.0.1"
    http_port: int = 8000
    grpc_port: int | None = 50051
    model: Path | str | None = None
    env: dict[str, str] = field(default_factory=dict)
    unset: tuple[str, ...] = ()  # variables of this process the replicas must not inherit
    restart: bool = True
    startup_timeout_s: float = 180.0
    check_interval_ms: int = 1000


class Fleet:
    """The running fleet; a context manager that stops every process it started."""

    def __init__(self, config: FleetConfig = FleetConfig()) -> None:  # noqa: B008 (frozen)
        if config.replicas < 1:
            raise FleetError("a fleet needs at least one replica")
        self.config = config
        self.url = f"http://{config.host}:{config.http_port}"
        self.grpc_url = f"grpc://{config.host}:{config.grpc_port}" if config.grpc_port else None
        self._folder = Path(tempfile.mkdtemp(prefix="vgn-fleet-"))
        self.admin_socket = self._folder / "admin.sock"
        self.replicas: list[EmbeddedService] = []
        self.restarts = 0
        self._proxy: subprocess.Popen | None = None
        self._proxy_log = None
        self._stopped = threading.Event()

    # Starting -----------------------------------------------------------------------------------
    def start(self) -> Fleet:
        """Start the replicas side by side, then HAProxy, and wait until the proxy answers ready
        through every replica; a failure stops whatever started."""
        haproxy = shutil.which("haproxy")
        if haproxy is None:
            raise FleetError("HAProxy is not installed: apt-get install haproxy (or your system's package)")
        self._check_ports()
        try:
            for index in range(self.config.replicas):
                self.replicas.append(self._replica(index, free_port(), free_port()).launch())
            for replica in self.replicas:
                replica.wait_until_up()
            config_path = self._folder / "haproxy.cfg"
            config_path.write_text(render(self.proxy_config()))
            self._proxy_log = open(self._folder / "haproxy.log", "a+b")  # noqa: SIM115 (closed in stop)
            command = [sys.executable, "-c", EXEC_ENDING_WITH_PARENT, haproxy, "-f", str(config_path), "-db"]
            env = ending_with_this_process(dict(os.environ))
            self._proxy = subprocess.Popen(command, env=env, stdout=self._proxy_log, stderr=self._proxy_log)
            self._wait_until_serving()
        except BaseException:
            self.stop()
            raise
        return self

    def proxy_config(self) -> ProxyConfig:
        """The HAProxy configuration of the replicas started so far."""
        replicas = tuple(
            Replica(f"r{i}", replica.host, replica.port, replica.grpc_port or 0)
            for i, replica in enumerate(self.replicas)
        )
        return ProxyConfig(
            replicas,
            bind=self.config.host,
            http_port=self.config.http_port,
            grpc_port=self.config.grpc_port,
            admin_socket=self.admin_socket,
            check_interval_ms=self.config.check_interval_ms,
        )

    def _replica(self, index: int, port: int, grpc_port: int) -> EmbeddedService:
        return EmbeddedService(
            model=self.config.model,
            env=self.config.env,
            unset=self.config.unset,
            host="127.0.0.1",
            port=port,
            grpc=True,
            grpc_port=grpc_port,
            startup_timeout=self.config.startup_timeout_s,
            log_path=self._folder / f"replica-{index}.log",
        )

    def _check_ports(self) -> None:
        ports = [("port", self.config.http_port)]
        if self.config.grpc_port:
            ports.append(("gRPC port", self.config.grpc_port))
        for name, port in ports:
            error = bind_error(self.config.host, port)
            if error is not None:
                raise FleetError(
                    f"{name} {port} is not free on {self.config.host} ({error.strerror or error})"
                )

    def _wait_until_serving(self) -> None:
        """Until HAProxy counts every replica up and answers ``/readyz`` through them."""
        deadline = time.monotonic() + self.config.startup_timeout_s
        while time.monotonic() < deadline:
            if self._proxy is None or self._proxy.poll() is not None:
                raise FleetError(f"HAProxy exited:\n{self.proxy_log()}")
            states = self.server_states()
            if states and all(state == "UP" for state in states.values()):
                try:
                    if httpx.get(f"{self.url}/readyz", timeout=2.0).status_code == 200:
                        return
                except httpx.TransportError:
                    pass
            time.sleep(0.1)
        raise FleetError(
            f"the fleet was not ready within {self.config.startup_timeout_s:g} s: {self.server_states()}"
        )

    # Running ------------------------------------------------------------------------------------
    def stats(self) -> list[dict[str, str]]:
        """HAProxy's statistics, a row per frontend, backend and server (``pxname``, ``svname``,
        ``status``, ``hrsp_5xx``, ...), from its runtime API; empty while it does not answer."""
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as admin:
                admin.settimeout(2.0)
                admin.connect(str(self.admin_socket))
                admin.sendall(b"show stat\n")
                text = b"".join(iter(lambda: admin.recv(65536), b"")).decode()
        except OSError:
            return []
        lines = text.splitlines()
        if not lines or not lines[0].startswith("# "):
            return []
        names = lines[0][2:].split(",")
        return [dict(zip(names, line.split(","), strict=False)) for line in lines[1:] if line]

    def server_states(self) -> dict[str, str]:
        """Each replica's state in HAProxy's HTTP backend ("UP", "DOWN", ...)."""
        return {
            row["svname"]: row["status"].split(" ")[0]
            for row in self.stats()
            if row.get("pxname") == "vgn_http" and row.get("svname") not in ("FRONTEND", "BACKEND")
        }

    def watch(self, poll_s: float = 0.5) -> None:
        """Block until ``stop()`` (or HAProxy exits), starting a replica that died again."""
        while not self._stopped.wait(poll_s):
            if self._proxy is None or self._proxy.poll() is not None:
                raise FleetError(f"HAProxy exited:\n{self.proxy_log()}")
            if not self.config.restart:
                continue
            for index, replica in enumerate(self.replicas):
                if not replica.running and not self._stopped.is_set():
                    replica.stop()
                    self.replicas[index] = self._replica(
                        index, replica.port, replica.grpc_port or free_port()
                    )
                    self.replicas[index].start()
                    self.restarts += 1

    def proxy_log(self, size: int = 4000) -> str:
        """The end of HAProxy's output."""
        path = self._folder / "haproxy.log"
        return path.read_bytes()[-size:].decode(errors="replace") if path.is_file() else ""

    # Stopping -----------------------------------------------------------------------------------
    def stop(self) -> None:
        """Stop the proxy (no new requests), then every replica; a no-op once stopped."""
        self._stopped.set()
        if self._proxy is not None:
            if self._proxy.poll() is None:
                self._proxy.terminate()
                try:
                    self._proxy.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    self._proxy.kill()
                    self._proxy.wait()
            self._proxy = None
        if self._proxy_log is not None:
            self._proxy_log.close()
            self._proxy_log = None
        for replica in self.replicas:
            replica.stop()
        shutil.rmtree(self._folder, ignore_errors=True)

    @property
    def pids(self) -> set[int]:
        """Every process of the fleet that runs: HAProxy and the replicas."""
        pids = {replica.pid for replica in self.replicas if replica.running and replica.pid}
        if self._proxy is not None and self._proxy.poll() is None:
            pids.add(self._proxy.pid)
        return pids

    def __enter__(self) -> Fleet:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
