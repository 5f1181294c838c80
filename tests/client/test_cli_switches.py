"""``--clearance/--no-clearance``, ``--grip/--no-grip`` and ``--turn-average/--no-turn-average``: left out, the
request leaves the choice to the service's default (its best answer); given, it is sent either
way, over HTTP and gRPC alike."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import pytest

from client import cli
from vgn_contract.grpc_api import convert
from vgn_contract.schemas import GraspQuery, GraspResult

#: (flags, the query options they make)
CASES = [
    ((), {}),
    (("--clearance",), {"clearance": True}),
    (("--no-clearance",), {"clearance": False}),
    (("--turn-average",), {"turn_average": True}),
    (("--no-turn-average",), {"turn_average": False}),
    (("--grip",), {"grip": True}),
    (("--no-grip",), {"grip": False}),
    (("--no-turn-average", "--no-clearance"), {"turn_average": False, "clearance": False}),
    (
        ("--no-turn-average", "--no-clearance", "--no-grip"),
        {"turn_average": False, "clearance": False, "grip": False},
    ),
]


class RecordingClient:
    """Stands in for a service client: keeps the options of each grasp or viewer request."""

    url = "http://recorded"

    def __init__(self) -> None:
        self.options: list[dict[str, Any]] = []

    def grasps(self, session_id: str, **options: Any) -> GraspResult:
        self.options.append(options)
        return GraspResult(
            grasps=[], planning_ms=1.0, integration_ms=1.0, frame_count=1, model="m", threshold=0.5
        )

    def view_page(self, session_id: str, **options: Any) -> str:
        self.options.append(options)
        return "<html></html>"


@pytest.fixture
def recorded(monkeypatch: pytest.MonkeyPatch) -> RecordingClient:
    client = RecordingClient()

    @contextlib.contextmanager
    def connect(url: str, api_key: str | None = None) -> Iterator[RecordingClient]:
        yield client

    monkeypatch.setattr(cli, "connect", connect)
    return client


def switches(options: dict[str, Any]) -> dict[str, bool]:
    """The switches a request's options set (``None`` is left to the service)."""
    return {
        name: value
        for name in ("clearance", "grip", "turn_average")
        if (value := options.get(name)) is not None
    }


@pytest.mark.parametrize(("flags", "expected"), CASES)
@pytest.mark.parametrize("command", ["grasps", "view", "clear-scene"])
def test_the_flags_parse_to_the_choice_or_none(command: str, flags: tuple[str, ...], expected: dict):
    head = {"grasps": ["grasps", "s"], "view": ["view", "s"], "clear-scene": ["clear-scene", "--sim"]}[
        command
    ]
    args = cli.build_parser().parse_args([*head, *flags])
    assert switches(vars(args)) == expected
    for name in ("clearance", "grip", "turn_average"):
        assert getattr(args, name) is expected.get(name), "left out: None, the service's default"


@pytest.mark.parametrize(("flags", "expected"), CASES)
def test_grasps_and_view_pass_the_choice_on(
    recorded, tmp_path, capsys, flags: tuple[str, ...], expected: dict
):
    assert cli.main(["grasps", "s", "--url", "http://x", *flags]) == 0
    assert cli.main(["view", "s", "--url", "http://x", "--out", str(tmp_path / "v.html"), *flags]) == 0
    capsys.readouterr()
    for options in recorded.options:
        assert switches(options) == expected
        query = GraspQuery(**options)
        params = query.to_params()
        assert {k: v for k, v in params.items() if k in ("clearance", "grip", "turn_average")} == {
            k: "true" if v else "false" for k, v in expected.items()
        }, "sent on or off whenever given, never when left out"
        message = convert.grasp_query_message("s", query)
        assert {
            k: getattr(message, k) for k in ("clearance", "grip", "turn_average") if message.HasField(k)
        } == expected
        assert switches(GraspQuery(**convert.grasp_query_dict(message)).model_dump()) == expected
