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


# ----------------------------------------------------------------------------- the docs' list
# The files the tests above exercise for a new collider kind: the table (events.py), the
# switch and its module table (colliders/__init__.py), and the readers explain reaches that
# rebuild a contact's geometry and refuse a kind they have no branch for (check-run's,
# analysis/departure.py, is listed by the page but not run here).
KIND_FILES = ("events.py", "engine/colliders/__init__.py", "analysis/tunnel.py", "analysis/audit.py")


def test_the_architecture_page_lists_every_file_these_tests_exercise_for_a_new_kind():
    """docs/architecture.md, "Adding": read alone, it names every file a new collider kind
    (a capsule) touches; the ones this file checks are among them, and colliders.md's own
    list names them too."""
    import re
    from pathlib import Path

    docs = Path(__file__).resolve().parents[1] / "docs"
    page = (docs / "architecture.md").read_text()
    listed = page[page.index("**A collider kind**"):page.index("**A cause**")]
    named = set(re.findall(r"`((?:[a-z_]+/)*[a-z_]+\.py)`", listed))
    assert "engine/colliders/capsule.py" in named
    assert [f for f in KIND_FILES if f not in named] == []
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
                                  "step": 1, "bodies": [], "advice": ""}


def test_the_architecture_page_names_every_file_a_new_cause_is_written_in():
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "architecture.md").read_text()
    listed = page[page.index("**A cause**"):page.index("**A channel**")]
    named = set(re.findall(r"`((?:[a-z_]+/)*[a-z_]+\.py)`", listed))
    assert [f for f in CAUSE_FILES if f not in named] == []
