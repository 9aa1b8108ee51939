"""The ``physdbg`` command: a thin layer over :mod:`physdbg.api`.

Each command parses its options, calls one library function and prints. Every
user-facing failure is a PhysdbgError, printed as ``error: ...`` with exit code 2 —
never a traceback. Heavy modules (numpy, numba) are imported inside the commands so
``physdbg --help`` stays quick.

Why one module of this size: typer reads each command's options from its signature, so
the options and their --help text are most of it (one command, one function, in the order
of ``physdbg --help``); what a command does is a call into api.
"""

from __future__ import annotations

import gc
import json
import os
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Optional

import typer

from . import viewers
from .errors import PhysdbgError, one_line, os_error_words
from .serve import DEFAULT_PORT as SERVE_PORT, MAX_BYTES as SERVE_MAX_BYTES

app = typer.Typer(
    name="physdbg",
    help="A physics engine that shows its work: run or record a sphere scene and see every contact.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain help: importing rich would cost ~0.15 s on every call
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _show_version(value: bool) -> None:
    if value:
        from .version import __version__

        typer.echo(f"physdbg {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[bool, typer.Option("--version", callback=_show_version, is_eager=True,
                                          help="Print physdbg's version and exit.")] = False,
) -> None:
    """A physics engine that shows its work: run or record a sphere scene and see every contact."""
    # rerun's own log lines for a failed .rrd write (a full disk) would print beside
    # physdbg's one error line, which says the same; read once, when rerun is first imported
    os.environ.setdefault("RUST_LOG", "warn,re_log_encoding=off")


@contextmanager
def _user_errors(as_json: bool = False):
    """Turn PhysdbgError (and unreadable files) into a one-line message and exit code 2.
    as_json: the command was asked for JSON, so the error is also printed on stdout as
    {"error": ..., "exit_code": ...} (a script reading stdout gets JSON either way)."""
    try:
        yield
    except PhysdbgError as err:
        message = one_line(str(err))
        typer.echo(f"error: {message}", err=True)
        if as_json:
            _json_error(message, err.exit_code)
        raise typer.Exit(err.exit_code) from None
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        raise typer.Exit(130) from None
    except MemoryError:
        typer.echo("error: out of memory; use fewer particles, or lower max_memory / the per-step budgets "
                   "(docs/scenes.md)", err=True)
        raise typer.Exit(2) from None
    except (typer.Exit, typer.Abort, SystemExit):
        raise
    except BrokenPipeError:  # `physdbg ... | head`: the reader has all it wanted. click ends quietly (exit 1)
        raise
    except OSError as err:  # a file the user named that the system refuses (a name too long, ...)
        message = os_error_words(err)
        if message is None or os.environ.get("PHYSDBG_TRACEBACK"):
            _internal_error(err, as_json)
        message = one_line(message)
        typer.echo(f"error: {message}", err=True)
        if as_json:
            _json_error(message, 2)
        raise typer.Exit(2) from None
    except Exception as err:  # a bug in physdbg: still one line, with how to see the rest
        _internal_error(err, as_json)


def _internal_error(err: Exception, as_json: bool) -> None:
    """A bug in physdbg: one line, with how to see the traceback (PHYSDBG_TRACEBACK=1 raises it)."""
    if os.environ.get("PHYSDBG_TRACEBACK"):
        raise err
    message = one_line(f"internal error ({type(err).__name__}: {err}); this is a bug in physdbg: please report it "
                       f"with the command you ran (PHYSDBG_TRACEBACK=1 shows the traceback)")
    typer.echo(f"error: {message}", err=True)
    if as_json:
        _json_error(message, 70)
    raise typer.Exit(70) from None


def _json_error(message: str, code: int) -> None:
    from .analysis.report import versioned

    typer.echo(json.dumps(versioned({"error": message, "exit_code": code}), indent=2))


scenes_app = typer.Typer()  # (its help is the callback's docstring)
app.add_typer(scenes_app, name="scenes")


@scenes_app.callback(invoke_without_command=True)
def scenes(
    ctx: typer.Context,
    as_json: Annotated[bool, typer.Option("--json", help="Print the scenes as JSON (name and description).")]
    = False,
) -> None:
    """List the built-in scenes, one line each; `physdbg scenes show NAME` prints one.

    Example: physdbg scenes
    """
    if ctx.invoked_subcommand is not None:
        return
    from .scenes import builtin_descriptions

    rows = builtin_descriptions()
    if as_json:
        typer.echo(json.dumps([{"name": name, "description": description} for name, description in rows], indent=2))
        return
    width = max(len(name) for name, _ in rows)
    for name, description in rows:
        typer.echo(f"{name:<{width}}  {description}")


@scenes_app.command("show")
def scenes_show(
    scene: Annotated[str, typer.Argument(help="Built-in scene name (see `physdbg scenes`) or a .toml file.",
                                         autocompletion=lambda incomplete: _complete_scene(incomplete))],
    set_: SetOption = None,
    output_format: Annotated[str, typer.Option(
        "--format", help="toml: the scene file as it is; json: the scene with every value stated (each sphere "
                         "and plane listed, dt in seconds), as check-run and physdbg-trace.js read it; js: the "
                         "same as a JavaScript file a browser page or Node loads.")] = "toml",
) -> None:
    """Print a scene as a file (TOML), as JSON, or as a JavaScript module an engine loads:
    the spheres, planes, gravity, drag, dt and integrator of a sphere scene, stated in full.

    Example: physdbg scenes show bounce --format js > bounce-scene.js
    """
    with _user_errors():
        from .api import show_scene

        typer.echo(show_scene(scene, output_format, set_ or []).rstrip("\n"))


def _pile_note(scene) -> None:
    """Before a run: say on stderr when the scene makes a pile its settings will not let
    rest (advisor.pile_note), so nobody waits minutes without knowing why."""
    from .advisor import pile_note

    note = pile_note(scene)
    if note:
        typer.echo(f"note: {note}", err=True)


def _choose_tier(scene, overrides) -> object:
    """Compiled or interpreted for a run of ``scene`` (tier.for_scene), before the engine is loaded."""
    from . import tier

    return tier.for_scene(scene, overrides or [])


def _choose_tier_for(*recordings: Path) -> object:
    """The tier for commands that read recordings (tier.for_recordings)."""
    from . import tier

    return tier.for_recordings(*recordings)


def _after_interpreted(chosen, quiet: bool = False) -> None:
    """After an interpreted run on a cold cache, start the background compile (tier.py)."""
    from . import tier

    if getattr(chosen, "background", False):
        pid = tier.start_background_compile()
        if not quiet:
            typer.echo("note: the kernels are compiling in the background for the next run "
                       + (f"(pid {pid}; it ends by itself, at most {tier.BACKGROUND_TIMEOUT:.0f} s)" if pid
                          else "(it could not start: the next large run compiles them)"), err=True)


def _complete_scene(incomplete: str) -> list[str]:
    """Shell completion of a scene: the built-in names, then .toml files (`physdbg
    --install-completion` once, then TAB)."""
    from .scenes import builtin_names

    names = [name for name in builtin_names() if name.startswith(incomplete)]
    folder = Path(incomplete).parent if incomplete else Path(".")
    try:
        files = sorted(str(f) for f in folder.glob("*.toml") if str(f).startswith(incomplete))
    except OSError:
        files = []
    return names + files


def _complete_set(incomplete: str) -> list[str]:
    """Shell completion of --set: the scene's top-level fields and the tables' fields, as KEY=."""
    from .scene import FIELDS

    lists = ("particles", "planes", "meshes")  # arrays of tables: the first one's fields
    keys = [name if table == "scene" else f"{table}.0.{name}" if table in lists else f"{table}.{name}"
            for table, fields in FIELDS.items() for name in fields if name not in FIELDS]  # not tables alone
    return [f"{key}=" for key in keys if key.startswith(incomplete)]


SetOption = Annotated[
    Optional[list[str]],
    typer.Option("--set", "-s", metavar="KEY=VALUE", autocompletion=_complete_set,
                 help="Override a scene field, e.g. --set integrator=verlet --set generate.count=500. "
                      "Repeatable."),
]
SceneArgument = Annotated[str, typer.Argument(help="Built-in scene name (see `physdbg scenes`) or a .toml file.",
                                              autocompletion=_complete_scene)]


@app.command()
def run(
    scene: SceneArgument,
    set_: SetOption = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON (for scripts).")] = False,
    dts: Annotated[Optional[Path], typer.Option(
        "--dts", help="Repeat a run exactly: read each step's dt (one number per line) from this file.")] = None,
    dts_out: Annotated[Optional[Path], typer.Option(
        "--dts-out", help="Write each step's dt to this file (to repeat a real-time run with --dts).")] = None,
    progress: Annotated[bool, typer.Option(
        "--progress/--no-progress", show_default=False,
        help="Show a progress bar on long runs (default: when stderr is a terminal).")]
    = sys.stderr.isatty(),
    fail_on_findings: Annotated[bool, typer.Option(
        "--fail-on-findings", help="Exit 1 when the audit finds anything (tunnelling, overlap, energy gain, a "
                                   "budget hit, ...), for CI; without it a run that finished exits 0.")] = False,
    full_audit: Annotated[bool, typer.Option(
        "--full-audit", help="Walk every pair of spheres' path again in the audit, as `physdbg explain` does; by "
                             "default a step whose swept tests were exact and complete takes its pairs from the "
                             "engine's own tests (docs/diff.md, 'How explain works').")] = False,
) -> None:
    """Run a scene and print a summary: steps, contacts, energy and momentum change, ms/step,
    and the audit's findings.

    Example: physdbg run bullet-wall --set detection=discrete --fail-on-findings
    """
    with _user_errors(as_json):
        tier = _choose_tier(scene, set_)
        from .analysis.report import summary_text
        from .api import load_scene, read_step_lengths
        from .api import run as run_scene

        loaded = load_scene(scene, set_ or [])
        _pile_note(loaded)
        step_lengths = read_step_lengths(dts) if dts is not None else None
        total = len(step_lengths) if step_lengths is not None else loaded.steps
        bar = _progress_bar(total, show=progress and not as_json)
        try:
            summary = run_scene(loaded, dts=step_lengths, on_step=bar.update, on_status=bar.status,
                                audit="full" if full_audit else True)
        finally:
            bar.close()
        if dts_out is not None:
            try:
                dts_out.write_text("".join(f"{d!r}\n" for d in summary.dts))
            except OSError as err:
                raise PhysdbgError(f"{dts_out}: cannot write the step lengths ({err})") from None
        _after_interpreted(tier, quiet=as_json)
        if as_json:
            from .analysis.report import report_json

            typer.echo(report_json(summary))
        else:
            typer.echo(summary_text(summary))
        if fail_on_findings and summary.finding_counts:
            raise typer.Exit(1)


@app.command()
def record(
    scene: Annotated[Optional[str], typer.Argument(
        help="Built-in scene name (see `physdbg scenes`) or a .toml file; none with --from.",
        autocompletion=_complete_scene, show_default=False)] = None,
    set_: SetOption = None,
    output: Annotated[Optional[Path], typer.Option(
        "--output", "-o", help="The MCAP file to write (default recordings/<scene>.mcap).")] = None,
    rrd: Annotated[Optional[Path], typer.Option(
        "--rrd", help="The Rerun file to write (default: beside the MCAP file, ending .rrd).")] = None,
    no_rrd: Annotated[bool, typer.Option("--no-rrd", help="Write only the MCAP file.")] = False,
    spawn: Annotated[bool, typer.Option("--spawn", help="Also stream to a Rerun viewer started now.")] = False,
    detail: Annotated[Optional[str], typer.Option(
        "--detail", help="What to record: state (states, stats, warnings), contacts (+ every contact), "
                         "full (+ swept tests, broad phase, BVH nodes). Default: full (a fork: its parent's).",
        show_default=False)] = None,
    view: Annotated[Optional[bool], typer.Option(
        "--view/--no-view", help="Write the view channels (Foxglove 3D scene, point cloud, log) in the MCAP file, "
                                 "or leave them out (smaller, quicker; physdbg's own tools do not need them). "
                                 "Default: written up to 2000 spheres.", show_default=False)] = None,
    bvh_max_nodes: Annotated[Optional[int], typer.Option(
        "--bvh-max-nodes", min=0, help="Log at most this many BVH nodes a step, whole levels from the root "
                                "(default 4095; 0 = all).")] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing recordings.")] = False,
    dts: Annotated[Optional[Path], typer.Option(
        "--dts", help="Repeat a run exactly: read each step's dt (one number per line) from this file.")] = None,
    progress: Annotated[bool, typer.Option(
        "--progress/--no-progress", show_default=False,
        help="Show a progress bar on long runs (default: when stderr is a terminal).")]
    = sys.stderr.isatty(),
    check_against: Annotated[Optional[Path], typer.Option(
        "--check-against", help="After recording, diff against this golden recording: exit 1 (and say why) when "
                                "the runs part.")] = None,
    full_audit: Annotated[bool, typer.Option(
        "--full-audit", help="Walk every pair of spheres' path again in the audit, as `physdbg explain` does; by "
                             "default a step whose swept tests were exact and complete takes its pairs from the "
                             "engine's own tests (docs/diff.md, 'How explain works').")] = False,
    fork_from: Annotated[Optional[Path], typer.Option(
        "--from", help="Fork this recording instead of running a scene: repeat it up to --at, then go on with the "
                       "--set changes (docs/recording.md, \"Forking a recording\").", show_default=False)] = None,
    at: Annotated[Optional[int], typer.Option(
        "--at", min=1, help="With --from: the step the fork starts at (its changes apply from this step on).",
        show_default=False)] = None,
    steps: Annotated[Optional[int], typer.Option(
        "--steps", min=1, help="With --from: how many steps from --at on (default: to the parent's end).",
        show_default=False)] = None,
    try_: Annotated[bool, typer.Option(
        "--try", help="Try each audit finding's advice that is a change of settings on a fork of the new recording "
                      "from the finding's step, and say what it changed (as explain --try).")] = False,
    try_steps: Annotated[int, typer.Option(
        "--try-steps", min=0, help="With --try: how many steps after the finding's the fork runs.")] = 20,
) -> None:
    """Run a scene and record every step: MCAP (lossless) and Rerun (.rrd, to look at).

    Example: physdbg record bounce        then: .venv/bin/rerun recordings/bounce.rrd

    Fork a recording: physdbg record --from bounce.mcap --at 40 -s detection=discrete -o fork.mcap
    """
    if try_steps != 20 and not try_:
        with _user_errors():
            raise PhysdbgError("--try-steps says how long --try's forks run: give it with --try")
    if fork_from is not None or at is not None or steps is not None:
        if try_:
            with _user_errors():
                raise PhysdbgError("--try tries a new recording's advice: record it first, then `physdbg explain "
                                   "FORK --try`")
        return _record_fork(scene, fork_from, at, steps, set_, output, rrd, no_rrd, detail, view, force, progress,
                            dts)
    with _user_errors():
        if scene is None:
            raise PhysdbgError("give a scene to record (a built-in name or a .toml file), or --from a recording to "
                               "fork")
        tier = _choose_tier(scene, set_)
        from .analysis.report import size_words, summary_text
        from .api import diff as api_diff
        from .api import load_scene, read_step_lengths
        from .api import record as record_scene

        if check_against is not None and not check_against.is_file():
            raise PhysdbgError(f"{check_against}: no such recording to check against")
        loaded = load_scene(scene, set_ or [])
        _pile_note(loaded)
        step_lengths = read_step_lengths(dts) if dts is not None else None
        total = len(step_lengths) if step_lengths is not None else loaded.steps
        bar = _progress_bar(total, show=progress)
        try:
            result = record_scene(loaded, mcap_path=str(output) if output else None,
                                  rrd_path=str(rrd) if rrd else None, rrd=not no_rrd, detail=detail or "full",
                                  force=force, spawn=spawn, bvh_max_nodes=bvh_max_nodes, dts=step_lengths,
                                  on_step=bar.update, on_status=bar.status, view=view,
                                  audit="full" if full_audit else True)
        finally:
            bar.close()
        _after_interpreted(tier)
        typer.echo(summary_text(result.summary, "the recording and the audit"))
        typer.echo(f"recorded    {result.frames - 1} steps, detail {result.detail}")
        typer.echo(f"mcap        {result.mcap}  ({size_words(result.bytes_mcap)})")
        if result.rrd:
            typer.echo(f"rerun       {result.rrd}  ({size_words(result.bytes_rrd)})")
        typer.echo(f"view        {result.view_note}")
        if result.bvh_note:
            typer.echo(f"note        {result.bvh_note}")
        me = _command("physdbg")
        typer.echo("open with   " + (f"{_command('rerun')} {result.rrd}" if result.rrd
                                 else f"{me} replay {result.mcap} --spawn"))
        typer.echo(f"then try    {me} info {result.mcap}   |   {me} explain {result.mcap}")
        if try_:
            from .analysis.report import tried_words
            from .fork import try_advice

            for tried in try_advice(result.mcap, result.summary, try_steps):
                typer.echo(f"try         {tried_words(tried)}")
            if not result.summary.tried:
                typer.echo("try         no finding's advice is a change of settings: nothing to try")
        if check_against is not None:
            report = api_diff(check_against, result.mcap)
            from .analysis.report import diff_text

            typer.echo(f"check       against {check_against}")
            typer.echo(diff_text(report))
            raise typer.Exit(report.exit_code)


def _record_fork(scene, parent, at, steps, set_, output, rrd, no_rrd, detail, view, force, progress, dts) -> None:
    """record --from PARENT --at K: a fork (fork.fork_recording), printed as a recording is."""
    with _user_errors():
        if scene is not None:
            raise PhysdbgError(f"give a scene ({scene}) or --from a recording to fork, not both: a fork runs its "
                               f"parent's scene")
        if parent is None or at is None:
            raise PhysdbgError("a fork needs --from (the recording) and --at (the step it starts at)")
        if dts is not None:
            raise PhysdbgError("--dts does not go with --from: a fork repeats its parent's steps (--set dt=... "
                               "changes them from --at on)")
        if not parent.is_file():
            raise PhysdbgError(f"{parent}: no such recording to fork")
        tier = _choose_tier_for(parent)
        from .analysis.report import size_words, summary_text
        from .fork import fork_recording

        bar = _progress_bar(None, show=progress)
        try:
            result = fork_recording(parent, at, set_ or [], steps, mcap_path=str(output) if output else None,
                                    rrd_path=str(rrd) if rrd else None, rrd=not no_rrd,
                                    detail=detail, force=force,
                                    on_step=bar.update, on_status=bar.status, view=view)
        finally:
            bar.close()
        _after_interpreted(tier)
        typer.echo(summary_text(result.summary, "the recording and the audit"))
        from .analysis.report import fork_line

        typer.echo(f"fork        {fork_line(result.fork)}")
        typer.echo(f"recorded    {result.frames - 1} steps, detail {result.detail}")
        typer.echo(f"mcap        {result.mcap}  ({size_words(result.bytes_mcap)})")
        if result.rrd:
            typer.echo(f"rerun       {result.rrd}  ({size_words(result.bytes_rrd)})")
        me = _command("physdbg")
        typer.echo(f"then try    {me} diff {parent} {result.mcap}   |   {me} replay {result.mcap} --verify")


NoVerifyOption = Annotated[bool, typer.Option(
    "--no-verify", help="Read the recordings without checking each state against its stored hash and the frame "
                        "index (docs/recording.md, \"Integrity\"): for a file known to be altered.")]
OutputFormat = Annotated[str, typer.Option(
    "--format", "-f", help="text (default), json (schema in docs/diff.md) or markdown (for a CI step summary).")]


def _render(report, kind: str, output_format: str, as_json: bool, markdown: bool) -> str:
    from .analysis import report as rendering

    chosen = "json" if as_json else "markdown" if markdown else output_format
    if chosen not in ("text", "json", "markdown"):
        raise PhysdbgError(f"--format must be text, json or markdown, not {chosen!r}")
    if chosen == "json":
        return rendering.report_json(report)
    return rendering.RENDERINGS[kind, chosen](report)


@app.command()
def diff(
    a: Annotated[Path, typer.Argument(help="The first recording (.mcap), e.g. the golden one.")],
    b: Annotated[Path, typer.Argument(help="The second recording (.mcap).")],
    atol: Annotated[Optional[float], typer.Option(
        "--atol", min=0.0, help="Absolute tolerance (m, m/s). Default: exact when no setting that matters differs, "
                                "else 1e-9.")] = None,
    rtol: Annotated[Optional[float], typer.Option("--rtol", min=0.0, help="Relative tolerance (default as --atol).")]
    = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the report as JSON.")] = False,
    markdown: Annotated[bool, typer.Option("--markdown", help="Print the report as Markdown (CI step summary).")]
    = False,
    output_format: OutputFormat = "text",
    overlay: Annotated[Optional[Path], typer.Option(
        "--rrd", help="Also write both runs into one Rerun file, side by side, opened at the divergence.")] = None,
    spawn: Annotated[bool, typer.Option("--spawn", help="Open the overlay in the Rerun viewer.")] = False,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing --rrd file.")] = False,
    no_verify: NoVerifyOption = False,
    try_: Annotated[bool, typer.Option(
        "--try", help="Try each cause's advice that is a change of settings on a fork of the run it happened in, "
                      "from the cause's step, and say what it changed.")] = False,
    try_steps: Annotated[int, typer.Option(
        "--try-steps", min=0, help="With --try: how many steps after the cause's the fork runs.")] = 20,
) -> None:
    """Find where two recordings part ways and say why. Exit 0 equivalent, 1 different, 2 error
    (a file that is missing, damaged or altered).

    Example: physdbg diff recordings/ci/cradle.mcap cradle-index.mcap --markdown
    """
    with _user_errors(as_json or output_format == "json"):
        tier = _choose_tier_for(a, b)
        from . import api
        from .fork import TRY_STEPS, try_causes

        if try_steps != TRY_STEPS and not try_:
            raise PhysdbgError("--try-steps says how long --try's forks run: give it with --try")
        report = api.diff(a, b, atol=atol, rtol=rtol, verify=not no_verify)
        if try_:
            try_causes(report, try_steps)
        _after_interpreted(tier, quiet=True)
        typer.echo(_render(report, "diff", output_format, as_json, markdown))
        if try_ and not report.tried and not (as_json or markdown or output_format != "text"):
            typer.echo("try      no cause's advice is a change of settings: nothing to try")
        if overlay or spawn:
            written = api.overlay(a, b, report, str(overlay) if overlay else None, force=force, spawn=spawn,
                                  verify=not no_verify)
            if written and not (as_json or markdown):
                typer.echo(f"overlay  {written}  (both runs side by side, opened at the divergence)")
        raise typer.Exit(report.exit_code)


@app.command()
def explain(
    recording: Annotated[Path, typer.Argument(help="A .mcap recording to audit.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the report as JSON.")] = False,
    markdown: Annotated[bool, typer.Option("--markdown", help="Print the report as Markdown.")] = False,
    output_format: OutputFormat = "text",
    no_verify: NoVerifyOption = False,
    every: Annotated[bool, typer.Option("--all", help="List every finding (default: the first 5 of each kind, "
                                                      "with the count of each).")] = False,
    try_: Annotated[bool, typer.Option(
        "--try", help="Try each advice that is a change of settings on a fork of the run from the finding's step "
                      "(docs/recording.md, \"Forking a recording\"): is the finding gone, what else changed, what "
                      "it cost.")] = False,
    try_steps: Annotated[int, typer.Option(
        "--try-steps", min=0, help="With --try: how many steps after the finding's the fork runs.")] = 20,
) -> None:
    """Audit one recording: tunnelling, overlaps, out-of-order contacts, energy gained, NaN,
    budgets hit, collapse. Exit 0 clean, 1 findings, 2 error (a file that is missing,
    damaged or altered).

    Example: physdbg explain recordings/bullet-wall.mcap
    """
    with _user_errors(as_json or output_format == "json"):
        tier = _choose_tier_for(recording)
        from . import api

        report = api.explain(recording, verify=not no_verify, every_finding=every)
        from .fork import TRY_STEPS, try_advice

        if try_:
            try_advice(recording, report, try_steps)
        elif try_steps != TRY_STEPS:
            raise PhysdbgError("--try-steps says how long --try's forks run: give it with --try")
        _after_interpreted(tier, quiet=True)
        typer.echo(_render(report, "explain", output_format, as_json, markdown))
        raise typer.Exit(0 if report.clean else 1)


@app.command()
def replay(
    recording: Annotated[Path, typer.Argument(help="A .mcap recording made by `physdbg record`.")],
    rrd: Annotated[Optional[Path], typer.Option("--rrd", help="Write the Rerun view to this .rrd file.")] = None,
    spawn: Annotated[bool, typer.Option("--spawn", help="Open the Rerun viewer on the recording.")] = False,
    web: Annotated[bool, typer.Option("--web", help="Serve the Rerun web viewer on localhost.")] = False,
    port: Annotated[int, typer.Option("--port", min=1, max=65535,
                                      help="The web viewer's HTTP port on localhost (with --web).")] = 9090,
    verify: Annotated[bool, typer.Option(
        "--verify", help="Re-simulate from the embedded scene and check every step's hash; "
                         "exit 1 at the first mismatch.")] = False,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing --rrd file.")] = False,
    at: Annotated[Optional[int], typer.Option(
        "--at", metavar="STEP", min=1,
        help="Open the view paused at this step (default: the first contact; in a scene with meshes the first on "
             "a mesh).")] = None,
    no_verify: NoVerifyOption = False,
) -> None:
    """Rebuild the Rerun view of a recording from the MCAP file alone, or verify it.
    Every state read is checked against its stored hash (--no-verify skips that);
    --verify also re-simulates every step.

    Example: physdbg replay recordings/bounce.mcap --rrd bounce.rrd --verify
    """
    with _user_errors():
        _choose_tier_for(recording)
        from . import api

        if not (rrd or spawn or web or verify):
            raise PhysdbgError("say what to do: --rrd FILE, --spawn, --web and/or --verify")
        if at is not None and not (rrd or spawn or web):
            raise PhysdbgError("--at opens the view at a step: give it with --rrd FILE, --spawn or --web")
        if verify and no_verify:
            raise PhysdbgError("--verify checks the file and re-simulates it; --no-verify skips the checks: give one")
        if verify:
            result = api.verify(recording)
            if result.ok:
                typer.echo(f"verify      ok: {result.checked} steps re-simulated, every state hash matches")
                if result.truncated:
                    typer.echo(f"            INCOMPLETE: {recording} has no summary (its writer was stopped before "
                               f"closing it, or is still writing it): only the {result.checked} whole steps it "
                               f"holds so far were checked")
            else:
                typer.echo(f"verify      MISMATCH at step {result.first_bad_step}: {result.reason}")
                raise typer.Exit(1)
        if rrd or spawn or web:
            import shutil
            import tempfile

            scratch = None if rrd else Path(tempfile.mkdtemp(prefix="physdbg-"))
            target = rrd or scratch / (recording.stem + ".rrd")
            try:
                done = api.replay(recording, str(target), force=force, verify=not no_verify, at=at)
                typer.echo(f"replayed    {done['steps']} steps"
                           + (" (truncated recording)" if done["truncated"] else "") + f" -> {target}")
                if web:
                    viewers.serve_web(target, port, typer.echo)
                elif spawn:
                    viewers.spawn_viewer(target)
                    scratch = None  # the viewer reads it after we exit; the OS cleans temp folders
            finally:
                if scratch is not None:
                    shutil.rmtree(scratch, ignore_errors=True)


OverwriteRecording = Annotated[bool, typer.Option("--force", help="Overwrite an existing recording.")]


TimeUnitOption = Annotated[Optional[str], typer.Option(
    "--time-unit", help="The unit of the run's time column: s (the default) or ms (JavaScript's Date.now()); "
                        "velocities stay per second.")]
LengthUnitOption = Annotated[Optional[str], typer.Option(
    "--length-unit", help="The unit of the run's positions and velocities (per second): m (the default), cm or "
                          "mm.")]


@app.command("import")
def import_(
    run: Annotated[Path, typer.Argument(help="The other engine's run: a .csv or .jsonl trajectory "
                                              "(docs/foreign-runs.md).")],
    scene: Annotated[str, typer.Option("--scene", help="The scene it ran: a built-in name or a .toml file.")],
    set_: SetOption = None,
    output: Annotated[Optional[Path], typer.Option(
        "--output", "-o", help="The recording to write (default: the run's name, ending .mcap).")] = None,
    force: OverwriteRecording = False,
    time_unit: TimeUnitOption = None,
    length_unit: LengthUnitOption = None,
) -> None:
    """Turn a run of another engine (your own, pybullet, MuJoCo) into a physdbg recording,
    so explain, diff and replay work on it.

    Example: physdbg import my-engine.csv --scene bullet-wall -o mine.mcap
    """
    with _user_errors():
        from .analysis.report import size_words
        from .api import import_run

        result = import_run(run, scene, set_ or [], output, force, time_unit=time_unit, length_unit=length_unit)
        me = _command("physdbg")
        bodies = f"{result.bodies} body" if result.bodies == 1 else f"{result.bodies} bodies"
        typer.echo(f"imported    {result.frames - 1} steps of {bodies} from {run} (velocities {result.velocities})")
        typer.echo(f"mcap        {result.mcap}  ({size_words(result.bytes)})")
        typer.echo(f"then try    {me} explain {result.mcap}   |   {me} replay {result.mcap} --spawn")


def _check_class(folder: Path, scene: str | None, overrides: list[str], atol, rtol, time_unit, length_unit, jobs, dask,
                 chosen: str, verify: bool = True) -> None:
    """check-run of a folder of runs: one table (analysis.classroom); verify: check every
    state read against its stored hash, as for one run (--no-verify: not)."""
    with _user_errors(chosen == "json"):
        import json

        from .analysis import classroom

        if chosen not in ("text", "json", "markdown", "csv"):
            raise PhysdbgError(f"--format must be text, json, markdown or csv, not {chosen!r}")
        from .api import check_class

        report = check_class([folder], scene, overrides, workers=jobs, dask=dask, atol=atol, rtol=rtol,
                             time_unit=time_unit, length_unit=length_unit, verify=verify)
        if chosen == "json":
            typer.echo(json.dumps(report.as_dict(), indent=2))
        else:
            typer.echo(classroom.CLASS_FORMATS[chosen](report).rstrip("\n"))
        if report.exit_code:
            raise typer.Exit(report.exit_code)


@app.command("trace-js")
def trace_js(
    output: Annotated[Path, typer.Option("--output", "-o", help="The folder to write physdbg-trace.js into.")]
    = Path("."),
    force: Annotated[bool, typer.Option("--force", help="Replace a physdbg-trace.js already there.")] = False,
) -> None:
    """Write physdbg-trace.js, a dependency-free JavaScript tracer: three calls in a browser
    (or Node) engine record its run for check-run (docs/foreign-runs.md, "From a JavaScript
    engine").

    Example: physdbg trace-js -o my-engine/
    """
    with _user_errors():
        from .api import write_trace_js

        out = write_trace_js(output, force)
        me = _command("physdbg")
        typer.echo(f"wrote       {out}")
        typer.echo(f"scene       {me} scenes show bounce --format js > bounce-scene.js   (your engine loads it; "
                   f"scene.integrator = \"euler\" if it steps x += v·dt, v += a·dt)")
        typer.echo("then add    const trace = physdbgTrace.start(scene);  trace.frame(t, positions, velocities);  "
                   "trace.finish();")
        typer.echo(f"and run     {me} check-run bounce.jsonl   (the run carries its scene; a run started with "
                   f"start(\"bounce\") compares with the scene's own integrator: add -s integrator=euler)")


@app.command("check-run")
def check_run(
    run: Annotated[Optional[Path], typer.Argument(help="The other engine's run: a .csv, .jsonl or .mcap trajectory "
                                                        "(docs/foreign-runs.md), or a folder of runs.")] = None,
    scene: Annotated[Optional[str], typer.Option(
        "--scene", help="The scene it ran: a built-in name or a .toml file (default: the scene a .jsonl run "
                        "carries on its first line, as physdbg-trace.js's start(scene) writes it).")] = None,
    set_: SetOption = None,
    atol: Annotated[Optional[float], typer.Option(
        "--atol", min=0.0, help="A body departs when its position (m) or velocity (m/s) is off by more than "
                                "atol + rtol·|physdbg's| (default 1e-6).")] = None,
    rtol: Annotated[Optional[float], typer.Option("--rtol", min=0.0, help="Relative tolerance (default 1e-6).")]
    = None,
    keep: Annotated[Optional[Path], typer.Option(
        "--keep", help="Keep both recordings in this folder (run.mcap and reference.mcap) for replay, diff and "
                       "overlay.")] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite recordings already in the --keep folder.")]
    = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the report as JSON.")] = False,
    markdown: Annotated[bool, typer.Option("--markdown", help="Print the report as Markdown.")] = False,
    output_format: OutputFormat = "text",
    no_verify: NoVerifyOption = False,
    time_unit: TimeUnitOption = None,
    length_unit: LengthUnitOption = None,
    jobs: Annotated[Optional[int], typer.Option(
        "--jobs", "-j", min=1, help="A folder of runs: local processes to check them in (default: every core).")]
    = None,
    dask: Annotated[Optional[str], typer.Option(
        "--dask", help="A folder of runs: check them on an existing Dask cluster (its scheduler's address, "
                       "tcp://host:8786; needs pip install 'physdbg[dask]').")] = None,
    serve: Annotated[bool, typer.Option(
        "--serve", help="Listen on 127.0.0.1 for runs a page sends (physdbg-trace.js's finish()): check each, "
                        "print its verdict, keep its recordings (in --keep, default physdbg-runs) and answer the "
                        "page, which shows it. Ctrl-C stops.")] = False,
    port: Annotated[Optional[int], typer.Option(
        "--port", min=0, max=65535, help=f"With --serve: the port (0: any free one; default {SERVE_PORT}).")] = None,
    max_bytes: Annotated[Optional[int], typer.Option(
        "--max-bytes", min=1, help=f"With --serve: the largest run a page may send, in bytes (default "
                                   f"{SERVE_MAX_BYTES}).")] = None,
) -> None:
    """Run physdbg's exact version of the scene with the run's own time steps and say where
    the run departs and why: tunnelling, a bounce at the wrong time, energy at a contact,
    contacts out of order, the integrator. Exit 0 same within tolerance, 1 departs, 2 error.
    RUN may be a folder: every run in it is checked (a class of submissions), one row each,
    as text, markdown, json or csv (--format), the causes counted; exit 0 when all are same.

    Example: physdbg check-run docs/examples/student-bounce.csv --scene bounce
    (a run traced with its scene needs no --scene: physdbg check-run bounce.jsonl;
    the verdict in the page that traced it: physdbg check-run --serve)
    """
    if serve:
        with _user_errors():
            if run is not None:
                raise PhysdbgError(f"--serve checks the runs pages send; check {run} without --serve")
            _serve(scene, set_ or [], keep or Path("physdbg-runs"), SERVE_PORT if port is None else port,
                   max_bytes or SERVE_MAX_BYTES, force, atol=atol, rtol=rtol, time_unit=time_unit,
                   length_unit=length_unit, verify=not no_verify)
        return
    if port is not None or max_bytes is not None:
        with _user_errors(as_json or output_format == "json"):
            raise PhysdbgError("--port and --max-bytes go with --serve")
    if run is None:
        with _user_errors(as_json or output_format == "json"):
            raise PhysdbgError("give the run to check (a .csv, .jsonl or .mcap file, or a folder of runs), or "
                               "--serve to check the runs pages send")
    if run.is_dir():
        if keep is not None:
            with _user_errors(as_json or output_format == "json"):
                raise PhysdbgError(f"--keep keeps the two recordings of one run, and {run} is a folder of runs: "
                                   f"check the run you want to keep on its own with --keep")
        _check_class(run, scene, set_ or [], atol, rtol, time_unit, length_unit, jobs, dask,
                     "json" if as_json else "markdown" if markdown else output_format, verify=not no_verify)
        return
    with _user_errors(as_json or output_format == "json"):
        if scene is None:  # the run's own scene, for the tier's estimate of the work
            from .record.foreign import run_scene
            from .scenes import builtin_names

            carried = run_scene(run)  # (a name that is not a built-in one is not read as a file)
            tier = _choose_tier(carried if isinstance(carried, dict) or carried in builtin_names() else "", set_)
        else:
            tier = _choose_tier(scene, set_)
        from . import api

        result = api.check_run(run, scene, set_ or [], atol=atol, rtol=rtol, keep=keep, force=force,
                               verify=not no_verify, time_unit=time_unit, length_unit=length_unit)
        _after_interpreted(tier, quiet=True)
        typer.echo(_render(result.report, "check_run", output_format, as_json, markdown))
        if result.run and not (as_json or markdown or output_format != "text"):
            me = _command("physdbg")
            typer.echo(f"kept       {result.run}, {result.reference}")
            typer.echo(f"then try   {me} diff {result.run} {result.reference} --rrd both.rrd   |   {me} replay {result.run} --spawn")
        raise typer.Exit(result.report.exit_code)


def _serve(scene: str | None, overrides: list[str], folder: Path, port: int, max_bytes: int, force: bool,
           **options) -> None:
    """check-run --serve (physdbg/serve.py) until Ctrl-C or SIGTERM; options: check_run's."""
    from .serve import CheckServer

    server = CheckServer(folder, scene, overrides, port=port, max_bytes=max_bytes, force=force,
                         on_verdict=lambda verdict: typer.echo(verdict.line()), **options)
    typer.echo(f"serving     {server.url}  (127.0.0.1 only; pages with physdbg-trace.js send their runs here "
               f"when finish() is called)")
    typer.echo(f"scene       {scene or 'each run' + chr(39) + 's own (its first line)'}"
               + (f", {' '.join('-s ' + o for o in overrides)}" if overrides else ""))
    typer.echo(f"keeping     {folder}/  (each run with run.mcap and reference.mcap; Ctrl-C stops)")
    if viewers.until_stopped(server.serve_forever):
        typer.echo("stopped")


@app.command("record-peer")
def record_peer(
    peer: Annotated[str, typer.Argument(help="The peer engine: pybullet or mujoco (pip install 'physdbg[peers]').")],
    scene: SceneArgument,
    set_: SetOption = None,
    output: Annotated[Optional[Path], typer.Option(
        "--output", "-o", help="The recording to write (default: SCENE-PEER.mcap).")] = None,
    force: OverwriteRecording = False,
) -> None:
    """Run a scene in pybullet or MuJoCo from the same initial state and record it as a
    foreign run, to check-run, diff, explain and replay against physdbg's.

    Example: physdbg record-peer pybullet bounce -o bounce-pybullet.mcap
    """
    with _user_errors():
        from .api import record_peer as run_peer

        result = run_peer(peer, scene, set_ or [], output, force)
        me = _command("physdbg")
        bodies = f"{result.bodies} body" if result.bodies == 1 else f"{result.bodies} bodies"
        typer.echo(f"ran         {result.frames - 1} steps of {bodies} in {peer} ({result.seconds:.3g} s)")
        for note in result.notes:
            typer.echo(f"how         {note}")
        typer.echo(f"mcap        {result.mcap}")
        typer.echo(f"then try    {me} check-run {result.mcap} --scene {scene}   |   {me} replay {result.mcap} --spawn")


@app.command()
def check(
    scene: SceneArgument,
    set_: SetOption = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print as JSON.")] = False,
) -> None:
    """Advise on a scene from the scene alone: which methods fail on it and why, the
    cheapest safe settings, and whether the scene's own settings are safe (exit 1 when
    they are predicted to tunnel or leave overlaps). `integrator = "auto"` (and detection,
    ordering) in a scene takes this advice.

    Example: physdbg check bullet-wall -s detection=discrete
    """
    with _user_errors(as_json):
        from .analysis.report import check_text
        from .api import check as check_scene

        result = check_scene(scene, set_ or [])
        if as_json:
            from .analysis.report import check_dict, versioned

            typer.echo(json.dumps(versioned(check_dict(result)), indent=2, default=str))
        else:
            typer.echo(check_text(result))
        if not result.ok:
            raise typer.Exit(1)


JobsOption = Annotated[Optional[int], typer.Option(
    "--jobs", "-j", min=1, help="Local processes to run the sweep in (default: every core; 1: this one).")]
DaskOption = Annotated[Optional[str], typer.Option(
    "--dask", help="Run the sweep on an existing Dask cluster: its scheduler's address (tcp://host:8786); "
                   "needs pip install 'physdbg[dask]'.")]
NoChartOption = Annotated[bool, typer.Option(
    "--no-chart", help="Only the CSV and the table. Without it the chart is drawn when matplotlib is installed "
                       "(pip install 'physdbg[charts]'), and a note says so when it is not.")]
BenchForceOption = Annotated[bool, typer.Option("--force", help="Overwrite files from an earlier run.")]
BenchProgressOption = Annotated[bool, typer.Option("--progress/--no-progress", help="Show a progress bar.")]
bench_app = typer.Typer(help="Benchmarks users run: methods charted against each other.", no_args_is_help=True)
app.add_typer(bench_app, name="bench")


@bench_app.command("accuracy")
def bench_accuracy(
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder for accuracy.csv, .md, .png and .svg.")]
    = Path("accuracy"),
    quick: Annotated[bool, typer.Option("--quick", help="Two dt per method instead of four (under a minute).")]
    = False,
    problem: Annotated[Optional[list[str]], typer.Option(
        "--problem", help="Only this problem (repeat for more); default all.")] = None,
    no_chart: NoChartOption = False,
    rrd: Annotated[Optional[Path], typer.Option("--rrd", help="Also write the chart as a Rerun file.")] = None,
    jobs: JobsOption = None,
    dask: DaskOption = None,
    force: BenchForceOption = False,
    progress: BenchProgressOption = sys.stderr.isatty(),
) -> None:
    """Every integrator × detection × ordering on reference problems with known answers:
    error against the answer and wall time per simulated second, as a table, a CSV and a
    chart (error against cost, Pareto front drawn).

    Example: physdbg bench accuracy --quick -o docs/accuracy
    """
    with _user_errors():
        from .api import bench_accuracy as run_accuracy

        bar = _progress_bar(None, show=progress)
        command = "physdbg bench accuracy" + (" --quick" if quick else "")
        try:
            result = run_accuracy(out, quick=quick, force=force, chart=False if no_chart else None, rrd_path=str(rrd) if rrd else None,
                                  problems=problem, on_run=lambda run, done, total: bar.update(done, total),
                                  command=command, workers=jobs, dask=dask, on_status=bar.status)
        finally:
            bar.close()
        from .analysis.accuracy import summary_lines

        typer.echo(f"{len(result.runs)} runs in {result.seconds:.1f} s")
        for line in summary_lines(result.runs):
            typer.echo(line)
        _bench_files(result)


@bench_app.command("engines")
def bench_engines(
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder for engines.csv, .md, .png and .svg.")]
    = Path("engines"),
    quick: Annotated[bool, typer.Option("--quick", help="The small scenes and box-rain 1k (a minute or two), "
                                                       "not box-rain 10k.")] = False,
    scene: Annotated[Optional[list[str]], typer.Option(
        "--scene", help="Only this scene (repeat for more): bounce, cradle, bullet-wall, gas, 'box-rain 1k', "
                        "'box-rain 10k'.")] = None,
    no_chart: NoChartOption = False,
    force: BenchForceOption = False,
    progress: BenchProgressOption = sys.stderr.isatty(),
) -> None:
    """physdbg's methods and the peers (pybullet, MuJoCo: pip install 'physdbg[peers]'),
    each set up for the same frictionless physics, on the same scenes: ms/step against
    largest overlap, energy error, first-contact time error and tunnelled bodies, each
    measured against physdbg's exact run; a table, a CSV and a chart.

    Example: physdbg bench engines --quick -o engines
    """
    with _user_errors():
        from .api import bench_engines as run_engines

        bar = _progress_bar(None, show=progress)
        command = "physdbg bench engines" + (" --quick" if quick else "")
        try:
            result = run_engines(out, quick=quick, force=force, chart=False if no_chart else None, scenes=scene,
                                 on_run=lambda run, done, total: bar.update(done, total), command=command,
                                 on_status=bar.status)
        finally:
            bar.close()
        from .analysis.engines import summary_lines

        typer.echo(f"{len(result.runs)} runs in {result.seconds:.1f} s")
        for line in summary_lines(result.runs):
            typer.echo(line)
        _bench_files(result)


@bench_app.command("stability")
def bench_stability(
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder for stability.csv, .md and the heatmaps.")]
    = Path("stability"),
    quick: Annotated[bool, typer.Option("--quick", help="A coarser grid.")] = False,
    no_chart: NoChartOption = False,
    jobs: JobsOption = None,
    dask: DaskOption = None,
    force: BenchForceOption = False,
    progress: BenchProgressOption = sys.stderr.isatty(),
) -> None:
    """Where each integrator × detection breaks: pass or fail over (dt, impact speed) at a
    thin wall and over (restitution, height) for resting stacks, each failure named.

    Example: physdbg bench stability --quick -o docs/stability
    """
    with _user_errors():
        from .api import bench_stability as run_stability

        bar = _progress_bar(None, show=progress)
        command = "physdbg bench stability" + (" --quick" if quick else "")
        try:
            result = run_stability(out, quick=quick, force=force, chart=False if no_chart else None,
                                   on_cell=lambda cell, done, total: bar.update(done, total), command=command,
                                   workers=jobs, dask=dask, on_status=bar.status)
        finally:
            bar.close()
        from .analysis.stability import REACH, summary_lines

        typer.echo(f"{len(result.runs)} cells in {result.seconds:.1f} s; REACH = wall thickness/2 + r = {REACH:g} m")
        for line in summary_lines(result.runs):
            typer.echo(line)
        _bench_files(result)


def _bench_files(result) -> None:
    """The files a benchmark wrote, and the note when it drew no chart."""
    for path in result.files:
        typer.echo(f"wrote       {path}")
    if result.note:
        typer.echo(f"note        {result.note}")


@app.command()
def info(
    recording: Annotated[Path, typer.Argument(help="A .mcap recording.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print as JSON.")] = False,
) -> None:
    """Show what a recording holds: scene, settings, steps, channels and sizes.

    Example: physdbg info recordings/bounce.mcap
    """
    with _user_errors(as_json):
        from .analysis.report import info_text
        from .api import info as recording_info

        data = recording_info(recording)
        if as_json:
            typer.echo(json.dumps(data, indent=2))
            return
        typer.echo(info_text(data))


@app.command()
def overlap(
    a: Annotated[str, typer.Argument(help="A mesh: an .obj or .stl file, or a built-in shape (box, ramp, funnel, "
                                          "box-with-hole, paddle, icosphere).")],
    b: Annotated[str, typer.Argument(help="The other mesh, likewise.")],
    pose: Annotated[Optional[str], typer.Option(
        "--pose", help="Where B sits: x,y,z or x,y,z,rx,ry,rz (m, then degrees about x, y and z). Default: at the "
                       "origin, unturned.")] = None,
    pose_a: Annotated[Optional[str], typer.Option("--pose-a", help="Where A sits, likewise.")] = None,
    volume: Annotated[str, typer.Option(
        "--volume", help="The bounding volume tested at every node: auto, aabb, obb or sphere.")] = "auto",
    builder: Annotated[str, typer.Option("--builder", help="How each BVH is built: median, mean, sah or lbvh.")]
    = "sah",
    hull: Annotated[bool, typer.Option("--hull/--no-hull", help="Test the convex hulls (qhull) before the trees.")]
    = True,
    max_lines: Annotated[int, typer.Option("--max-lines", min=0,
                                           help="Node pairs of the search tree to print (0: all).")] = 40,
    as_json: Annotated[bool, typer.Option("--json", help="Print the report as JSON (the whole search tree).")]
    = False,
) -> None:
    """Do two meshes overlap? Search both BVHs at once and print the search tree: every node
    pair visited and what its volumes said. Exit 0 apart, 1 they meet, 2 error.

    Example: physdbg overlap icosphere paddle --pose 0.5,0,0,0,0,30
    """
    with _user_errors(as_json):
        from .analysis.mesh_pair_search import overlap_text
        from .analysis.report import versioned
        from .api import overlap as search

        report = search(a, b, pose_a=pose_a, pose_b=pose, volume=volume, builder=builder, hull=hull)

        typer.echo(json.dumps(versioned(report.as_dict()), indent=2) if as_json else overlap_text(report, max_lines))
        raise typer.Exit(report.exit_code)


def _command(name: str) -> str:
    """How to run ``name`` (rerun, physdbg) from here: the bare name if it is on PATH, else
    its path in this venv (after README command 1 the venv is not activated)."""
    import os
    import shutil

    if shutil.which(name):
        return name
    beside = os.path.join(os.path.dirname(sys.executable), name)
    if not os.path.exists(beside):
        return name
    relative = os.path.relpath(beside)
    return relative if not relative.startswith("..") else beside


class _progress_bar:
    """Progress on stderr: a note when the kernels take a while to compile (the first run),
    and a bar once a run has taken more than a second (whatever its step count).

    show: draw the bar at all (off for --json or when stderr is not a terminal); the
    compile note is shown whenever compiling takes more than a second.
    """

    AFTER_SECONDS = 1.0

    def __init__(self, total: int | None, show: bool = True):
        import time

        self.total = total
        self.show = show
        self._time = time.perf_counter
        self._started = self._time()
        self._last = 0.0
        self._drawn = False
        self._timer = None

    def status(self, what: str) -> None:
        """'compiling': start a timer that says so after a second; 'running': the steps begin."""
        import threading

        if what == "compiling":
            self._compiling_since = self._time()
            self._said_compiling = False
            self._timer = threading.Timer(self.AFTER_SECONDS, self._say_compiling)
            self._timer.daemon = True
            self._timer.start()
        else:
            self._cancel()
            if getattr(self, "_said_compiling", False):
                sys.stderr.write(f"compiled in {self._time() - self._compiling_since:.0f} s\n")
                sys.stderr.flush()
            self._started = self._time()

    def _say_compiling(self) -> None:
        # every compile is announced: the first, and a later one for a feature no run has
        # used yet (another broad phase, sleeping, meshes), each cached once compiled
        self._said_compiling = True
        sys.stderr.write("compiling the engine's kernels this run needs (once per engine version and feature: "
                         "30 s to a minute and more the first time; cached afterwards)...\n")
        sys.stderr.flush()

    def _cancel(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def update(self, done: int, total: int | None) -> None:
        now = self._time()
        if not self.show or now - self._started < self.AFTER_SECONDS:
            return
        if now - self._last < 0.1 and done != total:
            return
        self._last = now
        self._drawn = True
        if total:
            filled = int(30 * done / total)
            sys.stderr.write(f"\r[{'#' * filled}{'.' * (30 - filled)}] step {done}/{total}")
        else:
            sys.stderr.write(f"\rstep {done}")
        sys.stderr.flush()

    def close(self) -> None:
        self._cancel()
        if self._drawn:
            sys.stderr.write("\n")


def console_main() -> None:
    """The ``physdbg`` console script: run the typer app, then leave quickly.

    Why the garbage-collector settings: importing numba and loading the cached kernels
    make about 10^5 long-lived objects (types, templates, kernels), and with CPython's
    default thresholds the collector walks them some 270 times in a ``physdbg run
    bounce`` (0.13 s); a larger first threshold makes that 9 times (0.05 s). At exit the
    finalizer runs full collections over every object still alive; freezing them first
    skips that work (0.2-0.3 s). Together about a quarter of the warm ``run bounce`` that
    the speed targets want under 1 s (docs/benchmarks.md). Library callers keep their own settings: only this entry
    point changes them.
    """
    gc.set_threshold(20_000, 20, 20)
    try:
        app(prog_name="physdbg")
    finally:
        gc.freeze()


if __name__ == "__main__":  # pragma: no cover
    console_main()
