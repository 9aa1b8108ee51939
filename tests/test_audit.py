"""physdbg explain and the live audit: findings where there are problems, none where there are not."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import api
from physdbg.analysis import explain
from physdbg.cli import app
from physdbg.errors import PhysdbgError
from physdbg.events import HOW_AT_ONE_INSTANT

ROOT = Path(__file__).resolve().parent.parent


def test_explain_finds_the_discrete_tunnelling_and_nothing_in_the_swept_run(tmp_path):
    discrete = tmp_path / "d.mcap"
    api.record("bullet-wall", ["detection=discrete"], mcap_path=str(discrete), rrd=False)
    report = explain(discrete)
    assert report.counts == {"tunnelling": 1}
    found = report.findings[0]
    assert found.step == 1 and found.particles == [0] and "went through wall 'thin wall'" in found.message
    assert found.position == pytest.approx([1.0, 0.0, 0.0])  # where the path met the wall
    assert "detection = swept" in found.advice
    swept = tmp_path / "s.mcap"
    api.record("bullet-wall", [], mcap_path=str(swept), rrd=False)
    assert explain(swept).clean


@pytest.mark.parametrize("scene", ["billiards", "bounce", "bullet-wall", "cradle", "funnel", "gas", "rain", "ramp", "rest"])
@pytest.mark.slow
def test_no_false_alarms_on_the_builtin_scenes(scene):
    report = explain(ROOT / "recordings" / "ci" / f"{scene}.mcap")
    assert report.clean, [f"step {f.step}: {f.message}" for f in report.findings]
    assert report.checked == report.steps > 0


def test_index_ordering_is_found_out_of_the_recording_alone(tmp_path):
    out = tmp_path / "c.mcap"
    api.record("cradle", ["ordering=index"], mcap_path=str(out), rrd=False)
    report = explain(out)
    assert report.counts.get("tunnelling") and report.findings[0].step == 44
    assert "ordering = time" in report.findings[0].advice


def test_the_run_summary_says_it_and_the_viewer_marks_it(tmp_path):
    result = CliRunner().invoke(app, ["run", "bullet-wall", "--set", "detection=discrete"])
    assert "audit       1 tunnelling" in result.output
    assert "step 1: sphere 0 went through wall 'thin wall'" in result.output
    clean = CliRunner().invoke(app, ["run", "bullet-wall"])
    assert "audit       clean" in clean.output
    rrd = tmp_path / "d.rrd"
    api.record("bullet-wall", ["detection=discrete"], mcap_path=str(tmp_path / "d.mcap"), rrd_path=str(rrd))
    from rerun.chunk import RrdReader

    paths = {str(chunk.entity_path) for chunk in RrdReader(rrd).stream()}
    assert "/world/findings" in paths


def test_explain_cli_exit_codes_and_formats(tmp_path):
    out = tmp_path / "d.mcap"
    api.record("bullet-wall", ["detection=discrete"], mcap_path=str(out), rrd=False)
    runner = CliRunner()
    found = runner.invoke(app, ["explain", str(out)])
    assert found.exit_code == 1 and "[tunnelling]" in found.output and "what to do:" in found.output
    assert '"tunnelling": 1' in runner.invoke(app, ["explain", str(out), "--json"]).output
    clean = runner.invoke(app, ["explain", str(ROOT / "recordings" / "ci" / "cradle.mcap")])
    assert clean.exit_code == 0 and "CLEAN" in clean.output
    bad = tmp_path / "bad.mcap"
    bad.write_text("not a recording")
    failed = runner.invoke(app, ["explain", str(bad)])
    assert failed.exit_code == 2 and "not an MCAP file" in failed.output


def test_collapse_is_found_where_bounces_pile_up_and_the_advice_names_the_rule_that_is_off(tmp_path):
    """A ball on a floor with the resting and rapid-contact rules off bounces ever more
    often (inelastic collapse) until the contact budget stops a step."""
    out = tmp_path / "z.mcap"
    api.record("bounce", ["rest_fraction=0", "rapid_contact_time=0"], mcap_path=str(out), rrd=False)
    report = explain(out)
    assert report.counts == {"budget": 1, "overlap": 1, "collapse": 1}
    budget, collapse = (next(f for f in report.findings if f.kind == kind) for kind in ("budget", "collapse"))
    assert "max_contacts_per_step budget (10000 contacts resolved)" in budget.message  # the automatic cap
    # and on whom it was spent
    assert budget.message.endswith("contacts were sphere 0's, most with wall 'floor'.") and budget.particles == [0]
    assert collapse.message.startswith("10000 bounces among 1 sphere (0) in one step") and collapse.particles == [0]
    assert "rest_fraction, now 0.0" in collapse.advice and "rapid_contact_time (now 0.0 s)" in collapse.advice


def test_contacts_a_rule_holds_are_the_remedy_not_a_collapse():
    """A settled pile resolves many contacts a step, nearly all held by the resting and
    rapid rules (restitution 0): only bounces among few spheres are a collapse."""
    from physdbg.analysis.audit import Auditor
    from physdbg.events import HOW_IMPULSE, HOW_RAPID, KIND_PAIR, Contacts
    from physdbg.record import open_recording

    with open_recording(ROOT / "recordings" / "ci" / "rain.mcap") as rec:
        header = rec.header
    contacts = Contacts.empty(5, 400)
    contacts.kind[:] = KIND_PAIR
    contacts.a[:], contacts.other[:] = [i % 10 for i in range(400)], [10 + i % 10 for i in range(400)]
    contacts.how[:], contacts.restitution[:] = HOW_RAPID, 0.0  # 20 spheres, 20 contacts each, all held
    auditor = Auditor(header)  # rain sleeps: a rattle waits to be judged until the run ends (finish)
    auditor._check_collapse(5, None, contacts)
    auditor.finish()
    assert auditor.counts == {}
    contacts.how[:], contacts.restitution[:] = HOW_IMPULSE, 0.8  # the same contacts, all bounces
    auditor._check_collapse(5, None, contacts)
    auditor.finish()
    assert auditor.counts == {"collapse": 1}
    assert auditor.examples[0].message.startswith("400 bounces among 20 spheres")


def test_a_storm_in_a_discrete_run_is_named_as_the_discrete_test_s_own_and_advises_swept():
    """With detection = discrete every contact is found where a step ends, among spheres
    overlapping there: 400 bounces among 20 spheres is the test's storm, not "the
    collision rate has blown up" nor inelastic collapse; the advice, swept detection, is
    one explain --try can try."""
    from physdbg.analysis.audit import Auditor
    from physdbg.events import HOW_IMPULSE, KIND_PAIR, Contacts
    from physdbg.record import open_recording

    with open_recording(ROOT / "recordings" / "ci" / "rain.mcap") as rec:
        header = rec.header
    header.meta["settings"] = {**header.meta["settings"], "detection": "discrete", "sleep_speed": 0.0}
    contacts = Contacts.empty(5, 400)
    contacts.kind[:] = KIND_PAIR
    contacts.a[:], contacts.other[:] = [i % 10 for i in range(400)], [10 + i % 10 for i in range(400)]
    contacts.how[:], contacts.restitution[:] = HOW_IMPULSE, 0.8
    contacts.time_in_step[:] = 1 / 60  # all where the step ends, as a discrete test finds them
    auditor = Auditor(header)
    auditor._check_collapse(5, None, contacts)
    finding = auditor.examples[0]
    assert finding.message.startswith("400 bounces among 20 spheres (0, 1, 2, 3, 4, …) in one step, at the "
                                      "instants the discrete test looks (where the step ends)"), finding.message
    assert "blown up" not in finding.message and "inelastic collapse" not in finding.message
    assert finding.advice.startswith("use detection = swept") and finding.try_settings == {"detection": "swept"}


def test_under_the_tc_rule_the_collapse_advice_names_the_hold_rule():
    """Under rapid_contact_rule = tc a dense bed's fast rapid contacts stay elastic and it
    rattles (rain-500: ~5 000 bounces a step among its 500 spheres); the advice says which
    setting holds them."""
    from physdbg.analysis.audit import Auditor
    from physdbg.events import HOW_IMPULSE, KIND_PAIR, Contacts
    from physdbg.record import open_recording

    with open_recording(ROOT / "recordings" / "ci" / "rain.mcap") as rec:
        header = rec.header
    contacts = Contacts.empty(5, 400)
    contacts.kind[:] = KIND_PAIR
    contacts.a[:], contacts.other[:] = [i % 10 for i in range(400)], [10 + i % 10 for i in range(400)]
    contacts.how[:], contacts.restitution[:] = HOW_IMPULSE, 1.0  # elastic rapid contacts are bounces too
    for rule, sleep_speed, named, asleep_said in (("hold", 0.0, False, False), ("tc", 0.0, True, False),
                                                  ("tc", 0.05, True, True)):
        auditor = Auditor(header)
        auditor.settings = {**auditor.settings, "rapid_contact_time": 1e-4, "rapid_contact_rule": rule,
                            "sleep_speed": sleep_speed, "sleep_time": 0.1}
        auditor._check_collapse(5, None, contacts)
        auditor.finish()
        assert auditor.counts == {"collapse": 1}
        advice = auditor.examples[0].advice
        assert ("rapid_contact_rule=hold" in advice) == named
        assert ("sleep_speed" in advice) == named  # under tc: sleeping is named, on or off
        assert ("rattles until its spheres fall asleep" in advice) == asleep_said


def test_a_budget_hit_in_a_pile_names_the_settings_that_let_it_rest(tmp_path):
    """A pile (advisor.py) under tc alone collapses: the event cap stops step 54.
    The budget finding says, besides raising the budget, what lets the pile fall asleep;
    the bouncing ball above (a budget hit but no pile) says nothing of piles."""
    pile = ["generate.count=100", "box.max=[0.3,1,0.3]", "generate.speed=0", "generate.restitution=0.5",
            "box.restitution=0.5", "rapid_contact_rule=tc", "sleep_speed=0", "steps=55"]
    out = tmp_path / "pile.mcap"
    api.record("rain", pile, mcap_path=str(out), rrd=False, detail="contacts", view=False)
    report = explain(out)
    hint = "this scene makes a pile about 3.3 layers deep, which tc does not let rest"
    budget = next(f for f in report.findings if f.kind == "budget")
    assert budget.step == 54 and hint in budget.advice and "--set max_contacts_per_step=N" in budget.advice
    assert all(hint in f.advice for f in report.findings if f.kind == "tunnelling")
    from physdbg.analysis.audit import Auditor
    from physdbg.record.header import RecordingHeader
    from physdbg.api import load_scene

    auditor = Auditor(RecordingHeader.from_scene(load_scene("rain", pile)))
    assert auditor._pile() == ("this scene makes a pile about 3.3 layers deep, which tc does not let rest: "
                               "-s rapid_contact_rule=tc -s sleep_speed=0.1 -s sleep_time=0.1 lets it fall asleep "
                               "(physdbg check)")
    assert Auditor(RecordingHeader.from_scene(load_scene("bounce")))._pile() is None
    assert Auditor(RecordingHeader.from_scene(load_scene("rain", pile + ["sleep_speed=0.1"])))._pile() is None


@pytest.mark.slow
def test_a_bed_that_rattles_and_then_falls_asleep_is_no_collapse(tmp_path):
    """rain's 300 spheres under the pile rules (tc, sleeping; auto picks them from about 350
    spheres): from step 282 a few dozen spheres of the bed bounce 10+ times a step, then
    fall asleep. Run to step 360 every one of them sleeps: a note, no finding, and explain
    of the recording agrees. Stopped at step 290, some are still awake: collapse findings,
    which say how many."""
    rules = ["rapid_contact_time=1e-4", "rapid_contact_rule=tc", "sleep_speed=0.1", "sleep_time=0.1"]
    whole = api.run("rain", ["generate.count=300", "steps=360", *rules])
    assert whole.finding_counts == {} and whole.asleep_at_end == 300
    out = tmp_path / "pile.mcap"
    api.record("rain", ["generate.count=300", "steps=360", *rules], mcap_path=str(out), rrd=False,
               detail="contacts", view=False)
    report = explain(out)
    assert report.counts == {} and any(n.startswith("the bed rattled (at least 10 bounces a sphere) in 6 steps "
                                                    "from step 282") and "asleep by step 346" in n
                                       for n in report.notes), report.notes
    cut = api.run("rain", ["generate.count=300", "steps=290", *rules])
    assert cut.finding_counts == {"collapse": 3}
    first = cut.findings[0]
    assert first.kind == "collapse" and first.step == 282 and first.message.startswith("354 bounces among 29 spheres (")
    assert "7 of the 29 spheres were still awake when the run ended (step 290)" in first.message
    from physdbg.analysis.report import summary_text

    assert "  step 282: 354 bounces among 29 spheres (" in summary_text(cut)


def test_the_readme_pile_falling_asleep_at_the_end_is_a_note_not_a_collapse():
    """`physdbg run rain -s generate.count=500` (README: the pile settles) ended with 2 of a
    rattling step's 220 spheres awake, 22 quiet steps after it: a false collapse finding.
    Now a note says the bed was still falling asleep; a bed still rattling is reported."""
    settled = api.run("rain", ["generate.count=500"])
    assert settled.finding_counts == {}
    gas = api.run("gas", ["dt=1e6", "steps=1"])
    assert "with restitution 1 this is not inelastic collapse" in next(
        f.message for f in gas.findings if f.kind == "collapse")


def test_an_overlap_names_its_spheres_and_place_and_blames_the_method_that_left_it(tmp_path):
    index = tmp_path / "index.mcap"
    api.record("cradle", ["ordering=index"], mcap_path=str(index), rrd=False, detail="contacts")
    overlap = next(f for f in explain(index).findings if f.kind == "overlap")
    assert overlap.step == 44 and overlap.particles == [1, 2] and overlap.position is not None
    assert overlap.message.startswith("spheres 1 and 2 overlap by 3.33 mm")
    assert "ordering = index" in overlap.advice and "detection" not in overlap.advice
    discrete = tmp_path / "discrete.mcap"
    api.record("bounce", ["detection=discrete"], mcap_path=str(discrete), rrd=False, detail="contacts")
    floor = next(f for f in explain(discrete).findings if f.kind == "overlap")
    assert floor.particles == [0] and floor.evidence["wall"] == "floor"
    assert floor.message.startswith("sphere 0 and wall 'floor' overlap by") and "detection = discrete" in floor.advice


V_MESH = ("v -1 1 -1\nv 0 0 -1\nv 0 0 1\nv -1 1 1\nv 1 1 -1\nv 1 1 1\n"
          "f 1 2 3\nf 1 3 4\nf 2 5 6\nf 2 6 3\n")  # a symmetric 90° V, its crease along z at the origin


V_REORDERED = V_MESH.replace("f 1 2 3\nf 1 3 4\nf 2 5 6\nf 2 6 3\n", "f 2 5 6\nf 2 6 3\nf 1 3 4\nf 1 2 3\n")


def _v_drop(tmp_path, mesh: str, overrides=()):
    """A ball (e = 0.6) dropped exactly onto the crease of the V: the recording's path and
    the first step with contacts."""
    (tmp_path / "v.obj").write_text(mesh)
    scene = tmp_path / "vdrop.toml"
    scene.write_text('name = "vdrop"\ndt = "1/60"\nduration = 0.5\ngravity = [0.0, -9.81, 0.0]\n'
                     '[[meshes]]\nname = "v"\nfile = "v.obj"\nrestitution = 0.6\n'
                     '[[particles]]\nposition = [0.0, 1.0, 0.0]\nradius = 0.1\nrestitution = 0.6\n')
    recording = tmp_path / "vdrop.mcap"
    api.record(str(scene), list(overrides), mcap_path=str(recording), rrd=False, force=True)
    report = explain(str(recording))
    first = next(s for s in range(1, report.steps + 1) if len(explain_contacts(recording, s)))
    return recording, report, first


@pytest.mark.parametrize("mesh", [V_MESH, V_REORDERED], ids=["faces-in-order", "faces-reordered"])
def test_a_drop_onto_the_crease_of_a_symmetric_v_leaves_it_straight_up(tmp_path, mesh):
    """The ball meets both slopes at one instant; the two contacts are solved together
    (resolve.resolve_at_one_instant), each with e = 0.6 and the same impulse, so it leaves
    straight up at 0.6 of its landing speed, whichever face the file lists first, and the
    audit has nothing to say. (With the rapid-contact rule on, as a scene may ask: without
    it the two perpendicular contacts are independent and are resolved in turn, to the same
    outcome, which the last lines check.)"""
    recording, report, first = _v_drop(tmp_path, mesh, ["rapid_contact_time=1e-4"])
    assert report.counts == {}, report.counts
    rows = explain_contacts(recording, first)
    assert len(rows) == 2 and rows.time_in_step[0] == rows.time_in_step[1]  # one instant, to the bit
    assert list(rows.how) == [HOW_AT_ONE_INSTANT] * 2 and list(rows.restitution) == [0.6, 0.6]
    assert rows.impulse[0] == pytest.approx(rows.impulse[1], rel=1e-12)
    before, after = np.asarray(rows.velocity_a_before[0]), np.asarray(rows.velocity_a_after[1])
    assert abs(after[0]) < 1e-12 and abs(after[2]) < 1e-12
    assert after[1] == pytest.approx(-0.6 * before[1], rel=1e-12)
    recording, report, first = _v_drop(tmp_path, mesh)  # the default: no rapid-contact rule
    assert report.counts == {}, report.counts
    rows = explain_contacts(recording, first)
    assert len(rows) == 2 and list(rows.how) != [HOW_AT_ONE_INSTANT] * 2  # in turn
    after = np.asarray(rows.velocity_a_after[1])
    assert abs(after[0]) < 1e-12 and abs(after[2]) < 1e-12 and after[1] == pytest.approx(-0.6 * before[1], rel=1e-12)


def test_a_drop_onto_the_crease_resolved_in_turn_is_a_simultaneous_finding(tmp_path):
    """ordering = index resolves the two contacts one after the other: the second is held
    by the rapid-contact rule only because it came right after the first, and the ball
    leaves sideways. The audit names the pair and says the order decided it; the same ball
    dropped beside the crease meets one slope at a time and is clean. (The rule on, as a
    scene may ask; without it the order cannot decide: the test above.)"""
    recording, report, first = _v_drop(tmp_path, V_MESH, ["ordering=index", "rapid_contact_time=1e-4"])
    found = [f for f in report.findings if f.kind == "simultaneous"]
    assert len(found) == 1 and report.counts.get("simultaneous") == 1, report.counts
    finding = found[0]
    assert finding.step == first and finding.particles == [0]
    assert "mesh 'v' triangle" in finding.message and "the order decided how it left" in finding.message
    assert "ordering = time solves a sphere's contacts at one instant together" in finding.advice
    rows = explain_contacts(recording, first)
    assert rows.time_in_step[0] == rows.time_in_step[1]  # one instant, to the bit
    assert abs(rows.velocity_a_after[1][0]) > 1.0  # and it left sideways
    beside = tmp_path / "beside.mcap"
    api.record(str(tmp_path / "vdrop.toml"), ["ordering=index", "rapid_contact_time=1e-4",
                                              "particles.0.position=[0.3, 1.0, 0.0]"],
               mcap_path=str(beside), rrd=False)
    assert not [f for f in explain(str(beside)).findings if f.kind == "simultaneous"]


def explain_contacts(path, step):
    from physdbg import open_recording

    with open_recording(path) as rec:
        return rec.contacts(step)


def test_an_overlap_with_a_moving_mesh_names_the_triangle_where_the_mesh_is(tmp_path):
    """A platform rising at 57 m/s ends step 1 5 cm into a ball that discrete detection
    tests only there: the overlap finding names the sphere and the triangle, found with the
    mesh where it is at the end of the step (the audit once looked where it was at time 0,
    found nothing there, and said only "spheres overlap")."""
    (tmp_path / "plate.obj").write_text("v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 1 3 2\nf 1 4 3\n")
    scene = tmp_path / "rising.toml"
    scene.write_text('name = "rising"\ndt = "1/60"\nsteps = 2\ngravity = [0.0, 0.0, 0.0]\ndetection = "discrete"\n'
                     '[[meshes]]\nname = "plate"\nfile = "plate.obj"\nvelocity = [0.0, 57.0, 0.0]\n'
                     '[[particles]]\nposition = [-0.5, 1.0, 0.5]\nradius = 0.1\n')
    summary = api.run(str(scene))
    first = next(f for f in summary.findings if f.kind == "overlap")
    assert first.step == 1 and first.particles == [0], summary.findings
    assert first.message.startswith("sphere 0 and mesh 'plate' triangle 1 (face) overlap by 50 mm"), first.message
    from physdbg.analysis.report import summary_text

    assert "  step 1: sphere 0 and mesh 'plate' triangle 1 (face) overlap by 50 mm" in summary_text(summary)


def test_a_collapse_driven_by_a_kinematic_mesh_says_so_and_what_helps(tmp_path):
    """A ball on a rising platform with the resting rules off is struck by the platform
    thousands of times a step: the collapse finding names the mesh as the cause and its
    advice turns the rules back on; it does not offer a lower restitution or dt (the
    issue's new user tried both: 1.04 and 3.58 million contacts)."""
    (tmp_path / "platform.obj").write_text("v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 1 3 2\nf 1 4 3\n")
    scene = tmp_path / "elevator.toml"
    scene.write_text('name = "elevator"\ndt = "1/60"\nsteps = 8\ngravity = [0.0, -9.81, 0.0]\n'
                     '[[meshes]]\nname = "platform"\nfile = "platform.obj"\nvelocity = [0.0, 0.5, 0.0]\n'
                     '[[particles]]\nposition = [0.0, 0.1, 0.0]\nradius = 0.1\nrestitution = 0.5\n')
    recording = tmp_path / "elevator.mcap"
    api.record(str(scene), ["rest_fraction=0", "rapid_contact_time=0", "max_contacts_per_step=2000"],
               mcap_path=str(recording), rrd=False, detail="contacts")
    collapse = next(f for f in explain(str(recording)).findings if f.kind == "collapse")
    assert "kinematic mesh 'platform' drives them: its prescribed motion strikes the same spheres" in collapse.message
    assert collapse.advice.startswith("let slow pressed contacts rest (rest_fraction, now 0")
    assert "lowering the restitution or dt does not stop a prescribed motion" in collapse.advice


def test_contact_energies_are_the_rows_kinetic_energies_relative_to_a_moving_surface():
    """Rows: a pair (both spheres count), a pair with an immovable b (only a counts), a
    wall (b's velocity NaN: a counts as it moved) and a moving mesh (a counts relative to
    the surface's velocity, recorded as b's)."""
    from physdbg.analysis.audit import contact_energies

    mass = np.array([2.0, 1.0, np.inf])
    a, other = np.array([0, 1, 0, 1]), np.array([1, 2, 0, 5])
    pair = np.array([True, True, False, False])
    va0 = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, -3.0, 0.0], [0.0, -1.0, 0.0]])
    va1 = np.array([[-1.0, 0.0, 0.0], [0.0, -2.0, 0.0], [0.0, 3.0, 0.0], [0.0, 2.0, 0.0]])
    vb0 = np.array([[-2.0, 0.0, 0.0], [0.0, 0.0, 0.0], [np.nan] * 3, [0.0, 0.5, 0.0]])
    vb1 = np.array([[2.0, 0.0, 0.0], [0.0, 0.0, 0.0], [np.nan] * 3, [0.0, 0.5, 0.0]])
    before, after = contact_energies(mass, a, other, pair, va0, va1, vb0, vb1)
    assert before.tolist() == [0.5 * 2 * 1 + 0.5 * 1 * 4, 0.5 * 1 * 4, 0.5 * 2 * 9, 0.5 * 1 * 1.5**2]
    assert after.tolist() == [0.5 * 2 * 1 + 0.5 * 1 * 4, 0.5 * 1 * 4, 0.5 * 2 * 9, 0.5 * 1 * 1.5**2]


PASSING_PAIRS = """
name = "passing pairs"
dt = 0.1
steps = 4
integrator = "exact"
detection = "swept"
gravity = [0.0, 0.0, 0.0]
max_contacts_per_step = 1

# two pairs head-on, 20 m/s apart: the first meets 0.01 s into step 1, the second 0.04 s
# in, and would be 1 m past itself by the step's end
[[particles]]
position = [0.0, 0.0, 0.0]
velocity = [10.0, 0.0, 0.0]
radius = 0.1
[[particles]]
position = [0.4, 0.0, 0.0]
velocity = [-10.0, 0.0, 0.0]
radius = 0.1
[[particles]]
position = [0.0, 5.0, 0.0]
velocity = [10.0, 0.0, 0.0]
radius = 0.1
[[particles]]
position = [1.0, 5.0, 0.0]
velocity = [-10.0, 0.0, 0.0]
radius = 0.1
"""


def test_a_live_audit_takes_the_pairs_of_exact_steps_from_the_engine_and_walks_the_rest(tmp_path):
    """A live audit walks the pairs' paths of a step the engine did not finish (here the
    contact budget left the second pair unresolved, so it passed through itself) and takes
    them from the engine's swept tests where its tests were exact and complete; the
    findings are those of the full walk and of explain."""
    scene = tmp_path / "pairs.toml"
    scene.write_text(PASSING_PAIRS)
    default = api.run(str(scene))
    full = api.run(str(scene), audit="full")
    assert default.finding_counts == full.finding_counts and default.finding_counts["tunnelling"] == 1
    assert default.findings == full.findings
    assert any("spheres 2 and 3 passed into each other" in f.message for f in default.findings)
    assert default.audit_pairs == {"from_engine": 3, "steps": 4} and full.audit_pairs["from_engine"] == 0
    from physdbg.analysis.report import summary_text

    assert "  pairs of spheres in 3 of 4 steps taken from the engine's own swept tests" in summary_text(default)
    assert "pairs of spheres" not in summary_text(full)
    recording = tmp_path / "pairs.mcap"
    api.record(str(scene), mcap_path=str(recording), rrd=False)
    assert explain(recording).counts == full.finding_counts
    # the same in words, and --full-audit walks every step
    runner = CliRunner()
    said = runner.invoke(app, ["run", "cradle"])
    assert said.exit_code == 0 and "  pairs of spheres in all 180 steps taken from the engine's" in said.output
    walked = runner.invoke(app, ["run", "cradle", "--full-audit"])
    assert walked.exit_code == 0 and "audit       clean" in walked.output and "pairs of spheres" not in walked.output
    recorded = runner.invoke(app, ["record", "cradle", "--full-audit", "--no-rrd", "-o", str(tmp_path / "c.mcap")])
    assert recorded.exit_code == 0 and "audit       clean" in recorded.output and "pairs of spheres" not in recorded.output
    index = runner.invoke(app, ["run", "cradle", "--set", "ordering=index"])  # not exact: every step walked
    assert "tunnelling" in index.output and "pairs of spheres" not in index.output
    with pytest.raises(PhysdbgError, match="audit must be True, False or 'full', not 'fast'"):
        api.run("cradle", audit="fast")


@pytest.mark.parametrize("scene", ["billiards", "cradle", "gas", "rain", "ramp", "rest"])
def test_the_live_audit_finds_what_the_full_walk_finds_on_the_builtin_scenes(scene):
    """Taking an exact step's pairs from the engine changes no finding (the built-in scenes
    with their own settings: none either way)."""
    default = api.run(scene, ["duration=0.5"])
    assert default.finding_counts == api.run(scene, ["duration=0.5"], audit="full").finding_counts == {}
    assert default.audit_pairs["from_engine"] > 0


def test_an_overlap_left_by_a_discrete_test_advises_swept_as_settings_a_fork_can_try(tmp_path):
    """bounce with detection = discrete leaves the ball inside the floor at step 28; the
    advice (swept detection) is a change of settings (Finding.try_settings), and a swept
    run's overlap, were there one, would have none to try."""
    out = tmp_path / "bounce.mcap"
    api.record("bounce", ["detection=discrete", "steps=30"], mcap_path=str(out), rrd=False, detail="contacts")
    (overlap,) = [f for f in explain(out).findings if f.kind == "overlap"]
    assert overlap.advice.startswith("detection = discrete finds a contact only once the spheres overlap")
    assert overlap.try_settings == {"detection": "swept"}
