"""README.md as a newcomer meets it: a fresh copy of the repository, a fresh venv made by
README command 1 verbatim (``pip install --no-compile -e .``: no test extras, no matplotlib, no peers),
and then every command of the README in order, each as its own process, with the exit
code its comment gives and every line its ``text`` blocks show. The README's commands
run here only (tests/test_docs.py runs those of docs/), so they are not paid for twice."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from .test_docs import OPENS_A_WINDOW, ROOT, _commands_and_exits_in, _readme_commands, check_shown

README = ROOT / "README.md"

# One fresh venv for the module: under pytest-xdist both tests run on the worker that made it;
# it is installed from a package registry (conftest.package_registry: skipped without one).
pytestmark = [pytest.mark.xdist_group("readme"), pytest.mark.registry]


def _fresh_copy(dest: Path) -> None:
    """The repository's files as a clone would have them (tracked and new, not ignored)."""
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                            capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        source = ROOT / name
        if source.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, dest / name)


@pytest.fixture(scope="module")
def newcomer(tmp_path_factory, package_registry):
    """(folder, environment) after README command 1 ran there, verbatim."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.fail("the README test copies the repository with git ls-files: run it from a git clone")
    folder = tmp_path_factory.mktemp("newcomer")
    _fresh_copy(folder)
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH", "NUMBA_DISABLE_JIT")}
    env["PATH"] = f"{folder / '.venv' / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    command_1 = _readme_commands()[0]
    done = subprocess.run(["bash", "-c", command_1], cwd=folder, env=env, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, f"README command 1 failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    assert "recordings/bounce.mcap" in done.stdout and (folder / "recordings" / "bounce.mcap").is_file()
    assert (folder / "recordings" / "bounce.rrd").is_file()
    return folder, env


@pytest.mark.slow
def test_readme_command_1_installs_no_more_than_the_core(newcomer):
    """What the README's commands need is in the core install: no test or chart extras."""
    folder, env = newcomer
    done = subprocess.run([str(folder / ".venv" / "bin" / "python"), "-c",
                           "import importlib.util as u; print(u.find_spec('pytest') is None, "
                           "u.find_spec('matplotlib') is None)"], env=env, capture_output=True, text=True)
    assert done.stdout.split() == ["True", "True"]


@pytest.mark.slow
def test_every_readme_command_runs_in_the_fresh_venv_as_written(newcomer):
    folder, env = newcomer
    setup_commands = set(_readme_commands())
    output = ""
    ran = 0
    for kind, block in re.findall(r"```(sh|text|python|toml)\n(.*?)```", README.read_text(), re.S):
        if kind == "text":
            check_shown(block, output, "README")
            continue
        if kind == "python":
            done = subprocess.run([str(folder / ".venv" / "bin" / "python"), "-c", block], cwd=folder, env=env,
                                  capture_output=True, text=True, timeout=600)
            assert done.returncode == 0, f"README's Python example failed:\n{block}\n{done.stderr[-3000:]}"
            output = done.stdout
            said = re.search(r"# step (\d+) first", block)  # the step the example says it prints first
            if said:
                assert output.split()[0] == said.group(1), f"the Python example printed {output[:200]!r}"
            continue
        if kind == "toml":
            from physdbg.scene import parse_scene

            parse_scene(block, "README.md example")
            continue
        if block.strip() in setup_commands:
            continue  # command 1 made this venv; command 2 is this test suite itself
        for command, expected in _commands_and_exits_in(block):
            if any(marker in command for marker in OPENS_A_WINDOW):
                continue
            done = subprocess.run(["bash", "-c", command], cwd=folder, env=env, capture_output=True, text=True,
                                  timeout=600)
            output = done.stdout + done.stderr
            assert done.returncode == expected, f"README: `{command}` exited {done.returncode}, not " \
                                                f"{expected}:\n{output[-3000:]}"
            assert "Traceback" not in output, f"README: `{command}`:\n{output[-3000:]}"
            ran += 1
    assert ran >= 30, f"only {ran} README commands ran"
