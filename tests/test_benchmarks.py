"""benchmarks/box_rain.py's checkpoints: a run carried on from one is the same run."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.box_rain import box_rain, load_checkpoint, run_physdbg


def test_a_run_resumed_from_its_checkpoint_is_the_uninterrupted_run(tmp_path, capsys):
    key = (200, ())
    whole = run_physdbg(box_rain(200, 40), trace=True, key=key)
    straight = capsys.readouterr().out.splitlines()[1:]
    path = str(tmp_path / "run.pickle")
    run_physdbg(box_rain(200, 25), trace=True, checkpoint=path, every=10, key=key)  # written at 10, 20 and 25
    first = capsys.readouterr().out.splitlines()[1:]
    resumed = load_checkpoint(path, key)
    assert resumed["world"].step_index == 25
    rest = run_physdbg(box_rain(200, 40), trace=True, resumed=resumed, key=key)
    second = capsys.readouterr().out.splitlines()[1:]

    def without_timing(lines):  # the ms and peak-MB columns differ from run to run
        return [line.split()[2:-2] + line.split()[-1:] for line in lines]

    assert len(first) == 25 and len(second) == 15
    assert without_timing(first + second) == without_timing(straight)  # every count and the state hash
    assert rest["rows"] == whole["rows"] and rest["steps"] == 40
    assert rest["capped"] == whole["capped"] and rest["worst_overlap"] == whole["worst_overlap"]


def test_a_checkpoint_of_another_run_is_refused(tmp_path):
    path = str(tmp_path / "run.pickle")
    run_physdbg(box_rain(50, 3), checkpoint=path, every=1, key=(50, ()))
    with pytest.raises(ValueError, match="another run"):
        load_checkpoint(path, (50, ("generate.restitution=0.5",)))


def test_the_command_refuses_bad_checkpoint_options_with_a_clear_error(tmp_path, monkeypatch, capsys):
    """Before anything is compiled or run: a zero interval, a missing file, another run's
    checkpoint, a file that is not one each end with argparse's exit 2 and say why."""
    from benchmarks import box_rain

    path = str(tmp_path / "run.pickle")
    run_physdbg(box_rain.box_rain(50, 2), checkpoint=path, every=1, key=(50, ()))
    (tmp_path / "junk").write_bytes(b"not a pickle")
    cases = [(["--checkpoint-every", "0"], "--checkpoint-every must be at least 1"),
             (["--resume", str(tmp_path / "none")], "No such file"),
             (["--count", "60", "--resume", path], "is a checkpoint of another run (--count 50), not of --count 60"),
             (["--resume", str(tmp_path / "junk")], "cannot resume from"),
             (["--rounds", "2"], "more than 1 only with --peers"),
             (["--peers", "--rounds", "0"], "--rounds must be at least 1"),
             (["--with-run"], "give --peers too")]
    for argv, said in cases:
        monkeypatch.setattr("sys.argv", ["box_rain.py", *argv])
        with pytest.raises(SystemExit) as stopped:
            box_rain.main()
        assert stopped.value.code == 2
        assert said in capsys.readouterr().err


def test_rounds_time_every_engine_in_turn_and_summarise_each_ratio(monkeypatch, capsys):
    """--rounds: physdbg and each peer run once a round, in turn; every round's ratio is
    the peer's time over that round's physdbg time, and the summary is their median and
    range (the peers here are stand-ins that take a known time)."""
    from benchmarks import box_rain

    peer_seconds = iter([2.0, 1.0, 4.0, 3.0, 6.0, 5.0])  # pybullet, mujoco in each of three rounds
    monkeypatch.setattr(box_rain, "run_peer_timed", lambda scene, setup: next(peer_seconds))
    physdbg_seconds = iter([0.5, 1.0])  # rounds two and three (round one's time is given)
    monkeypatch.setattr(box_rain, "run_physdbg", lambda scene: {"seconds": next(physdbg_seconds)})
    ratios = box_rain.compare_with_peers(box_rain.box_rain(20, 2), 1.0, rounds=3)
    mujoco = box_rain.FAST_SETUPS[1].label
    assert ratios == {"pybullet": [2.0, 8.0, 6.0], mujoco: [1.0, 6.0, 5.0]}
    out = capsys.readouterr().out
    assert "physdbg against pybullet over 3 rounds: median 6.00x, range 2.00-8.00x" in out
    assert f"physdbg against {mujoco} over 3 rounds: median 5.00x, range 1.00-6.00x" in out


def test_with_run_times_physdbg_run_against_each_peer_in_every_round(monkeypatch, capsys):
    """--with-run: each round also times `physdbg run` (the engine with its default audit,
    really run here) and gives each peer's time over it as a ratio of its own."""
    from benchmarks import box_rain

    monkeypatch.setattr(box_rain, "run_peer_timed", lambda scene, setup: 10.0)
    monkeypatch.setattr(box_rain, "run_physdbg", lambda scene: {"seconds": 1.0})
    ran = []
    real = box_rain.run_audited
    monkeypatch.setattr(box_rain, "run_audited", lambda scene: ran.append(real(scene)) or 2.0)
    ratios = box_rain.compare_with_peers(box_rain.box_rain(20, 2), 1.0, rounds=2, with_run=True)
    mujoco = box_rain.FAST_SETUPS[1].label
    assert len(ran) == 2 and all(seconds > 0 for seconds in ran)
    assert ratios == {"pybullet": [10.0, 10.0], "pybullet (run)": [5.0, 5.0], mujoco: [10.0, 10.0],
                      f"{mujoco} (run)": [5.0, 5.0]}
    out = capsys.readouterr().out
    assert "physdbg run (engine + default audit): 1000.0 ms/step" in out and ", `physdbg run` 5.00x" in out
    assert f"physdbg against {mujoco} (run) over 2 rounds: median 5.00x" in out


def test_the_peers_step_the_scene_physdbg_steps():
    """box_rain's peers are physdbg/peers.py's (record-peer's translation): each steps the
    same initial state, frictionless, and keeps the spheres in the box."""
    from benchmarks import box_rain
    from physdbg.peers import build

    scene = box_rain.box_rain(50, 60)
    for setup in (box_rain.FAST_SETUPS + box_rain.ALL_SETUPS[1:3]):
        world = build(scene, setup)
        try:
            assert np.array_equal(world.positions(), scene.state.positions)
            for _ in range(scene.steps):
                world.step()
            x = world.positions()
        finally:
            world.close()
        side = -scene.walls.offsets[1]
        assert np.all(x > -0.01) and np.all(x < side + 0.01), setup.label
        assert x[:, 1].mean() < scene.state.positions[:, 1].mean(), setup.label  # they fall


def test_renumbering_the_spheres_changes_no_contact_and_the_calls_fit_in_the_step():
    """benchmarks/step_parts.py: the spheres in any order give the same contacts (only
    time may differ); Morton order brings partners closer in index; the calls it times
    add up to no more than the step."""
    from benchmarks import step_parts

    runs = {}
    for order in step_parts.ORDERS:
        scene = step_parts.scene_for("rain", 200, 40)
        step_parts.renumber(scene, order)
        runs[order] = step_parts.measure(scene)
    assert runs["as-generated"]["contacts"] > 0
    assert len({run["contacts"] for run in runs.values()}) == 1
    assert runs["morton"]["index_distance"] < runs["random"]["index_distance"]
    assert runs["columns"]["index_distance"] < runs["random"]["index_distance"]
    # the world's own numbering (space_order = "morton"), renewed every 16 steps from where
    # the spheres are, keeps partners closer than an order made at the start
    assert runs["inside"]["index_distance"] < runs["morton"]["index_distance"]
    # numbered by where the spheres are near the run's end, the last step's partners are
    # closer in index than in any order fixed at the start
    assert runs["landed"]["index_distance"] < min(runs[o]["index_distance"] for o in ("morton", "columns", "random"))
    for run in runs.values():
        assert {"run_time_order", "predict_into", "state_hash", "broad phase pairs"} <= set(run["calls"])
        assert 0.0 < sum(run["calls"].values()) <= run["wall"]


def test_column_keys_order_by_column_then_height():
    from benchmarks.step_parts import column_keys

    points = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    # (x, y) = (0, 0) first, lowest first; then x = 1; then y = 1; then both
    assert np.argsort(column_keys(points, bits=1), kind="stable").tolist() == [3, 1, 0, 2, 4]


def test_step_parts_prints_each_call_and_refuses_a_bad_count(monkeypatch, capsys):
    """benchmarks/step_parts.py as a user runs it: the header, a row per timed call, the
    Python between them; --count 1 ends with argparse's exit 2 and says what is allowed."""
    from benchmarks import step_parts

    monkeypatch.setattr("sys.argv", ["step_parts.py", "--count", "60", "--steps", "5", "--order", "morton"])
    step_parts.main()
    out = capsys.readouterr().out
    assert out.startswith("rain N=60, 5 steps, spheres morton: ")
    assert "run_time_order" in out and "Python between them" in out and "loop pauses for a re-query" in out
    monkeypatch.setattr("sys.argv", ["step_parts.py", "--count", "1"])
    with pytest.raises(SystemExit) as stopped:
        step_parts.main()
    assert stopped.value.code == 2
    assert "--count must be at least 2 and --steps at least 1" in capsys.readouterr().err
    monkeypatch.setattr("sys.argv", ["step_parts.py", "--count", "60", "--landed-step", "3"])
    with pytest.raises(SystemExit) as stopped:
        step_parts.main()
    assert stopped.value.code == 2
    assert "--landed-step goes with --order landed" in capsys.readouterr().err
    monkeypatch.setattr("sys.argv", ["step_parts.py", "--count", "60", "--steps", "5", "--order", "landed",
                                     "--landed-step", "3"])
    step_parts.main()
    assert capsys.readouterr().out.startswith("rain N=60, 5 steps, spheres landed (Morton order of step 3's places): ")


def test_step_parts_in_turn_steps_each_order_to_the_same_contacts(monkeypatch, capsys):
    """--in-turn: every order named, each with its ms/step and the same contacts; a name
    that is not an order, or one named twice, is refused with what is allowed."""
    from benchmarks import step_parts

    monkeypatch.setattr("sys.argv", ["step_parts.py", "--count", "200", "--steps", "30", "--in-turn",
                                     "as-generated,morton,landed"])
    step_parts.main()
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "rain N=200, 30 steps, the orders stepped in turn in one process:"
    rows = [line.split() for line in out[1:]]
    assert [row[0] for row in rows] == ["as-generated", "morton", "landed"]
    assert float(rows[0][1]) > 0 and rows[0][2] == "ms/step,"
    assert len({row[3] for row in rows}) == 1 and int(rows[0][3]) > 0  # the same contacts in every order
    assert rows[0][5:7] == ["state", "hash"] and len(rows[0][7]) == 8
    for bad in ("morton,zigzag", "morton,morton"):
        monkeypatch.setattr("sys.argv", ["step_parts.py", "--in-turn", bad])
        with pytest.raises(SystemExit) as stopped:
            step_parts.main()
        assert stopped.value.code == 2
        assert "--in-turn takes distinct orders among as-generated, random, morton" in capsys.readouterr().err


def test_profile_annotation_puts_each_sample_beside_its_instruction_and_leads_up_to_the_hottest():
    from benchmarks.perf_profile import annotated, hottest

    listing = """
/tmp/x.o:     file format elf64-x86-64

Disassembly of section .text:

0000000000000010 <_ZN7physdbg6engine8timeline10_repredictB4v2E5ArrayIdLi2E>:
  10:	mov    (%rsi,%rcx,8),%rsi
  14:	mov    %rsi,%rdi
  17:	cmp    %r12,(%r9,%r8,8)
  1b:	jne    40 <_ZN7physdbg6engine8timeline10_repredictB4v2E5ArrayIdLi2E+0x30>
  1d:	jmp    10 <_ZN7physdbg6engine8timeline10_repredictB4v2E5ArrayIdLi2E>
"""
    rows = annotated(listing, {0x14: 30, 0x1b: 10, 0x99: 5})
    assert [(offset, count) for offset, count, _ in rows] == [(0x10, 0), (0x14, 30), (0x17, 0), (0x1b, 10), (0x1d, 0)]
    assert rows[3][2] == "jne    40 <+0x30>" and rows[4][2] == "jmp    10 <>"  # names dropped, offsets kept
    lines = hottest(rows, top=5, before=1)
    # hottest first, each after the instruction before it; instructions with no sample are not listed
    assert lines[0] == "-- 75.0 % of the function's samples at +0x14"
    assert lines[1].split()[:2] == ["0", "+0x10"] and lines[2].split()[:2] == ["30", "+0x14"]
    assert lines[3] == "-- 25.0 % of the function's samples at +0x1b"
    assert len(lines) == 6


def test_queue_benchmark_times_both_heaps_and_they_pop_the_same_order(monkeypatch, capsys):
    from benchmarks.experiments import event_queue

    monkeypatch.setattr("sys.argv", ["event_queue.py", "--sizes", "3", "200", "--ops", "3000"])
    event_queue.main()
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and all("binary (engine)" in line and "4-ary" in line and "same order" in line
                                   for line in lines)
    monkeypatch.setattr("sys.argv", ["event_queue.py", "--ops", "0"])
    with pytest.raises(SystemExit):
        event_queue.main()


def test_the_calendar_gas_makes_the_engines_collisions_with_either_queue_and_any_shell(capsys):
    """benchmarks/experiments/calendar_gas.py (small): the design with anchors that outlive
    the step, neighbour lists with a shell and one event per sphere makes the engine's
    collisions — the first ones pair for pair and time for time, and as many in all — with
    the heap and with the calendar, at a thin and a thick shell."""
    from benchmarks.experiments import calendar_gas

    calendar_gas.main(["--count", "300", "--steps", "30", "--rounds", "1", "--shells", "1.1", "1.6", "--first", "300"])
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("gas N=300, packing 0.3, periodic, 30 steps of 0.01 s")
    engine = int(out[1].split(": ")[1].split()[0])
    rows = out[2:]
    assert [row.split("  ")[1].strip() for row in rows] == ["shell 1.1, heap", "shell 1.1, calendar",
                                                            "shell 1.6, heap", "shell 1.6, calendar"]
    assert engine > 300 and all(f" {engine} collisions in " in row for row in rows)
    assert all(row.endswith("first 300 collisions the engine's: yes") for row in rows)
    with pytest.raises(SystemExit):
        calendar_gas.main(["--shells", "1.0"])


def test_step_shell_lists_hold_every_pair_the_steps_pair(capsys):
    """benchmarks/experiments/step_shell.py (small): a list kept across steps holds at least
    the pairs of every step it lasts (its boxes hold the steps' boxes), a list lasts at
    least one step, and a thicker skin holds more pairs; bad arguments stop with a usage error."""
    from benchmarks.experiments import step_shell

    found = step_shell.measure(step_shell.scene_of("gas", 200, 20), [0.05, 0.5])
    assert found["pairs"] > 0
    for skin in (0.05, 0.5):
        lasts, pairs = found[skin]
        assert 1.0 <= lasts <= 20.0 and pairs >= found["pairs"]
    assert found[0.5][1] > found[0.05][1]
    step_shell.main(["--count", "100", "--steps", "5", "--skins", "0.2"])
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("gas N=100, 5 steps: the step's broad phase pairs") and "skin 0.2 σ each side" in out[1]
    with pytest.raises(SystemExit):
        step_shell.main(["--skins", "0"])


def test_partner_scan_replays_the_same_hits_in_every_form(monkeypatch, capsys):
    from benchmarks.experiments import partner_scan

    monkeypatch.setattr("sys.argv", ["partner_scan.py", "--count", "300", "--step", "100", "--spheres", "2000"])
    partner_scan.main()  # raises SystemExit if two forms disagree on the hits
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("box-rain N=300, step 100: 2000 re-predicted spheres")
    forms = [line.split("  ")[1].strip() for line in out[1:]]
    assert forms[:3] == ["numba", "numba, unsigned", "numba, packed"] and forms[3].startswith("C")
    hits = {line.split("(")[1] for line in out[1:4]}
    assert len(hits) == 1 and hits != {"0 hits)"}
    monkeypatch.setattr("sys.argv", ["partner_scan.py", "--spheres", "0"])
    with pytest.raises(SystemExit):
        partner_scan.main()


def test_profile_refuses_a_listings_folder_that_is_not_there_before_it_runs(monkeypatch, capsys, tmp_path):
    from benchmarks import perf_profile

    missing = tmp_path / "nowhere"
    monkeypatch.setattr("sys.argv", ["perf_profile.py", "rain", "--annotate", "physdbg.engine.timeline._repredict",
                                     "--listings", str(missing)])
    with pytest.raises(SystemExit) as stopped:
        perf_profile.main()
    assert stopped.value.code == 2
    assert f"--listings {missing}: no such folder" in capsys.readouterr().err


def test_audit_cost_times_both_scenes_check_by_check_and_leaves_the_auditor_as_it_was(monkeypatch, capsys):
    """benchmarks/audit_cost.py as a user runs it (small): both scenes' lines, each check's
    time; the timing wrappers are taken off again; a bad count ends with argparse's exit 2."""
    from benchmarks import audit_cost
    from physdbg.analysis import audit, tunnel

    before = (audit.Auditor._check_crossings, tunnel.pair_crossings, audit.AUDIT_CHECKS)
    monkeypatch.setattr("sys.argv", ["audit_cost.py", "--count", "200", "--steps", "5", "--gas-count", "100",
                                     "--gas-steps", "5", "--rounds", "1"])
    audit_cost.main()
    out = capsys.readouterr().out
    assert out.startswith("box-rain 200: engine alone ") and "exact gas 100 (packing 0.3): engine alone " in out
    assert out.count("with the default audit") == 2 and out.count(", with --full-audit") == 2
    assert out.count("_check_crossings") == 2 and "pair_crossings" in out
    assert (audit.Auditor._check_crossings, tunnel.pair_crossings, audit.AUDIT_CHECKS) == before
    monkeypatch.setattr("sys.argv", ["audit_cost.py", "--count", "1"])
    with pytest.raises(SystemExit) as stopped:
        audit_cost.main()
    assert stopped.value.code == 2 and "at least 2" in capsys.readouterr().err


def test_edmd_harness_sets_the_parameters_writes_the_spheres_in_sigma_and_reads_the_count(tmp_path, monkeypatch,
                                                                                        capsys):
    """benchmarks/edmd.py without the foreign code: a stand-in Single/ with EDMD's globals
    and Makefile, whose program prints what EDMD prints; the harness sets maxtime, turns the
    thermostat off, gives it the gas in σ units and reads the last collision count. A folder
    that is not a checkout ends with argparse's exit 2."""
    from benchmarks import edmd

    single = tmp_path / "EDMD" / "Single"
    single.mkdir(parents=True)
    (single / "mdSingle.c").write_text(
        '#include <stdio.h>\n#include "mdSingle.h"\n'
        "double maxtime = 100;           //Simulation stops at this time\n"
        'int initialconfig = 1;\nchar inputfilename[100] = "x.sph";\nconst int usethermostat = 1;\n'
        'int main(void) { FILE *f = fopen(inputfilename, "r"); int n = 0; if (!f || fscanf(f, "%d", &n) != 1) '
        'return 3; printf("Simtime: 1, Collisions: 7, T: 1\\nSimtime: 2, Collisions: %d, T: %d\\n'
        'Packing fraction      : 0.300000\\n", (int)(n * maxtime), usethermostat + initialconfig); return 0; }\n')
    (single / "mdSingle.h").write_text("")
    (single / "mt19937ar.c").write_text("")
    (single / "Makefile").write_text("md: mdSingle.c mdSingle.h\n\tgcc mdSingle.c -o md\n")
    scene = edmd.gas_scene(64, 0.3, 1)
    build = tmp_path / "build"
    build.mkdir()
    edmd.write_sph(scene, build / "init.sph")
    lines = (build / "init.sph").read_text().splitlines()
    assert lines[0] == "64" and len(lines) == 66
    side = float(lines[1].split()[0])
    rows = np.array([[float(q) for q in line.split()[1:]] for line in lines[2:]])
    assert np.allclose(rows[:, 3], 0.5) and side == pytest.approx(scene.walls.period[0] / 0.1)
    assert np.pi / 6 * 64 / side**3 == pytest.approx(0.3, rel=1e-9)  # the packing, in σ units
    program = edmd.build_edmd(single, build, 2.5)
    collisions, cpu, packing = edmd.run_edmd(program)
    assert collisions == 160 and packing == "0.300000" and cpu >= 0.0  # 64 · maxtime, the last count
    code = (build / "mdSingle.c").read_text()
    assert "double maxtime = 2.5;" in code and "const int usethermostat = 0;" in code
    assert 'char inputfilename[100] = "init.sph";' in code and "int initialconfig = 0;" in code
    monkeypatch.setattr("sys.argv", ["edmd.py", "--edmd", str(tmp_path)])
    with pytest.raises(SystemExit) as stopped:
        edmd.main()
    assert stopped.value.code == 2 and "no Single/mdSingle.c there" in capsys.readouterr().err


def test_gas_benchmark_runs_either_event_loop_in_a_periodic_box(monkeypatch, capsys):
    """benchmarks/gas.py (small): the calendar's rates and phases, in a periodic box."""
    from benchmarks import gas

    monkeypatch.setattr("sys.argv", ["gas.py", "--count", "100", "--steps", "5", "--periodic",
                                     "--event-loop", "calendar"])
    gas.main()
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("gas N=100, packing 0.3, periodic box, event_loop = calendar, 5 steps of 0.01 s")
    assert "pair collisions" in out[1] and "resolve" in out[2]


def test_calendar_scenes_benchmark_says_where_the_calendar_served_each_scene(monkeypatch, capsys):
    """benchmarks/calendar_scenes.py (small): a row per scene with both loops' times, the
    calendar's measured phases and the run summary's words on where it served."""
    from benchmarks import calendar_scenes

    monkeypatch.setattr("sys.argv", ["calendar_scenes.py", "--longest", "0.1", "--scene", "cradle", "--scene",
                                     "paddle"])
    calendar_scenes.main()
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("scene") and len(out) == 3
    cradle, paddle = out[1].split(), out[2].split()
    assert cradle[0] == "cradle" and cradle[1] == "6" and out[1].endswith("calendar in 6 of 6 steps")
    shares = [float(p.rstrip("%,")) for p in cradle[4:9]]
    assert shares[3] > 0 and abs(sum(shares) - 100) <= 3  # measured: resolve takes time, the shares make the whole
    assert paddle[0] == "paddle" and "calendar in 0 of 6 steps" in out[2] and "kinematic mesh" in out[2]
