"""Compiled or interpreted (physdbg/tier.py): the same hashes both ways, and the rule."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from physdbg import api, precompile, tier
from physdbg.scenes import builtin_names

# every built-in scene at a size the interpreted tier runs in a few seconds
SMALL = {"highspeed": ["generate.count=40", "duration=0.2"], "rain": ["generate.count=40", "duration=0.5"],
         "funnel": ["generate.count=30", "duration=0.5"], "gas": ["duration=0.5"], "ramp": ["duration=1"]}


def _interpreted_run(name: str, overrides: list[str]) -> dict:
    command = [sys.executable, "-m", "physdbg", "run", name, "--json"]
    for item in overrides:
        command += ["-s", item]
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    done = subprocess.run(command, capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr + done.stdout
    return json.loads(done.stdout)


@pytest.mark.slow
@pytest.mark.parametrize("name", builtin_names())
def test_every_built_in_scene_gives_the_same_hash_interpreted_and_compiled(name):
    overrides = SMALL.get(name, [])
    interpreted = _interpreted_run(name, overrides)
    assert interpreted["kernels"] == {"interpreted": True, "why": "interpreted (NUMBA_DISABLE_JIT=1)"}
    compiled = api.run(name, overrides)
    assert interpreted["final_hash"] == compiled.final_hash
    assert interpreted["contacts"] == compiled.contacts and interpreted["steps"] == compiled.steps


def test_the_work_of_a_scene_is_estimated_from_its_file_before_it_is_loaded(tmp_path):
    assert tier.estimate("bounce") == 300  # one ball, 5 s at 1/60
    assert tier.estimate("rain", ["generate.count=2000"]) == 2000 * 240
    assert tier.estimate("cradle", ["duration=1"]) == 5 * 60
    scene = tmp_path / "s.toml"
    scene.write_text('dt = 0.01\nsteps = 7\n[[particles]]\nposition = [0, 0, 0]\n[[particles]]\nposition = [1, 0, 0]\n')
    assert tier.estimate(str(scene)) == 14
    scene.write_text('dt = "real"\nduration = 1\n[[particles]]\nposition = [0, 0, 0]\n')
    assert tier.estimate(str(scene)) is None  # unknown: counts as large
    assert tier.estimate("no-such-scene") is None


@pytest.fixture
def cold(tmp_path, monkeypatch):
    """A kernel cache folder with nothing in it, and no numba switch set by the user."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("PHYSDBG_COMPILE", raising=False)
    monkeypatch.setattr(tier, "interpreted", lambda: False)
    return tmp_path / "cache"


def test_a_small_run_on_a_cold_cache_is_interpreted_and_compiles_in_the_background(cold):
    chosen = tier.choose(300)
    assert chosen.interpreted and chosen.background
    assert chosen.reason.startswith("interpreted: 300 sphere-steps on a cold kernel cache (compiled from 20,000)")
    large = tier.choose(tier.INTERPRET_UP_TO + 1)
    assert not large.interpreted and "the first compile takes" in large.reason
    assert not tier.choose(None).interpreted  # unknown work: compiled


def test_a_warm_cache_and_the_setting_decide(cold, monkeypatch):
    for name in ("resolve.settle_held-1.py311.1.nbc", "timeline.run_time_order-2.py311.1.nbc"):
        (cold / "engine_x").mkdir(parents=True, exist_ok=True)
        (cold / "engine_x" / name).write_bytes(b"")
    assert tier.cache_is_warm()
    assert tier.choose(300) == tier.Tier(False, "compiled (the kernel cache is warm)")
    (cold / "engine_x" / "timeline.run_time_order-2.py311.1.nbc").unlink()
    assert not tier.cache_is_warm()
    monkeypatch.setenv("PHYSDBG_COMPILE", "now")
    assert not tier.choose(300).interpreted
    monkeypatch.setenv("PHYSDBG_COMPILE", "never")
    chosen = tier.choose(10**9)
    assert chosen.interpreted and not chosen.background
    monkeypatch.setenv("PHYSDBG_COMPILE", "sometimes")
    with pytest.raises(ValueError, match="PHYSDBG_COMPILE='sometimes': one of auto, now, background, never"):
        tier.choose(300)


def test_a_cache_filled_on_another_cpu_is_cold(cold):
    """numba keys each cached kernel by the CPU it was compiled for: a folder holding only
    another CPU's versions (a CI cache restored on another runner model) is cold here."""
    import pickle

    import numba

    def fill(cpu):
        for name in ("resolve.settle_held-1.py311", "timeline.run_time_order-2.py311"):
            (cold / "engine_x").mkdir(parents=True, exist_ok=True)
            (cold / "engine_x" / f"{name}.1.nbc").write_bytes(b"")
            index = pickle.dumps((b"stamp", {(("a signature",), cpu, ("hash", "hash")): f"{name}.1.nbc"}))
            (cold / "engine_x" / f"{name}.nbi").write_bytes(pickle.dumps(numba.__version__) + index)

    fill(("x86_64-unknown-linux-gnu", "k8", ""))
    assert not tier.cache_is_warm()
    assert tier.choose(300).interpreted
    fill(precompile.this_cpu())
    assert tier.cache_is_warm()


def test_a_cold_first_run_answers_in_seconds_and_says_why(tmp_path):
    """README's first scene on an empty kernel cache, as a fresh clone meets it (the
    background compile not started: PHYSDBG_COMPILE=never)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PHYSDBG_COMPILE="never")
    env.pop("NUMBA_DISABLE_JIT", None)
    done = subprocess.run([sys.executable, "-m", "physdbg", "run", "bounce"], capture_output=True, text=True,
                          env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "kernels     interpreted (PHYSDBG_COMPILE=never, and the kernel cache is cold)" in done.stdout
    assert "state hash  8001b275691de3af018776bfb275eecf" in done.stdout  # the golden hash of bounce
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").rglob("*.nbc"))


def test_the_background_compile_runs_this_physdbg_without_the_numba_switch():
    command = tier.background_command()
    assert command[0] == sys.executable and "physdbg.tier" in command[-1] and "t.main()" in command[-1]


def test_quick_commands_in_a_row_start_one_background_compile_not_one_each(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    started = []

    class FakeProcess:
        pid = os.getpid()  # alive: this very process

    monkeypatch.setattr(tier.subprocess, "Popen", lambda *a, **k: started.append(a) or FakeProcess())
    first = tier.start_background_compile()
    again = tier.start_background_compile()
    assert first == again == os.getpid() and len(started) == 1
    (tmp_path / "cache" / "background-compile.pid").write_text("999999999")  # a process long gone
    assert tier.running_background_compile() is None
    tier.start_background_compile()
    assert len(started) == 2


def test_a_benchmark_compiles_before_its_runs_and_says_so(tmp_path, monkeypatch):
    """bench never runs interpreted (wall time is what it measures): it compiles first, and
    the CLI hears "compiling" before and "running" after, as a run's progress does."""
    heard: list[str] = []
    real = precompile.compile_kernels

    def compile_kernels(*args, **kwargs):
        heard.append("compile")
        return real(*args, **kwargs)

    monkeypatch.setattr(precompile, "compile_kernels", compile_kernels)
    api.bench_accuracy(tmp_path / "acc", quick=True, chart=False, problems=["head-on"], workers=1,
                       on_status=heard.append)
    assert heard[:3] == ["compiling", "compile", "running"]
    assert not tier.interpreted()


def test_the_work_estimate_is_total_for_numbers_past_any_range():
    """dt = "1e400" and a 400-digit step count overflowed the estimate before the scene's
    own checks could name the field (an internal error, exit 70)."""
    assert tier.estimate("rest", ['dt="1e400"']) is None
    assert tier.estimate("rest", ["steps=1e300", "generate.count=1e300"]) is None
    # a count past a float is no count: the estimate falls back to the file's own duration
    assert tier.estimate("rest", ["steps=" + "9" * 400]) == tier.estimate("rest")
    from typer.testing import CliRunner

    from physdbg.cli import app

    for override, field in (('dt="1e400"', "'dt'"), ("steps=" + "9" * 400, "'steps'")):
        result = CliRunner().invoke(app, ["run", "rest", "-s", override])
        assert result.exit_code == 2 and f"field {field}" in result.output, result.output


_CLONE_PROGRAM = """
import json, sys
from physdbg.engine.toi import pair_toi_swept_scalar as kernel
kernel(1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0, 0.0, 1.0, 1e-12)
import physdbg.tier as tier
print(json.dumps({"hits": sum(kernel.stats.cache_hits.values()), "misses": sum(kernel.stats.cache_misses.values()),
                  "path": kernel._cache._cache_path, "warm": tier.cache_is_warm()}))
"""


@pytest.mark.slow
def test_a_second_clone_of_the_same_version_loads_the_first_clone_s_kernels(tmp_path):
    """numba filed cached kernels under a hash of the checkout's absolute folder, so a second
    clone of one version found nothing to load and compiled for 40 s in the foreground; the
    kernels are now filed by their path inside the package (engine/jit.py)."""
    import shutil
    from pathlib import Path

    import physdbg

    source = Path(physdbg.__file__).parent
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    found = []
    for clone in ("first", "second"):
        shutil.copytree(source, tmp_path / clone / "physdbg", ignore=shutil.ignore_patterns("__pycache__"))
        done = subprocess.run([sys.executable, "-c", _CLONE_PROGRAM], cwd=tmp_path / clone, env=env,
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        found.append(json.loads(done.stdout.strip().splitlines()[-1]))
    first, second = found
    assert first["misses"] == 1 and first["hits"] == 0  # compiled, and cached
    assert second["misses"] == 0 and second["hits"] == 1, second  # loaded, not compiled again
    assert first["path"] == second["path"] and first["path"].endswith("physdbg_engine")
