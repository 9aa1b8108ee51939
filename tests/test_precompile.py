"""physdbg.precompile: the kernels compiled on two processes when the cache is cold."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from physdbg import precompile
from physdbg.engine.warm import warm_up_without_forces


def test_a_warm_cache_starts_no_helper(monkeypatch):
    """The suite's session start compiled everything: no second process is worth starting."""
    started = []
    monkeypatch.setattr(precompile, "start_helper", lambda audit=False: started.append(1))
    assert not precompile.cache_is_cold()
    assert precompile.compile_kernels("grid", sleeping=True) < 30.0
    assert started == []


def test_a_cold_cache_with_two_cpus_compiles_the_held_solve_in_a_helper(monkeypatch):
    """The order of the work: the helper starts, this process compiles the rest of the
    step, waits for the helper, then runs the whole warm-up (which loads everything)."""
    calls = []

    class Helper:
        returncode = None  # running until waited for

        def wait(self, timeout=None):
            calls.append(f"helper waited for (at most {timeout} s)")
            self.returncode = 0

        def poll(self):
            return self.returncode

    monkeypatch.setattr(precompile, "cache_is_cold", lambda: True)
    monkeypatch.setattr(precompile, "usable_cpus", lambda: 2)
    monkeypatch.setattr(precompile, "start_helper",
                        lambda audit=False: calls.append(f"helper started, audit {audit}") or Helper())
    import physdbg.analysis.audit as audit
    import physdbg.engine.warm as world

    monkeypatch.setattr(world, "warm_up_without_forces", lambda bp: calls.append(f"without forces {bp}"))
    monkeypatch.setattr(world, "warm_up", lambda bp, sleeping, meshes=False, calendar=False: calls.append(f"warm up {bp} {sleeping}"))
    monkeypatch.setattr(audit, "warm_up", lambda: calls.append("checker"))
    precompile.compile_kernels("grid", sleeping=True)
    assert calls == ["helper started, audit False", "without forces grid",
                     f"helper waited for (at most {precompile.HELPER_TIMEOUT} s)", "warm up grid True"]
    calls.clear()
    # an audited run: the helper compiles the checker after the held solve; this process
    # then loads it (or compiles what the helper did not)
    precompile.compile_kernels("grid", sleeping=True, audit=True)
    assert calls == ["helper started, audit True", "without forces grid",
                     f"helper waited for (at most {precompile.HELPER_TIMEOUT} s)", "warm up grid True", "checker"]
    assert precompile.helper_command(audit=True)[-1].endswith(
        "warm_up_held_solve(); from physdbg.analysis.audit import warm_up; warm_up()")


def test_one_cpu_or_parallel_off_means_one_process(monkeypatch):
    monkeypatch.setattr(precompile, "cache_is_cold", lambda: True)
    monkeypatch.setattr(precompile, "start_helper", lambda audit=False: (_ for _ in ()).throw(AssertionError("no helper")))
    monkeypatch.setattr(precompile, "usable_cpus", lambda: 1)
    precompile.compile_kernels()
    monkeypatch.setattr(precompile, "usable_cpus", lambda: 2)
    precompile.compile_kernels(parallel=False)


def test_an_interrupted_compile_kills_the_helper(monkeypatch):
    """Ctrl-C while this process compiles: the helper does not outlive the call."""
    helper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    monkeypatch.setattr(precompile, "cache_is_cold", lambda: True)
    monkeypatch.setattr(precompile, "usable_cpus", lambda: 2)
    monkeypatch.setattr(precompile, "start_helper", lambda audit=False: helper)
    import physdbg.engine.warm as world

    def interrupted(bp):
        raise KeyboardInterrupt

    monkeypatch.setattr(world, "warm_up_without_forces", interrupted)
    try:
        precompile.compile_kernels()
    except KeyboardInterrupt:
        pass
    assert helper.poll() is not None


def test_a_stuck_helper_is_killed_and_the_compile_goes_on(monkeypatch):
    """A helper that never ends does not hang the run: after HELPER_TIMEOUT it is killed and
    this process finishes the warm-up itself."""
    helper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    monkeypatch.setattr(precompile, "HELPER_TIMEOUT", 0.5)
    monkeypatch.setattr(precompile, "cache_is_cold", lambda: True)
    monkeypatch.setattr(precompile, "usable_cpus", lambda: 2)
    monkeypatch.setattr(precompile, "start_helper", lambda audit=False: helper)
    assert precompile.compile_kernels() < 30.0
    assert helper.poll() is not None


@pytest.mark.slow
def test_the_helper_program_and_this_process_s_part_run_on_a_warm_cache():
    """The helper's program itself, on the warm cache (it loads, so it is quick), exits 0;
    this process's part runs too, and a warm-up after them takes a finite time."""
    done = subprocess.run(precompile.helper_command(), capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    warm_up_without_forces("grid")
    assert np.isfinite(precompile.compile_kernels("grid"))


def test_the_helper_compiles_this_physdbg_whatever_the_working_folder_holds(tmp_path):
    """A folder named physdbg where the helper starts (a checkout of another version, say)
    or on PYTHONPATH is not what it imports: it is told where this physdbg lives."""
    (tmp_path / "physdbg").mkdir()
    (tmp_path / "physdbg" / "__init__.py").write_text("raise SystemExit('the wrong physdbg')\n")
    program = precompile.helper_command()[-1].replace("warm_up_held_solve()", "print(__import__('physdbg').__file__)")
    done = subprocess.run(precompile.helper_command()[:-1] + [program], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, env={**os.environ, "PYTHONPATH": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == precompile.__file__.replace("precompile.py", "__init__.py")


@pytest.mark.slow
def test_the_helper_fills_an_empty_cache_with_the_held_solve(tmp_path):
    """The real thing, once: the helper's program compiles into an empty cache folder, and
    a process started afterwards finds the held solve and the resting solve there (so the
    main process's warm-up loads them instead of compiling them). About half a minute."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    check = ("from physdbg.precompile import cache_is_cold; from physdbg.engine.resting import solve_contacts; "
             "print(cache_is_cold(), bool(solve_contacts._cache._cache_file._load_index()))")
    assert subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True,
                          check=True).stdout.strip() == "True False"
    subprocess.run(precompile.helper_command(), env=env, check=True, timeout=600)
    assert subprocess.run([sys.executable, "-c", check], env=env, capture_output=True, text=True,
                          check=True).stdout.strip() == "False True"
    # filled for this CPU: on another CPU model (as numba names it) the same folder is cold
    other_cpu = {**env, "NUMBA_CPU_NAME": "k8", "NUMBA_CPU_FEATURES": ""}
    assert subprocess.run([sys.executable, "-c", check], env=other_cpu, capture_output=True, text=True,
                          check=True).stdout.strip() == "True True"


def test_an_audited_run_loads_no_kernel_after_compile_kernels(monkeypatch):
    """compile_kernels(audit=True) loads the audit's step checker too: with compiling and
    loading turned off afterwards, an audited run with contacts still finds a version of
    every kernel (else ~11 s of a cold cache went to its first step, counted as the
    audit's time a step)."""
    import gc

    from numba.core.registry import CPUDispatcher

    from physdbg import api

    precompile.compile_kernels("grid", sleeping=True, audit=True)
    for kernel in [k for k in gc.get_objects() if isinstance(k, CPUDispatcher)]:
        monkeypatch.setattr(kernel, "_can_compile", False)
    summary = api.run("rain", ["steps=20", "generate.count=40", "broad_phase=grid"], audit=True)
    assert summary.contacts > 0
