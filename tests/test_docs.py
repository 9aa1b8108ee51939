"""The docs cannot drift from the code: fields, scenes and the two commands."""

from __future__ import annotations

import re
from pathlib import Path

from physdbg.scene import FIELDS
from physdbg.scenes import builtin_names

ROOT = Path(__file__).resolve().parents[1]


def test_every_scene_field_and_built_in_scene_is_documented():
    text = (ROOT / "docs" / "scenes.md").read_text()
    for table, fields in FIELDS.items():
        for name in fields:
            assert f"`{name}`" in text, f"docs/scenes.md lacks {table}.{name}"
    for name in builtin_names():
        assert f"| `{name}` |" in text, f"docs/scenes.md lacks scene {name}"


def _readme_commands():
    return re.findall(r"```sh\n(python3 -m venv[^\n]*)\n```", (ROOT / "README.md").read_text())


def test_readme_has_the_two_commands_and_ci_runs_the_second_verbatim():
    setup_and_run, setup_and_test = _readme_commands()
    assert "physdbg record" in setup_and_run
    assert "pytest" in setup_and_test
    ci = (ROOT / ".ci" / "run").read_text()
    assert setup_and_test in ci.splitlines()
