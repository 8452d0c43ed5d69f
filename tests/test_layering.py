"""The package's structure is its data flow: descriptions -> code generation -> hybrid simulation
-> optimal control -> nonsmooth analysis -> studies -> the paper's presets -> edges (plots,
record, ROS transport) -> nodes -> command line. Dependencies point one way along it.

Two checks on the source itself (AST, every module, function-level imports included, so an
import hidden inside a function to dodge a cycle is seen): no module imports a module of a
higher layer, and the module graph has no cycle. A third runs the interpreter: importing the
numerical core loads no ROS, plotting or file-format code.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "biped_opt"

#: layers from the bottom up; a module may import modules of its own layer or of lower ones
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("base", ("biped_opt.errors", "biped_opt.strict_json", "biped_opt._jit",
              "biped_opt.progress", "biped_opt.piecewise", "biped_opt.version",
              "biped_opt.system_spec", "biped_opt.children",
              "biped_opt.input_files")),
    ("descriptions", ("biped_opt.systems",)),
    ("code generation", ("biped_opt.codegen",)),
    ("hybrid simulation", ("biped_opt.simulation",)),
    ("optimal control", ("biped_opt.control",)),
    ("nonsmooth analysis", ("biped_opt.analysis",)),
    ("studies", ("biped_opt.studies",)),
    ("the paper's presets", ("biped_opt.paper",)),
    ("edges", ("biped_opt.plots", "biped_opt.record", "biped_opt.ros",
               "biped_opt.interface_defs")),
    ("nodes", ("biped_opt.nodes",)),
    ("command line", ("biped_opt.cli",)),
    ("public API", ("biped_opt",)),
]
#: the kernel template is appended to generated modules, never imported itself
TEMPLATES = {"biped_opt.codegen.kernel"}

CORE = ["biped_opt.systems", "biped_opt.codegen.render", "biped_opt.simulation.compiled",
        "biped_opt.control.solve", "biped_opt.control.theorem1", "biped_opt.analysis.nonsmooth",
        "biped_opt.analysis.gradients", "biped_opt.analysis.pieces", "biped_opt.studies.study"]
FORBIDDEN = ["rclpy", "cyclonedds", "rosbags", "mcap", "mcap_ros2", "matplotlib",
             "biped_opt.ros", "biped_opt.interface_defs", "biped_opt.plots", "biped_opt.nodes",
             "biped_opt.record", "biped_opt.cli"]


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _layer(module: str) -> int:
    best, rank = -1, -1
    for i, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best:
                best, rank = len(prefix), i
    if rank < 0:
        raise AssertionError(f"{module} is in no layer: add it to LAYERS")
    return rank


def _imports(module: str, path: Path) -> set[str]:
    """The package's modules that ``module`` imports anywhere in its source."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            # ``from biped_opt import ros`` imports the module biped_opt.ros
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base
                     for a in node.names]
        else:
            continue
        for name in names:
            while name and name not in MODULES:
                name = name.rpartition(".")[0]
            if name.startswith("biped_opt") and name != module:
                found.add(name)
    return found


GRAPH = {m: _imports(m, p) for m, p in MODULES.items() if m not in TEMPLATES}


def test_every_module_is_in_a_layer():
    for module in MODULES:
        _layer(module)


def test_no_module_imports_a_higher_layer():
    upward = [f"{m} ({LAYERS[_layer(m)][0]}) imports {t} ({LAYERS[_layer(t)][0]})"
              for m, targets in GRAPH.items() for t in sorted(targets)
              if _layer(t) > _layer(m)]
    assert upward == []


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    assert _cycles(GRAPH) == []


@pytest.mark.parametrize("graph, expected", [
    ({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}, [["a", "b", "c"]]),
    ({"a": {"b"}, "b": set()}, []),
])
def test_the_cycle_finder_finds_cycles(graph, expected):
    # the check above is only as good as this finder: a three-module loop must be reported
    assert _cycles(graph) == expected


def test_the_import_reader_sees_function_level_and_package_imports(tmp_path):
    source = ("def f():\n    from biped_opt.control import solve\n"
              "from biped_opt import ros\nimport biped_opt.simulation.compiled as c\n")
    path = tmp_path / "probe.py"
    path.write_text(source)
    assert _imports("biped_opt.analysis.probe", path) == {
        "biped_opt.control.solve", "biped_opt.ros", "biped_opt.simulation.compiled"}


def test_core_imports_nothing_outside_the_core():
    code = (
        "import importlib, json, sys\n"
        f"for name in {CORE!r}: importlib.import_module(name)\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, check=True)
    loaded = json.loads(proc.stdout)
    leaked = [m for m in loaded if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)]
    assert leaked == []
