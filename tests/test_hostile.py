"""Hostile input: every scene text and override either runs or gets physdbg's own error
naming the field; resources are bounded before they are spent; each step's work is
budgeted; NaN never passes silently."""

from __future__ import annotations

import math
import re
import string

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from physdbg.api import run
from physdbg.engine import NonFiniteState
from physdbg.errors import NonFiniteRunError, PhysdbgError, SceneError
from physdbg.api import load_scene
from physdbg.scene import FIELDS, parse_scene

from .conftest import make_state, make_world

# ----------------------------------------------------------------------------- generated input
# Values a hostile user types: extremes of every kind, wrong types, deep and huge structures.
EXTREME_NUMBERS = [0, -1, 1, 2**63, 10**100, -10**100, 1e308, -1e308, 5e-324, 1e-310, 1e200, 1e-200,
                   math.inf, -math.inf, math.nan, 0.5, 1e6, 1e-12, 1e12, 4.9e-324, 2**64, 1000000000]
SCALARS = st.one_of(st.sampled_from(EXTREME_NUMBERS), st.integers(), st.floats(allow_nan=True),
                    st.booleans(), st.text(string.printable, max_size=12))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.sampled_from(["x", "min", "radius"]),
                                                                       inner, max_size=3)), max_leaves=12)
KEYS = sorted({f"{table}.{name}" if table != "scene" else name for table, fields in FIELDS.items()
               for name in fields} | {"particles.0.radius", "particles.0.mass", "particles.0.velocity",
                                      "planes.0.normal", "dt.x", "dt.1.x", "box.min.0", "generate.count.x"})
SCENES = ["bounce", "cradle", "gas", "rain", "bullet-wall"]
# What every generated run may use: small budgets, so that a hostile value is refused or
# hits a budget in milliseconds instead of running for minutes.
BOUNDS = ["max_particle_steps=3000", "max_memory=2e7", "max_pairs_per_step=20000",
          "max_swept_tests_per_step=50000", "max_resting_work_per_step=20000", "max_events_per_step=2000"]


def _toml_value(value) -> str:
    """A TOML literal for a generated value (inf and nan included, as TOML allows)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"


def _outcome(scene: str, overrides: list[str]):
    """Run the scene for at most 3 steps under the bounds; return what happened."""
    try:
        loaded = load_scene(scene, overrides + BOUNDS)
        steps = min(loaded.steps or 3, 3)
        return run(loaded, dts=[loaded.dt or 0.01] * steps)
    except SceneError as err:
        assert err.field or err.source, err  # names where
        assert "\n" not in str(err)
        return err
    except NonFiniteRunError as err:
        assert "sphere" in str(err) and "step" in str(err)
        return err
    except PhysdbgError as err:
        return err


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scene=st.sampled_from(SCENES), key=st.sampled_from(KEYS), value=VALUES)
def test_any_override_runs_or_names_the_field(scene, key, value):
    outcome = _outcome(scene, [f"{key}={_toml_value(value)}"])
    if isinstance(outcome, SceneError):
        assert outcome.field, outcome


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(fields=st.dictionaries(st.sampled_from(sorted(FIELDS["scene"]) + ["dt", "steps"]), VALUES, max_size=6),
       particle=st.dictionaries(st.sampled_from(sorted(FIELDS["particles"])), VALUES, max_size=4))
def test_any_scene_text_runs_or_names_the_field(fields, particle):
    lines = ["dt = 0.01", "steps = 2"] + [f"{k} = {_toml_value(v)}" for k, v in fields.items()
                                          if k not in ("particles", "planes", "box", "generate")]
    lines += ["[[particles]]", "position = [0, 1, 0]", "radius = 0.1"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in particle.items() if k not in ("position", "radius")]
    text = "\n".join(dict.fromkeys(lines))  # a repeated key is invalid TOML; keep the first
    try:
        scene = parse_scene(text, "hostile.toml", BOUNDS)
    except SceneError as err:
        assert "hostile.toml" in str(err)
        return
    try:
        run(scene, dts=[scene.dt or 0.01] * min(scene.steps or 2, 2))
    except NonFiniteRunError:
        pass


@pytest.mark.parametrize("override, field, words", [
    ("dt.x=1", "dt.x", "'dt' is a value"),
    ("dt.1.x=2", "dt.1.x", "'dt' is a value"),
    (f"steps={10**100}", "steps", "<= 1e+12"),
    ('dt="1e400"', "dt", "between 1e-12 and 1e+12"),
    ("duration=1e10", "max_particle_steps", "particle-steps"),
    ("generate.count=1000000000", "max_memory", "GiB"),
    ("generate.count=10000000", "max_memory", "--set max_memory="),
    ("samples=18446744073709551616", "samples", "<= 1000"),
    ("gravity=[0, 1e200, 0]", "gravity", "1e+12"),
    ("planes.0.normal=[1e200, 0, 0]", "planes.0.normal", "1e+12"),
    ("particles.0.mass=1e-310", "particles.0.mass", ">= 1e-12"),
    ("particles.0.gravity_scale=1e308", "particles.0.gravity_scale", "<= 1e+12"),
    ("particles.0.radius=4.9e-324", "particles.0.radius", ">= 1e-12"),
    ("rest_speed=1e308", "rest_speed", "rest_fraction"),
    ("v=" + "[" * 1000 + "]" * 1000, "v", ""),
])
def test_the_classes_found_are_refused_with_the_field(override, field, words):
    scene = "rain" if override.startswith("generate") else "bounce"
    with pytest.raises(SceneError) as info:
        load_scene(scene, [override])
    assert f"'{field}" in str(info.value) and words in str(info.value)


@pytest.mark.parametrize("inverse_mass", ["1e-300", "5e-324", "9.9e-13"])
def test_an_inverse_mass_past_the_mass_bound_is_refused_with_the_field(inverse_mass):
    """A mass of 1e300 kg given as its inverse was taken: the run's momentum then overflowed
    numpy's norm (a RuntimeWarning on the user's terminal; 5e-324, the division). The
    inverse is held to the bounds mass has; 0 (immovable) and the bounds themselves pass."""
    text = "dt = 0.01\nsteps = 2\n[[particles]]\nposition = [0, 1, 0]\nradius = 0.1\ninverse_mass = {}\n"
    with pytest.raises(SceneError) as info:
        parse_scene(text.format(inverse_mass), "heavy.toml", BOUNDS)
    assert ("heavy.toml" in str(info.value) and "'particles.0.inverse_mass'" in str(info.value)
            and "expected 0 (immovable) or a number >= 1e-12 and <= 1e+12" in str(info.value))
    for fine in ("0", "1e-12", "1e12"):
        scene = parse_scene(text.format(fine), "heavy.toml", BOUNDS)
        assert scene.state.inverse_mass.tolist() == [float(fine)]


def test_a_deeply_nested_scene_file_is_refused(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("dt = 0.01\nsteps = 1\nx = " + "[" * 1000 + "]" * 1000 + "\n")
    with pytest.raises(SceneError, match="nested more deeply"):
        load_scene(str(path))


@pytest.mark.parametrize("key", ["a" + ".a" * 100_000 + " = 1", "[" + ".".join(["a"] * 100_000) + "]",
                                 '"a".' * 50_000 + "b = 1"])
def test_a_dotted_key_deeper_than_any_field_is_refused_before_parsing(tmp_path, key):
    """Python's TOML parser keeps every prefix of a dotted key: 100,000 parts took 23 GB.
    The key is refused by a linear scan before the parser sees it, naming file and line."""
    import time

    path = tmp_path / "deep.toml"
    path.write_text("dt = 0.01\nsteps = 1\n" + key + "\n")
    started = time.perf_counter()
    with pytest.raises(SceneError) as info:
        load_scene(str(path))
    assert time.perf_counter() - started < 1.0
    assert str(info.value) == (f"{path}: a dotted key on line 3 has more parts than any scene field (at most 6): "
                               f"not read")


def test_dots_in_values_strings_and_comments_are_not_keys():
    text = ('description = "a.b.c.d.e.f.g.h.i.j"  # and.so.on.and.so.on.and.so.on\n'
            "dt = 0.01\nsteps = 1\nrestitution_rule = '''m.i.n.\n.a.b.c.d.e.f.g.h'''\n")
    with pytest.raises(SceneError) as info:
        parse_scene(text, "dots.toml")
    assert "field 'restitution_rule'" in str(info.value)  # refused for its value, not as a deep key


def test_a_number_longer_than_python_reads_is_a_scene_error():
    with pytest.raises(SceneError, match="a number of more than 4300 digits: not read"):
        parse_scene("dt = 0.01\nsteps = " + "1" * 5000 + "\n", "long.toml")


def test_a_tiny_plane_normal_is_normalised_not_zeroed():
    scene = load_scene("bounce", ["planes.0.normal=[0, 1e-200, 0]"])
    assert scene.walls.normals[0].tolist() == [0.0, 1.0, 0.0]


def test_rain_that_does_not_fit_says_what_to_set_and_it_then_fits():
    with pytest.raises(SceneError) as info:
        load_scene("rain", ["generate.count=5000"])
    message = str(info.value)
    assert "set generate.radius to at most" in message and "box.max = " in message
    radius = float(message.split("at most ")[1].split(",")[0])
    assert len(load_scene("rain", ["generate.count=5000", f"generate.radius={radius}"]).state.radius) == 5000
    box = message.split("box.max = ")[1].split(" with")[0]
    assert len(load_scene("rain", ["generate.count=5000", f"box.max={box}"]).state.radius) == 5000


# ----------------------------------------------------------------------------- budgets
def test_spheres_at_one_point_hit_the_pair_budget_not_memory():
    positions = np.full((600, 3), 0.5)
    world, obs = make_world(make_state(positions, radius=0.01), gravity=(0, 0, 0), max_pairs_per_step=1000)
    stats = world.step(0.01)
    assert [w.code for w in stats.warnings] == ["max_pairs_per_step"]
    assert "--set max_pairs_per_step=" in stats.warnings[0].message
    assert stats.counts.swept_tests == 0  # no sphere–sphere tests were spent


def test_the_swept_test_budget_stops_a_step_that_would_run_long():
    scene = load_scene("gas", ["dt=10", "steps=1"])
    world = scene.build_world()
    world.settings.max_swept_tests_per_step = 5000
    stats = world.step(scene.dt)
    assert [w.code for w in stats.warnings] == ["max_swept_tests_per_step"]
    # the budget is checked before each contact, and one contact re-predicts two particles
    assert stats.counts.swept_tests <= 5000 + 2 * (64 + 6)
    assert np.isfinite(world.state.positions).all()


def test_the_resting_work_budget_bounds_the_contact_solve():
    scene = load_scene("rest", ["max_resting_work_per_step=20"])
    world = scene.build_world()
    codes = set()
    for _ in range(30):
        codes |= {w.code for w in world.step(scene.dt).warnings}
    assert "max_resting_work_per_step" in codes


def test_strong_gravity_piles_stay_bounded_and_out_of_the_floor():
    scene = load_scene("rain", ["gravity=[0, -1e6, 0]", "steps=3"])
    world = scene.build_world()
    for _ in range(3):
        stats = world.step(scene.dt)
        assert stats.counts.swept_tests < scene.settings.swept_test_budget(world.state.count)
        assert stats.max_overlap <= scene.settings.contact_tolerance


# ----------------------------------------------------------------------------- NaN
def test_nan_is_reported_at_its_step_and_particle_and_stops_the_run():
    state = make_state([[0, 1, 0], [3, 1, 0]], [[0, 0, 0], [1e300, 0, 0]])
    world, obs = make_world(state, gravity=(0, 0, 0))
    world.step(1.0)
    with pytest.raises(NonFiniteState) as info:
        world.step(1e10)
    assert info.value.particle == 1 and info.value.step == 2 and info.value.field == "position"
    assert [w.code for w in obs.warnings] == ["non-finite"]
    assert obs.events[-1].__class__.__name__ == "StepEnd"  # the step was reported first


def test_a_world_refuses_a_non_finite_start_and_a_bad_dt():
    with pytest.raises(ValueError, match="initial velocity of sphere 0"):
        make_world(make_state([[0, 0, 0]], [[math.nan, 0, 0]]))
    world, _ = make_world(make_state([[0, 1, 0]]))
    with pytest.raises(ValueError, match="step_lengths"):
        world.step(None)


# ----------------------------------------------------------------------------- the gas
def test_a_gas_starts_uniform_not_in_a_corner():
    scene = load_scene("gas", ["generate.count=2000", "generate.packing_fraction=0.3"])
    x = scene.state.positions
    side = -scene.walls.offsets.min()  # the x+, y+, z+ walls sit at -side
    octant = ((x > side / 2).astype(int) * [1, 2, 4]).sum(axis=1)
    counts = np.bincount(octant, minlength=8)
    assert counts.min() > 0.8 * 250 and counts.max() < 1.2 * 250, counts


def test_a_dense_gas_starts_without_hitting_a_budget():
    scene = load_scene("gas", ["generate.count=2000", "generate.packing_fraction=0.3", "steps=3"])
    world = scene.build_world()
    for _ in range(3):
        stats = world.step(scene.dt)
        assert not stats.warnings
        assert stats.max_overlap <= scene.settings.contact_tolerance


@pytest.mark.parametrize("speed", [1e-3, 1.0, 100.0])
def test_an_elastic_gas_keeps_its_energy_at_any_speed(speed):
    scene = load_scene("gas", ["generate.count=200", "generate.packing_fraction=0.2", f"generate.speed={speed}",
                               f"dt={0.01 / speed}", "steps=100"])
    summary = run(scene)
    assert summary.contacts > 100  # it really collided
    assert abs(summary.energy_drift) < 1e-12
    assert summary.held_at_end == 0


def test_the_slow_gas_from_the_issue_keeps_its_energy():
    summary = run("gas", ["generate.count=200", "generate.packing_fraction=0.2", "generate.speed=0.001",
                          "dt=10", "steps=100"])
    assert abs(summary.energy_drift) < 1e-12


# ----------------------------------------------------------------------------- the CLI and files
def _cli(*args):
    from typer.testing import CliRunner

    from physdbg.cli import app

    return CliRunner().invoke(app, list(args))


@pytest.mark.parametrize("args, words", [
    (("record", "bounce", "--bvh-max-nodes", "-5", "--no-rrd"), "--bvh-max-nodes"),
    (("replay", "x.mcap", "--web", "--port", "99999"), "--port"),
])
def test_options_out_of_range_are_refused(args, words):
    result = _cli(*args)
    assert result.exit_code == 2 and words in result.output


def test_a_device_is_never_a_recording_even_with_force():
    result = _cli("record", "bounce", "-o", "/dev/full", "--no-rrd", "--force")
    assert result.exit_code == 2 and "not a regular file" in result.output
    import os

    assert os.path.exists("/dev/full")


def test_dts_beyond_the_range_of_a_dt_are_refused(tmp_path):
    dts = tmp_path / "dts.txt"
    dts.write_text("0.01\n1e300\n")
    result = _cli("run", "bounce", "--dts", str(dts))
    assert result.exit_code == 2 and "entry 2" in result.output and "1e+12" in result.output


def test_a_fifo_is_not_opened_as_a_recording(tmp_path):
    import os

    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    result = _cli("info", str(fifo))  # would block forever if opened
    assert result.exit_code == 2 and "not a regular file" in result.output


def test_a_run_that_turns_nan_exits_3_and_leaves_a_readable_recording(tmp_path, monkeypatch):
    from physdbg import open_recording

    from .conftest import nan_in_step

    nan_in_step(monkeypatch)  # sphere 1's velocity turns NaN as step 3 begins
    out = tmp_path / "cradle.mcap"
    result = _cli("record", "cradle", "-s", "steps=10", "-o", str(out), "--no-rrd")
    assert result.exit_code == 3, result.output
    assert "of sphere 1 became NaN or infinite in step 3" in result.output
    assert "is readable and holds steps 1..3" in result.output
    with open_recording(out) as rec:
        assert rec.steps == 3
        assert np.isnan(rec.state(3).velocities[1]).any() and np.isfinite(rec.state(2).velocities).all()


def test_a_full_disk_ends_the_recording_readable_with_a_message(tmp_path):
    import subprocess
    import sys

    script = ("import resource, signal, sys\n"
              "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # past the limit writes fail, as on a full disk\n"
              "resource.setrlimit(resource.RLIMIT_FSIZE, (1500000, 1500000))\n"
              "from physdbg.cli import app\n"
              "app(sys.argv[1:])\n")
    out = tmp_path / "full.mcap"
    done = subprocess.run([sys.executable, "-c", script, "record", "rain", "-s", "generate.count=300",
                           "-s", "steps=400", "-o", str(out), "--no-rrd", "--no-progress"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert "writing the recording failed" in done.stderr and "is readable and holds steps 1.." in done.stderr
    from physdbg import open_recording

    with open_recording(out) as rec:
        steps = int(done.stderr.split("holds steps 1..")[1].split()[0])
        assert rec.steps == steps > 0 and rec.truncated


def test_two_recordings_of_one_scene_are_two_rerun_recordings_with_readable_names(tmp_path):
    from physdbg.record.header import RecordingHeader
    from physdbg.api import load_scene

    a = RecordingHeader.from_scene(load_scene("cradle", ["ordering=index"]))
    b = RecordingHeader.from_scene(load_scene("cradle"))
    assert a.meta["run_id"] != b.meta["run_id"]
    assert a.run_name.startswith("cradle ordering=index 20")


def test_a_wall_name_with_a_space_is_escaped_in_the_rerun_file(tmp_path):
    scene = tmp_path / "thin.toml"
    scene.write_text('dt = 0.1\nsteps = 2\n[[planes]]\nname = "thin wall"\nnormal = [1, 0, 0]\noffset = 1\n'
                     'two_sided = true\n[[particles]]\nposition = [0, 0, 0]\nvelocity = [5, 0, 0]\nradius = 0.1\n')
    out = tmp_path / "thin.mcap"
    result = _cli("record", str(scene), "-o", str(out))
    assert result.exit_code == 0, result.output
    from rerun.chunk import RrdReader

    paths = {str(chunk.entity_path) for chunk in RrdReader(out.with_suffix(".rrd")).stream()}
    assert "/world/walls/thin\\ wall" in paths, paths


def test_run_json_and_info_json_give_walls_the_same_shape(tmp_path):
    import json

    ran = json.loads(_cli("run", "cradle", "--json", "-s", "steps=2").output)
    _cli("record", "cradle", "-s", "steps=2", "-o", str(tmp_path / "c.mcap"), "--no-rrd")
    info = json.loads(_cli("info", str(tmp_path / "c.mcap"), "--json").output)
    assert ran["walls"] == info["walls"] and isinstance(ran["walls"], list)


def test_warnings_are_totalled_per_kind_with_one_step_number_each():
    result = _cli("run", "rain", "-s", "generate.count=300", "-s", "steps=4", "-s", "max_events_per_step=5")
    assert result.exit_code == 0
    line = next(line for line in result.output.splitlines() if line.startswith("warnings"))
    assert "max_events_per_step" in line
    total = int(line.split()[1])
    assert total >= 4
    examples = [line for line in result.output.splitlines() if line.startswith("  step ")]
    assert examples and all(len(re.findall(r"step \d+", line)) == 1 for line in examples)


@pytest.mark.parametrize("phi", ["5e-324", "1e-40"])
def test_a_packing_fraction_that_makes_the_box_too_big_is_refused_with_the_least(phi):
    """5e-324 made the box's side infinite and ended in an internal error (exit 70)."""
    with pytest.raises(SceneError) as info:
        load_scene("gas", [f"generate.packing_fraction={phi}"])
    assert "field 'generate.packing_fraction'" in str(info.value) and "give at least 3.35e-38" in str(info.value)


def test_a_full_disk_under_the_rerun_file_is_said_and_never_hangs(tmp_path):
    """The .rrd fills the disk first (it is larger than a --detail state MCAP): rerun's own
    file writer only logs the failure, and its flush (and its exit hook) then waited
    forever. The flush is bounded by the file's growth, and the dead stream abandoned."""
    import subprocess
    import sys

    script = ("import resource, signal, sys\n"
              "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # past the limit writes fail, as on a full disk\n"
              "resource.setrlimit(resource.RLIMIT_FSIZE, (500000, 500000))\n"
              "from physdbg.cli import app\n"
              "app(sys.argv[1:])\n")
    out = tmp_path / "full.mcap"
    done = subprocess.run([sys.executable, "-c", script, "record", "rain", "-s", "steps=100", "-o", str(out),
                           "--detail", "state", "--no-view", "--no-progress"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert f"the Rerun file {tmp_path / 'full.rrd'} could not be written (" in done.stderr
    assert "is the disk full? It holds only what was written before" in done.stderr
    assert "full.mcap is readable and holds steps 1.." in done.stderr
