"""Command-line options declared on the dataclass fields they set.

Each field's metadata (:func:`option`) holds its help, argument group and whatever its name and
type do not say: flag, metavar, choices. :func:`add_options` derives the parser from the fields
and :func:`config_values` turns the parsed arguments back into the dataclass's keyword arguments,
so a new option is one field. A field that is itself a dataclass contributes its own fields'
options; a field marked :data:`NOT_AN_OPTION` has none.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from types import UnionType
from typing import Any, get_args, get_origin, get_type_hints

#: The metadata key of a field's :class:`Option`.
OPTION = "option"


@dataclass(frozen=True)
class Option:
    """How a field appears on the command line.

    ``flag`` defaults to ``--field-name`` (``--no-field-name`` for a bool that is on by default);
    a command of the settings alone keeps that name (:func:`add_options`'s ``own_names``), so
    ``flag`` is the name among other options. ``none`` is the word that stands for None, and ``off``
    a flag that gives that word; ``parse`` turns the text into the value where the type cannot.
    """

    group: str
    help: str
    flag: str | None = None
    metavar: str | None = None
    choices: tuple[str, ...] | None = None
    none: str | None = None
    off: str | None = None
    parse: Callable[[str], Any] | None = None


def option(group: str, help: str, **how: Any) -> dict[str, Option]:
    """Field metadata declaring a command-line option in ``group`` (:class:`Option`'s other fields)."""
    return {OPTION: Option(group, help, **how)}


#: Field metadata of a setting that is not on the command line.
NOT_AN_OPTION: dict[str, Option | None] = {OPTION: None}


@dataclass(frozen=True)
class Declared:
    """One option: its field, the field's resolved type, and its ``dest`` (``parent.child`` when nested)."""

    dest: str
    field: dataclasses.Field
    kind: Any
    option: Option

    @property
    def default(self) -> Any:
        """The field's default value (``dataclasses.MISSING`` for a required field)."""
        factory = self.field.default_factory
        return factory() if factory is not dataclasses.MISSING else self.field.default

    def value(self, parsed: Any) -> Any:
        """The field's value for what argparse produced."""
        if self.option.none is not None and parsed == self.option.none:
            return None
        if get_origin(_inner(self.kind)) is tuple and parsed is not None:
            return tuple(parsed)
        return parsed


def declared_options(config: type, prefix: str = "") -> Iterator[Declared]:
    """Every option of ``config``'s fields, nested dataclasses' included, in field order; a field
    that declares neither an option nor :data:`NOT_AN_OPTION` is a mistake and raises TypeError."""
    hints = get_type_hints(config)
    for field in dataclasses.fields(config):
        kind = hints[field.name]
        if dataclasses.is_dataclass(kind):
            yield from declared_options(kind, f"{prefix}{field.name}.")
        elif OPTION not in field.metadata:
            raise TypeError(f"{config.__name__}.{field.name} declares no command-line option")
        elif field.metadata[OPTION] is not None:
            yield Declared(prefix + field.name, field, kind, field.metadata[OPTION])


def add_options(groups: dict[str, argparse._ArgumentGroup], config: type, own_names: bool = False) -> None:
    """Add one argument per option of ``config`` to its group in ``groups`` (titles to groups);
    with ``own_names`` each flag is named after its field, whatever flag it declares."""
    for declared in declared_options(config):
        group = groups[declared.option.group]
        flag, arguments = _argument(declared, own_names)
        group.add_argument(flag, **arguments)
        if declared.option.off is not None:
            group.add_argument(
                declared.option.off,
                dest=declared.dest,
                action="store_const",
                const=declared.option.none,
                default=arguments["default"],
                help=f"same as {flag} {declared.option.none}",
            )


def config_values(args: argparse.Namespace, config: type, prefix: str = "") -> dict[str, Any]:
    """``config``'s keyword arguments from parsed options (:func:`add_options`); a nested
    dataclass is built from its own options, and settings that are no option keep their defaults."""
    hints, values = get_type_hints(config), {}
    for field in dataclasses.fields(config):
        kind, dest = hints[field.name], prefix + field.name
        if dataclasses.is_dataclass(kind):
            values[field.name] = kind(**config_values(args, kind, f"{dest}."))
        elif field.metadata.get(OPTION) is not None:
            declared = Declared(dest, field, kind, field.metadata[OPTION])
            values[field.name] = declared.value(getattr(args, dest))
    return values


def _argument(declared: Declared, own_names: bool = False) -> tuple[str, dict[str, Any]]:
    """The flag and ``add_argument`` keywords of one option."""
    option, kind, default = declared.option, _inner(declared.kind), declared.default
    name = declared.field.name.replace("_", "-")
    if own_names:
        option = dataclasses.replace(option, flag=None)
    arguments: dict[str, Any] = {"dest": declared.dest, "help": option.help}
    if kind is bool:
        flag = option.flag or (f"--no-{name}" if default else f"--{name}")
        return flag, arguments | {"action": "store_false" if default else "store_true"}
    element = _element(declared.kind)
    if element is not None:
        arguments["action"], kind = "append", element
    if option.metavar is not None:
        arguments["metavar"] = option.metavar
    if option.choices is not None:
        arguments["choices"] = option.choices + ((option.none,) if option.none is not None else ())
    elif option.parse is not None or kind is not str:
        arguments["type"] = option.parse or kind
    if default is dataclasses.MISSING:
        arguments["required"] = True
    else:
        arguments["default"] = option.none if default is None and option.none is not None else default
    return option.flag or f"--{name}", arguments


def _inner(kind: Any) -> Any:
    """``X`` of ``X | None``; any other type unchanged."""
    kinds = [k for k in get_args(kind) if k is not type(None)]
    return kinds[0] if get_origin(kind) is UnionType and len(kinds) == 1 else kind


def _element(kind: Any) -> Any:
    """The element type of a ``list[X]`` or ``tuple[X, ...]`` field (a repeatable flag), else None."""
    inner = _inner(kind)
    if get_origin(inner) is list or (get_origin(inner) is tuple and get_args(inner)[1:] == (Ellipsis,)):
        return get_args(inner)[0]
    return None
