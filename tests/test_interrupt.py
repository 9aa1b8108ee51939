"""Time is bounded like memory: Ctrl-C ends any run within a second, and a hostile dt or
speed finishes (or is refused) in seconds (physdbg/interrupt.py, World.request_stop, the
sized held-contact budget)."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time

import pytest

from physdbg import api, open_recording
from physdbg.api import load_scene
from physdbg.errors import StepStopped

# 20 spheres at 10⁶ m/s in the rain box, with the held-contact budget of a big pile: each
# step spends ~10 s in hopeless held-contact solves inside compiled code
# (the rapid-contact rule's held contacts make the long solves: on, as a scene may ask)
LONG_STEPS = ["generate.count=20", "generate.speed=1e6", "steps=7", "max_resting_work_per_step=1000000000",
              "rapid_contact_time=1e-4"]


def test_a_world_asked_to_stop_from_another_thread_stops_mid_step_at_once():
    """The compiled solves release the GIL and read the stop switch as they go."""
    world = load_scene("rain", LONG_STEPS).build_world()
    threading.Timer(0.5, world.request_stop).start()
    started = time.perf_counter()
    with pytest.raises(StepStopped, match="stopped in step 1"):
        world.step(1 / 120)
    assert time.perf_counter() - started < 1.5
    with pytest.raises(StepStopped):  # and it stays stopped
        world.step(1 / 120)


@pytest.mark.slow
def test_ctrl_c_ends_a_recording_in_a_long_step_within_a_second(tmp_path):
    out = tmp_path / "long.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "physdbg", "record", "rain", *sum((["-s", o] for o in LONG_STEPS), []),
                             "-o", str(out), "--no-rrd"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.perf_counter() + 120
    while not (out.exists() and out.stat().st_size > 0) and time.perf_counter() < deadline:
        time.sleep(0.05)  # the recorder has written frame 0: the first (~10 s) step is under way
    time.sleep(1.0)
    assert proc.poll() is None
    started = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert time.perf_counter() - started < 1.0
    assert proc.returncode == 130 and "Traceback" not in err
    assert f"{out} holds the initial state only (no step was completed)" in err
    with open_recording(out) as rec:  # closed properly: whole, with its summary
        assert rec.steps == 0 and not rec.truncated


def test_a_gas_stepped_a_million_seconds_at_a_time_finishes_in_seconds():
    """Every sphere crosses the box ~10⁶ times a step: the contact budget stops each step
    (a warning says so) instead of the run taking minutes."""
    started = time.perf_counter()
    summary = api.run("gas", ["dt=1e6", "steps=3"])
    assert time.perf_counter() - started < 10.0
    assert summary.steps == 3 and summary.warning_counts == {"max_contacts_per_step": 3}


def test_the_held_contact_budget_is_sized_to_the_scene():
    """A fixed 10⁹ updates let 20 spheres spend ~10 s a step; sized, 10⁶ a sphere from 10⁷."""
    settings = load_scene("rain").settings
    assert settings.max_resting_work_per_step == 0
    assert settings.budget("max_resting_work_per_step", 5) == 10_000_000
    assert settings.budget("max_resting_work_per_step", 20) == 20_000_000
    assert settings.budget("max_resting_work_per_step", 500) == 500_000_000
    assert settings.budget("max_resting_work_per_step", 100_000) == 1_000_000_000
    started = time.perf_counter()
    summary = api.run("rain", ["generate.count=20", "generate.speed=1e6", "steps=7"])
    assert time.perf_counter() - started < 15.0 and summary.steps == 7
