"""What the CLI calls: run a scene and summarise it.

Why one module of this size: it is the library's one public surface — each command's one
function (run, record, replay, diff, explain, check, check-run, import, record-peer, scenes
show, the benches), each a short composition of the layers below it, so that a user reads
one page of entry points. The work itself lives in engine/, record/ and analysis/.

>>> from physdbg.api import run
>>> summary = run("bounce", ["duration=1.0"])
>>> summary.steps, summary.contacts
(60, 2)
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from collections.abc import Callable, Sequence
import dataclasses
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .errors import NonFiniteRunError, PhysdbgError, RecordingInterrupted, StuckRunError
from .advisor import decide, mesh_sizes
from .events import partner_words
from .scene import Scene, read_scene


@dataclass
class RunSummary:
    """What a run did. Energies in J, momentum in kg·m/s, times in s (ms_per_step in ms).

    rapid: contacts the rapid-contact (TC) rule acted on; released: held contacts let go (all
    steps; beside rapid, a pile's churn); held_at_end: contacts held at the end.
    asleep_at_end, slept, woken: spheres asleep at the end, fallen asleep and woken over
    the run (sleeping, engine/sleep.py; 0 with it off).
    energy_drift: (E_end - E_start) / |E_start| of kinetic + potential (0 when E_start = 0);
    momentum_drift: |p_end - p_start| (kg·m/s); dts: every step's dt, to repeat the run.
    compile_seconds: compiling (first run) or loading (cached) the numba kernels, not
    counted in wall_seconds or ms_per_step. ms_per_step: the whole loop (the engine and
    whatever observes it: a recorder, the audit); engine_ms_per_step: the engine's own five
    phases (phase_seconds), what a run costs without observers. walls: the walls' names.
    warning_counts: how many engine warnings of each kind (code); warnings: the first few of
    each kind, each {step, code, message, bodies} with the step counted from 1 (step k ends
    at frame k of a recording). finding_counts / findings: what the audit found
    (physdbg.analysis.audit: tunnelling, overlaps, out-of-order contacts, energy gained,
    NaN, budgets, collapse), per kind and the first few (audit.Finding; in the JSON each
    finding's fields); empty when the run is clean or was not audited. The sentences are
    report.summary_text's. audit_pairs: {from_engine, steps}, in how many of the steps the
    audit took the pairs of spheres from the engine's own swept tests instead of walking
    their paths again ({} when the run was not audited). event_loop: where the event
    calendar was asked for, {calendar_steps, steps, unfit}: the steps it served and why the
    last it could not serve could not (None), {} for the time-ordered loop.
    """

    scene: str
    source: str
    integrator: str
    detection: str
    ordering: str
    broad_phase: str
    broad_phase_reason: str
    scanned_steps: int
    together_steps: int
    mesh_search: str
    particles: int
    walls: list[str]
    steps: int
    sim_time: float
    contacts: int
    swept_tests: int
    held_at_end: int
    rapid: int
    released: int
    asleep_at_end: int
    slept: int
    woken: int
    max_contacts_in_a_step: int
    energy_start: float
    energy_end: float
    energy_drift: float
    momentum_start: list[float]
    momentum_end: list[float]
    momentum_drift: float
    max_overlap: float
    wall_seconds: float
    compile_seconds: float
    ms_per_step: float
    engine_ms_per_step: float
    phase_seconds: dict[str, float]
    final_hash: str
    warning_counts: dict[str, int] = field(default_factory=dict)
    warnings: list[dict] = field(default_factory=list)
    finding_counts: dict[str, int] = field(default_factory=dict)
    # the collider kinds of the run's partners the audit's tunnelling check has no rule for
    audit_unchecked: list[str] = field(default_factory=list)
    findings: list = field(default_factory=list)  # audit.Finding
    dts: list[float] = field(default_factory=list, repr=False)
    auto: dict = field(default_factory=dict)  # setting -> advisor.Decision, for settings given as auto

    meshes: dict[str, int] = field(default_factory=dict)  # each fixed mesh's name: its triangles
    # partners of each collider kind declaring its own fields (docs/colliders.md): kind name: how many
    partners: dict[str, int] = field(default_factory=dict)
    mesh_notes: list[str] = field(default_factory=list)  # what loading the meshes left out
    # the engine's tier (tier.py): {interpreted: bool, why: its words}
    kernels: dict = field(default_factory=lambda: {"interpreted": False, "why": "compiled"})
    meshes_move: bool = False  # two meshes or more, one kinematic: the audit looks for them passing into each other
    # who overlapped most and in which step, when known and past the contact tolerance:
    # {step, kind, sphere, partner, partner_name} (overlap_parties)
    overlap_where: dict = field(default_factory=dict)
    start_notes: list[str] = field(default_factory=list)  # the spheres that start inside another body
    meshes_driven: bool = False  # a kinematic mesh: its prescribed motion does work on what it strikes
    audit_pairs: dict = field(default_factory=dict)
    event_loop: dict = field(default_factory=dict)
    # each finding's advice tried on a fork (fork.try_advice: record --try), as explain's
    tried: list = field(default_factory=list)

    def as_dict(self) -> dict:
        """The JSON's fields: every field above, each finding as its own (audit.Finding.as_dict)."""
        return {**asdict(self), "findings": [f.as_dict() for f in self.findings]}


def overlap_parties(parties: tuple[int, int, int], step: int, names) -> dict:
    """RunSummary.overlap_where of the deepest overlap's (kind, sphere, partner) in ``step``
    (StepEnd.overlap_with), the partner named as reports name it (events.partner_words)."""
    kind, sphere, partner = (int(q) for q in parties)
    return {"step": int(step), "kind": kind, "sphere": sphere, "partner": partner,
            "partner_name": partner_words(kind, partner, names)}


def calendar_use(world, steps: int) -> dict:
    """Where a world asked for the event calendar used it: {calendar_steps, steps, unfit}
    (RunSummary.event_loop), {} when it was not asked for."""
    if world.settings.event_loop != "calendar":
        return {}
    return {"calendar_steps": world.calendar_steps, "steps": steps,
            "unfit": world.calendar_unfit if world.calendar_steps < steps else None}


def load_scene(scene: str, overrides: Sequence[str] = ()) -> Scene:
    """Load a built-in scene or a TOML file with ``key=value`` overrides, validate it, and
    decide its "auto" settings (physdbg.advisor.decide; scene.auto says why): a scene
    ready to build a World from."""
    return decide(read_scene(scene, list(overrides)))


def ready_scene(scene: Scene | str, overrides: Sequence[str] = ()) -> Scene:
    """A scene ready to run: a name or path is loaded (load_scene); a Scene has its "auto"
    settings decided (overrides belong to loading, so a Scene with overrides is refused)."""
    if not isinstance(scene, Scene):
        return load_scene(scene, overrides)
    if overrides:
        raise PhysdbgError("give overrides when loading the scene, not with a Scene object")
    return decide(scene)


def run(scene: Scene | str, overrides: Sequence[str] = (), observer=None,
        dts: Sequence[float] | None = None,
        on_step: Callable[[int, int | None], None] | None = None,
        on_status: Callable[[str], None] | None = None, audit: bool | str = True,
        on_finding: Callable | None = None, fork: dict | None = None) -> RunSummary:
    """Run a scene (built-in name, path, or Scene) to the end and summarise it.

    dts: replay exactly these step lengths (e.g. from a real-time run) instead of the
    scene's dt. on_step(done, total): called after each step (for progress bars).
    on_status(what): "compiling" before the kernels are compiled or loaded, "running"
    when the first step starts. Raises NonFiniteRunError (exit code 3) when a position or
    velocity becomes NaN or infinite, StuckRunError (its base, exit code 3) when the world
    cannot go on otherwise (a sphere pinned by a moving mesh: errors.PinnedSphere); the
    observer has seen every step up to that one.
    audit: check every step as it runs (physdbg.analysis.audit): True takes the pairs of
    spheres of a step whose swept tests were exact and complete from the engine
    (audit.engine_tests_exact), "full" walks every pair's path again as ``explain`` does,
    False does not audit; on_finding(finding): called with each finding as it is made.
    fork: a fork's header entry (fork_recording): its chain's settings change before
    each of its steps (World.retune), and the audit takes them there too.
    """
    scene = ready_scene(scene, overrides)
    from .advisor import meshes_out_of_reach, start_words, starting_overlaps
    from .engine import NonFiniteState, energies, state_hash
    from .errors import WorldStuck
    from .events import RunTally
    from .interrupt import StopOnCtrlC
    from .observe import FanOut
    from .precompile import compile_kernels
    from .tier import chosen as chosen_tier

    if audit not in (True, False, "full"):
        raise PhysdbgError(f"audit must be True, False or 'full', not {audit!r}")
    auditor = None
    if audit:
        from .analysis.audit import Auditor
        from .record.header import RecordingHeader

        header = RecordingHeader.from_scene(scene)
        if fork is not None:
            header.meta["fork"] = fork  # the audit takes the fork's settings from their steps on
        auditor = Auditor(header, on_finding, engine_tested=audit != "full")
        observer = FanOut(observer, auditor) if observer is not None else auditor
    overlaps = starting_overlaps(scene)  # said before a step is run: the run cannot mend them
    start_notes = [start_words(overlaps)] if overlaps else []
    out_of_reach = meshes_out_of_reach(scene)
    world = scene.build_world(observer)
    kernels = chosen_tier()
    if on_status is not None and not kernels.interpreted:
        on_status("compiling")
    compile_seconds = 0.0 if kernels.interpreted else compile_kernels(
        world.broad_phase.name, sleeping=world.sleepers is not None, audit=auditor is not None,
        meshes=bool(scene.walls.meshes.triangles), calendar=scene.settings.event_loop == "calendar")
    if on_status is not None:
        on_status("running")
    st = world.state

    k0, p0, mom0 = energies(st, world.gravity)
    total = len(dts) if dts is not None else scene.steps
    used: list[float] = []
    tally = RunTally()
    warnings = WarningTally()
    started = time.perf_counter()
    digest = state_hash(st.positions, st.velocities)
    with StopOnCtrlC(world):  # Ctrl-C ends even a long step within a second (interrupt.py)
        for dt in scene.step_lengths(dts):
            for entry in (fork or {}).get("chain", []):
                if entry["at"] == len(used) + 1:
                    world.retune(entry["changes"])
            try:
                end = world.step(dt)
            except NonFiniteState as err:
                raise NonFiniteRunError(f"{err}: the run stopped there (a NaN or infinity cannot be stepped on); "
                                        f"look at the contacts of that step") from None
            except WorldStuck as err:
                raise StuckRunError(f"{err}; the run stopped after that step") from None
            used.append(dt)
            tally.add(end)
            warnings.add(end.warnings)
            digest = end.state_hash
            if on_step is not None:
                on_step(len(used), total)
    wall = time.perf_counter() - started
    report = auditor.report(scene.name) if auditor else None  # before its counts: it ends what waits
    k1, p1, mom1 = energies(st, world.gravity)
    e0, e1 = k0 + p0, k1 + p1
    drift = (e1 - e0) / abs(e0) if e0 != 0 else (e1 - e0)
    n_steps = len(used)
    return RunSummary(
        auto=dict(scene.auto),
        scene=scene.name, source=scene.source, integrator=scene.settings.integrator,
        detection=scene.settings.detection, ordering=scene.settings.ordering,
        broad_phase=world.broad_phase.name,
        broad_phase_reason=world.broad_phase_reason, scanned_steps=world.scanned_steps,
        together_steps=world.together_steps, mesh_search=scene.settings.mesh_search,
        event_loop=calendar_use(world, n_steps),
        particles=st.count, walls=list(scene.walls.names), meshes=mesh_sizes(scene.walls.meshes),
        partners={kind: len(partners) for kind, partners in scene.walls.partners.items()},
        meshes_move=bool(scene.walls.meshes.moving.any()) and len(scene.walls.meshes) > 1,
        mesh_notes=list(scene.walls.meshes.notes) + [
            f"'{name}' {scene.walls.meshes.motion_words(k)}" for k, name in enumerate(scene.walls.meshes.names)
            if scene.walls.meshes.moving[k]] + out_of_reach, steps=n_steps,
        sim_time=world.time,
        contacts=tally.total["contacts"], swept_tests=tally.total["swept_tests"],
        held_at_end=tally.total["held"], rapid=tally.total["rapid"], released=tally.total["released"],
        asleep_at_end=tally.total["asleep"], slept=tally.total["slept"], woken=tally.total["woken"],
        max_contacts_in_a_step=tally.most["contacts"], energy_start=e0, energy_end=e1, energy_drift=drift,
        momentum_start=[float(c) for c in mom0], momentum_end=[float(c) for c in mom1],
        momentum_drift=float(np.linalg.norm(mom1 - mom0)), max_overlap=tally.max_overlap,
        start_notes=start_notes, meshes_driven=bool(scene.walls.meshes.moving.any()),
        overlap_where=(overlap_parties(tally.overlap_with, tally.overlap_step, scene.walls.partner_names())
                       if tally.overlap_with is not None and tally.max_overlap > scene.settings.contact_tolerance
                       else {}),  # (a rounding-sized overlap, within the tolerance, is nobody's doing)
        kernels={"interpreted": kernels.interpreted, "why": kernels.reason}, wall_seconds=wall, compile_seconds=compile_seconds, ms_per_step=1000.0 * wall / n_steps if n_steps else math.nan,
        engine_ms_per_step=1000.0 * sum(tally.seconds.values()) / n_steps if n_steps else math.nan,
        phase_seconds=tally.seconds, final_hash=digest, warning_counts=dict(warnings.counts),
        warnings=warnings.examples(), findings=list(report.findings) if report else [],
        finding_counts=dict(auditor.counts) if auditor else {}, dts=used,
        audit_unchecked=list(auditor.unchecked_kinds) if auditor else [],
        audit_pairs={"from_engine": auditor.pairs_from_engine, "steps": auditor.steps} if auditor else {})


class WarningTally:
    """Engine warnings of a run: a total per kind and the first few of each, as records."""

    def __init__(self, examples_per_kind: int = 3):
        self.counts: dict[str, int] = {}
        self.first: dict[str, list[str]] = {}
        self.keep = examples_per_kind

    def add(self, warnings) -> None:
        """warnings: EngineWarning events (step, code, message, bodies)."""
        for w in warnings:
            self.counts[w.code] = self.counts.get(w.code, 0) + 1
            kept = self.first.setdefault(w.code, [])
            if len(kept) < self.keep:
                kept.append({"step": w.step, "code": w.code, "message": w.message, "bodies": list(w.bodies)})

    def examples(self) -> list[dict]:
        """The first few warnings of each kind, as records (step, code, message, bodies)."""
        return [w for kept in self.first.values() for w in kept]


# ----------------------------------------------------------------------------- recording
@dataclass
class RecordResult:
    """What ``record`` wrote. mcap / rrd: paths (rrd None when not written); frames:
    states in the MCAP file (frame 0 = initial state); bytes_mcap / bytes_rrd: sizes;
    bvh_note: set when the BVH was logged only down to some depth. (A run stopped by
    Ctrl-C raises RecordingInterrupted instead; its files hold every step completed.)"""

    summary: RunSummary | None
    mcap: str
    rrd: str | None
    detail: str
    frames: int
    bytes_mcap: int
    bytes_rrd: int
    bvh_note: str = ""
    view_note: str = ""
    fork: dict | None = None  # a fork's header entry (fork_recording)


VIEW_AUTO_MAX_SPHERES = 2000  # above this the view channels cost more than the record (docs/recording.md)


def view_choice(view: bool | None, spheres: int) -> tuple[bool, str]:
    """Whether to write the view channels, and the note that says so: as asked, or (None)
    up to VIEW_AUTO_MAX_SPHERES spheres, where they cost less than the record itself."""
    if view is not None:
        return view, "Foxglove view channels written" if view else "view channels left out (--no-view)"
    if spheres <= VIEW_AUTO_MAX_SPHERES:
        return True, "Foxglove view channels written (--no-view leaves them out)"
    return False, (f"view channels left out: {spheres} spheres > {VIEW_AUTO_MAX_SPHERES}, where they would cost "
                   "more than the record (--view writes them)")





def default_paths(scene: Scene, mcap_path: str | None, rrd_path: str | None, rrd: bool) -> tuple[Path, Path | None]:
    """recordings/<scene>.mcap and .rrd unless given; the .rrd follows -o when only that is given."""
    mcap_out = Path(mcap_path) if mcap_path else Path("recordings") / f"{scene.name}.mcap"
    if not rrd:
        return mcap_out, None
    return mcap_out, Path(rrd_path) if rrd_path else mcap_out.with_suffix(".rrd")


def check_writable(paths: Sequence[Path | None], force: bool) -> None:
    """Never overwrite a recording unless forced; make the folders."""
    for path in paths:
        if path is None:
            continue
        if path.exists() and path.is_dir():
            raise PhysdbgError(f"{path} is a directory")
        if path.exists() and not path.is_file():  # /dev/full, a FIFO: never written, never removed
            raise PhysdbgError(f"{path} is not a regular file; give a file path for the recording")
        if path.exists() and not force:
            raise PhysdbgError(f"{path} already exists; pass --force to overwrite it")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise PhysdbgError(f"{path.parent}: cannot create the folder ({err.strerror})") from None
        try:  # found now, before a run is spent, not when the file is first written
            with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".physdbg-probe-"):
                pass
        except OSError as err:
            raise PhysdbgError(f"{path}: cannot write in {path.parent} ({err.strerror})") from None


def record(scene: Scene | str, overrides: Sequence[str] = (), mcap_path: str | None = None,
           rrd_path: str | None = None, rrd: bool = True, detail: str = "full", force: bool = False,
           spawn: bool = False, bvh_max_nodes: int | None = None, dts: Sequence[float] | None = None,
           on_step: Callable[[int, int | None], None] | None = None,
           on_status: Callable[[str], None] | None = None, view: bool | None = None,
           audit: bool | str = True, fork: dict | None = None) -> RecordResult:
    """Run a scene and record every step to MCAP (and Rerun unless rrd=False), audited as
    it runs (``audit``: as for run).

    view: also write the view channels (Foxglove's SceneUpdate, PointCloud and Log; see
    docs/recording-format.md), which Foxglove and ``rerun mcap convert`` show; None: up to
    VIEW_AUTO_MAX_SPHERES spheres (``view_choice``).
    bvh_max_nodes: log at most this many BVH nodes a step, whole levels from the root
    (None: the default cap, 0: no cap). Ctrl-C ends the run with valid files up to the
    last complete step and raises RecordingInterrupted. fork: where this run forks from
    another (``fork_recording``): {parent, parent_run_id, parent_hash, at, changes},
    kept in the header; ``changes`` (settings) apply from step ``at`` on.
    """
    from .record.format import DETAIL_LEVELS
    from .record.header import DEFAULT_BVH_MAX_NODES, RecordingHeader
    from .record.mcap_sink import McapRecorder
    from .record.outputs import claim
    from .observe import FanOut

    scene = ready_scene(scene, overrides)
    if detail not in DETAIL_LEVELS:
        raise PhysdbgError(f"--detail must be one of {', '.join(DETAIL_LEVELS)}, not {detail!r}")
    mcap_out, rrd_out = default_paths(scene, mcap_path, rrd_path, rrd)
    if rrd_out is not None and rrd_out.resolve() == mcap_out.resolve():
        raise PhysdbgError(f"the MCAP and Rerun outputs are the same file: {mcap_out}")
    check_writable([mcap_out, rrd_out], force)
    cap = DEFAULT_BVH_MAX_NODES if bvh_max_nodes is None else (bvh_max_nodes or None)
    header = RecordingHeader.from_scene(scene, detail, cap)
    if fork is not None:
        header.meta["fork"] = fork
    view, view_note = view_choice(view, header.count)
    outputs = claim([mcap_out, rrd_out], force)  # one writer per file: see record/outputs.py
    mcap_file, rrd_file = outputs.paths
    sinks = []
    summary = None
    mcap_sink = None
    interrupted = False
    failure: str | None = None  # why writing failed, if it did
    non_finite: StuckRunError | None = None
    try:
        if rrd_out is not None or spawn:  # first: if the viewer cannot start, no file is left behind
            from .record.rerun_sink import RerunSink

            try:
                sinks.append(RerunSink(header, rrd_file, spawn=spawn))
            except RuntimeError as err:  # rerun's file sink: an unwritable folder or file
                raise PhysdbgError(f"{rrd_out}: cannot write the Rerun file ({err})") from None
        try:
            mcap_sink = McapRecorder(mcap_file, header, view=view)
        except OSError as err:
            raise PhysdbgError(f"{mcap_out}: cannot write the recording ({err.strerror or err})") from None
        sinks.insert(0, mcap_sink)
        markers = [s.mark_finding for s in sinks if hasattr(s, "mark_finding")]  # both views mark findings
        summary = run(scene, observer=FanOut(*sinks), dts=dts, on_step=on_step, on_status=on_status,
                      on_finding=lambda finding: [mark(finding) for mark in markers], audit=audit,
                      fork=fork)
    except KeyboardInterrupt:
        interrupted = True
    except StuckRunError as err:
        non_finite = err
    except (OSError, RuntimeError) as err:
        failure = str(err)
    except BaseException:
        outputs.abandon()  # an error before or during the run (a bad scene for the viewer, ...)
        raise
    finally:
        for sink in sinks:
            try:
                sink.close()
            except (OSError, RuntimeError) as err:
                failure = failure or str(err)
    if mcap_sink is None:  # Ctrl-C before the first byte was written
        outputs.abandon()
        raise RecordingInterrupted("interrupted before the recording began; nothing was written")
    if failure is not None or non_finite is not None:
        kept = _what_is_kept(mcap_file, mcap_out)
        if rrd_file is not None:
            kept += _what_became_of_the_rrd(rrd_file, rrd_out, mcap_out, outputs)
        if not mcap_file.exists():
            outputs.abandon()
        outputs.publish()
        if failure is not None:
            raise PhysdbgError(f"writing the recording failed ({failure}); {kept}")
        raise type(non_finite)(f"{non_finite}; {kept}")
    outputs.publish()
    note = ""
    if mcap_sink.bvh_capped_steps:
        note = (f"BVH logged down to depth {mcap_sink.bvh_logged_depth} ({cap} nodes at most) in "
                f"{mcap_sink.bvh_capped_steps} steps; use --bvh-max-nodes 0 for every node")
    result = RecordResult(summary, str(mcap_out), str(rrd_out) if rrd_out else None, detail, mcap_sink.frames,
                          mcap_out.stat().st_size, rrd_out.stat().st_size if rrd_out and rrd_out.exists() else 0,
                          note, view_note)
    if interrupted:
        raise RecordingInterrupted(
            f"interrupted: {mcap_out} holds {_steps_held(mcap_sink.frames - 1)}")
    return result


def _steps_held(steps: int) -> str:
    """What a recording stopped early holds, in words."""
    if steps <= 0:
        return "the initial state only (no step was completed)"
    return f"steps 1..{steps} (every step completed)"


def _what_became_of_the_rrd(written: Path, rrd_out: Path, mcap_out: Path, outputs) -> str:
    """The Rerun file of a recording stopped early, in words: kept when rerun finished it
    (its footer written), else removed (a torn .rrd is of no use beside the MCAP file,
    from which ``replay --rrd`` draws it again); under --force the old file stays."""
    from .record.rerun_sink import rrd_is_whole

    if rrd_is_whole(written):
        return f"; the Rerun file {rrd_out} was finished and shows the same steps"
    outputs.abandon(written)
    fate = "removed" if written == rrd_out else "not replaced (the previous one is left as it was)"
    return (f"; the Rerun file {rrd_out} could not be finished and was {fate} (`physdbg replay {mcap_out} "
            f"--rrd {rrd_out}` draws it from the recording)")


def _what_is_kept(written: Path, mcap_out: Path) -> str:
    """What a user can still read after a recording stopped early: which steps, or nothing.
    written: the file the run wrote (mcap_out, or its partial name under --force); removed
    when nothing in it is readable."""
    from .record import open_recording

    try:
        with open_recording(written) as rec:
            return f"{mcap_out} is readable and holds {_steps_held(rec.steps)}"
    except PhysdbgError:
        if not written.is_file():
            return f"nothing readable could be written to {mcap_out}"
        written.unlink()
        fate = "left as it was" if written != mcap_out else "removed"  # --force keeps the old file until the end
        return f"nothing readable could be written, so {mcap_out} was {fate}"


@dataclass
class VerifyResult:
    """Outcome of re-simulating a recording. ok: every step matched; checked: steps
    compared; first_bad_step: frame of the first mismatch (None if none); reason: why."""

    ok: bool
    checked: int
    first_bad_step: int | None = None
    reason: str = ""
    truncated: bool = False  # the file has no summary: its writer was stopped, or is still writing


def verify(path: str | Path, on_step: Callable[[int, int | None], None] | None = None,
           check_file: bool = True) -> VerifyResult:
    """Re-simulate a recording from its embedded scene and step lengths; compare every
    step's state hash. With check_file, each stored state is checked against its stored
    hash and the frame index as it is read (RecordingIntegrityError: an altered file)."""
    from .precompile import compile_kernels
    from .record import open_recording

    with open_recording(path, verify=check_file) as rec:
        foreign = rec.meta.get("foreign")
        if foreign:
            raise PhysdbgError(f"{path} is a run of another engine (imported from {foreign['source']}): there is no "
                               "physdbg run to repeat. `physdbg explain` audits it; `physdbg diff` compares it "
                               "with a physdbg recording of the same scene")
        world = rec.scene.build_world()
        compile_kernels(world.broad_phase.name, sleeping=world.sleepers is not None,
                        meshes=bool(rec.scene.walls.meshes.triangles))
        first = rec.state(0)  # the reader checks each state against its stored hash (check_file)
        if world.state.positions.tobytes() != first.positions.tobytes() or \
                world.state.velocities.tobytes() != first.velocities.tobytes():
            return VerifyResult(False, 0, 0, "the scene in the file does not give the recorded initial state")
        from .interrupt import StopOnCtrlC

        with StopOnCtrlC(world):  # Ctrl-C ends even a long step within a second
            result = _verify_steps(rec, world, on_step)
        result.truncated = rec.truncated
        return result


def _verify_steps(rec, world, on_step) -> VerifyResult:
    """verify's loop: re-simulate each step and compare it with the file."""
    checked = 0
    fork = rec.meta.get("fork")
    for frame in rec.states(1):
        k = frame.frame
        for entry in (fork or {}).get("chain", []):
            if entry["at"] == k:
                world.retune(entry["changes"])
        stats = world.step(frame.dt)
        # the states themselves, not only the hashes: without check_file a stored state
        # need not give its stored hash
        if stats.state_hash != frame.state_hash or \
                world.state.positions.tobytes() != frame.positions.tobytes() or \
                world.state.velocities.tobytes() != frame.velocities.tobytes():
            from .analysis.align import state_difference

            d = state_difference(world.state.positions, world.state.velocities, frame.positions,
                                 frame.velocities)
            worst = ", ".join(f"sphere {p['particle']} |Δx| = {p['position']:.3g} m" for p in d.particles[:3])
            return VerifyResult(False, checked, k, f"step {k}: re-simulated state (hash {stats.state_hash}) is "
                                                  f"not the recorded one (hash {frame.state_hash}); {d.count} "
                                                  f"spheres differ ({worst})")
        checked += 1
        if on_step is not None:
            on_step(checked, rec.steps)
    return VerifyResult(True, checked)


def replay(path: str | Path, rrd_path: str | None = None, force: bool = False, spawn: bool = False,
           verify: bool = True, at: int | None = None) -> dict:
    """Rebuild the Rerun view of a recording from the MCAP file alone; returns what was written.
    verify: check every state against its stored hash and the frame index as it is read;
    at: the step the view opens on, paused (default: its first contact, on a mesh where
    the scene has meshes)."""
    from .record import open_recording
    from .record.rerun_sink import RerunSink

    from .record.outputs import claim

    out = Path(rrd_path) if rrd_path else None
    if out is not None:
        check_writable([out], force)
    from .analysis.audit import Auditor

    with open_recording(path, verify=verify) as rec:
        if at is not None and not 1 <= at <= rec.steps:
            raise PhysdbgError(f"--at {at}: {path} holds steps 1..{rec.steps}")
        outputs = claim([out], force)
        sink = RerunSink(rec.header, outputs.paths[0], spawn=spawn, open_at=at)
        auditor = Auditor(rec.header, sink.mark_finding)  # the findings marked, as in the live picture
        try:
            try:
                for events in rec.iter_step_events():
                    for event in events:
                        sink.on_event(event)
                        auditor.on_event(event)
                auditor.finish()  # a rattling bed that never fell asleep is marked too
            finally:
                sink.close()
        except OSError as err:  # the .rrd could not be written (a full disk)
            outputs.abandon()  # no half-made picture left behind
            raise PhysdbgError(f"{err}; it was removed") from None
        except BaseException:
            outputs.abandon()
            raise
        outputs.publish()
        return {"mcap": str(path), "rrd": str(out) if out else None, "steps": rec.steps,
                "truncated": rec.truncated}


def info(path: str | Path) -> dict:
    """What a recording holds: scene, settings, steps, channels and sizes."""
    from .record import open_recording

    with open_recording(path) as rec:
        meta = rec.meta
        last = rec.state(rec.frames - 1)
        size = Path(path).stat().st_size
        n = rec.header.count
        return {
            "path": str(path), "bytes": size, "truncated": rec.truncated,
            "scene": meta["scene"]["name"], "source": meta["scene"]["source"],
            "description": meta["scene"]["description"],
            "physdbg_version": meta["physdbg_version"], "format_version": meta["format_version"],
            "detail": rec.detail, "particles": n, "walls": list(rec.header.walls.names),
            "meshes": mesh_sizes(rec.header.walls.meshes),
            "partners": {kind: len(partners) for kind, partners in rec.header.walls.partners.items()},
            "fork": rec.meta.get("fork"),
            # how each kinematic mesh moves, as the run summary says it
            "mesh_motion": [f"'{name}' {rec.header.walls.meshes.motion_words(k)}"
                            for k, name in enumerate(rec.header.walls.meshes.names) if rec.header.walls.meshes.moving[k]],
            "steps": rec.steps, "sim_time": last.time, "final_hash": last.state_hash,
            "settings": meta["settings"], "dt": meta.get("dt"), "bvh_max_nodes": meta.get("bvh_max_nodes"),
            "bytes_per_particle_step": size / (n * rec.frames) if n and rec.frames else None,
            "channels": [{"topic": c.topic, "encoding": c.message_encoding, "schema": c.schema_name,
                          "messages": c.messages} for c in rec.channels()],
            "equation_of_state": _equation_of_state(rec),
            "foreign": meta.get("foreign"),
            # spheres asleep after the last step (None: the run did not let spheres sleep)
            "asleep_at_end": int(last.asleep.sum()) if last.asleep is not None else None,
        }


def _equation_of_state(rec) -> dict | None:
    """Z and kT from the collisions (analysis.pressure), for a run of several moving spheres
    that collided; None otherwise."""
    from dataclasses import asdict

    from .analysis.pressure import BLOCKS, equation_of_state

    if rec.steps < 2 * BLOCKS or int(np.count_nonzero(rec.header.inverse_mass > 0)) < 2:
        return None
    try:
        eos = equation_of_state(rec)
    except ValueError:  # nothing moved in part of the window (a pile asleep): no kT
        return None
    return dict(asdict(eos), periodic=rec.header.walls.periodic) if eos.z_virial != 1.0 else None


# ----------------------------------------------------------------------------- analysis
def diff(a: str | Path, b: str | Path, atol: float | None = None, rtol: float | None = None,
         verify: bool = True):
    """Where two recordings part and why (physdbg.analysis.diff.DiffReport). verify: check
    every state read against its stored hash and the frame index (docs/recording.md,
    "Integrity"); False is ``--no-verify``."""
    from .analysis.diff import diff as _diff

    return _diff(a, b, atol=atol, rtol=rtol, verify=verify)


def explain(path: str | Path, verify: bool = True, every_finding: bool = False):
    """Audit one recording (physdbg.analysis.audit.AuditReport); verify as for diff;
    every_finding: list every finding, not the first few of each kind."""
    from .analysis.audit import explain as _explain

    return _explain(path, verify=verify, every_finding=every_finding)


def overlay(a: str | Path, b: str | Path, report=None, rrd_path: str | None = None, force: bool = False,
            spawn: bool = False, verify: bool = True) -> str | None:
    """Both runs in one Rerun recording, side by side, opened at the divergence."""
    from .analysis.overlay import write_overlay

    from .record.outputs import write_claimed

    report = report if report is not None else diff(a, b, verify=verify)
    if rrd_path is None:
        return write_overlay(a, b, report, None, spawn=spawn, verify=verify)
    check_writable([Path(rrd_path)], force)
    write_claimed(Path(rrd_path), force,
                  lambda path: write_overlay(a, b, report, str(path), spawn=spawn, verify=verify))
    return rrd_path


# ----------------------------------------------------------------------------- other engines
@dataclass
class ImportResult:
    """What ``import_run`` wrote: mcap (path), frames (steps + 1), bodies, velocities
    ("given" or "estimated" from positions), bytes."""

    mcap: str
    frames: int
    bodies: int
    velocities: str
    bytes: int


def import_run(run_path: str | Path, scene: Scene | str, overrides: Sequence[str] = (),
               mcap_path: str | Path | None = None, force: bool = False, time_unit: str | None = None,
               length_unit: str | None = None) -> ImportResult:
    """Turn a run of another engine (a .csv or .jsonl trajectory, docs/foreign-runs.md) of
    ``scene`` into a physdbg recording, so explain, diff and replay work on it (units: as
    for check_run)."""
    from .record.foreign import import_run as write_run
    from .record.outputs import write_claimed

    scene = ready_scene(scene, overrides)
    out = Path(mcap_path) if mcap_path else Path(run_path).with_suffix(".mcap")
    if out.resolve() == Path(run_path).resolve():
        raise PhysdbgError(f"the run and the recording are the same file: {out}")
    check_writable([out], force)
    run = read_run_in_units(run_path, scene, time_unit, length_unit)
    frames = write_claimed(out, force, lambda path: write_run(run, scene, path))
    return ImportResult(str(out), frames, scene.state.count, "given" if run.velocities is not None else "estimated",
                        out.stat().st_size)


@dataclass
class CheckRunResult:
    """What ``check_run`` did: report (analysis.departure.CheckRunReport); run and
    reference: the two recordings it compared (kept only when ``keep`` named a folder)."""

    report: object
    run: str | None
    reference: str | None
    velocities: str


def _check_class_row(run: str, scene: str | None, overrides: tuple, options: dict):
    """check-run of one run of a class as its row (analysis.classroom): any error, expected
    or not, is the row's, since a hostile file must not end the batch. Module-level, so a
    worker process or a Dask worker can be handed it."""
    from .analysis.classroom import error_row, row_of

    try:
        return row_of(run, check_run(run, scene, list(overrides), **options).report)
    except Exception as err:  # noqa: BLE001 - a row, not the end of the class
        return error_row(run, err)


def check_class(runs: Sequence[str | Path], scene: str | None, overrides: Sequence[str] = (),
                workers: int | None = None, dask: str | None = None, **options):
    """check-run of every run of a class against ``scene`` (a built-in name or a .toml path,
    read by each worker; None: each run's own scene, which a run without one is an error
    row for): an analysis.classroom.ClassReport. runs: runs, or folders of runs
    (analysis.classroom.runs_in: every run in them); workers: local processes (None: every
    core); dask: an existing cluster's scheduler; options: check_run's atol, rtol,
    time_unit, length_unit, verify."""
    from .analysis.classroom import class_report, runs_in
    from .analysis.sweep import run_jobs

    runs = runs_in([Path(run) for run in runs])

    # a wrong scene is one error, before any run
    name = load_scene(scene, list(overrides)).name if scene is not None else "each run's own scene"
    jobs = [(str(run), scene, tuple(overrides), options) for run in runs]
    return class_report(name, run_jobs(_check_class_row, jobs, workers=workers, dask=dask))


def overlap(a: str, b: str, **options):
    """Do two meshes (files or built-in shapes) overlap? The two-tree search of
    analysis.mesh_pair_search.overlap (options: pose_a, pose_b, volume, builder, hull): an
    OverlapReport, its search tree whole."""
    from .analysis.mesh_pair_search import overlap as search

    return search(a, b, **options)


def read_step_lengths(path: str | Path) -> list[float]:
    """Step lengths (s) from a file, one per line, each by the rule of a scene's dt
    (scene.step_length): ``run --dts FILE``."""
    from .scene import STEP_LENGTH_RANGE, step_length

    path = Path(path)
    try:
        lines = path.read_text().split()
    except (OSError, UnicodeDecodeError) as err:
        raise PhysdbgError(f"{path}: cannot read step lengths ({err})") from None
    out = []
    for number, text in enumerate(lines, 1):
        value = step_length(text)
        if value is None:
            raise PhysdbgError(f"{path}: entry {number} is {text[:40]!r}; each dt must be a number of seconds "
                               f"{STEP_LENGTH_RANGE}")
        out.append(value)
    if not out:
        raise PhysdbgError(f"{path}: no step lengths in the file")
    return out


SCENE_FORMATS = ("toml", "json", "js")


def show_scene(scene: str, output_format: str = "toml", overrides: Sequence[str] = ()) -> str:
    """A scene (a built-in name or a .toml file) as text: "toml", the file as it is (with
    ``overrides`` only as a stated table: TOML text is not rewritten, so overrides need
    json or js); "json", its table with every value stated (scene.scene_table: what
    check-run reads from a run's first line); "js", that table as a JavaScript file that
    defines ``physdbgScenes[NAME]`` in a page and exports it under Node."""
    from .scene import read_scene, read_scene_text, scene_table

    if output_format not in SCENE_FORMATS:
        raise PhysdbgError(f"--format {output_format!r}: one of {', '.join(SCENE_FORMATS)}")
    if output_format == "toml":
        if overrides:
            raise PhysdbgError("--set with --format toml: the TOML is printed as it is; give --format json or js "
                               "for the scene with the overrides applied")
        read_scene(scene)  # a scene that does not load is refused here too
        return read_scene_text(scene)[0]
    table = scene_table(read_scene(scene, list(overrides)))
    # one line a field, a sphere or a plane
    text = "{\n" + ",\n".join(
        f"  {json.dumps(key)}: [\n" + ",\n".join(f"    {json.dumps(item)}" for item in value) + "\n  ]"
        if isinstance(value, list) and value and isinstance(value[0], dict) else f"  {json.dumps(key)}: {json.dumps(value)}"
        for key, value in table.items()) + "\n}"
    if output_format == "json":
        return text + "\n"
    name = json.dumps(table["name"])
    return (f"// physdbg scene {table['name']}: {table.get('description', '')}\n"
            f"// Made by `physdbg scenes show {scene} --format js`: dt and every value in SI units (s, m, kg).\n"
            f"// In a page: <script src=\"this file\"></script> defines physdbgScenes[{name}];\n"
            f"// under Node: const scene = require(\"./this file\");\n"
            f"(function (root) {{\n"
            f"  const scene = {text.replace(chr(10), chr(10) + '  ')};\n"
            f"  if (typeof module === \"object\" && module && module.exports) module.exports = scene;\n"
            f"  root.physdbgScenes = Object.assign(root.physdbgScenes || {{}}, {{ [{name}]: scene }});\n"
            f"}})(typeof globalThis !== \"undefined\" ? globalThis : this);\n")


TRACE_JS = "physdbg-trace.js"  # the JavaScript tracer shipped in the package (physdbg/js/)


def write_trace_js(folder: str | Path, force: bool = False) -> Path:
    """Write the JavaScript tracer (physdbg-trace.js: three calls that record a browser or
    Node engine's run in the JSON Lines run format; docs/foreign-runs.md, "From a
    JavaScript engine") into ``folder`` (made if missing); an existing file is replaced only
    with ``force``. Returns its path."""
    from importlib.resources import files

    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise PhysdbgError(f"{folder}: exists and is not a folder")
    out = folder / TRACE_JS
    if out.exists() and not force:
        raise PhysdbgError(f"{out} exists; --force replaces it")
    folder.mkdir(parents=True, exist_ok=True)
    out.write_text((files("physdbg") / "js" / TRACE_JS).read_text(encoding="utf-8"), encoding="utf-8")
    return out


def read_run_in_units(run_path: str | Path, scene: Scene, time_unit: str | None = None,
                      length_unit: str | None = None):
    """A foreign run of ``scene`` (foreign.read_run) in seconds and metres: read as written
    in the units given, or, with none given, refused (ForeignRunError, a line per unit) when
    it looks written in other units than SI."""
    from .errors import ForeignRunError
    from .record.foreign import in_units, read_run, unit_mistakes

    run = read_run(run_path, scene.state.count)
    if time_unit is None and length_unit is None:
        mistakes = unit_mistakes(run, scene.dt, scene.state.positions)
        if mistakes:
            raise ForeignRunError(f"{run_path}: " + "; and ".join(mistakes))
    return in_units(run, time_unit or "s", length_unit or "m")


# what a scene sent by a page (check-run --serve) may not hold: fields that read files or
# lift the limits on the work and memory a run takes (the server's own stay in force)
PAGE_SCENE_REFUSED = ("meshes", "max_memory", "max_particle_steps")


def scene_of_run(run_path: str | Path, overrides: Sequence[str] = (), from_a_page: bool = False) -> Scene:
    """The scene a JSON Lines run carries on its first line (foreign.run_scene, written by
    physdbg-trace.js's start(scene)), ready to run: a built-in scene's name is loaded; a
    scene object is validated as a scene file is (an error names the run's line 1 and
    the field), with ``key=value`` overrides applied. from_a_page: the run came over the
    network (check-run --serve), so its scene may hold none of PAGE_SCENE_REFUSED nor a
    budget (state.BUDGETS)."""
    from .engine.state import BUDGETS, RENAMED_SETTINGS
    from .errors import SceneError
    from .record.foreign import run_scene
    from .scene import scene_from_dict
    from .scenes import builtin_names

    value = run_scene(run_path)
    if value is None:
        raise PhysdbgError(f"{run_path}: the run carries no scene (a run traced with physdbgTrace.start(scene) has it "
                           f"on its first line); give the scene it ran with --scene, a built-in name or a .toml file")
    if isinstance(value, str):
        if value not in builtin_names():
            raise PhysdbgError(f"{run_path}, line 1: field 'scene' is {value[:60]!r}, not a built-in scene (one of "
                               f"{', '.join(builtin_names())}); give a scene object, or the scene with --scene")
        return load_scene(value, overrides)
    source = f"{run_path}, line 1 (the run's scene)"
    if from_a_page and isinstance(value, dict):
        for key in (*PAGE_SCENE_REFUSED, *BUDGETS, *RENAMED_SETTINGS):
            if key in value:
                why = ("meshes are read from files" if key == "meshes" else
                       "it lifts a bound on the work and memory a check takes")
                raise SceneError(source, key, f"a scene a page sends may not set {key} ({why}); give the scene "
                                              f"with check-run --serve --scene instead")
    return decide(scene_from_dict(value, source, overrides=overrides))


def check_run(run_path: str | Path, scene: Scene | str | None = None, overrides: Sequence[str] = (),
              atol: float | None = None,
              rtol: float | None = None, keep: str | Path | None = None, force: bool = False,
              on_status: Callable[[str], None] | None = None, verify: bool = True,
              time_unit: str | None = None, length_unit: str | None = None,
              from_a_page: bool = False) -> CheckRunResult:
    """Record physdbg's exact run of ``scene`` with the foreign run's own time steps and
    say where the foreign run (a .csv, .jsonl or .mcap trajectory) departs from it and why
    (analysis.departure). keep: a folder to keep both recordings in (run.mcap and
    reference.mcap, for replay, diff and overlay); otherwise they are temporary.
    time_unit, length_unit: what the run is written in (foreign.TIME_UNITS, LENGTH_UNITS);
    when neither is given, a run that looks written in milliseconds, centimetres or
    millimetres is refused with a line naming the unit (foreign.unit_mistakes).
    A step that only one of physdbg's own modelling rules explains (departure.OWN_RULES)
    is compared again against physdbg without that rule, and the report says so.
    scene None: the scene the run carries (scene_of_run; from_a_page: sent by a page)."""
    import numpy as np

    from .analysis.departure import compare, too_long
    from .record.foreign import import_run as write_run
    from .record.outputs import write_claimed

    carried = scene is None
    scene = scene_of_run(run_path, overrides, from_a_page) if carried else ready_scene(scene, overrides)
    if scene.walls.periodic:
        raise PhysdbgError(f"scene '{scene.name}' has a periodic box; check-run reads a run's steps from consecutive "
                           f"positions, which wrap there, and does not compare periodic runs yet")
    run = read_run_in_units(run_path, scene, time_unit, length_unit)
    if len(run.times) < 2:
        raise PhysdbgError(f"{run_path}: the run has only its initial state; there is no step to check")
    too_long(len(run.times), scene.state.count)  # before physdbg's reference is recorded
    with tempfile.TemporaryDirectory(prefix="physdbg-check-run-") as scratch:
        folder = Path(keep) if keep is not None else Path(scratch)
        if keep is not None:
            if folder.exists() and not folder.is_dir():
                raise PhysdbgError(f"{folder}: exists and is not a folder")
            folder.mkdir(parents=True, exist_ok=True)
        run_out, reference_out = folder / "run.mcap", folder / "reference.mcap"
        check_writable([run_out, reference_out], force)
        if on_status is not None:
            on_status("importing")
        write_claimed(run_out, force, lambda path: write_run(run, scene, path))
        dts = np.diff(run.times)
        velocities = "given" if run.velocities is not None else "estimated"
        del run  # (the comparison reads it back from run.mcap: one copy in memory at a time)
        if scene.dt is not None and np.all(np.abs(dts - scene.dt) <= 1e-9 * scene.dt):
            # the scene's steps, summed up in the run's time column: take the scene's dt itself,
            # as the differences of the sums are a bit off it and a chaotic scene grows that
            dts = np.full(len(dts), scene.dt)

        def reference(scene: Scene) -> None:  # physdbg's run of the scene with the run's own steps
            record(scene, mcap_path=str(reference_out), rrd=False, detail="contacts", force=True,
                   dts=dts.tolist(), view=False, on_status=on_status)

        reference(scene)
        if on_status is not None:
            on_status("comparing")
        report = compare(run_out, reference_out, atol, rtol, verify=verify)
        set_aside: list[dict] = []
        while True:
            # a step that only physdbg's own modelling rule explains (departure.OWN_RULES): the
            # run is compared again against physdbg without that rule, once per rule
            rule = next((d for d in report.departures if d.kind == "own-rule"
                         and d.evidence["setting"] not in {r["setting"] for r in set_aside}), None)
            if rule is None:
                break
            set_aside.append({**rule.evidence, "step": rule.step})
            scene = dataclasses.replace(scene, settings=dataclasses.replace(
                scene.settings, **{rule.evidence["setting"]: rule.evidence["value"]}))
            if on_status is not None:
                on_status(f"comparing without physdbg's {rule.evidence['name']}")
            reference(scene)
            report = compare(run_out, reference_out, atol, rtol, verify=verify, set_aside=set_aside)
        report.run = str(run_path)
        if carried:
            walls = len(scene.walls)
            report.notes.insert(0, f"the scene is the one the run carries on its first line ('{scene.name}': "
                                   f"{scene.state.count} sphere{'s' if scene.state.count != 1 else ''}, {walls} "
                                   f"plane{'s' if walls != 1 else ''}), compared with its own integrator "
                                   f"({scene.settings.integrator})")
        kept = keep is not None
        return CheckRunResult(report, str(run_out) if kept else None, str(reference_out) if kept else None,
                              velocities)


@dataclass
class PeerResult:
    """What ``record_peer`` wrote: mcap (path), peer, frames (steps + 1), bodies, notes
    (what the translation set), seconds (the peer's wall time)."""

    mcap: str
    peer: str
    frames: int
    bodies: int
    notes: list[str]
    seconds: float


def record_peer(peer: str, scene: Scene | str, overrides: Sequence[str] = (), mcap_path: str | Path | None = None,
                force: bool = False) -> PeerResult:
    """Run ``scene`` in a peer engine (pybullet or mujoco, optional extras) from the same
    initial state and write it as a foreign-run recording (see physdbg.peers)."""
    import time as clock

    from .peers import run_peer
    from .record.foreign import import_run as write_run
    from .record.outputs import write_claimed

    scene = ready_scene(scene, overrides)
    out = Path(mcap_path) if mcap_path else Path(f"{scene.name}-{peer}.mcap")
    check_writable([out], force)
    started = clock.perf_counter()
    run, notes = run_peer(peer, scene)
    seconds = clock.perf_counter() - started
    frames = write_claimed(out, force, lambda path: write_run(run, scene, path, notes=notes))
    return PeerResult(str(out), peer, frames, scene.state.count, notes, seconds)


# ----------------------------------------------------------------------------- advice
@dataclass
class CheckResult:
    """What ``check`` found. advice: advisor.Advice; current: the scene's own
    integrator, detection and ordering; problems: the predictions against them that fail
    (tunnels, overlap left) and warnings (inexact)."""

    scene: Scene
    advice: object
    current: dict[str, str]
    problems: list
    warnings: list

    @property
    def ok(self) -> bool:
        return not self.problems


def check(scene: Scene | str, overrides: Sequence[str] = ()) -> CheckResult:
    """The advisor on a scene: which methods fail on it, the cheapest safe settings, and
    whether the scene's own settings are among the safe ones."""
    from .advisor import advise

    scene = ready_scene(scene, overrides)
    advice = advise(scene)
    current = {name: getattr(scene.settings, name) for name in ("integrator", "detection", "ordering")}
    mine = [p for name, value in current.items() for p in advice.fails(name, value)]
    mine += [p for p in advice.predictions if p.setting == "dt"]  # a periodic box too small for dt
    mine += [p for p in advice.predictions if p.setting == "start"]  # a sphere starting inside another body
    return CheckResult(scene, advice, current, [p for p in mine if p.outcome != "inexact"],
                       [p for p in mine if p.outcome == "inexact"])


# ----------------------------------------------------------------------------- benchmarks
@dataclass
class BenchResult:
    """What a ``bench_*`` function wrote: files (paths), runs (analysis.accuracy.Run or
    analysis.stability.Cell), seconds."""

    files: list[str]
    runs: list
    seconds: float
    note: str = ""  # why no chart was drawn, and how to get one


def _chart_choice(chart: bool | None) -> tuple[bool, str]:
    """Whether to draw the chart: as asked, or (None) when matplotlib is installed; and
    the note that says so when it is not."""
    if chart is not None:
        return chart, ""
    import importlib.util

    if importlib.util.find_spec("matplotlib") is not None:
        return True, ""
    return False, ("no chart drawn: matplotlib is not installed (pip install 'physdbg[charts]' draws it; the CSV "
                   "and the table are written)")


ACCURACY_FILES = ("accuracy.csv", "accuracy.md", "accuracy.png", "accuracy.svg")


def _bench_paths(out_dir: str | Path, names: Sequence[str], chart: bool, force: bool,
                 extra: Sequence[Path | None] = ()) -> list[Path]:
    """The files a benchmark will write (its first two, the CSV and the table, without the
    chart), checked writable; and matplotlib checked before any run, not after (chart:
    as _chart_choice decided)."""
    paths = [Path(out_dir) / name for name in (names if chart else names[:2])]
    check_writable([*paths, *extra], force)
    if chart:
        from .analysis.charts import _pyplot

        _pyplot()
    return paths


def bench_accuracy(out_dir: str | Path = "accuracy", quick: bool = False, force: bool = False,
                   chart: bool | None = None,
                   rrd_path: str | None = None, problems: Sequence[str] | None = None,
                   on_run: Callable | None = None, command: str = "physdbg bench accuracy",
                   workers: int | None = None, dask: str | None = None,
                   on_status: Callable[[str], None] | None = None) -> BenchResult:
    """Every method on the reference problems (analysis.accuracy): accuracy.csv, accuracy.md
    and (chart) accuracy.png / .svg in out_dir; rrd_path: the same chart for Rerun.
    workers: local processes (None: every core, 1: this process); dask: a scheduler address;
    on_status: as run()'s, around compiling the kernels first (_compile_for_bench)."""
    from .analysis import accuracy

    unknown = [p for p in problems or () if p not in accuracy.PROBLEMS]
    if unknown:
        raise PhysdbgError(f"no accuracy problem {unknown[0]!r}; the problems are: {', '.join(accuracy.PROBLEMS)}")
    chart, note = _chart_choice(chart)
    paths = _bench_paths(out_dir, ACCURACY_FILES, chart, force, [Path(rrd_path) if rrd_path else None])
    started = time.perf_counter()
    from .precompile import compile_kernels

    _compile_for_bench(on_status)
    runs = accuracy.run_all(list(problems) if problems else None, quick=quick, on_run=on_run, workers=workers,
                            dask=dask, warm=compile_kernels)
    paths[0].write_text(accuracy.to_csv(runs))
    paths[1].write_text(accuracy.to_markdown(runs, command))
    if chart:
        from .analysis.charts import accuracy_chart

        accuracy_chart(runs, paths[2:], f"Accuracy against cost ({'quick: ' if quick else ''}"
                                         f"{len(runs)} runs; `{command}`)")
    if rrd_path:
        from .analysis.charts import accuracy_rrd

        accuracy_rrd(runs, Path(rrd_path))
        paths.append(Path(rrd_path))
    return BenchResult([str(p) for p in paths], runs, time.perf_counter() - started, note)


def _compile_for_bench(on_status: Callable[[str], None] | None) -> None:
    """Compile (or load) the kernels before a benchmark's runs, said to ``on_status`` as
    run() says it ("compiling", then "running"), so the CLI can announce a cold compile.
    A benchmark always runs compiled, whatever the cache (never the interpreted tier of
    physdbg/tier.py): wall time is one of its measures, and interpreted steps cost 10–100
    times as much."""
    from .precompile import compile_kernels

    if on_status is not None:
        on_status("compiling")
    try:
        compile_kernels(None, sleeping=True)
    finally:
        if on_status is not None:
            on_status("running")


ENGINES_FILES = ("engines.csv", "engines.md", "engines.png", "engines.svg")


def bench_engines(out_dir: str | Path = "engines", quick: bool = False, force: bool = False,
                  chart: bool | None = None,
                  scenes: Sequence[str] | None = None, on_run: Callable | None = None,
                  command: str = "physdbg bench engines",
                  on_status: Callable[[str], None] | None = None) -> BenchResult:
    """physdbg's methods and the peers on the same scenes (analysis.engines): engines.csv,
    engines.md and (chart) engines.png / .svg, cost against error, in out_dir; on_status:
    as bench_accuracy's."""
    from .analysis import engines

    unknown = [name for name in scenes or () if name not in engines.SCENES]
    if unknown:
        raise PhysdbgError(f"no engines scene {unknown[0]!r}; the scenes are: {', '.join(engines.SCENES)}")
    chart, note = _chart_choice(chart)
    paths = _bench_paths(out_dir, ENGINES_FILES, chart, force)
    started = time.perf_counter()
    _compile_for_bench(on_status)
    runs = engines.run_all(list(scenes) if scenes else None, quick=quick, on_run=on_run)
    paths[0].write_text(engines.to_csv(runs))
    paths[1].write_text(engines.to_markdown(runs, command))
    if chart:
        from .analysis.charts import engines_chart

        engines_chart(runs, paths[2:], f"Cost against error, physdbg and its peers on the same physics (`{command}`)")
    return BenchResult([str(p) for p in paths], runs, time.perf_counter() - started, note)


STABILITY_FILES = ("stability.csv", "stability.md", "stability-impact.png", "stability-impact.svg",
                   "stability-stack.png", "stability-stack.svg")


def bench_stability(out_dir: str | Path = "stability", quick: bool = False, force: bool = False,
                    chart: bool | None = None,
                    on_cell: Callable | None = None, command: str = "physdbg bench stability",
                    workers: int | None = None, dask: str | None = None,
                    on_status: Callable[[str], None] | None = None) -> BenchResult:
    """Where each method breaks (analysis.stability): stability.csv, stability.md and (chart)
    a heatmap per map as PNG and SVG in out_dir. workers, dask, on_status: as bench_accuracy."""
    from .analysis import stability

    chart, note = _chart_choice(chart)
    paths = _bench_paths(out_dir, STABILITY_FILES, chart, force)
    started = time.perf_counter()
    from .precompile import compile_kernels

    _compile_for_bench(on_status)
    cells = stability.maps(quick=quick, on_cell=on_cell, workers=workers, dask=dask, warm=compile_kernels)
    paths[0].write_text(stability.to_csv(cells))
    paths[1].write_text(stability.to_markdown(cells, command))
    if chart:
        from .analysis.charts import stability_chart

        stability_chart(cells, "impact", paths[2:4], f"Impact: a sphere at a thin wall, pass or fail (`{command}`)")
        stability_chart(cells, "stack", paths[4:6], f"Resting stacks for 1 s at dt = 1/60 (`{command}`)")
    return BenchResult([str(p) for p in paths], cells, time.perf_counter() - started, note)
