"""A private ROS 2 graph for the bridge's tests: a random domain kept on this machine, a test
node that plays the robot's camera, and ``vgn-ros`` started as its own process."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger

from service.launch.lifetime import ending_with_this_process

ROOT = Path(__file__).resolve().parents[2]
#: The console script an install puts beside this Python (CI's editable install has it); where it
#: is missing, ``python -m ros_bridge`` runs the same ``main``.
VGN_ROS = Path(sys.executable).with_name("vgn-ros")
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: A subscriber that gets the bridge's last plan on joining, as RViz set to Transient Local does.
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


@contextmanager
def private_domain() -> Iterator[dict[str, str]]:
    """A random ``ROS_DOMAIN_ID`` and discovery on this machine only, set while the graph lives,
    so that test runs side by side, and robots on the network, never see each other."""
    env = {
        "ROS_DOMAIN_ID": str(random.SystemRandom().randint(1, 100)),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
    }
    saved = {name: os.environ.get(name) for name in env}
    os.environ.update(env)
    try:
        yield env
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


class Graph:
    """The test's own rclpy context and node, spun on demand."""

    def __init__(self) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node("vgn_bridge_test", context=self.context)
        self._executor = SingleThreadedExecutor(context=self.context)
        self._executor.add_node(self.node)
        self._clients: dict[str, Any] = {}

    def spin_until(
        self, done: Callable[[], Any], timeout: float, what: str, log: Callable[[], str] | None = None
    ) -> Any:
        """Spin until ``done()`` is truthy; ``TimeoutError`` saying ``what`` did not happen, with
        ``log()`` (read when it fails) below."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            result = done()
            if result:
                return result
            self._executor.spin_once(timeout_sec=0.02)
        raise TimeoutError(f"{what} within {timeout:g} s" + (f":\n{log()}" if log else ""))

    def spin_for(self, seconds: float) -> None:
        """Spin for ``seconds``."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self._executor.spin_once(timeout_sec=0.02)

    def call(self, service: str, timeout: float = 20.0) -> Trigger.Response:
        """Call a Trigger service and wait for its answer."""
        if service not in self._clients:
            self._clients[service] = self.node.create_client(Trigger, service)
        client = self._clients[service]
        self.spin_until(client.service_is_ready, timeout, f"{service} did not come up")
        future = client.call_async(Trigger.Request())
        return self.spin_until(
            lambda: future.done() and future.result(), timeout, f"{service} did not answer"
        )

    def close(self) -> None:
        self._executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


class Bridge:
    """``vgn-ros`` under ``namespace``, logging to a file; the checkout's code comes first on its
    path, so the script runs what is tested."""

    def __init__(
        self,
        namespace: str,
        parameters: dict[str, Any],
        log: Path,
        params_file: Path | None = None,
        env: dict[str, str] | None = None,
    ) -> None:
        self.namespace, self.log = namespace, log
        command = (
            [str(VGN_ROS)]
            if VGN_ROS.is_file() or os.environ.get("CI")
            else [sys.executable, "-m", "ros_bridge"]
        )
        args = [*command, "--ros-args", "-r", f"__ns:={namespace}"]
        if params_file is not None:
            args += ["--params-file", str(params_file)]
        for name, value in parameters.items():
            args += ["-p", f"{name}:={_yaml(value)}"]
        env = {
            **os.environ,
            **(env or {}),
            "RCUTILS_LOGGING_BUFFERED_STREAM": "0",
            "RCUTILS_COLORIZED_OUTPUT": "0",
        }
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
        self._out = log.open("wb")
        self.process = subprocess.Popen(
            args, cwd=ROOT, env=ending_with_this_process(env), stdout=self._out, stderr=subprocess.STDOUT
        )

    def topic(self, name: str) -> str:
        """A topic of the node (``grasps``) or of its namespace (``depth/image_rect``)."""
        private = name in ("grasps", "grasp_scores", "grasp_markers", "plan", "reset", "status", "fuse")
        return f"{self.namespace}/vgn_bridge/{name}" if private else f"{self.namespace}/{name}"

    def text(self) -> str:
        return self.log.read_text(errors="replace")

    def stop(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self._out.close()


def _yaml(value: Any) -> str:
    """A parameter value as ``--ros-args -p`` reads it (YAML): strings quoted, so an id of
    digits stays a string."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return "'" + value.replace("'", "''") + "'"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_yaml(v) for v in value) + "]"
    return repr(value)
