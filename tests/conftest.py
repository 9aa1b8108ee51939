"""Shared helpers: small worlds built directly from arrays."""

from __future__ import annotations

import os

# The suite compiles the kernels itself (pytest_sessionstart): a physdbg process it starts
# must not start a background compile of its own (physdbg/tier.py) that would outlive it
# and take a core from the tests. Tests of the tiers set PHYSDBG_COMPILE themselves.
os.environ.setdefault("PHYSDBG_COMPILE", "now")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings as hypothesis_settings  # noqa: E402

# Hypothesis draws: in CI (CI set) the same draw every run, so a failure there is the code's,
# not the draw's, and repeats; in development a new draw each run, to find what CI's misses.
# HYPOTHESIS_PROFILE=ci|dev picks one by hand.
hypothesis_settings.register_profile("ci", derandomize=True, print_blob=True)
hypothesis_settings.register_profile("dev", print_blob=True)
hypothesis_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") else "dev"))

from physdbg.engine import Settings, State, Walls, World  # noqa: E402
from physdbg.observe import ListObserver  # noqa: E402


def pytest_sessionstart(session):
    """Compile the kernels once, before the first test, on two cores when the cache is
    cold and two are free (physdbg.precompile: ~37 s instead of ~70 s here), rather than
    in the first tests that use them, one by one in this process."""
    from physdbg.precompile import compile_kernels

    compile_kernels("grid", sleeping=True)


@pytest.fixture(scope="session")
def package_registry():
    """For a test that installs packages (mark ``registry``): skip it, saying why, where pip
    can fetch nothing here (no network, no mirror, no wheel folder); under CI, which
    promises a registry (README command 2 installs from it), fail instead of skipping."""
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as folder:  # the smallest thing pip can be asked: one pure wheel, no deps
        done = subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--quiet", "--dest", folder,
                               "--timeout", "20", "--retries", "1", "iniconfig"], capture_output=True, text=True,
                              timeout=120)
    if done.returncode != 0:
        why = (done.stderr.strip().splitlines() or ["no answer"])[-1]
        message = f"pip can fetch no package here (a registry, a mirror or a wheel folder): {why}"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)


MAX_AUTO_WORKERS = 4  # a worker holds ~0.5 GB (numba and the kernels) before its tests use any


def pytest_xdist_auto_num_workers(config):
    """``-n auto``: one worker per CPU this process may use (its affinity, as
    physdbg.precompile counts them, not the host's cores that psutil would count in a
    container), at most MAX_AUTO_WORKERS: beyond that the README test's fresh venv
    (about 2 min, one worker) bounds the suite's time, and the workers' memory would only
    grow. PYTEST_XDIST_AUTO_NUM_WORKERS, when set, decides instead (xdist's own rule)."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None
    from physdbg.precompile import usable_cpus

    return max(1, min(usable_cpus(), MAX_AUTO_WORKERS))


def pytest_collection_modifyitems(config, items):
    """For pytest-xdist (pyproject's addopts: ``-n auto --dist loadgroup``): the slow tests
    first, so that the last test a worker takes is a short one and the workers end
    together; every test that opens the native Rerun viewer (it asks for
    ``virtual_display``) on one worker, one at a time: a viewer started while another
    listens on rerun's port hands its file to that one, and one Xvfb display is enough.
    Every worker collects the same items in the same order, as xdist requires. In one
    process (``-n 0``) the marks do nothing and only the order changes."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)  # stable: file order within each tier
    for item in items:
        if "virtual_display" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.xdist_group("viewer"))


def make_state(positions, velocities=None, *, radius=0.1, inverse_mass=1.0, restitution=1.0, gravity_scale=1.0):
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    n = len(positions)
    velocities = np.zeros((n, 3)) if velocities is None else np.asarray(velocities, dtype=float).reshape(-1, 3)

    def per(value):
        return np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()

    return State(positions, velocities, per(inverse_mass), per(radius), per(restitution), per(gravity_scale))


def make_walls(*planes):
    """planes: (normal, offset, restitution[, two_sided])."""
    names, normals, offsets, rest, two = [], [], [], [], []
    for k, plane in enumerate(planes):
        normal, offset, e = plane[:3]
        n = np.asarray(normal, dtype=float)
        names.append(f"w{k}")
        normals.append(n / np.linalg.norm(n))
        offsets.append(offset)
        rest.append(e)
        two.append(plane[3] if len(plane) > 3 else False)
    return Walls(names, np.array(normals).reshape(-1, 3), np.array(offsets, dtype=float),
                 np.array(rest, dtype=float), np.array(two, dtype=bool), np.zeros(len(planes)))


def make_world(state, walls=None, observe=True, **settings):
    observer = ListObserver() if observe else None
    world = World(state, walls if walls is not None else make_walls(), Settings(**settings), observer)
    return world, observer


@pytest.fixture
def floor():
    return make_walls(([0, 1, 0], 0.0, 1.0))


@pytest.fixture
def virtual_display():
    """A DISPLAY on a fresh Xvfb screen with the Rerun viewer available; skips, saying why,
    where Xvfb or the viewer is missing (.ci/run installs xvfb and mesa)."""
    import os
    import shutil
    import subprocess
    import time

    from physdbg.record.rerun_sink import viewer_binary

    if shutil.which("Xvfb") is None or shutil.which(viewer_binary()) is None:
        pytest.skip("needs Xvfb and the Rerun viewer (.ci/run installs xvfb and mesa)")
    display = f":{90 + os.getpid() % 150}"
    xvfb = subprocess.Popen(["Xvfb", display, "-screen", "0", "1280x800x24"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    time.sleep(1.0)
    try:
        yield display
    finally:
        xvfb.terminate()
        xvfb.wait(timeout=10)


def nan_in_step(monkeypatch, step_index: int = 2, sphere: int = 1) -> None:
    """Make sphere's velocity NaN as step ``step_index`` (0-based) begins, in every World.
    Validated scenes keep every product finite, so this stands for a NaN that a bug (or a
    foreign state) brings in. monkeypatch.undo() ends it."""
    import math

    from physdbg.engine import World

    original = World.step

    def step(self, dt):
        if self.step_index == step_index:
            self.state.velocities[sphere, 0] = math.nan
        return original(self, dt)

    monkeypatch.setattr(World, "step", step)
