"""Import directions between the repository's packages (docs/architecture.md).

The robot-side client stays light only while it imports none of the heavy packages, and the
server stays deployable without the simulator only while ``service`` never reaches into
``sim_worker`` or ``training``. Nothing at run time would notice a wrong import until someone
installs the light client or builds the service image, so this test reads every module with
``ast`` (module- and function-level imports, and ``importlib.import_module("...")`` calls) and
names the file, line and import that break a rule.
"""

from __future__ import annotations

import ast
import re
import textwrap
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: What each package may import of the others (its own modules always). A dotted name is a
#: subpackage: as a key, its rule replaces its package's for its modules; in a set, it allows that
#: subpackage alone. ``vgn_contract`` (the wire contract both sides build on) imports nothing of
#: ours. ``service.launch`` starts the server in child processes and imports none of it, so the
#: simulator and the ROS bridge may start a service without depending on the server's code.
#: ``client.extras`` is the one wording of a missing extra, which the server's commands use too.
#: ``benchmarks`` may use anything, and is in no other package's set: nothing that ships may
#: depend on a benchmark.
RULES: dict[str, frozenset[str]] = {
    "vgn_contract": frozenset(),
    "client": frozenset({"vgn_contract"}),
    "vgn_data": frozenset({"vgn_contract"}),
    "service": frozenset({"vgn_contract", "vgn_data", "client.extras"}),
    "service.launch": frozenset({"vgn_contract", "client.extras"}),
    "sim_worker": frozenset({"vgn_contract", "client", "vgn_data", "service.launch"}),
    "training": frozenset({"vgn_contract", "client", "vgn_data", "service", "sim_worker"}),
    "ros_bridge": frozenset({"vgn_contract", "client", "service.launch"}),
    "benchmarks": frozenset(
        {"vgn_contract", "client", "vgn_data", "service", "sim_worker", "training", "ros_bridge"}
    ),
}

#: Modules a package names in a string to run them, not to import their code: ``vgn-client serve``
#: and the embedded service start the server with uvicorn (``serve`` itself is handed to the launch
#: package), and ``vgn-client``'s ``clear-scene/generate-data --sim`` and ``clean-data`` hand their
#: arguments to the package that owns the command, loaded only when the user runs it. A new entry
#: here is a new runtime dependency of that file: add it on purpose, not to make the test pass.
RUNTIME_DISPATCH: frozenset[tuple[str, str]] = frozenset(
    {
        ("client/cli.py", "service.launch.serve"),
        ("client/cli.py", "sim_worker.clear_scene"),
        ("client/cli.py", "sim_worker.generate_data"),
        ("client/cli.py", "vgn_data.clean_data"),
        ("service/launch/embedded.py", "service.app:app"),
        ("service/launch/serve.py", "service.app:app"),
    }
)

#: The old ``client`` modules of process management, which moved to ``service.launch``: each
#: forwards its names there for one release, loading the module on first use (importlib; the
#: import for type checkers never runs), so importing ``client`` loads nothing of the server's
#: package; its deprecation warning names the module too. Goes with those modules.
FORWARDS: frozenset[tuple[str, str]] = frozenset(
    {
        ("client/embedded.py", "service.launch.embedded"),
        ("client/fleet.py", "service.launch.fleet"),
        ("client/haproxy.py", "service.launch.haproxy"),
        ("client/lifetime.py", "service.launch.lifetime"),
    }
)

DOTTED = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)+(:[A-Za-z_]\w*)?")


@dataclass(frozen=True)
class Reference:
    """One place a module names another: ``how`` is import, importlib or string."""

    path: str
    line: int
    module: str
    how: str


def module_name(root: Path, path: Path) -> str:
    """``pkg/sub/mod.py`` -> ``pkg.sub.mod`` (a package's ``__init__`` is the package)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def absolute(module: str | None, level: int, importer: str, is_package: bool) -> str:
    """The absolute name a (possibly relative) ``from`` import refers to."""
    if not level:
        return module or ""
    base = importer.split(".")
    base = base[: len(base) - level + (1 if is_package else 0)]
    return ".".join([*base, module] if module else base)


def _not_references(tree: ast.Module) -> set[int]:
    """Ids of string nodes that are no string reference: docstrings (prose may mention a
    module) and the arguments of import calls (those are reported as importlib)."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Expr):
            found.add(id(node.value))
        elif isinstance(node, ast.Call) and _is_import_call(node):
            found.update(id(arg) for arg in node.args)
    return found


def _is_string(node: ast.AST) -> bool:
    return isinstance(node, ast.Constant) and isinstance(node.value, str)


def _is_import_call(node: ast.Call) -> bool:
    name = getattr(node.func, "attr", None) or getattr(node.func, "id", None)
    return name in ("import_module", "__import__")


def _names_module(root: Path, value: str) -> bool:
    """Whether ``value`` (``pkg.mod`` or ``pkg.mod:attr``) is a module of this repository, so
    file names such as ``service.log`` are not taken for one."""
    if not DOTTED.fullmatch(value):
        return False
    target = root.joinpath(*value.split(":")[0].split("."))
    return target.with_suffix(".py").is_file() or (target / "__init__.py").is_file()


def references(root: Path, path: Path) -> Iterator[Reference]:
    """Every module ``path`` imports or names for import, anywhere in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    importer, rel = module_name(root, path), path.relative_to(root).as_posix()
    is_package = path.name == "__init__.py"
    skipped = _not_references(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (Reference(rel, node.lineno, alias.name, "import") for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            target = absolute(node.module, node.level, importer, is_package)
            # ``from pkg import mod`` imports the module ``pkg.mod``: name it, so that a check
            # between modules (the cycle check below) sees it, not only the package.
            modules = [f"{target}.{a.name}" for a in node.names if _names_module(root, f"{target}.{a.name}")]
            if len(modules) < len(node.names):
                modules.append(target)
            yield from (Reference(rel, node.lineno, module, "import") for module in modules)
        elif isinstance(node, ast.Call) and _is_import_call(node) and node.args:
            if _is_string(node.args[0]):
                yield Reference(rel, node.lineno, node.args[0].value, "importlib")
        elif _is_string(node) and id(node) not in skipped and _names_module(root, node.value):
            yield Reference(rel, node.lineno, node.value, "string")


def within(module: str, package: str) -> bool:
    """Whether ``module`` is ``package`` or one of its modules (``a.b`` is within ``a``, ``ab`` is not)."""
    return module == package or module.startswith(package + ".")


def owner(module: str, rules: Mapping[str, frozenset[str]]) -> str | None:
    """The most specific package of ``rules`` that ``module`` belongs to."""
    packages = [package for package in rules if within(module, package)]
    return max(packages, key=len) if packages else None


def violations(
    root: Path,
    rules: Mapping[str, frozenset[str]] = RULES,
    dispatch: frozenset[tuple[str, str]] = RUNTIME_DISPATCH,
    forwards: frozenset[tuple[str, str]] = FORWARDS,
) -> list[str]:
    """One line per reference that runs against ``rules``: ``file:line: message``."""
    ours = {package.split(".")[0] for package in rules}
    found = []
    for package, allowed in rules.items():
        for path in sorted((root / package.replace(".", "/")).rglob("*.py")):
            if owner(module_name(root, path), rules) != package:
                continue  # a subpackage with a rule of its own
            for ref in references(root, path):
                target = ref.module.split(":")[0]
                if target.split(".")[0] not in ours or within(target, package):
                    continue
                if any(within(target, other) for other in allowed):
                    continue
                if ref.how == "string" and (ref.path, ref.module) in dispatch:
                    continue
                if (ref.path, ref.module) in forwards:
                    continue
                others = ", ".join(sorted(allowed)) or "none of the other packages"
                found.append(
                    f"{ref.path}:{ref.line}: {package} must not {_verb(ref.how)} {ref.module!r} "
                    f"({package} may use: {others})"
                )
    return found


def _verb(how: str) -> str:
    return {"import": "import", "importlib": "load (importlib)", "string": "name for import"}[how]


def import_graph(root: Path, package: str) -> dict[str, set[str]]:
    """Which of ``package``'s modules each of its modules imports (importlib included; a module
    named in a string is run, not imported, and the package's ``__init__`` is left out)."""
    modules = {module_name(root, path): path for path in sorted((root / package).rglob("*.py"))}
    graph = {}
    for name, path in modules.items():
        imported = {ref.module for ref in references(root, path) if ref.how != "string"}
        graph[name] = {module for module in imported if module in modules and module not in (name, package)}
    return graph


def import_cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """One cycle per module that starts one, as ``[a, b, ..., a]``: a depth-first search that
    reports each edge back to a module still on its path."""
    cycles, done = [], set()

    def visit(module: str, path: list[str]) -> None:
        for imported in sorted(graph.get(module, ())):
            if imported in path:
                cycles.append([*path[path.index(imported) :], imported])
            elif imported not in done:
                visit(imported, [*path, imported])
        done.add(module)

    for module in sorted(graph):
        if module not in done:
            visit(module, [module])
    return cycles


def top_level_packages(root: Path) -> set[str]:
    """The repository's importable top-level packages (tests are not one that ships)."""
    return {p.parent.name for p in root.glob("*/__init__.py")} - {"tests"}


# The repository itself.


def test_every_package_has_a_rule():
    missing = top_level_packages(ROOT) - set(RULES)
    assert not missing, f"add {sorted(missing)} to RULES here and to docs/architecture.md"


def test_every_rule_names_a_package_with_modules():
    for package in RULES:
        folder = package.replace(".", "/")
        assert list((ROOT / folder).rglob("*.py")), f"{folder}/ has no modules: is RULES out of date?"


def test_imports_run_the_allowed_way():
    found = violations(ROOT)
    assert not found, "imports against docs/architecture.md:\n" + "\n".join(found)


def test_grpc_latency_does_not_import_latency():
    """``benchmarks.latency`` adds the gRPC rows to its report: the dependency runs one way, and
    what both use lives in ``benchmarks.timing`` and ``benchmarks.workload``."""
    graph = import_graph(ROOT, "benchmarks")
    assert "benchmarks.grpc_latency" in graph["benchmarks.latency"]
    assert "benchmarks.latency" not in graph["benchmarks.grpc_latency"]


def test_no_benchmark_imports_one_that_imports_it_back():
    cycles = import_cycles(import_graph(ROOT, "benchmarks"))
    assert not cycles, "import cycles among benchmarks modules:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_runtime_dispatch_targets_exist():
    """A stale entry would allow a string that no longer names anything."""
    for path, module in RUNTIME_DISPATCH | FORWARDS:
        assert (ROOT / path).is_file(), path
        assert _names_module(ROOT, module), module


# The checker, on a small tree made up for the purpose.

TOY_RULES = {"client": frozenset(), "service": frozenset({"client"}), "sim_worker": frozenset({"client"})}


def _write(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    return root


def _toy(tmp_path: Path, extra: dict[str, str]) -> Path:
    base = {
        "client/__init__.py": "",
        "client/schemas.py": "X = 1\n",
        "service/__init__.py": "",
        "service/app.py": "from client.schemas import X\n",
        "sim_worker/__init__.py": "",
        "sim_worker/world.py": "from client import schemas\n",
    }
    return _write(tmp_path, {**base, **extra})


def test_checker_accepts_allowed_imports(tmp_path):
    assert violations(_toy(tmp_path, {}), TOY_RULES, frozenset()) == []


def test_checker_finds_a_module_level_import(tmp_path):
    root = _toy(tmp_path, {"client/http.py": "import os\nimport service.app\n"})
    assert violations(root, TOY_RULES, frozenset()) == [
        "client/http.py:2: client must not import 'service.app' (client may use: none of the other packages)"
    ]


def test_checker_finds_a_function_level_import(tmp_path):
    code = """
        def run():
            from sim_worker.world import step
            return step
    """
    root = _toy(tmp_path, {"service/core.py": code})
    (found,) = violations(root, TOY_RULES, frozenset())
    assert found.startswith("service/core.py:3: service must not import 'sim_worker.world'")


def test_checker_finds_an_importlib_call(tmp_path):
    code = 'import importlib\n\nworld = importlib.import_module("sim_worker.world")\n'
    root = _toy(tmp_path, {"service/core.py": code})
    (found,) = violations(root, TOY_RULES, frozenset())
    assert found.startswith("service/core.py:3: service must not load (importlib) 'sim_worker.world'")


def test_checker_finds_a_module_named_in_a_string_unless_declared(tmp_path):
    code = 'COMMANDS = {"step": "sim_worker.world"}\nLOG = "sim_worker.log"\n'
    root = _toy(tmp_path, {"client/cli.py": code})
    (found,) = violations(root, TOY_RULES, frozenset())
    assert found.startswith("client/cli.py:1: client must not name for import 'sim_worker.world'")
    assert violations(root, TOY_RULES, frozenset({("client/cli.py", "sim_worker.world")})) == []


def test_checker_ignores_docstrings_and_resolves_relative_imports(tmp_path):
    code = '"""Mentions sim_worker.world in prose."""\nfrom . import schemas\nfrom .schemas import X\n'
    root = _toy(tmp_path, {"client/grpc.py": code})
    assert violations(root, TOY_RULES, frozenset()) == []
    assert absolute(None, 1, "client.grpc_api", True) == "client.grpc_api"
    assert absolute("schemas", 2, "client.grpc_api.convert", False) == "client.schemas"


def test_checker_applies_a_subpackage_rule(tmp_path):
    rules = {
        **TOY_RULES,
        "service.launch": frozenset({"client"}),
        "sim_worker": frozenset({"service.launch"}),
    }
    files = {
        "service/launch/__init__.py": "",
        "service/launch/run.py": "from client.schemas import X\nfrom service.app import X as Y\n",
        "service/core.py": "from service.launch.run import X\n",
        "sim_worker/world.py": "from service.launch import run\nimport service.app\n",
    }
    assert (
        owner("service.launch.run", rules) == "service.launch" and owner("service.core", rules) == "service"
    )
    assert sorted(violations(_toy(tmp_path, files), rules, frozenset(), frozenset())) == [
        "service/launch/run.py:2: service.launch must not import 'service.app' (service.launch may use: client)",
        "sim_worker/world.py:2: sim_worker must not import 'service.app' (sim_worker may use: service.launch)",
    ]


def test_checker_allows_a_declared_forward(tmp_path):
    code = 'import importlib\n\nrun = importlib.import_module("service.app")\n'
    root = _toy(tmp_path, {"client/old.py": code})
    (found,) = violations(root, TOY_RULES, frozenset(), frozenset())
    assert found.startswith("client/old.py:3: client must not load (importlib) 'service.app'")
    assert violations(root, TOY_RULES, frozenset(), frozenset({("client/old.py", "service.app")})) == []


def test_checker_ignores_imports_of_other_libraries(tmp_path):
    root = _toy(tmp_path, {"client/http.py": "import numpy\nfrom pydantic import BaseModel\n"})
    assert violations(root, TOY_RULES, frozenset()) == []


def test_checker_names_a_module_imported_from_its_package(tmp_path):
    code = "from client import schemas\nfrom client.schemas import X\n"
    refs = list(references(_toy(tmp_path, {"service/core.py": code}), tmp_path / "service/core.py"))
    assert [ref.module for ref in refs] == ["client.schemas", "client.schemas"]


def test_checker_finds_an_import_cycle_between_modules(tmp_path):
    files = {
        "service/a.py": "def late():\n    from service import b\n",
        "service/b.py": "from service.c import Y\n",
        "service/c.py": "import importlib\n\nY = importlib.import_module('service.a')\n",
        "service/d.py": "from service import a\nRUN = 'service.d'\n",
    }
    graph = import_graph(_toy(tmp_path, files), "service")
    assert graph["service.a"] == {"service.b"} and graph["service.d"] == {"service.a"}
    assert import_cycles(graph) == [["service.a", "service.b", "service.c", "service.a"]]
    assert import_cycles({"a": {"b"}, "b": set(), "c": {"a", "b"}}) == []
