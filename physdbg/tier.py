"""Compiled or interpreted: the first run answers in seconds, and both tiers give one result.

The engine's functions are numba kernels. Compiled, a step of a large scene costs
microseconds; but the first compile on a machine (a cold cache: a fresh clone, a CI
runner, a changed engine) takes 30–70 s, for a one-ball ``bounce`` whose 300 steps then
take 0.03 s. Interpreted (each kernel's own Python source, as ``NUMBA_DISABLE_JIT=1`` runs
it: ``engine/jit.py`` hands the function back uncompiled), a step costs 10–100 times as
much, and nothing is compiled. Both tiers run the same source in the same order with the
same floating-point operations (no fused multiply-add, the same libm), so they give
bit-identical states and hashes (``tests/test_tier.py`` runs every built-in scene both
ways).

The rule (``choose``), decided before the engine is imported, since numba reads the
switch when a kernel is defined:

* ``PHYSDBG_COMPILE=now``: compiled (compiling in the foreground if the cache is cold);
* ``PHYSDBG_COMPILE=never``: interpreted when the cache is cold, and nothing is started;
* otherwise (``auto``, or ``background``): interpreted when the cache is cold and the run is
  small (at most ``INTERPRET_UP_TO`` sphere-steps, estimated from the scene file before
  loading it: ``estimate``), then the kernels are compiled by a background process
  (``start_background_compile``) so that the next run finds them; compiled otherwise.

The background compile is one detached process (``python -m physdbg.tier``, at the lowest
CPU priority) that compiles the kernels a run uses and writes numba's cache, and ends by
itself: when it is done, or after ``BACKGROUND_TIMEOUT`` s at most. It is a process of its
own session, so a terminal closing does not stop it; a CI job's end stops it with the
job's processes (runners kill what a job started). ``PHYSDBG_COMPILE=never`` or ``now``
starts none.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

from . import kernel_cache

# Runs of at most this many sphere-steps are interpreted on a cold cache. Measured on this
# project's 2-core machines (docs/benchmarks.md, "The first run"): interpreted, a whole
# `physdbg run` costs about 0.45 s to start and 0.1–0.2 ms a sphere-step (gas, rain,
# funnel, billiards), 1.6 ms in the ramp scene's crease (held contacts made and released
# every step), so 20,000 take 2–5 s (rain 200 × 120: 4.7 s), against a cold compile of 30–70 s.
INTERPRET_UP_TO = 20_000
BACKGROUND_TIMEOUT = 900.0  # s: a background compile still running after this ends itself
CHOICES = ("auto", "now", "background", "never")


@dataclass(frozen=True)
class Tier:
    """interpreted: run the engine's functions as Python; reason: why, in words;
    background: start a background compile after the run."""

    interpreted: bool
    reason: str
    background: bool = False


def setting() -> str:
    """PHYSDBG_COMPILE, checked (auto when unset)."""
    value = os.environ.get("PHYSDBG_COMPILE", "auto").strip().lower() or "auto"
    if value not in CHOICES:
        raise ValueError(f"PHYSDBG_COMPILE={value!r}: one of {', '.join(CHOICES)}")
    return value


def cache_is_warm() -> bool:
    """Whether numba's cache folder for these engine sources (physdbg/kernel_cache.py names
    it) holds the compiled step for this CPU: the held-contact solve and the time-ordered
    loop, the two trees a cold compile spends its time on. Read from the files (the engine
    is not imported): each needs its code (.nbc) and, where its index (.nbi) can be read,
    an entry for this machine's CPU (numba keys every cached kernel by the CPU's name and
    features: a folder filled on another CPU model is compiled again; docs/compiling.md, "A
    cache for any CPU")."""
    folder = kernel_cache.folder()
    if not folder.is_dir():
        return False
    names = ("resolve.settle_held-", "timeline.run_time_order-")
    code = {name: False for name in names}
    cpus: dict[str, set | None] = {name: None for name in names}  # None: no index read
    for path in Path(folder).rglob("*.nb[ci]"):
        for name in names:
            if not path.name.startswith(name):
                continue
            if path.suffix == ".nbc":
                code[name] = True
            elif (listed := _index_cpus(path)) is not None:
                cpus[name] = (cpus[name] or set()) | listed
    if not all(code.values()):
        return False
    if all(listed is None for listed in cpus.values()):
        return True  # no index read: the code files decide
    from .precompile import this_cpu

    here = this_cpu()
    return all(listed is None or here in listed for listed in cpus.values())


def _index_cpus(path: Path) -> set | None:
    """The CPUs a numba index file (.nbi) lists compiled versions for, or None when it
    cannot be read (numba's own layout: its version pickled, then (source stamp,
    {(signature, cpu, code hashes): data file name}) pickled; an internal, so unreadable
    means "unknown", never cold)."""
    import pickle

    try:
        with open(path, "rb") as f:
            pickle.load(f)
            _stamp, overloads = pickle.loads(f.read())
        return {key[1] for key in overloads}
    except Exception:  # noqa: BLE001 - another numba's layout: the code files decide
        return None


def _number(value) -> float | None:
    if isinstance(value, bool):
        return None
    try:
        if isinstance(value, (int, float)):
            number = float(value)
        elif isinstance(value, str):
            number = float(Fraction(value.strip()))
        else:
            return None
    except (ValueError, ZeroDivisionError, OverflowError):  # "1e400", a 400-digit integer
        return None
    return number if math.isfinite(number) else None


def estimate(spec: str | dict, overrides=()) -> int | None:
    """Sphere-steps (spheres × steps) of a scene, read from its TOML before it is loaded
    (a built-in name or a file; ``overrides`` as ``-s key=value``), or None when the file
    does not say (a real-time dt, a file that does not parse: the engine's checks will
    speak; None counts as large)."""
    from .scenes import builtin_names, builtin_text

    try:
        path = Path(spec) if isinstance(spec, str) else None
        if isinstance(spec, dict):  # a scene table (a run's own scene: foreign.run_scene)
            raw = spec
        elif path.is_file():
            raw = tomllib.loads(path.read_text(encoding="utf-8"))
        elif spec in builtin_names():
            raw = tomllib.loads(builtin_text(spec))
        else:
            return None
    except (OSError, ValueError):
        return None
    values: dict[str, object] = {}
    for item in overrides:
        key, _, value = str(item).partition("=")
        try:
            values[key.strip()] = tomllib.loads(f"v = {value}")["v"]
        except ValueError:
            values[key.strip()] = value
    generate = raw.get("generate") if isinstance(raw.get("generate"), dict) else {}
    count = values.get("generate.count", generate.get("count")) if generate or "generate.count" in values else None
    particles = raw.get("particles") if isinstance(raw.get("particles"), list) else []
    spheres = (_number(count) or 0.0) + len(particles)
    dt = _number(values.get("dt", raw.get("dt")))
    steps = _number(values.get("steps", raw.get("steps")))
    duration = _number(values.get("duration", raw.get("duration")))
    if steps is None and duration is not None and dt:
        steps = duration / dt
    if steps is None or not spheres:
        return None
    work = spheres * max(steps, 1.0)
    # the scene is not validated yet: a value out of every range is large work, and the
    # scene's own checks then say what is wrong with it
    return int(work) if math.isfinite(work) else None


def estimate_recording(path) -> int | None:
    """Sphere-steps of a recording (its particles × its states), read from the MCAP
    summary and metadata with the mcap library (the engine is not imported); None when
    the file does not say (not a physdbg recording, damaged: the reader will say)."""
    if not Path(path).is_file():  # a FIFO would block the open: the reader refuses it
        return None
    try:
        from mcap.reader import make_reader

        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            particles = None
            for record in reader.iter_metadata():
                if record.name == "physdbg":
                    particles = int(record.metadata.get("particles", ""))
            if summary is None or summary.statistics is None or particles is None:
                return None
            states = sum(summary.statistics.channel_message_counts.get(channel_id, 0)
                         for channel_id, channel in summary.channels.items() if channel.topic == "/physdbg/state")
    except Exception:  # noqa: BLE001 - any unreadable file: unknown work, and the reader speaks
        return None
    return particles * max(states, 1)


def choose(work: int | None) -> Tier:
    """The tier for a run of ``work`` sphere-steps (None: unknown), from PHYSDBG_COMPILE
    and the cache (module doc)."""
    chosen = setting()
    if interpreted():  # numba's own switch, set by the user: the engine cannot compile
        return Tier(True, "interpreted (NUMBA_DISABLE_JIT=1)")
    if chosen == "now":
        return Tier(False, "compiled (PHYSDBG_COMPILE=now)")
    if cache_is_warm():
        return Tier(False, "compiled (the kernel cache is warm)")
    if chosen == "never":
        return Tier(True, "interpreted (PHYSDBG_COMPILE=never, and the kernel cache is cold)")
    size = "an unknown number of" if work is None else f"{work:,}"
    if work is not None and work <= INTERPRET_UP_TO:
        return Tier(True, f"interpreted: {size} sphere-steps on a cold kernel cache (compiled from "
                          f"{INTERPRET_UP_TO:,}); compiling in the background for the next run", True)
    return Tier(False, f"compiled: {size} sphere-steps (interpreted only up to {INTERPRET_UP_TO:,} on a cold "
                       f"cache); the first compile takes 30–70 s")


_chosen: Tier | None = None  # the tier this process runs in, once chosen (apply)


def apply(tier: Tier) -> Tier:
    """Switch the engine to ``tier`` before it is imported, and remember it (``chosen``);
    compiled instead (and said) if the engine was imported already in this process, since
    numba read the switch then."""
    global _chosen
    if tier.interpreted:
        if any(name.startswith("physdbg.engine") for name in sys.modules):
            tier = Tier(False, "compiled (the engine was loaded before the tier was chosen)")
        else:
            os.environ["NUMBA_DISABLE_JIT"] = "1"
            if "numba" in sys.modules:
                from numba.core import config

                config.DISABLE_JIT = True
    _chosen = tier
    return tier


def for_scene(scene: str | dict, overrides=()) -> Tier:
    """Choose and apply the tier for a run of ``scene`` (a built-in name, a .toml path or a
    scene table) with ``overrides``: the work estimated from the scene before it is loaded.
    A wrong PHYSDBG_COMPILE is a PhysdbgError."""
    return _chosen_for(lambda: estimate(scene, list(overrides)))


def for_recordings(*paths) -> Tier:
    """Choose and apply the tier for a command that reads recordings (the audit's and the
    diff's checks are compiled functions too): the work is the recordings' sphere-steps."""
    def work() -> int | None:
        works = [estimate_recording(path) for path in paths]
        return None if None in works else sum(works)

    return _chosen_for(work)


def _chosen_for(work) -> Tier:
    from .errors import PhysdbgError

    try:
        return apply(choose(work()))
    except ValueError as err:  # a wrong PHYSDBG_COMPILE
        raise PhysdbgError(str(err)) from None


def chosen() -> Tier:
    """The tier this process runs in: the one applied, else what numba's switch says."""
    if _chosen is not None:
        return _chosen
    if interpreted():
        return Tier(True, "interpreted (NUMBA_DISABLE_JIT=1)")
    return Tier(False, "compiled")


def interpreted() -> bool:
    """Whether the engine's functions run interpreted in this process."""
    if "numba" not in sys.modules:
        return os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0")
    from numba.core import config

    return bool(config.DISABLE_JIT)


def background_command() -> list[str]:
    """The background compile's command: this interpreter, this physdbg first on its path."""
    root = str(Path(__file__).resolve().parent.parent)
    return [sys.executable, "-c", f"import sys; sys.path.insert(0, {root!r}); import physdbg.tier as t; t.main()"]


def _marker() -> Path:
    """The file a running background compile holds its pid in (in the cache folder)."""
    return kernel_cache.folder() / "background-compile.pid"


def running_background_compile() -> int | None:
    """The pid of a background compile running for this cache folder, or None."""
    marker = _marker()
    try:
        pid = int(marker.read_text()) if marker is not None else 0
    except (OSError, ValueError):
        return None
    if pid <= 0:
        return None
    try:
        os.kill(pid, 0)  # is it alive? (signal 0 only checks)
    except ProcessLookupError:
        return None
    except PermissionError:
        return pid
    return pid


def start_background_compile() -> int | None:
    """Start the background compile (module doc), unless one is running for this cache
    already (several quick commands in a row start one, not one each); its pid, or None
    when it could not start."""
    running = running_background_compile()
    if running is not None:
        return running
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_DISABLE_JIT"}
    try:
        process = subprocess.Popen(background_command(), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL, env=env, start_new_session=True)
    except OSError:
        return None
    marker = _marker()
    if marker is not None:
        try:
            marker.parent.mkdir(parents=True, exist_ok=True)
            marker.write_text(str(process.pid))
        except OSError:
            pass
    return process.pid


def main() -> None:
    """The background compile itself: lowest priority, a deadline, then every kernel of
    a run (engine.warm_up with and without sleeping, and the audit's checker)."""
    import signal

    try:
        os.nice(19)
    except OSError:
        pass
    if hasattr(signal, "SIGALRM"):
        signal.alarm(int(BACKGROUND_TIMEOUT))  # ends it, whatever it is doing
    from .precompile import compile_kernels

    try:
        compile_kernels(None, sleeping=True, parallel=False, audit=True, meshes=True)
    finally:
        marker = _marker()
        try:
            if marker is not None and marker.read_text().strip() == str(os.getpid()):
                marker.unlink()
        except OSError:
            pass


if __name__ == "__main__":
    main()
