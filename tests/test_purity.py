"""The core stays pure: the engine imports numpy, numba and a little of the standard library.

(numba itself imports parts of the standard library such as csv through importlib.metadata;
the AST test below is what holds our own source to the rule.)
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import physdbg

PACKAGE = Path(physdbg.__file__).parent
CORE_FILES = sorted((PACKAGE / "engine").rglob("*.py")) + [PACKAGE / "events.py", PACKAGE / "observe.py"]
ALLOWED = {"numpy", "numba", "math", "hashlib", "heapq", "dataclasses", "typing", "time", "__future__"}


def _imports(path: Path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name.split(".")[0], 0
        elif isinstance(node, ast.ImportFrom):
            yield (node.module or "").split(".")[0], node.level


def test_core_source_imports_only_numpy_numba_and_basic_stdlib():
    for path in CORE_FILES:
        for module, level in _imports(path):
            if level:  # relative: must stay inside engine/, or reach the typed events
                continue
            assert module in ALLOWED, f"{path.name} imports {module}"
    for path in sorted((PACKAGE / "engine").rglob("*.py")):
        depth = len(path.relative_to(PACKAGE / "engine").parts)  # 1: engine/x.py, 2: engine/pkg/x.py
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level > depth:
                assert node.level == depth + 1 and node.module in ("events", "errors", "kernel_cache"), (
                    f"{path.name} reaches outside the core: {'.' * node.level}{node.module}")


def test_the_broad_phase_package_has_no_import_circle():
    """grid and bvh depend on the leaf module boxes, never on each other or on __init__."""
    for name in ("boxes", "grid", "bvh"):
        tree = ast.parse((PACKAGE / "engine" / "broadphase" / f"{name}.py").read_text())
        local = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.level == 1}
        assert local <= ({"boxes"} if name != "boxes" else set()), f"{name}.py imports {local}"


def test_importing_the_engine_loads_no_file_or_viewer_library():
    code = ("import sys, physdbg.engine, physdbg.events, physdbg.observe\n"
            "bad = {'tomllib', 'typer', 'click', 'rich', 'rerun', 'mcap',\n"
            "       'physdbg.scene', 'physdbg.api', 'physdbg.cli'}\n"
            "print(sorted(bad & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


# ----------------------------------------------------------------------------- imports point down
def _module_graph() -> dict[str, set[str]]:
    """physdbg's modules (dotted, under the package) and the package modules each imports,
    at its top or inside a function alike."""
    def name(path: Path) -> str:
        parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts) or "physdbg"

    modules = {name(p): p for p in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        if module == "physdbg":
            package = []
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level == 0:
                if not (node.module or "").startswith("physdbg."):
                    continue
                base = node.module.split(".")[1:]
            else:
                base = package[:len(package) - (node.level - 1)] + [p for p in (node.module or "").split(".") if p]
            for alias in node.names:  # "from . import x": x may be a module
                target = ".".join([*base, alias.name])
                if target not in modules:
                    target = ".".join(base)
                if target in modules and target != module:
                    graph[module].add(target)
    return graph


def test_no_two_modules_import_each_other_however_indirectly():
    """Imports point down: errors and events at the bottom, then the engine, scenes and the
    advisor, recording, analysis, api, the CLI. A circle (record importing analysis, the
    format and its protobuf classes importing each other) fails here, naming its modules."""
    graph = _module_graph()
    graph.pop("physdbg", None)  # the package's own door: it may name anything, lazily
    for imports in graph.values():
        imports.discard("physdbg")
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles: list[list[str]] = []

    def visit(module: str) -> None:  # Tarjan's strongly connected components
        index[module] = low[module] = len(index)
        stack.append(module)
        for other in graph[module]:
            if other not in index:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in stack:
                low[module] = min(low[module], index[other])
        if low[module] == index[module]:
            component = []
            while True:
                other = stack.pop()
                component.append(other)
                if other == module:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for module in list(graph):
        if module not in index:
            visit(module)
    assert circles == [], f"import circles: {circles}"


def test_the_layers_import_only_downwards():
    graph = _module_graph()
    layer = {"errors": 0, "version": 0, "limits": 0, "kernel_cache": 0, "write_switch": 0, "events": 1, "observe": 2, "engine": 2, "scenes": 3, "advisor": 3, "meshes": 3,
             "scene": 4, "record": 5, "peers": 6, "analysis": 7, "precompile": 8, "tier": 9, "interrupt": 9, "api": 10, "viewers": 10, "serve": 11, "fork": 11,
             "cli": 12, "__main__": 13, "physdbg": 14}
    for module, imports in graph.items():
        here = layer[module.split(".")[0]]
        for other in imports:
            there = layer[other.split(".")[0]]
            assert there <= here, f"{module} (layer {here}) imports {other} (layer {there})"


def test_every_exception_class_lives_in_errors_py():
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "errors.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                bases = {getattr(b, "id", getattr(b, "attr", "")) for b in node.bases}
                assert not bases & {"Exception", "PhysdbgError", "FloatingPointError", "ValueError", "RuntimeError"} \
                    and not node.name.endswith("Error"), f"{path.name} defines {node.name}"


def test_importing_physdbg_defines_names_and_does_nothing_else():
    """`import physdbg` neither hashes the engine's sources nor sets NUMBA_CACHE_DIR for the
    process, nor loads numba: the engine does that when it is first imported."""
    code = ("import os, sys, physdbg\n"
            "assert 'NUMBA_CACHE_DIR' not in os.environ\n"
            "assert not {'numba', 'numpy', 'physdbg.kernel_cache', 'physdbg.engine'} & set(sys.modules), "
            "sorted(m for m in sys.modules if m.startswith(('numba', 'numpy', 'physdbg')))\n"
            "import physdbg.engine\n"
            "from physdbg import kernel_cache\n"
            "assert os.environ['NUMBA_CACHE_DIR'] == str(kernel_cache.folder())\n"
            "import numba.core.config\n"
            "assert numba.core.config.CACHE_DIR == os.environ['NUMBA_CACHE_DIR']\n")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr


def test_no_sentence_in_analysis_is_assembled_or_taken_apart_by_pattern_or_replace():
    """Findings, causes and departures are data (kind, step, bodies, advice as fields): no
    module of analysis/ rewrites or parses a sentence with the re module or str.replace
    (dataclasses.replace, which copies a record, is not a sentence's)."""
    found = []
    for path in sorted((PACKAGE / "analysis").glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [alias.name for alias in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                if "re" in names or "regex" in names:
                    found.append(f"{path.name}:{node.lineno} imports re")
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "replace"
                  and not (isinstance(node.func.value, ast.Name) and node.func.value.id == "dataclasses")):
                found.append(f"{path.name}:{node.lineno} calls .replace")
    assert found == []


MODULE_LINES = 800  # a module longer than this says at its top why it is one module


def test_a_module_over_800_lines_says_why_it_is_one_module():
    """Modules are sized by responsibility: one over MODULE_LINES lines gives its reason in
    its docstring ("Why one module of this size: ..."), so a reader knows it was weighed."""
    unexplained = []
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text()
        if text.count("\n") > MODULE_LINES and "Why one module of this size" not in (ast.get_docstring(ast.parse(text)) or ""):
            unexplained.append(f"{path.relative_to(PACKAGE)} ({text.count(chr(10))} lines)")
    assert unexplained == []
