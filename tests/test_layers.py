"""The folder tree is the architecture: imports point one way, and this test keeps them so.

workflow: base <- models <- damping <- calibration <- optimise <- pipeline <- cli, with execution (pool, Dask,
cache) beside the models and below optimise, and rendering (textures, drive synthesis) on damping.  instruments: drivers <- simulator <- procedures
<- (pipeline, cli).  Command modules import no other command module, only ``cli.options``.  No import cycle, not even
through an import inside a function: what two modules both need lives in a module below them.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

BASE = (
    "workflow", "workflow.errors", "workflow.units", "workflow.serialise", "workflow.logformat", "workflow.progress",
    "workflow.inputfiles", "workflow.resonance", "workflow.sampling",
    "instruments",
)
LAYER_PREFIXES = {
    "models": "workflow.models",
    "execution": "workflow.execution",
    "damping": "workflow.damping",
    "calibration": "workflow.calibration",
    "optimise": "workflow.optimise",
    "rendering": "workflow.rendering",
    "pipeline": "workflow.pipeline",
    "cli": "workflow.cli",
    "drivers": "instruments.drivers",
    "simulator": "instruments.simulator",
    "procedures": "instruments.procedures",
}
ALLOWED = {
    "base": {"base"},
    "models": {"base", "models"},
    "execution": {"base", "execution"},
    "damping": {"base", "models", "damping"},
    "calibration": {"base", "models", "damping", "calibration"},
    "optimise": {"base", "models", "execution", "damping", "calibration", "optimise"},
    "rendering": {"base", "models", "damping", "rendering"},
    "drivers": {"base", "drivers"},
    "simulator": {"base", "models", "damping", "drivers", "simulator"},
    "procedures": {"base", "drivers", "simulator", "procedures"},
    "pipeline": set(LAYER_PREFIXES) - {"cli"} | {"base"},
    "cli": set(LAYER_PREFIXES) | {"base"},
}
PURE_LAYERS = ("models", "execution", "damping", "calibration", "optimise", "rendering")
"""Layers that never draw, parse arguments or print figures."""
FORBIDDEN_IN_PURE = ("matplotlib", "argparse")


def layer_of(module: str) -> str | None:
    if module in BASE:
        return "base"
    if module == "workflow.__main__":
        return "cli"
    for layer, prefix in LAYER_PREFIXES.items():
        if module == prefix or module.startswith(prefix + "."):
            return layer
    return None


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute module) of every import in a file, relative ones resolved."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module
            found.append((node.lineno, base))
            found += [(node.lineno, f"{base}.{alias.name}") for alias in node.names if _is_module(f"{base}.{alias.name}")]
    return found


def _is_module(dotted: str) -> bool:
    path = ROOT.joinpath(*dotted.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


SOURCES = sorted(p for folder in ("workflow", "instruments") for p in (ROOT / folder).rglob("*.py"))


def test_every_module_has_a_layer():
    assert [module_name(p) for p in SOURCES if layer_of(module_name(p)) is None] == []


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_point_one_way(path):
    here = module_name(path)
    layer = layer_of(here)
    wrong = []
    for line, target in imports(path):
        if target.split(".")[0] not in ("workflow", "instruments"):
            if layer in PURE_LAYERS and target.split(".")[0] in FORBIDDEN_IN_PURE:
                wrong.append(f"{path.name}:{line} imports {target} (a {layer} module must stay pure)")
            continue
        if target == "workflow" or target == "instruments":
            continue
        if layer_of(target) not in ALLOWED[layer]:
            wrong.append(f"{path.name}:{line}: {layer} module {here} imports {target} ({layer_of(target)})")
        if layer == "cli" and layer_of(target) == "cli" and target != "workflow.cli.options" and here != "workflow.__main__":
            wrong.append(f"{path.name}:{line}: command module {here} imports {target}; share code through cli.options")
    assert wrong == []


def test_the_checker_sees_a_violation(tmp_path, monkeypatch):
    """The rules are not vacuous: a model importing the pipeline is caught."""
    fake = ROOT / "workflow" / "models" / "_layer_probe.py"
    monkeypatch.setattr(Path, "read_text", lambda self, encoding=None: "from workflow.pipeline import steps\n")
    assert imports(fake) == [(1, "workflow.pipeline"), (1, "workflow.pipeline.steps")]
    assert layer_of("workflow.pipeline.steps") not in ALLOWED[layer_of(module_name(fake))]


def import_graph(sources=SOURCES) -> dict[str, set[str]]:
    """Module -> the project modules it imports, at the top or inside a function (a module's own packages left out:
    importing ``a.b.c`` runs ``a`` and ``a.b`` first whatever the code says)."""
    names = {module_name(p) for p in sources}
    graph = {}
    for path in sources:
        here = module_name(path)
        graph[here] = {t for _, t in imports(path) if t in names and t != here and not here.startswith(t + ".")}
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted: every import cycle is in one."""
    index, low, on_stack, stack, cycles = {}, {}, set(), [], []

    def visit(module):
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for target in sorted(graph[module]):
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in on_stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            component = []
            while not component or component[-1] != module:
                component.append(stack.pop())
                on_stack.discard(component[-1])
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return cycles


def test_no_import_cycles():
    """No two modules import each other, directly or through others, even from inside a function."""
    graph = import_graph()
    described = [" <-> ".join(cycle) + ": " + "; ".join(f"{m} imports {', '.join(sorted(graph[m] & set(cycle)))}"
                                                       for m in cycle) for cycle in import_cycles(graph)]
    assert described == []


def test_the_cycle_checker_sees_a_cycle_inside_a_function(monkeypatch):
    """A cycle closed by an import inside a function is caught, and a package's own ``__init__`` is no cycle."""
    graph = {"a.x": {"a.y"}, "a.y": {"a.z"}, "a.z": {"a.x"}, "a": {"a.w"}, "a.w": set(), "b": set()}
    assert import_cycles(graph) == [["a.x", "a.y", "a.z"]]
    assert import_cycles({**graph, "a.z": set()}) == []
    steps, loop = ROOT / "workflow" / "pipeline" / "steps.py", ROOT / "workflow" / "pipeline" / "loop.py"
    probe = {steps: "def f():\n    from workflow.pipeline import loop\n",
             loop: "def g():\n    from workflow.pipeline.steps import STEPS\n"}
    monkeypatch.setattr(Path, "read_text", lambda self, encoding=None: probe[self])
    assert import_cycles(import_graph([steps, loop])) == [["workflow.pipeline.loop", "workflow.pipeline.steps"]]


TEST_FOLDERS = {"base", *LAYER_PREFIXES} - {"drivers", "simulator", "procedures"} | {"instruments"}
"""The layer folders of ``tests/`` (the three instrument layers share one): a change's tests sit next to its layer."""
PROJECT_TESTS = {"test_docs.py", "test_layers.py", "test_packaging.py", "test_bench.py", "test_fem_bench.py"}
"""Tests of the whole project (documentation, architecture, packaging, benchmarks), at the top of ``tests/``."""


def test_the_tests_mirror_the_code():
    tests = ROOT / "tests"
    folders = {path.name for path in tests.iterdir() if path.is_dir() and any(path.glob("test_*.py"))}
    assert folders <= TEST_FOLDERS, folders - TEST_FOLDERS
    assert {path.name for path in tests.glob("test_*.py")} == PROJECT_TESTS
