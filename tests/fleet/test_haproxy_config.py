"""The proxy's configuration: the files in deploy/ are what ``service.launch.haproxy`` renders for them,
HAProxy accepts every configuration the project renders, and both backends share one ring."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from service.launch.haproxy import ProxyConfig, main, numbered, render

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
COMPOSE = ProxyConfig(numbered(2, "replica-{i}"), bind="0.0.0.0", resolvers=True)
KUBERNETES = ProxyConfig(
    numbered(2, "vgn-{i}.vgn-replicas.default.svc.cluster.local"), bind="0.0.0.0", resolvers=True
)
LOCAL = ProxyConfig(numbered(3, "127.0.0.1"), admin_socket=Path("/tmp/vgn-admin.sock"))
HAPROXY = shutil.which("haproxy")


def kubernetes_documents() -> dict[str, dict]:
    documents = {}
    for path in sorted((DEPLOY / "kubernetes").glob("*.yaml")):
        for document in yaml.safe_load_all(path.read_text()):
            documents[f"{document['kind']}/{document['metadata']['name']}"] = document
    return documents


def test_the_deploy_files_are_rendered_from_the_module():
    assert (DEPLOY / "haproxy.cfg").read_text() == render(COMPOSE), (
        "regenerate: python -m service.launch.haproxy --replicas 2 --server 'replica-{i}' --resolvers > deploy/haproxy.cfg"
    )
    documents = kubernetes_documents()
    assert documents["ConfigMap/vgn-haproxy"]["data"]["haproxy.cfg"] == render(KUBERNETES)
    assert documents["StatefulSet/vgn"]["spec"]["replicas"] == len(KUBERNETES.replicas)
    assert documents["StatefulSet/vgn"]["spec"]["serviceName"] == "vgn-replicas"
    assert documents["Service/vgn-replicas"]["spec"]["clusterIP"] == "None"
    probe = documents["StatefulSet/vgn"]["spec"]["template"]["spec"]["containers"][0]["readinessProbe"]
    assert probe["httpGet"]["path"] == "/readyz"
    compose = yaml.safe_load((DEPLOY / "compose.yaml").read_text())
    assert {f"replica-{i}" for i in range(len(COMPOSE.replicas))} <= set(compose["services"])


def test_both_backends_hash_the_session_header_over_the_same_servers():
    text = render(LOCAL)
    http, grpc = (
        text.split("\nbackend vgn_http")[1].split("frontend grpc")[0],
        text.split("\nbackend vgn_grpc")[1],
    )
    assert "balance hdr(X-Session-Id)" in http and "balance hdr(x-session-id)" in grpc
    assert http.count("hash-type consistent") == grpc.count("hash-type consistent") == 1
    names = [
        [line.split()[1] for line in part.splitlines() if line.strip().startswith("server ")]
        for part in (http, grpc)
    ]
    assert names[0] == names[1] == ["r0", "r1", "r2"]
    assert "proto h2" in text.split("frontend grpc")[1].splitlines()[1]


def test_the_command_line_prints_a_configuration(capsys):
    assert main(["--replicas", "2", "--server", "replica-{i}", "--resolvers"]) == 0
    assert capsys.readouterr().out == render(COMPOSE)


@pytest.mark.skipif(HAPROXY is None and not os.environ.get("CI"), reason="HAProxy is not installed")
@pytest.mark.parametrize("config", [COMPOSE, KUBERNETES, LOCAL], ids=["compose", "kubernetes", "local"])
def test_haproxy_accepts_the_configuration(tmp_path: Path, config: ProxyConfig):
    path = tmp_path / "haproxy.cfg"
    path.write_text(render(config))
    result = subprocess.run(
        [HAPROXY or "haproxy", "-c", "-f", str(path)], capture_output=True, text=True, timeout=30
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "[WARNING]" not in result.stdout + result.stderr, result.stdout + result.stderr
