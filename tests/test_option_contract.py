"""Every grasp query option is one declaration (``vgn_contract.schemas.GraspQuery``) that each way of asking
carries: the gRPC message, the command line's ``grasps`` and ``view``, and, for the switches the
operator sets defaults for, the service's settings, ``clear-scene`` and the benchmark."""

from __future__ import annotations

import argparse

import pytest

from benchmarks import clutter
from client.cli import build_parser
from service.settings import Settings
from vgn_contract.grpc_api import convert
from vgn_contract.grpc_api import grasp_planning_pb2 as pb
from vgn_contract.schemas import SWITCH_EFFECTS, SWITCHES, GraspDefaults, GraspQuery, GraspResult

#: gRPC fields that are not query options: which session the query is about.
ADDRESSING = {"session_id"}


def flags(parser: argparse.ArgumentParser) -> set[str]:
    return {action.dest for action in parser._actions if action.option_strings}


def subcommand(name: str) -> argparse.ArgumentParser:
    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return commands.choices[name]


def test_the_grpc_query_carries_exactly_the_http_querys_options():
    grpc_fields = {field.name for field in pb.GraspQuery.DESCRIPTOR.fields} - ADDRESSING
    assert grpc_fields == set(GraspQuery.model_fields)


#: A value other than the default for every grasp query option.
EVERY_OPTION_SET = GraspQuery(
    planner="antipodal", threshold=0.25, max_grasps=7, nms_size=3, crop_min="0.01,0.02,0.03",
    crop_max="0.2,0.25,0.3", approach="0,0.5,-1", max_approach_angle=30.0, clearance=False, grip=True,
    turn_average=False,
)  # fmt: skip


def test_every_query_option_crosses_grpc_both_ways():
    assert EVERY_OPTION_SET.model_fields_set == set(GraspQuery.model_fields), (
        "a new option wants a value here"
    )
    message = convert.grasp_query_message("s", EVERY_OPTION_SET)
    assert {field.name for field, _ in message.ListFields()} - ADDRESSING == set(GraspQuery.model_fields)
    back = GraspQuery.model_validate(convert.grasp_query_dict(message))
    assert back.model_dump(exclude={"crop_min", "crop_max", "approach"}) == EVERY_OPTION_SET.model_dump(
        exclude={"crop_min", "crop_max", "approach"}
    )
    assert all(back.vector(name) == EVERY_OPTION_SET.vector(name) for name in convert.QUERY_VECTORS)
    unset = convert.grasp_query_message("s", GraspQuery())
    assert GraspQuery.model_validate(convert.grasp_query_dict(unset)) == GraspQuery(), "unset stays unset"


def test_the_command_lines_grasps_and_view_take_every_query_option():
    for command in ("grasps", "view"):
        assert set(GraspQuery.model_fields) <= flags(subcommand(command)), command


def test_every_switch_has_a_service_default_and_a_flag_wherever_runs_are_made():
    assert set(SWITCHES) <= set(Settings.model_fields)
    assert set(SWITCHES) <= flags(subcommand("clear-scene"))
    benchmark = clutter.parse_args([])
    assert set(SWITCHES) <= set(vars(benchmark))
    assert set(SWITCHES) <= set(GraspQuery.model_fields)


def flag_helps(parser: argparse.ArgumentParser) -> dict[str, str]:
    return {action.dest: action.help for action in parser._actions if action.option_strings}


def benchmark_parser(monkeypatch: pytest.MonkeyPatch) -> argparse.ArgumentParser:
    """The benchmark's parser: its ``parse_args`` builds one and parses at once."""
    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", lambda self, *args, **kwargs: self)
    return clutter.parse_args([])


def test_every_query_flag_says_what_the_query_field_says():
    for command in ("grasps", "view"):
        helps = flag_helps(subcommand(command))
        for name, field in GraspQuery.model_fields.items():
            assert helps[name] == field.description, f"{command} --{name.replace('_', '-')}"


def test_what_a_switch_does_is_said_once(monkeypatch: pytest.MonkeyPatch):
    """The query field, the operator's default and every command's flag word a switch's effect
    from ``SWITCH_EFFECTS``; a help text written anew beside it fails here."""
    for name in SWITCHES:
        assert GraspQuery.model_fields[name].description.startswith(SWITCH_EFFECTS[name] + ". Unset:"), name
        assert Settings.model_fields[name].description.endswith(": " + SWITCH_EFFECTS[name]), name
    commands = {command: subcommand(command) for command in ("grasps", "view", "clear-scene")}
    commands["benchmark"] = benchmark_parser(monkeypatch)
    for command, parser in commands.items():
        helps = flag_helps(parser)
        for name in SWITCHES:
            assert helps[name].startswith(GraspQuery.model_fields[name].description), f"{command} {name}"


def test_every_switch_is_reported_as_a_default_and_in_every_answer():
    """``/model`` says what a request that leaves a switch unset gets, and each answer what it got,
    over HTTP and gRPC alike."""
    assert (
        set(SWITCHES)
        <= set(GraspDefaults.model_fields)
        == {f.name for f in pb.GraspDefaults.DESCRIPTOR.fields}
    )
    assert set(SWITCHES) <= set(GraspResult.model_fields)
    assert set(GraspResult.model_fields) - {"grasps"} <= {f.name for f in pb.GraspResult.DESCRIPTOR.fields}
