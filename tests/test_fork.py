"""Forking a recording (fork.fork_recording, `physdbg record --from REC --at K`): a fork
repeats its parent up to step K, every carried engine state included, and goes on from
there with the settings changed; with no change it is its parent bit for bit."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from physdbg import api, open_recording
from physdbg.fork import fork_recording
from physdbg.cli import app
from physdbg.errors import PhysdbgError

from . import tamper


def _hashes(path) -> list[str]:
    with open_recording(path) as rec:
        table = rec.frame_table()
        return [table.hash_hex(k) for k in range(rec.frames)]


@pytest.fixture(scope="module")
def rain(tmp_path_factory):
    """A small pile that rests, with held contacts, the rapid-contact rule and sleeping
    (the pile rules, asked for): what a recording's states alone do not hold."""
    path = tmp_path_factory.mktemp("fork") / "rain.mcap"
    api.record("rain", ["generate.count=60", "steps=240", "rapid_contact_time=1e-4", "rapid_contact_rule=tc",
                        "sleep_speed=0.1"], mcap_path=str(path), rrd=False, detail="contacts")
    with open_recording(path) as rec:
        settings = rec.meta["settings"]
        assert settings["sleep_speed"] > 0 and settings["rapid_contact_time"] > 0  # the state a fork must carry
        assert int(rec.stats(199, 200)["held"][0]) > 0  # held contacts carried into step 200 (sleep timers too)
    return path


def test_a_fork_with_no_change_is_its_parent_bit_for_bit(rain, tmp_path):
    result = fork_recording(rain, 200, [], mcap_path=str(tmp_path / "same.mcap"), rrd=False)
    assert _hashes(result.mcap) == _hashes(rain)
    with open_recording(result.mcap) as rec:
        fork = rec.meta["fork"]
        assert fork["at"] == 200 and fork["changes"] == {} and fork["parent"] == "rain.mcap"
        assert fork["parent_hash"] == _hashes(rain)[199]
        assert rec.detail == "contacts"  # the parent's
    assert api.verify(result.mcap).ok
    done = CliRunner().invoke(app, ["diff", str(rain), result.mcap])
    assert done.exit_code == 0 and "every state is bit-identical" in done.output, done.output


def test_a_fork_changes_its_settings_from_its_step_on_and_diff_says_so(tmp_path):
    parent = tmp_path / "bounce.mcap"
    api.record("bounce", ["steps=120"], mcap_path=str(parent), rrd=False)
    runner = CliRunner()
    done = runner.invoke(app, ["record", "--from", str(parent), "--at", "20", "-s", "detection=discrete",
                               "-o", str(tmp_path / "discrete.mcap"), "--no-rrd"])
    assert done.exit_code == 0, done.output
    assert "fork        of " in done.output and "at step 20: detection=discrete from step 20 on" in done.output
    mine, theirs = _hashes(tmp_path / "discrete.mcap"), _hashes(parent)
    assert mine[:20] == theirs[:20] and mine != theirs  # frames 0..19: the state at the start of step 20
    assert api.verify(tmp_path / "discrete.mcap").ok  # verify takes the change at step 20 too
    done = runner.invoke(app, ["diff", str(parent), str(tmp_path / "discrete.mcap")])
    assert done.exit_code == 1
    assert "B is a fork of A at step 20: different settings: detection: swept in A, discrete in B" in done.output
    assert "the state was changed outside its rules" not in done.output
    assert ("aligned  B is a fork of A at step 20: frames 0..19 are its parent's, equal as they should be; from step "
            "20 on, frame k of A against frame k of B") in done.output
    assert api.diff(parent, tmp_path / "discrete.mcap").fork == {"fork": "B", "parent": "A", "at": 20, "dt": None}
    # the overlay opens where the fork starts: the rows on its opening timeline begin at step 20
    from rerun.chunk import RrdReader

    overlay = tmp_path / "overlay.rrd"
    done = runner.invoke(app, ["diff", str(parent), str(tmp_path / "discrete.mcap"), "--rrd", str(overlay)])
    assert done.exit_code == 1 and overlay.exists(), done.output
    opening = [t for chunk in RrdReader(overlay).stream() if "diverged" in chunk.timeline_names
               for t in chunk.to_record_batch().column("diverged").to_pylist() if t is not None]
    assert min(opening) == 20
    # another dt from step 20 on: to the parent's end time, in steps of the new length
    result = fork_recording(parent, 20, ["dt=1/120"], mcap_path=str(tmp_path / "fine.mcap"), rrd=False)
    with open_recording(result.mcap) as rec:
        table = rec.frame_table()
        assert rec.steps == 19 + 202  # 101 steps of 1/60 s left in the parent: 202 of 1/120 s
        assert table.dt[19] == pytest.approx(1 / 60) and table.dt[20] == pytest.approx(1 / 120)
        assert table.time[-1] == pytest.approx(_parent_end(parent))
    assert _hashes(result.mcap)[:20] == theirs[:20]
    assert api.verify(result.mcap).ok
    short = fork_recording(parent, 20, ["integrator=verlet"], steps=5, mcap_path=str(tmp_path / "short.mcap"),
                               rrd=False)
    assert short.frames == 25 and api.verify(short.mcap).ok
    done = runner.invoke(app, ["diff", str(parent), result.mcap])  # a fork that changed its dt alone
    assert "B is a fork of A at step 20 (steps of 0.00833333 s from there): no setting differs" in done.output


def test_a_fork_of_a_fork_keeps_its_parent_s_changes_unless_it_sets_them(tmp_path):
    parent = tmp_path / "bounce.mcap"
    api.record("bounce", ["steps=60"], mcap_path=str(parent), rrd=False)
    child = fork_recording(parent, 10, ["detection=discrete"], mcap_path=str(tmp_path / "child.mcap"), rrd=False)
    # no change, after and before the child's own step: the child bit for bit
    for at in (20, 5):
        same = fork_recording(child.mcap, at, [], mcap_path=str(tmp_path / f"same{at}.mcap"), rrd=False)
        assert _hashes(same.mcap) == _hashes(child.mcap), at
        assert same.fork["chain"] == [{"at": 10, "changes": {"detection": "discrete"}}]
    # what the grandchild sets holds from its step on: swept again from step 5 is the first run
    back = fork_recording(child.mcap, 5, ["detection=swept"], mcap_path=str(tmp_path / "back.mcap"), rrd=False)
    assert _hashes(back.mcap) == _hashes(parent) and back.fork["chain"] == []
    euler = fork_recording(child.mcap, 30, ["integrator=euler"], mcap_path=str(tmp_path / "euler.mcap"),
                               rrd=False)
    assert _hashes(euler.mcap)[:30] == _hashes(child.mcap)[:30] and api.verify(euler.mcap).ok
    assert euler.summary.detection == "discrete" and euler.summary.integrator == "euler"
    info = CliRunner().invoke(app, ["info", euler.mcap])
    assert ("fork        of child.mcap at step 30: integrator=euler from step 30 on; and, as its parent, "
            "detection=discrete from step 10") in info.output, info.output


PASS = """\
dt = 0.1
steps = 5
gravity = [0.0, 0.0, 0.0]
[[particles]]
position = [-25.0, 0.0, 0.0]
velocity = [100.0, 0.0, 0.0]
radius = 0.1
[[particles]]
position = [25.0, 0.0, 0.0]
velocity = [-100.0, 0.0, 0.0]
radius = 0.1
"""


def test_the_audit_of_a_fork_takes_its_settings_from_its_step_live_and_in_explain(tmp_path):
    """Two spheres meeting head-on; the fork tests only where steps end from step 2 on, and
    they pass through each other in step 3: found by the live audit as by explain, with the
    discrete test named, and diff names the fork's change, not an engine fault."""
    scene = tmp_path / "pass.toml"
    scene.write_text(PASS)
    parent = tmp_path / "pass.mcap"
    api.record(str(scene), mcap_path=str(parent), rrd=False)
    fork = fork_recording(parent, 2, ["detection=discrete"], mcap_path=str(tmp_path / "fork.mcap"), rrd=False)
    assert fork.summary.finding_counts == {"tunnelling": 1}
    (live,) = fork.summary.findings
    (audited,) = api.explain(fork.mcap).findings
    assert live.step == audited.step == 3 and "detection = discrete tests only where each step ends" in live.message
    assert audited.message == live.message
    done = CliRunner().invoke(app, ["diff", str(parent), fork.mcap])
    assert "B is a fork of A at step 2: different settings: detection: swept in A, discrete in B" in done.output
    assert "detection = discrete tests only where each step ends" in done.output
    assert "should never do this" not in done.output


def _parent_end(path) -> float:
    with open_recording(path) as rec:
        return float(rec.frame_table().time[-1])


def test_a_fork_that_cannot_be_made_is_refused_in_one_line(tmp_path):
    parent = tmp_path / "bounce.mcap"
    api.record("bounce", ["steps=30"], mcap_path=str(parent), rrd=False)
    runner = CliRunner()

    def refused(*args) -> str:
        done = runner.invoke(app, ["record", "--from", str(parent), *args, "-o", str(tmp_path / "fork.mcap"),
                                   "--no-rrd"])
        assert done.exit_code == 2, done.output
        assert not (tmp_path / "fork.mcap").exists()
        return done.output

    assert "--at 31: " in refused("--at", "31") and "has steps 1..30" in refused("--at", "31")
    out = refused("--at", "10", "-s", "generate.count=5")
    assert "--set generate.count=5: generate.count cannot change in the middle of a run" in out
    assert "gravity cannot change in the middle of a run" in refused("--at", "10", "-s", "gravity=[0,0,0]")
    assert "a fork takes the value itself" in refused("--at", "10", "-s", "detection=auto")
    assert "a fork needs --from (the recording) and --at" in refused()
    done = runner.invoke(app, ["record", "bounce", "--from", str(parent), "--at", "3"])
    assert done.exit_code == 2 and "not both" in done.output
    done = runner.invoke(app, ["record"])
    assert done.exit_code == 2 and "give a scene to record (a built-in name or a .toml file), or --from" in done.output
    done = runner.invoke(app, ["record", "--from", str(parent), "--at", "10", "--steps", "4", "-o",
                               str(tmp_path / "four.mcap"), "--no-rrd"])
    assert done.exit_code == 0 and "recorded    13 steps" in done.output, done.output  # steps 1..9, then 4 from 10
    # a damaged parent: a state altered in place, or altered and rehashed everywhere (only a re-simulation tells)
    altered = tamper.nudge_state(parent, tmp_path / "altered.mcap", 5)
    done = runner.invoke(app, ["record", "--from", str(altered), "--at", "10", "-o", str(tmp_path / "f1.mcap")])
    assert done.exit_code == 2 and "frame 5" in done.output, done.output
    forged = tamper.nudge_state(parent, tmp_path / "forged.mcap", 5, rehash=True, reindex=True)
    with pytest.raises(PhysdbgError, match="does not repeat: step 5 taken again gives another state"):
        fork_recording(forged, 10, [], mcap_path=str(tmp_path / "f2.mcap"), rrd=False)
    assert not (tmp_path / "f2.mcap").exists()


FAST_RAMP = """\
name = "fast-ramp"
description = "A fast ball dropped on a small ramp: discrete detection lets it through in step 4"
dt = "1/60"
steps = 10
detection = "discrete"
gravity = [0.0, -9.81, 0.0]

[[particles]]
position = [1.0, 3.6, 0.0]
velocity = [0.0, -60.0, 0.0]
radius = 0.05

[[meshes]]
name = "ramp"
shape = "ramp"
rotation = [-90.0, 0.0, 0.0]
"""


def test_explain_tries_its_advice_on_a_fork_and_says_what_it_did(tmp_path):
    """A discrete mesh run that tunnels at step 4: explain --try forks it there with the
    advised swept detection, and says the tunnelling is gone, what else changed (diff's
    words) and the cost; the fork verifies; --json carries the same as fields."""
    import json

    scene = tmp_path / "fast-ramp.toml"
    scene.write_text(FAST_RAMP)
    recorded = tmp_path / "ramp.mcap"
    api.record(str(scene), mcap_path=str(recorded), rrd=False)
    runner = CliRunner()
    done = runner.invoke(app, ["explain", str(recorded), "--try"])
    assert done.exit_code == 1, done.output  # the run's own findings stand
    assert "step 4 [tunnelling] sphere 0 went through mesh 'ramp'" in done.output
    tried = next(line for line in done.output.splitlines() if line.startswith("try      "))
    assert tried.startswith("try      detection=swept from step 4 for 7 steps: the tunnelling of step 4 (sphere 0) "
                            "is gone; 0 tunnelling findings in those steps (1 in the run's same steps); what else "
                            "changed (diff of the run, A, against the fork, B): the runs part in step 4:"), tried
    assert "ms a step in the engine" in tried and "DID NOT VERIFY" not in tried
    done = runner.invoke(app, ["explain", str(recorded), "--try", "--try-steps", "2", "--json"])
    (entry,) = json.loads(done.output)["tried"]
    assert entry["gone"] is True and entry["verified"] is True and entry["steps"] == 3
    assert entry["settings"] == {"detection": "swept"} and entry["left_in_run"] == 1
    assert json.loads(done.output)["findings"][0]["try_settings"] == {"detection": "swept"}
    # advice that is not a change of settings is not tried; without --try nothing is
    done = runner.invoke(app, ["explain", str(recorded), "--json"])
    assert json.loads(done.output)["tried"] == []
    done = runner.invoke(app, ["explain", str(recorded), "--try-steps", "3"])
    assert done.exit_code == 2 and "--try-steps says how long --try's forks run: give it with --try" in done.output


def test_diff_and_record_try_the_advice_of_their_causes_and_findings(tmp_path):
    """The fast ramp recorded swept (A) and discrete (B): diff's cause, B's tunnelling at
    step 4, advises swept detection; diff --try forks B there with it and says the
    tunnelling is gone. record --try does the same for the new recording's own findings."""
    import json

    scene = tmp_path / "fast-ramp.toml"
    scene.write_text(FAST_RAMP)
    swept, discrete = tmp_path / "swept.mcap", tmp_path / "discrete.mcap"
    api.record(str(scene), ["detection=swept"], mcap_path=str(swept), rrd=False)
    runner = CliRunner()
    done = runner.invoke(app, ["record", str(scene), "-o", str(discrete), "--no-rrd", "--try", "--try-steps", "2"])
    assert done.exit_code == 0, done.output
    tried = next(line for line in done.output.splitlines() if line.startswith("try         "))
    assert tried.startswith("try         detection=swept from step 4 for 3 steps: the tunnelling of step 4 (sphere 0) "
                            "is gone"), tried
    done = runner.invoke(app, ["diff", str(swept), str(discrete), "--try", "--try-steps", "2"])
    assert done.exit_code == 1, done.output
    assert "went through mesh 'ramp' triangle" in done.output
    tried = next(line for line in done.output.splitlines() if line.startswith("try      "))
    assert tried.startswith("try      in run B: detection=swept from step 4 for 3 steps: the tunnelling of step 4 "
                            "(sphere 0) is gone"), tried
    report = json.loads(runner.invoke(app, ["diff", str(swept), str(discrete), "--try", "--try-steps", "2",
                                            "--json"]).output)
    (entry,) = report["tried"]
    assert entry["run"] == "B" and entry["gone"] is True and entry["verified"] is True
    assert any(c["try_settings"] == {"detection": "swept"} for c in report["causes"])
    # nothing to try where no cause is a change of settings; --try-steps alone is refused
    same = runner.invoke(app, ["diff", str(swept), str(swept), "--try"])
    assert same.exit_code == 0 and "try      no cause's advice is a change of settings: nothing to try" in same.output
    done = runner.invoke(app, ["diff", str(swept), str(discrete), "--try-steps", "3"])
    assert done.exit_code == 2 and "--try-steps says how long --try's forks run: give it with --try" in done.output
    done = runner.invoke(app, ["record", str(scene), "-o", str(tmp_path / "x.mcap"), "--no-rrd", "--try-steps", "3"])
    assert done.exit_code == 2 and "--try-steps says how long --try's forks run: give it with --try" in done.output
    done = runner.invoke(app, ["record", "--from", str(discrete), "--at", "2", "-o", str(tmp_path / "f.mcap"),
                               "--try"])
    assert done.exit_code == 2 and "--try tries a new recording's advice: record it first" in done.output
    assert not (tmp_path / "x.mcap").exists() and not (tmp_path / "f.mcap").exists()
