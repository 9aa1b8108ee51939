"""The docs cannot drift from the code: fields, scenes and the two commands."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

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


# ----------------------------------------------------------------------------- every command runs
# Commands that open a window or serve until stopped are the only ones not run here.
OPENS_A_WINDOW = ("--spawn", "--web", "bin/rerun ")
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _physdbg_commands(path: Path) -> list[str]:
    """Every `physdbg ...` command in the file's ```sh blocks, in order (also after &&)."""
    return [command for command, _ in _commands_and_exits(path)]


def _commands_and_exits(path: Path) -> list[tuple[str, int]]:
    """(command, expected exit code): 0, or N when its comment says "exit N"."""
    return [pair for block in re.findall(r"```sh\n(.*?)```", path.read_text(), re.S)
            for pair in _commands_and_exits_in(block)]


def _commands_and_exits_in(block: str) -> list[tuple[str, int]]:
    commands = []
    for line in block.splitlines():
        line, _, comment = line.partition("  #")
        expected = re.match(r"\s*exit (\d)\b", comment)
        for part in line.strip().split("&&"):
            part = part.strip()
            if part.startswith((".venv/bin/physdbg ", "physdbg ")):
                commands.append((part, int(expected.group(1)) if expected else 0))
    return commands


def check_shown(block: str, output: str, where: str) -> None:
    """A ```text block shows what the command before it printed: every line of it is in
    that output (or the line's start, before a closing "…")."""
    for line in block.splitlines():
        shown = line.rstrip().removesuffix("…").rstrip()
        assert shown in output, f"{where}: this line is not in the output of the command before it:\n" \
                                f"{line}\n--- the output was:\n{output}"


def test_the_docs_show_physdbg_commands_to_run():
    assert len(_physdbg_commands(ROOT / "README.md")) >= 12


# README.md's commands and examples run in a fresh venv made by its command 1 (tests/test_readme.py)
@pytest.mark.parametrize("path", [p for p in DOCS if p.name != "README.md"], ids=lambda p: p.name)
def test_every_command_and_python_example_in_the_docs_runs_as_written(path, tmp_path, monkeypatch):
    import shlex
    import shutil

    from typer.testing import CliRunner

    from physdbg.cli import app

    shutil.copytree(ROOT / "docs", tmp_path / "docs")  # example scenes the commands name
    shutil.copytree(ROOT / "recordings" / "ci", tmp_path / "recordings" / "ci")  # the goldens ci.md names
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    output = ""
    for kind, block in re.findall(r"```(sh|text)\n(.*?)```", path.read_text(), re.S):
        if kind == "text":
            check_shown(block, output, path.name)
            continue
        for command, expected in _commands_and_exits_in(block):
            if any(marker in command for marker in OPENS_A_WINDOW):
                continue
            result = runner.invoke(app, shlex.split(command)[1:])
            assert result.exit_code == expected, f"{path.name}: `{command}` exited {result.exit_code}:\n{result.output}"
            output = result.output
    for block in re.findall(r"```python\n(.*?)```", path.read_text(), re.S):
        exec(compile(block, f"{path.name} example", "exec"), {})  # noqa: S102 - our own docs
    for block in re.findall(r"```toml\n(.*?)```", path.read_text(), re.S):
        from physdbg.scene import parse_scene

        parse_scene(block, f"{path.name} example")
