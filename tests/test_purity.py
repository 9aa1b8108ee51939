"""The core stays pure: the engine imports numpy, numba and a little of the standard library.

(numba itself imports parts of the standard library such as csv through importlib.metadata;
the AST test below is what holds our own source to the rule.)
"""

from __future__ import annotations

import ast
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
                assert node.level == depth + 1 and node.module == "events", (
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
