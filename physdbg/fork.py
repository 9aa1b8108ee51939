"""Forking a recording, and trying advice on a fork (docs/recording.md, "Forking a recording").

``fork_recording`` repeats a recorded run up to a step in one world, so that everything
the engine carries across steps comes along, and goes on from there with settings
changed (World.retune); ``try_advice`` forks a run at each finding whose advice is a
change of settings and says what the change did (``physdbg explain --try``). A layer
above api: it records, verifies, audits and diffs through it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

from .api import RecordResult, diff, explain, record, verify
from .errors import PhysdbgError


def fork_recording(parent: str | Path, at: int, overrides: Sequence[str] = (), steps: int | None = None,
                   mcap_path: str | None = None, rrd_path: str | None = None, rrd: bool = True,
                   detail: str | None = None, force: bool = False,
                   on_step: Callable[[int, int | None], None] | None = None,
                   on_status: Callable[[str], None] | None = None, view: bool | None = None) -> RecordResult:
    """Fork a recording at the start of step ``at`` (K, from 1): the run repeats its parent
    up to the state of frame K-1, every engine state the parent carried included, then the
    settings ``overrides`` (``key=value``: only World.retune's RETUNABLE_SETTINGS and dt)
    apply from step K, to the parent's end (its end time, with another dt) or for
    ``steps`` steps from K. The new recording is whole (replay, explain, verify), frame
    for frame beside its parent up to K, and says where it came from (header ``fork``:
    the parent's file, run id, the hash of frame K-1, K, the changes, a changed dt, and
    ``chain``: every change with its step, the parent's own kept unless this fork sets
    them). With no change it is its parent bit for bit. detail: the parent's unless given.

    The steps before K are taken again, not read: the parent's states are the whole
    state only with what the engine carries across steps (held contacts, sleep, the
    rapid-contact times, its own numbering), which a recording does not hold. The
    parent's stored states up to K are checked against their hashes first; the steps
    taken again are checked against them once the fork is written (a parent that does not
    repeat is refused, PhysdbgError naming the step, and the fork removed)."""
    from .engine.world import RETUNABLE_SETTINGS
    from .record import open_recording
    from .scene import scene_from_dict

    with open_recording(parent) as rec:
        foreign = rec.meta.get("foreign")
        if foreign:
            raise PhysdbgError(f"{parent} is a run of another engine (imported from {foreign['source']}): there is no "
                               "physdbg run to fork; record the scene with physdbg and fork that")
        if not 1 <= at <= rec.steps:
            raise PhysdbgError(f"--at {at}: {parent} has steps 1..{rec.steps}; a fork starts at one of them")
        allowed = (*RETUNABLE_SETTINGS, "dt")
        for item in overrides:
            key = item.split("=", 1)[0].strip()
            if key not in allowed:
                raise PhysdbgError(f"--set {item}: {key} cannot change in the middle of a run (a fork starts from the "
                                   f"state the parent reached); a fork may change {', '.join(allowed)}")
        before = rec.scene
        info = rec.meta["scene"]
        meshes = rec.header.walls.meshes if len(rec.header.walls.meshes) else None
        after = scene_from_dict(info["table"], f"{info['source']} (from {Path(parent).name})", meshes,
                                [item for item in overrides if not item.startswith("dt")])
        # the parent's own fork chain: what it changed before K stays, what it changed at or
        # after K too, unless this fork sets it (then this fork's value holds from K on)
        from .analysis.diff_causes import settings_at

        chain = list((rec.meta.get("fork") or {}).get("chain", []))
        running = settings_at({"settings": {}, "fork": {"chain": [e for e in chain if e["at"] < at]}})
        base = {name: running.get(name, getattr(before.settings, name)) for name in RETUNABLE_SETTINGS}
        at_k = next((dict(e["changes"]) for e in chain if e["at"] == at), {})
        changes = {}
        for name in RETUNABLE_SETTINGS:
            if any(item.split("=", 1)[0].strip() == name for item in overrides):
                value = getattr(after.settings, name)
                if value == "auto":
                    raise PhysdbgError(f"--set {name}=auto: a fork takes the value itself (auto is decided for a "
                                       f"whole scene before its first step)")
                at_k.pop(name, None)
                changes[name] = value  # what the fork sets holds from K on, even where it is the value then
        set_here = set(changes)
        changes_needed = {name: value for name, value in changes.items() if value != base[name]}
        chain = ([e for e in chain if e["at"] < at] + ([{"at": at, "changes": {**at_k, **changes_needed}}]
                                                       if at_k or changes_needed else [])
                 + [{"at": e["at"], "changes": {k: v for k, v in e["changes"].items() if k not in set_here}}
                    for e in chain if e["at"] > at])
        chain = [e for e in chain if e["changes"]]
        table = rec.frame_table()
        for _ in rec.states(0, at):  # each stored state up to K against its hash and the index: a damaged parent
            pass                     # is refused here (RecordingIntegrityError names the frame)
        dts = [float(d) for d in table.dt[1:]]
        new_dt = next((item.split("=", 1)[1] for item in overrides if item.split("=", 1)[0].strip() == "dt"), None)
        if new_dt is not None:
            from .scene import STEP_LENGTH_RANGE, step_length

            dt = step_length(new_dt.strip())
            if dt is None:
                raise PhysdbgError(f"--set dt={new_dt}: a step's length is a number of seconds {STEP_LENGTH_RANGE}")
            remaining = float(table.time[-1] - table.time[at - 1])
            count = steps if steps is not None else max(1, math.floor(remaining / dt + 1e-9))  # not past its end
            after_k = [dt] * count
        else:
            after_k = dts[at - 1:] if steps is None else (dts[at - 1:at - 1 + steps] + [dts[-1]] *
                                                          max(0, steps - len(dts[at - 1:])))
        fork = {"parent": Path(parent).name, "parent_run_id": rec.meta.get("run_id"),
                "parent_hash": table.hash_hex(at - 1), "at": at, "changes": changes,
                "dt": dt if new_dt is not None else None, "chain": chain}
        parent_hashes = [table.hash_hex(k) for k in range(at)]
        parent_detail = rec.detail
    before.overrides = tuple(overrides)
    result = record(before, mcap_path=mcap_path, rrd_path=rrd_path, rrd=rrd, detail=detail or parent_detail,
                    force=force, dts=dts[:at - 1] + after_k, on_step=on_step, on_status=on_status, view=view,
                    fork=fork)
    with open_recording(result.mcap) as made:  # the steps before K are the parent's, bit for bit
        mine = made.frame_table()
        for k in range(1, at):
            if mine.hash_hex(k) != parent_hashes[k]:
                Path(result.mcap).unlink(missing_ok=True)
                if result.rrd:
                    Path(result.rrd).unlink(missing_ok=True)
                raise PhysdbgError(f"{parent} does not repeat: step {k} taken again gives another state than the "
                                   f"recorded one (a file from another physdbg, or an altered one; `physdbg replay "
                                   f"--verify {parent}` says more): no fork is made from it")
    result.fork = fork
    return result


TRY_STEPS = 20  # steps after a finding's own that a try of its advice runs (explain --try-steps)


def try_advice(path: str | Path, report, steps: int = TRY_STEPS) -> list[dict]:
    """Try each piece of advice of an audit (``report``, explain's AuditReport of the
    recording ``path``, or a RunSummary: anything with ``findings``) that is a change of
    settings (Finding.try_settings), on the run itself (try_change). Each kind's first
    finding with such advice is tried once per change. Sets and returns report.tried."""
    tried, seen, before = [], set(), {}
    for finding in report.findings:
        key = (finding.kind, tuple(sorted(finding.try_settings.items())))
        if not finding.try_settings or key in seen:
            continue
        seen.add(key)
        tried.append(try_change(path, finding.step, finding.try_settings, finding.kind, finding.particles, steps,
                                before))
    report.tried = tried
    return tried


def try_causes(report, steps: int = TRY_STEPS) -> list[dict]:
    """Try each cause of a diff (``report``, api.diff's DiffReport) whose advice is a change
    of settings (Cause.try_settings: a tunnelling in one run), on the run it happened in
    (A or B, the cause's evidence["run"]): try_change at the cause's step, the finding
    looked for being the audit's of that kind about the cause's bodies. Each (run, kind,
    change) is tried once. Sets and returns report.tried, each with "run" ("A" or "B")."""
    tried, seen, before = [], set(), {}
    for cause in report.causes:
        label = cause.evidence.get("run") if isinstance(cause.evidence, dict) else None
        key = (label, cause.kind, tuple(sorted(cause.try_settings.items())))
        if not cause.try_settings or cause.step is None or label not in ("A", "B") or key in seen:
            continue
        seen.add(key)
        path = report.a if label == "A" else report.b
        tried.append({"run": label, **try_change(path, cause.step, cause.try_settings, cause.kind,
                                                 list(cause.bodies), steps, before.setdefault(label, {}))})
    report.tried = tried
    return tried


def try_change(path: str | Path, at: int, settings: dict, kind: str, particles: Sequence[int],
               steps: int = TRY_STEPS, before: dict | None = None) -> dict:
    """Try a change of settings on the recording ``path`` for a finding of ``kind`` about
    ``particles`` at step ``at``: a fork at the start of that step with the change, for
    that step and ``steps`` more (fork_recording), audited. Returns one dict: the finding
    (kind, step, particles), settings, steps, gone (no finding of its kind at its step
    about its spheres in the fork), left (findings of its kind in the fork's window, and
    left_in_run: in the run's), in_run (the run's own audit names it: where it does not,
    nothing was there to remove, and gone is False), changed (diff's result line of the run against the fork:
    what else the change did), ms_before / ms_after (the engine's ms a step over the
    window in each), verified (the fork verifies). before: a dict this call may keep the
    run's own audit in, for the next call on the same run."""
    import tempfile

    from .events import STEP_PHASES
    from .record import open_recording

    before = {} if before is None else before
    with open_recording(path) as rec:
        last = rec.steps
    window = min(steps + 1, last - at + 1)
    with tempfile.TemporaryDirectory() as folder:
        fork = Path(folder) / "try.mcap"
        made = fork_recording(path, at, [f"{name}={value}" for name, value in settings.items()],
                              steps=window, mcap_path=str(fork), rrd=False, detail="contacts")
        after = explain(fork, every_finding=True)
        if "audit" not in before:
            before["audit"] = explain(path, every_finding=True)
        in_window = [f for f in after.findings if f.kind == kind and at <= f.step < at + window]
        run_window = [f for f in before["audit"].findings if f.kind == kind and at <= f.step < at + window]
        gone = not any(f.step == at and set(f.particles) == set(particles) for f in in_window)
        # a diff's cause is its own check's: the run's audit may not name it (then nothing was removed)
        in_run = any(f.step == at and set(f.particles) == set(particles) for f in run_window)
        changed = diff(path, fork)
        with open_recording(path) as a, open_recording(fork) as b:
            ms = [1000.0 * float(sum(r[f"seconds_{phase}"].sum() for phase in STEP_PHASES)) / window
                  for r in (a.stats(at, at + window), b.stats(at, at + window))]
        return {"kind": kind, "step": at, "particles": list(particles), "settings": dict(settings),
                "steps": window, "gone": gone and in_run, "in_run": in_run, "left": len(in_window),
                "left_in_run": len(run_window),
                "changed": changed.headline, "ms_before": ms[0], "ms_after": ms[1], "verified": verify(made.mcap).ok}
