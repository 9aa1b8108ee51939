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
# commands that open a window or serve until stopped (tests/test_serve.py runs --serve)
OPENS_A_WINDOW = ("--spawn", "--web", "bin/rerun ", "--serve")
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
# pages whose commands take 2 s or more here (pytest --durations=0): the slow tier
SLOW_PAGES = {"accuracy.md", "diff.md", "foreign-runs.md", "stability.md"}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.name in SLOW_PAGES else p
                                  for p in DOCS if p.name != "README.md"], ids=lambda p: p.name)
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
            command, _, into = command.partition(" > ")  # `physdbg ... > FILE` writes what it prints there
            result = runner.invoke(app, shlex.split(command)[1:])
            assert result.exit_code == expected, f"{path.name}: `{command}` exited {result.exit_code}:\n{result.output}"
            output = result.output
            if into:
                Path(into.strip()).write_text(output)
    for block in re.findall(r"```python\n(.*?)```", path.read_text(), re.S):
        exec(compile(block, f"{path.name} example", "exec"), {})  # noqa: S102 - our own docs
    for block in re.findall(r"```toml\n(.*?)```", path.read_text(), re.S):
        from physdbg.scene import parse_scene

        parse_scene(block, f"{path.name} example")


# ----------------------------------------------------------------------------- docs held to the code
def _table_codes(text: str) -> set[str]:
    """The codes a Markdown table lists in its first column: | `code` | or | `a` / `b` |."""
    rows = re.findall(r"^\| ((?:`[a-z_/.-]+`(?: / )?)+) \|", text, re.M)
    return {code for row in rows for code in re.findall(r"`([a-z_/.-]+)`", row)}


def test_every_channel_kind_cause_finding_and_phase_the_code_has_is_in_the_docs():
    """The lists the docs share with the code: a new one in the code and not in its page
    fails here, by name."""
    from physdbg import events
    from physdbg.analysis import audit, departure
    from physdbg.engine import colliders
    from physdbg.record import format as fmt

    docs = ROOT / "docs"
    channels = {value for name, value in vars(fmt).items() if name.startswith("TOPIC_")}
    assert channels - _table_codes((docs / "recording-format.md").read_text()) == set()
    check_run = _table_codes((docs / "foreign-runs.md").read_text())
    assert set(departure.DEPARTURE_KINDS) - check_run == set()  # check-run's causes, by its table
    diff_page = _table_codes((docs / "diff.md").read_text())
    from physdbg.analysis import diff_causes

    assert set(diff_causes.CAUSE_KINDS) - diff_page == set()  # diff's causes, by its table
    made = {kind for module in ("diff.py", "diff_causes.py") for kind in
            re.findall(r'Cause\(\s*"([a-z-]+)"', (ROOT / "physdbg" / "analysis" / module).read_text())}
    assert len(made) > 10 and made - set(diff_causes.CAUSE_KINDS) == set()  # the table lists every kind made
    assert {kind for detector in diff_causes.STEP_CAUSES for kind in detector.kinds} <= set(diff_causes.CAUSE_KINDS)
    assert set(audit.FINDING_KINDS) - diff_page == set()  # explain's findings
    # each finding comes from a check of the audit's table, and every check is a method
    assert {kind for check in audit.AUDIT_CHECKS for kind in check.kinds} == set(audit.FINDING_KINDS)
    assert all(vars(audit.Auditor).get(check.method.__name__) is check.method for check in audit.AUDIT_CHECKS)
    engine = (docs / "engine.md").read_text()
    assert [p for p in events.STEP_PHASES if f"`_{p}`" not in engine] == []
    for kind, module in zip(events.KIND_NAMES, colliders.KIND_MODULES, strict=True):  # the collider kinds
        assert f"`{module.__name__.rsplit('.', 1)[1]}.py`" in engine, kind
    codes = [f"{code} " for code in range(len(events.KIND_NAMES))]
    for page in ("events.md", "recording-format.md"):  # every `kind` (0 pair, 1 wall, ...) lists every code
        lists = re.findall(r"`kind` \(([^)]*)\)", (docs / page).read_text())
        assert lists and all(all(code in listed for code in codes) for listed in lists), (page, lists)


def test_the_architecture_page_names_every_module_and_only_files_that_exist():
    """docs/architecture.md is the map: every module of physdbg (outside the engine's own
    packages, which engine.md lists: test_the_engine_page_names_every_module_of_the_engine)
    is on it, and every path it names exists."""
    page = (ROOT / "docs" / "architecture.md").read_text()
    package = ROOT / "physdbg"
    named = set(re.findall(r"`((?:[a-z_]+/)*[a-z_-]+\.(?:py|js))`", page)) - {"engine/colliders/capsule.py"}  # the example
    missing = sorted(path for path in named if not any((root / path).exists() for root in (package, ROOT)))
    assert missing == [], missing
    modules = [p.relative_to(package).as_posix() for p in package.glob("*.py")] + \
        [p.relative_to(package).as_posix() for folder in ("analysis", "record") for p in (package / folder).glob("*.py")]
    unmapped = sorted(m for m in modules if not m.endswith("__init__.py") and m not in ("__main__.py", "py.typed")
                      and f"`{m}`" not in page)
    assert unmapped == [], unmapped
    index = (ROOT / "docs" / "README.md").read_text()
    pages = sorted(p.name for p in (ROOT / "docs").glob("*.md") if p.name != "README.md")
    assert [name for name in pages if f"({name})" not in index] == []


def test_the_engine_page_names_every_module_of_the_engine():
    """docs/engine.md's file table names every module of physdbg/engine (a package's modules
    in its folder's row, or by their path), as architecture.md names the rest."""
    rows = [line for line in (ROOT / "docs" / "engine.md").read_text().splitlines() if line.startswith("| `")]
    engine = ROOT / "physdbg" / "engine"
    unnamed = []
    for path in sorted(engine.rglob("*.py")):
        relative = path.relative_to(engine).as_posix()
        if path.name == "__init__.py" and relative.count("/") != 1:
            continue  # the engine package's own face
        folder = relative.rsplit("/", 1)[0] + "/" if "/" in relative else None
        named = any(f"`{relative}`" in row or (row.startswith(f"| `{folder}`") and f"`{path.name}`" in row)
                    if folder else f"`{relative}`" in row for row in rows)
        if not named and not (path.name == "__init__.py" and any(row.startswith(f"| `{folder}`") for row in rows)):
            unnamed.append(relative)
    assert unnamed == []


def test_every_relative_link_in_the_docs_resolves():
    broken = []
    for page in DOCS:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
            if not target.startswith(("http://", "https://", "mailto:")) and not (page.parent / target).exists():
                broken.append(f"{page.relative_to(ROOT)} -> {target}")
    assert broken == []


def test_every_file_the_docs_name_in_the_repository_exists():
    """A path the docs name in code font (benchmarks/…, tests/…, physdbg/…) is a file that
    is there: a moved benchmark or module leaves no stale pointer."""
    missing = []
    for page in DOCS:
        for path in re.findall(r"`((?:benchmarks|tests|physdbg)/[A-Za-z0-9_./-]+\.(?:py|js|toml|md))`", page.read_text()):
            if not (ROOT / path).exists():
                missing.append(f"{page.relative_to(ROOT)} -> {path}")
    assert missing == []


def test_every_exit_code_the_code_uses_is_in_the_exit_code_table():
    """The codes the CLI exits with (its typer.Exit calls, and each error class's
    exit_code) are the rows of diff.md's table for every command, and no more."""
    source = (ROOT / "physdbg" / "cli.py").read_text() + (ROOT / "physdbg" / "errors.py").read_text()
    used = {int(code) for code in re.findall(r"typer\.Exit\((\d+)\)|exit_code = (\d+)", source) for code in code if code}
    page = (ROOT / "docs" / "diff.md").read_text()
    table = page[page.index("| code | every command |"):]
    listed = {int(code) for code in re.findall(r"^\| \*\*(\d+)\*\* \|", table[:table.index("\n\n")], re.M)}
    assert used | {0, 1} == listed



def test_every_field_of_every_table_channel_is_named_in_its_row():
    """recording-format.md's row of each protobuf channel names each of its fields (the
    fields are the code's tables, record/format.py): a field added to a channel and not to
    its row fails here, by channel and name."""
    from physdbg.record import format as fmt

    rows = {line.split(" | ")[0].strip("| `"): line for line in
            (ROOT / "docs" / "recording-format.md").read_text().splitlines() if line.startswith("| `/physdbg/")}
    missing = {}
    for topic, message in fmt.MESSAGE_OF_TOPIC.items():
        if message not in fmt.PROTOBUF_MESSAGES:
            continue
        fields, _ = fmt.PROTOBUF_MESSAGES[message]
        absent = [name for name, *_ in fields if f"`{name}`" not in rows[topic]]
        if absent:
            missing[topic] = absent
    assert missing == {}
