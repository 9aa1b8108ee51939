"""Adding an integrator or a collider kind (docs/colliders.md, "Adding an integrator or a
collider kind"): a dummy of each, added where the docs say, is handled by every table and
reader; one left out of a table, or met in a recording this physdbg does not know, is
refused with a message that says what is missing."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import events
from physdbg.cli import app
from physdbg.engine import colliders, motion

from . import tamper


def _as_if_in_the_source(monkeypatch, module, name: str, value) -> None:
    """Give ``module.name`` a new value everywhere physdbg bound it (``from x import name``
    copies the binding): what editing the table in its source does."""
    import sys

    old = getattr(module, name)
    for other in list(sys.modules.values()):
        if getattr(other, "__name__", "").startswith("physdbg") and getattr(other, name, None) is old:
            monkeypatch.setattr(other, name, value)


# ----------------------------------------------------------------------------- integrators
def test_an_integrator_without_its_row_in_a_table_is_refused_naming_every_such_table():
    names = (*motion.INTEGRATOR_NAMES, "dummy")
    with pytest.raises(ValueError) as raised:
        motion.check_integrator_tables(names)
    message = str(raised.value)
    assert "5 integrators (euler, semi-implicit, verlet, exact, dummy)" in message
    for table in motion.INTEGRATOR_TABLES:
        assert f"{table} has 4 rows" in message
    assert 'docs/colliders.md, "Adding an integrator or a collider kind"' in message


@pytest.fixture
def dummy_integrator(monkeypatch):
    """A fifth integrator, "dummy", with Verlet's row in every table of motion.py (what
    docs/colliders.md says a new integrator adds there), as every reader sees the tables."""
    import physdbg.advisor  # noqa: F401  (the readers, loaded before their tables change)
    import physdbg.analysis.charts  # noqa: F401
    import physdbg.analysis.departure  # noqa: F401
    import physdbg.scene  # noqa: F401

    names = (*motion.INTEGRATOR_NAMES, "dummy")
    tables = {name: (*rows, rows[motion.VERLET]) for name, rows in motion.INTEGRATOR_TABLES.items()}
    motion.check_integrator_tables(names, tables)  # every table has its row
    _as_if_in_the_source(monkeypatch, motion, "INTEGRATOR_NAMES", names)
    for name, rows in tables.items():
        _as_if_in_the_source(monkeypatch, motion, name, rows)
    return "dummy"


def test_a_new_integrator_with_its_rows_is_handled_by_every_reader_of_the_tables(dummy_integrator):
    from physdbg.advisor import advise
    from physdbg.analysis.charts import marker_of
    from physdbg.analysis.departure import family_of, integrator_of
    from physdbg.api import load_scene

    # the charts give it a marker of its own, check-run knows how it moves
    assert marker_of("dummy") not in {marker_of(name) for name in ("euler", "semi-implicit", "verlet", "exact")}
    assert family_of("dummy") == family_of("verlet") == "exact"
    assert integrator_of("explicit-euler") == "euler" and integrator_of(None) == "exact"
    # the advisor judges it by its row (exact under gravity alone, like Verlet)
    predictions = {p.value: p for p in advise(load_scene("bounce")).predictions if p.setting == "integrator"}
    assert predictions["dummy"].outcome == predictions["verlet"].outcome == "safe"
    # a scene may name it
    from physdbg.scene import parse_scene

    assert parse_scene('integrator = "dummy"\ndt = 0.01\nsteps = 1\n').settings.integrator == "dummy"


def test_a_recording_made_with_an_integrator_this_physdbg_lacks_is_refused_clearly(tmp_path):
    runner = CliRunner()
    recorded = tmp_path / "bounce.mcap"
    assert runner.invoke(app, ["record", "bounce", "-s", "steps=60", "-o", str(recorded), "--no-rrd"]).exit_code == 0
    newer = tamper.with_setting(recorded, tmp_path / "newer.mcap", "integrator", "leapfrog")
    done = runner.invoke(app, ["explain", str(newer)])
    assert done.exit_code == 2, done.output
    assert "the run's integrator 'leapfrog' is not one this physdbg has (euler, semi-implicit, verlet, exact)" \
        in done.output


# ----------------------------------------------------------------------------- collider kinds
def test_a_collider_kind_without_its_module_is_refused_naming_it():
    with pytest.raises(ValueError) as raised:
        colliders.check_kind_modules((*events.KIND_NAMES, "capsule"))
    message = str(raised.value)
    assert "4 collider kinds in the table (sphere, wall, mesh, capsule) but 3 modules" in message
    assert "no module for 3 capsule" in message and 'docs/colliders.md, "Adding an integrator or a collider kind"' in message
    colliders.check_kind_modules()  # the engine's own table and modules agree


@pytest.fixture
def contact_of_kind_3(tmp_path):
    """A recording of bounce whose first contact is of collider kind 3 (one more than the table has)."""
    recorded = tmp_path / "bounce.mcap"
    done = CliRunner().invoke(app, ["record", "bounce", "-s", "steps=120", "-o", str(recorded), "--no-rrd"])
    assert done.exit_code == 0, done.output
    from physdbg import open_recording

    with open_recording(recorded) as rec:
        frame = next(k for k in range(1, rec.frames) if len(rec.contacts(k)))
    return recorded, tamper.edit_contact(recorded, tmp_path / "kind3.mcap", frame, kind=3), frame


def test_a_recording_with_a_kind_this_physdbg_does_not_know_is_refused_by_every_reader(contact_of_kind_3, tmp_path):
    recorded, changed, _ = contact_of_kind_3
    runner = CliRunner()
    for command in (["explain", str(changed)], ["diff", str(recorded), str(changed)],
                    ["replay", str(changed), "--rrd", str(tmp_path / "kind3.rrd")]):
        done = runner.invoke(app, command)
        assert done.exit_code == 2, (command, done.output)
        assert "a contact or swept test of collider kind 3, which this physdbg does not know (its kinds: 0 sphere, " \
               "1 wall, 2 mesh)" in done.output, command


def test_a_new_kind_in_the_table_is_handled_by_every_reader(contact_of_kind_3, tmp_path, monkeypatch):
    """With "dummy" (an immovable partner, like a wall) in the table, the readers take the
    kind-3 contact: they ask the table, not for a kind, and name it by its row (and by
    number, having no names of its own)."""
    import physdbg.analysis.audit  # noqa: F401  (the readers, loaded before the table changes)
    import physdbg.analysis.departure  # noqa: F401
    import physdbg.analysis.diff  # noqa: F401
    import physdbg.record.rerun_sink  # noqa: F401
    from physdbg.record import open_recording

    _as_if_in_the_source(monkeypatch, events, "KIND_NAMES", (*events.KIND_NAMES, "dummy"))
    _as_if_in_the_source(monkeypatch, events, "PARTNER_IS_SPHERE", (*events.PARTNER_IS_SPHERE, False))
    monkeypatch.setattr(events, "_PARTNER_IS_SPHERE", np.array(events.PARTNER_IS_SPHERE, dtype=bool))
    recorded, changed, frame = contact_of_kind_3

    with open_recording(changed, verify=False) as rec:
        contact = rec.contacts(frame).record(0)
        assert contact.kind == 3 and contact.velocity_b_before is None  # an immovable partner has no velocity
        assert events.partner_words(contact.kind, contact.other, rec.header.walls.partner_names()) == "dummy #0"
        assert events.collision_sums(rec.contacts(frame), rec.header.radius).collisions == 0
    runner = CliRunner()
    for command in (["explain", str(changed)], ["diff", str(recorded), str(changed)],
                    ["replay", str(changed), "--rrd", str(tmp_path / "kind3.rrd")], ["info", str(changed)]):
        done = runner.invoke(app, command)
        assert done.exception is None or isinstance(done.exception, SystemExit), (command, done.output)
        assert done.exit_code in (0, 1), (command, done.output)
    # the diff sees the contacts differ and names the new partner by its row
    done = runner.invoke(app, ["diff", str(recorded), str(changed)])
    assert done.exit_code == 1 and "dummy #0" in done.output, done.output


def test_a_kind_with_no_branch_in_the_switch_is_refused_at_its_first_use_never_run_as_another():
    """Every function of the collider switch names each kind it handles; a fourth kind (in
    the table, say, but not yet in the switch) raises UNKNOWN_KIND instead of running the
    mesh's code, as the last branch of each function once did."""
    from physdbg.engine.colliders import UNKNOWN_KIND
    from physdbg.engine.state import Walls

    geometry = colliders.geometry_of(Walls())
    x = np.zeros((2, 3))
    sigma = np.zeros(2)
    calls = [lambda kind: colliders.contact_normal(kind, x, sigma, 0, 1, geometry),
             lambda kind: colliders.contact_feature(kind, x, sigma, 0, 1, geometry),
             lambda kind: colliders.partner_restitution(kind, 1, np.ones(2), geometry),
             lambda kind: colliders.partner_normal_motion(kind, x, x, sigma, np.ones(2), 0, 1, 0.0, 1.0, 0.0,
                                                          geometry),
             lambda kind: colliders.partner_moves(kind, 1, geometry),
             lambda kind: colliders.narrow_candidates(kind, np.zeros((0, 2), dtype=np.int64), x, x, geometry),
             lambda kind: colliders.every_candidate(kind, 2, geometry),
             lambda kind: colliders.partner_count(kind, geometry),
             lambda kind: colliders.immovable_partners_in(kind, 0, x, x, geometry, np.zeros((4, 2), dtype=np.int64)),
             lambda kind: colliders.deepest_of_kind(kind, x, np.ones(2), np.zeros((0, 2), dtype=np.int64), geometry,
                                                    True)]
    for call in calls:
        call(events.KIND_PAIR)  # a kind it knows
        with pytest.raises(ValueError, match="a collider kind with no branch in this function of the switch"):
            call(3)
    assert "docs/colliders.md" in UNKNOWN_KIND


def test_what_the_switch_asks_of_every_kind_it_asks_through_the_switch():
    """The switch's functions over every kind (the most partners, their bound, the deepest
    overlap: one of them sizes a buffer) loop over the table's kinds and ask each through
    a function of the switch, so a kind with no branch there is refused, never left out:
    none of them names a kind's module itself."""
    import ast
    import inspect

    tree = ast.parse(inspect.getsource(colliders))
    bodies = {node.name: node for node in tree.body if isinstance(node, ast.FunctionDef)}
    for name in ("most_partners", "partners_bound", "deepest_overlap"):
        modules = {node.value.id for node in ast.walk(bodies[name])
                   if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)}
        assert modules.isdisjoint({"sphere", "plane", "mesh"}), (name, modules)
        assert "KINDS" in {node.id for node in ast.walk(bodies[name]) if isinstance(node, ast.Name)}, name


def test_the_calendar_takes_the_kinds_their_modules_declare_and_refuses_the_rest_by_name(monkeypatch):
    """Each kind's module says whether the event calendar predicts its contacts
    (``CALENDAR``, gathered in colliders.CALENDAR_TAKES): every kind today, fixed meshes
    only (a kinematic one is refused by name); a kind whose module withdrew its support
    (the mesh, then the wall, here) is refused the same way, by name, and a scene without
    its partners is still served."""
    from physdbg.api import load_scene

    assert colliders.CALENDAR_TAKES == tuple(module.CALENDAR for module in colliders.KIND_MODULES)
    world = load_scene("ramp", ["event_loop=calendar"]).build_world()
    world.step(1 / 120)
    assert world.calendar_steps == 1
    world = load_scene("paddle", ["event_loop=calendar"]).build_world()
    world.step(1 / 60)
    assert world.calendar_steps == 0 and "does not take a kinematic mesh" in world.calendar_unfit
    _as_if_in_the_source(monkeypatch, colliders, "CALENDAR_TAKES", (True, True, False))
    world = load_scene("ramp", ["event_loop=calendar"]).build_world()
    world.step(1 / 120)
    assert world.calendar_steps == 0 and "does not take mesh partners" in world.calendar_unfit
    _as_if_in_the_source(monkeypatch, colliders, "CALENDAR_TAKES", (True, False, False))
    world = load_scene("billiards", ["event_loop=calendar"]).build_world()
    world.step(1 / 120)
    assert world.calendar_steps == 0 and "does not take wall partners" in world.calendar_unfit
    world = load_scene("cradle", ["event_loop=calendar"]).build_world()  # no wall at all
    world.step(1 / 60)
    assert world.calendar_steps == 1


# ----------------------------------------------------------------------------- a kind added whole
POST_SCENE = """\
name = "posts"
dt = "1/60"
duration = 1.0
integrator = "exact"
detection = "swept"
ordering = "time"
gravity = [0.0, -9.81, 0.0]

[[particles]]
position = [0.0, 1.1, 0.0]
radius = 0.1
restitution = 0.8

[[post]]
name = "stump"
centre = [0.0, 0.0, 0.0]
radius = 0.3
restitution = 0.5
"""
# what the test reads back of a recording, in the copy's own physdbg
READ_CONTACTS = """\
import json, sys
from physdbg import open_recording
with open_recording(sys.argv[1]) as rec:
    rows = [dict(step=k, kind=int(c.kind), a=int(c.a), other=int(c.other), normal=[float(q) for q in c.normal],
                 before=[float(q) for q in c.velocity_a_before], after=[float(q) for q in c.velocity_a_after])
            for k in range(1, rec.frames) for c in (rec.contacts(k).record(i) for i in range(len(rec.contacts(k))))]
    from physdbg.record.view import scene_bounds
    lo, hi = scene_bounds(rec.header)
    print(json.dumps(dict(rows=rows, names=rec.header.walls.partner_names()[3][:], lo=lo.tolist(), hi=hi.tolist())))
"""


@pytest.fixture(scope="module")
def physdbg_with_posts(tmp_path_factory):
    """A copy of physdbg with a fourth collider kind, "post" (a fixed sphere: tests/kinds/
    post.py), added as docs/colliders.md says: its module beside the others, its row in
    the registry, then the switch written by its script. Nothing else is touched. Returns
    run(args, code=None) -> CompletedProcess, running the copy's physdbg interpreted
    (NUMBA_DISABLE_JIT=1: no compile for a test) in a folder with the scene post.toml."""
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    root = tmp_path_factory.mktemp("with_posts")
    package = root / "physdbg"
    shutil.copytree(Path(events.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(Path(__file__).parent / "kinds" / "post.py", package / "engine" / "colliders" / "post.py")
    registry = package / "events.py"
    last_row = '    ColliderKindRow("mesh", "mesh", False),\n'
    text = registry.read_text()
    assert text.count(last_row) == 1
    registry.write_text(text.replace(last_row, last_row + '    ColliderKindRow("post", "post", False),\n'))  # the line
    (root / "post.toml").write_text(POST_SCENE)
    env = dict(os.environ, PYTHONPATH=str(root), NUMBA_DISABLE_JIT="1", PHYSDBG_TRACEBACK="1")

    def run(args, code=None):
        command = [sys.executable, "-c", code, *args] if code else [sys.executable, "-m", "physdbg", *args]
        return subprocess.run(command, cwd=root, env=env, capture_output=True, text=True, timeout=600)

    stale = run(["run", "post.toml"])  # before the switch is written again, the copy refuses to load, saying why
    assert stale.returncode != 0
    assert ("the switch (switch.py) was written for the kinds' modules sphere, plane, mesh but the registry lists "
            "sphere, plane, mesh, post") in stale.stderr + stale.stdout
    written = subprocess.run([sys.executable, str(package / "write_switch.py")], cwd=root,
                             env=env, capture_output=True, text=True, timeout=120)
    assert written.returncode == 0 and "wrote" in written.stdout, written.stderr
    run.root = root
    return run


@pytest.mark.slow  # a copy of physdbg run in subprocesses, interpreted: about 20 s together
def test_a_kind_in_one_module_and_one_registry_line_runs_through_engine_audit_recording_and_view(physdbg_with_posts):
    """The Must-show of one owner per collider kind: a ball dropped on a post bounces off it
    (a contact of kind 3 with the post's normal and restitution), the audit checks its
    overlaps and says it has no tunnelling rule for posts (never "clean" of what it did
    not check), the recording replays bit for bit and reads back with the post's name,
    and both views draw the post."""
    import json

    from pathlib import Path

    run = physdbg_with_posts
    # the copy differs from this physdbg by the kind's module, its registry line and the written switch, no more
    ours, theirs = Path(events.__file__).parent, run.root / "physdbg"
    files = {path.relative_to(theirs).as_posix() for path in theirs.rglob("*") if path.is_file()
             and "__pycache__" not in path.parts}
    changed = {f for f in files if not (ours / f).exists() or (ours / f).read_bytes() != (theirs / f).read_bytes()}
    assert changed == {"engine/colliders/post.py", *KIND_FILES}, changed

    done = run(["record", "post.toml", "-o", "post.mcap"])
    assert done.returncode == 0, done.stderr
    read = run(["post.mcap"], READ_CONTACTS)
    assert read.returncode == 0, read.stderr
    seen = json.loads(read.stdout)
    assert seen["names"] == ["'stump'"]
    assert seen["lo"][1] <= -0.3 and seen["hi"][1] >= 1.2  # the view frames the post (centre 0, radius 0.3) and the ball
    assert [row["kind"] for row in seen["rows"]] == [3] * len(seen["rows"]) and len(seen["rows"]) >= 2
    first = seen["rows"][0]
    assert first["other"] == 0 and first["normal"] == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)
    # restitution: the combined rule of the ball's 0.8 and the post's 0.5 (docs/colliders.md), the
    # same rule as against a wall: min by default
    assert first["after"][1] == pytest.approx(-0.5 * first["before"][1], rel=1e-9)

    explained = run(["explain", "post.mcap"])
    assert explained.returncode == 0, explained.stderr
    assert "CLEAN: no tunnelling through the partners the audit checks" in explained.stdout
    assert "tunnelling through post partners is not checked" in explained.stdout
    info = run(["info", "post.mcap"])
    assert "1 particle, 0 walls, 1 post partner" in info.stdout, info.stdout
    verified = run(["replay", "post.mcap", "--verify", "--rrd", "replayed.rrd"])
    assert verified.returncode == 0 and "every state hash matches" in verified.stdout, verified.stdout + verified.stderr
    from rerun.chunk import RrdReader

    paths = {str(chunk.entity_path) for chunk in RrdReader(run.root / "post.rrd").stream()}
    assert "/world/post/spheres" in paths, sorted(paths)
    # this physdbg, which has no posts, refuses the recording in one line
    refused = CliRunner().invoke(app, ["explain", str(run.root / "post.mcap")])
    assert refused.exit_code == 2, refused.output
    assert ("the recording has partners of collider kind 'post', which this physdbg does not know (its kinds with "
            "partners of their own: none)") in refused.output
    # a scene with a wrong field of the kind is refused naming the file, the field and what is allowed
    (run.root / "bad.toml").write_text(POST_SCENE.replace("radius = 0.3", "radius = -0.3"))
    bad = run(["run", "bad.toml"])
    assert bad.returncode == 2 and "bad.toml: field 'post.0.radius': got -0.3; expected a number > 0" in bad.stderr
    # a ball that starts inside the post: check says so, and the audit finds the overlap, naming the post
    (run.root / "inside.toml").write_text(POST_SCENE.replace("position = [0.0, 1.1, 0.0]", "position = [0.0, 0.35, 0.0]"))
    checked = run(["check", "inside.toml"])
    assert "sphere 0 starts 50 mm inside post 'stump'" in checked.stdout, checked.stdout + checked.stderr
    assert "predicted to fail" in checked.stdout
    started = run(["run", "inside.toml", "-s", "steps=1"])
    assert "sphere 0 and post 'stump' overlap by 50 mm" in started.stdout, started.stdout + started.stderr
    # a kind's SWITCH changed since the switch was written: refused until the script runs again
    module = run.root / "physdbg" / "engine" / "colliders" / "post.py"
    text = module.read_text()
    module.write_text(text.replace('"partner_restitution": "restitution(other, group)"', '"partner_restitution": "1.0"'))
    try:
        stale = run(["run", "post.toml"])
    finally:
        module.write_text(text)
    assert stale.returncode == 2, stale.stdout + stale.stderr
    assert "the switch (switch.py) was written from other SWITCH tables than the kinds' modules hold now" in stale.stderr


@pytest.mark.slow  # a copy of physdbg run in subprocesses, interpreted: about 20 s together
def test_a_kind_the_calendar_does_not_take_is_refused_by_the_calendar_by_name(physdbg_with_posts):
    run = physdbg_with_posts
    taken = run(["run", "post.toml", "-s", "event_loop=calendar"])
    assert taken.returncode == 0, taken.stderr
    assert "event loop  calendar in 60 of 60 steps" in taken.stdout
    module = run.root / "physdbg" / "engine" / "colliders" / "post.py"
    text = module.read_text()
    module.write_text(text.replace("CALENDAR = True", "CALENDAR = False"))
    try:
        refused = run(["run", "post.toml", "-s", "event_loop=calendar"])
    finally:
        module.write_text(text)
    assert refused.returncode == 0, refused.stderr
    assert "calendar in 0 of 60 steps" in refused.stdout and "it does not take post partners" in refused.stdout


# ----------------------------------------------------------------------------- the docs' list
# The files a new collider kind touches besides its own module, as the post's copy of
# physdbg shows (test_a_kind_in_one_module_and_one_registry_line_...): the registry and the
# switch its script writes.
KIND_FILES = ("events.py", "engine/colliders/switch.py")


def test_the_architecture_page_lists_exactly_the_files_a_new_kind_touches():
    """docs/architecture.md, "Adding": read alone, its list for a new collider kind (a
    capsule) names the files the post's copy of physdbg differs by, and no other source
    file (the script that writes the switch and the docs test are tools it names); and
    colliders.md's own section names them too."""
    import re
    from pathlib import Path

    docs = Path(__file__).resolve().parents[1] / "docs"
    page = (docs / "architecture.md").read_text()
    listed = page[page.index("**A collider kind**"):page.index("`tests/test_extending.py` adds a test-only kind")]
    named = set(re.findall(r"`((?:[a-z_]+/)*[a-z_]+\.py)`", listed))
    tools = {"physdbg/write_switch.py", "tests/test_docs.py"}
    assert named - tools == {"engine/colliders/capsule.py", *KIND_FILES}, named
    colliders = (docs / "colliders.md").read_text()
    section = colliders[colliders.index("## Adding an integrator or a collider kind"):]
    assert [f for f in KIND_FILES if f.rsplit("/", 1)[-1] not in section] == []


# ----------------------------------------------------------------------------- a new cause
# The files a new cause of each command is written in (docs/architecture.md, "A cause").
CAUSE_FILES = ("analysis/diff_causes.py", "analysis/departure.py", "analysis/audit.py")


def test_a_new_diff_cause_in_the_table_is_tried_and_printed_in_every_format(monkeypatch, tmp_path):
    """A detector added to diff_causes.STEP_CAUSES (and its kind to CAUSE_KINDS) is run on
    the diverging step, after the ones before it, and its cause reaches the text,
    Markdown and JSON reports with no change anywhere else."""
    from physdbg.analysis import diff_causes

    def dummy(case, found):
        return [diff_causes.Cause("dummy", f"after {[c.kind for c in found]}", {}, step=case.div.step)]

    monkeypatch.setattr(diff_causes, "STEP_CAUSES",
                        (*diff_causes.STEP_CAUSES, diff_causes.Detector(("dummy",), dummy)))
    monkeypatch.setitem(diff_causes.CAUSE_KINDS, "dummy", "a test's own cause")
    runner = CliRunner()
    paths = []
    for name, flags in (("swept", []), ("discrete", ["-s", "detection=discrete"])):
        paths.append(str(tmp_path / f"{name}.mcap"))
        done = runner.invoke(app, ["record", "bullet-wall", *flags, "-o", paths[-1], "--no-rrd", "--detail", "contacts"])
        assert done.exit_code == 0, done.output
    text = runner.invoke(app, ["diff", *paths])
    assert text.exit_code == 1 and "  - step 1 [dummy] after ['settings', 'tunnelling']" in text.output, text.output
    markdown = runner.invoke(app, ["diff", *paths, "--markdown"])
    assert "- **step 1** *dummy*: after ['settings', 'tunnelling']" in markdown.output
    data = json.loads(runner.invoke(app, ["diff", *paths, "--json"]).output)
    assert data["causes"][-1] == {"kind": "dummy", "text": "after ['settings', 'tunnelling']", "evidence": {},
                                  "step": 1, "bodies": [], "advice": "", "try_settings": {}}


def test_the_architecture_page_names_every_file_a_new_cause_is_written_in():
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "architecture.md").read_text()
    listed = page[page.index("**A cause**"):page.index("**A channel**")]
    named = set(re.findall(r"`((?:[a-z_]+/)*[a-z_]+\.py)`", listed))
    assert [f for f in CAUSE_FILES if f not in named] == []
