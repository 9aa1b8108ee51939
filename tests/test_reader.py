"""The reader's integrity rules (docs/recording.md, "Integrity"): every command that reads a
recording refuses one that contradicts itself, with exit 2, naming the file and the frame."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from physdbg import api
from physdbg.cli import app
from physdbg.record import open_recording
from physdbg.record.reader import RecordingIntegrityError

from . import tamper

FRAME = 40


@pytest.fixture(scope="module")
def bounce(tmp_path_factory):
    """A recording of bounce (300 steps, contacts), made once for the module."""
    folder = tmp_path_factory.mktemp("bounce")
    path = folder / "bounce.mcap"
    api.record("bounce", [], mcap_path=str(path), rrd=False, detail="contacts")
    return path


def _commands(good, bad, tmp_path):
    """Every command that reads a recording, pointed at ``bad``."""
    return {
        "diff": ["diff", str(good), str(bad)],
        "diff (bad first)": ["diff", str(bad), str(good)],
        "explain": ["explain", str(bad)],
        "replay": ["replay", str(bad), "--rrd", str(tmp_path / "bad.rrd")],
        "replay --verify": ["replay", str(bad), "--verify"],
    }


def _refused_everywhere(good, bad, tmp_path, *expected):
    runner = CliRunner()
    for name, command in _commands(good, bad, tmp_path).items():
        result = runner.invoke(app, command)
        assert result.exit_code == 2, (name, result.output)
        assert "Traceback" not in result.output and "internal error" not in result.output, (name, result.output)
        assert str(bad) in result.output, (name, result.output)
        for words in expected:
            assert words in result.output, (name, result.output)
    assert not (tmp_path / "bad.rrd").exists()  # no half-made picture left behind


@pytest.mark.slow
def test_an_edited_state_with_its_old_hash_is_refused_naming_the_frame(bounce, tmp_path):
    bad = tamper.nudge_state(bounce, tmp_path / "kept.mcap", FRAME)
    _refused_everywhere(bounce, bad, tmp_path, f"frame {FRAME}", "does not give its stored hash")


@pytest.mark.slow
def test_an_edited_state_with_a_rewritten_hash_is_refused_by_the_frame_index(bounce, tmp_path):
    bad = tamper.nudge_state(bounce, tmp_path / "rehashed.mcap", FRAME, rehash=True)
    _refused_everywhere(bounce, bad, tmp_path, f"frame {FRAME}", "the frame index and the stored state disagree")


def test_a_consistent_forgery_reads_and_diff_says_the_state_changed_outside_the_engine(bounce, tmp_path):
    """State, its hash and the index all rewritten: nothing in the file contradicts
    anything, so it reads; diff names the frame and calls it an outside change."""
    forged = tamper.nudge_state(bounce, tmp_path / "forged.mcap", FRAME, rehash=True, reindex=True)
    report = api.diff(bounce, forged)
    assert report.exit_code == 1 and report.divergence.step == FRAME
    assert report.causes[0].kind == "outside-change"


def test_no_verify_is_the_explicit_escape(bounce, tmp_path):
    bad = tamper.nudge_state(bounce, tmp_path / "kept.mcap", FRAME)
    result = CliRunner().invoke(app, ["explain", str(bad), "--no-verify"])
    assert result.exit_code in (0, 1), result.output
    result = CliRunner().invoke(app, ["diff", str(bounce), str(bad), "--no-verify"])
    assert result.exit_code in (0, 1), result.output
    result = CliRunner().invoke(app, ["replay", str(bad), "--verify", "--no-verify"])
    assert result.exit_code == 2 and "give one" in result.output


@pytest.mark.parametrize("second", ["same", "other"])
def test_two_recordings_joined_into_one_file_are_refused(bounce, tmp_path, second):
    other = bounce
    if second == "other":
        other = tmp_path / "other.mcap"
        api.record("bounce", ["steps=50"], mcap_path=str(other), rrd=False, detail="contacts")
    joined = tamper.concatenate([bounce, other], tmp_path / "joined.mcap")
    with pytest.raises(RecordingIntegrityError, match="joined together"):
        open_recording(joined)
    _refused_everywhere(bounce, joined, tmp_path, "joined together")
    result = CliRunner().invoke(app, ["info", str(joined)])
    assert result.exit_code == 2 and "joined together" in result.output


def test_a_file_with_two_scene_headers_is_refused(bounce, tmp_path):
    bad = tamper.second_scene(bounce, tmp_path / "two.mcap")
    _refused_everywhere(bounce, bad, tmp_path, "more than one recording")


@pytest.mark.slow
def test_frames_out_of_order_are_refused(bounce, tmp_path):
    bad = tamper.swap_frames(bounce, tmp_path / "swapped.mcap", FRAME)
    _refused_everywhere(bounce, bad, tmp_path, "out of order")


def test_a_damaged_summary_is_refused(bounce, tmp_path):
    """One flipped byte in the summary section (its schema names live there)."""
    data = bytearray(bounce.read_bytes())
    at = data.rfind(b"physdbg.Particles")
    assert at > len(data) // 2  # the copy in the summary, not the one at the start
    data[at + 10] ^= 0x01
    bad = tmp_path / "summary.mcap"
    bad.write_bytes(bytes(data))
    _refused_everywhere(bounce, bad, tmp_path, "summary")


def test_a_good_file_checks_every_state_it_reads(bounce):
    with open_recording(bounce) as rec:
        assert rec.checked_frames == 1  # frame 0, read for the header
        for _ in rec.states():
            pass
        assert rec.checked_frames == rec.frames
    report = api.diff(bounce, bounce)
    assert report.exit_code == 0


def test_a_warning_names_its_spheres_in_new_files_and_a_pinned_one_in_older_files():
    """A recorded warning's bodies are read as written; a file made before warnings named
    them still gives a pinned warning its sphere (the one its message names first), so
    explain's pinned finding points at it; other warnings of such a file name none."""
    from physdbg.record.reader import _warning_bodies

    pinned = "sphere 3 is pinned between wall 'floor' and mesh 'press' triangle 1, which close on it"
    assert _warning_bodies({"code": "overlap", "message": "spheres 1 and 2 overlap", "bodies": [1, 2]}) == (1, 2)
    assert _warning_bodies({"code": "pinned", "message": pinned}) == (3,)
    assert _warning_bodies({"code": "overlap", "message": "spheres 1 and 2 overlap by 1 mm"}) == ()
