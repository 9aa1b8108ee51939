"""Where a scene's steps spend their time, by compiled function: perf over chosen steps.

(Named perf_profile, not profile: a script's folder comes first on the import path, and a
``profile.py`` there would stand in for the standard library's, which cProfile imports.)

    .venv/bin/python benchmarks/perf_profile.py rain --set generate.count=500 --skip 180 --steps 25 [--top 25]
        [--annotate physdbg.engine.timeline._repredict,... [--listings FOLDER]]

perf sees numba's compiled code as bare addresses, since it is loaded at run time. This
script names it: it compiles the kernels afresh in a temporary ``NUMBA_CACHE_DIR`` (about
a minute; cached libraries keep no object code), runs ``--skip`` steps unprofiled, attaches
``perf record`` to itself for the next ``--steps`` steps only, then writes perf's map file
``/tmp/perf-<pid>.map`` from each compiled library's object code (symbol offsets from
``nm``, placed where the library's entry point was loaded) and prints ``perf report``'s
functions, numba's readable by module and name. It leans on numba internals
(``Dispatcher.overloads``, a library's compiled object), so a numba upgrade may need it
changed. Needs ``perf`` and ``nm`` (Debian: linux-perf, binutils) and the rights to
attach perf to a process (root, or a permissive ``kernel.perf_event_paranoid``).

``--annotate`` goes one level down, for the functions named: the samples perf took at each
instruction (``objdump -d`` of the function's object code, offsets from where it was
loaded), the hottest instructions printed with the ones before them, the whole listing
written to a file. In the event loop a hot instruction is most often the one after a load
that missed the cache (docs/benchmarks.md, "Where the time goes"). Only the function's own
library is read: where LLVM inlined it into a caller, those samples are the caller's.
"""

from __future__ import annotations

import os
import tempfile

# before physdbg is imported (it keeps a NUMBA_CACHE_DIR that is already set); only when run:
# imported (the tests read its listing helpers), it must not move the importer's cache
if __name__ == "__main__":
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="physdbg-profile-")

import argparse  # noqa: E402
import gc  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from physdbg.engine.warm import warm_up  # noqa: E402
from physdbg.errors import PhysdbgError  # noqa: E402
from physdbg.api import load_scene  # noqa: E402


def write_perf_map(annotate: tuple[str, ...] = ()) -> tuple[int, dict[str, tuple[bytes, int, int, int]]]:
    """Write /tmp/perf-<pid>.map naming every function of the compiled libraries in this
    process; returns how many, and for each function named in ``annotate`` (readable
    names, e.g. ``physdbg.engine.timeline._repredict``) its library's object code, where
    that object's code starts in memory, and the function's offset and size in it."""
    from numba.core.dispatcher import Dispatcher

    rows = []
    objects: dict[str, tuple[bytes, int, int, int]] = {}
    seen = set()
    for obj in gc.get_objects():
        if not isinstance(obj, Dispatcher):
            continue
        for cres in list(obj.overloads.values()):
            library = cres.library
            if id(library) in seen:
                continue
            seen.add(id(library))
            try:
                blob = library._get_compiled_object()
            except RuntimeError:  # loaded from a cache: no object code kept
                continue
            with tempfile.NamedTemporaryFile(suffix=".o") as f:
                f.write(blob)
                f.flush()
                listing = subprocess.run(["nm", "-S", "--defined-only", f.name], capture_output=True, text=True,
                                         check=True).stdout
            symbols = {}
            for line in listing.splitlines():
                parts = line.split()
                if len(parts) == 4 and parts[2] in "tT":
                    symbols[parts[3]] = (int(parts[0], 16), int(parts[1], 16))
            entry = cres.fndesc.llvm_func_name
            if entry not in symbols:
                continue
            base = library.get_pointer_to_function(entry) - symbols[entry][0]
            rows += [(base + offset, size, name) for name, (offset, size) in symbols.items()]
            if readable(entry) in annotate and readable(entry) not in objects:
                objects[readable(entry)] = (blob, base, *symbols[entry])
    rows += _runtime_rows()
    rows.sort()
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as f:
        f.writelines(f"{start:x} {size:x} {name}\n" for start, size, name in rows)
    return len(rows), objects


def annotated(disassembly: str, samples: dict[int, int]) -> list[tuple[int, int, str]]:
    """objdump -d's listing as (offset, samples, instruction) rows, the samples perf took at
    each offset (the function's own offsets in its object) beside its instruction. Jump
    targets keep only their offset (numba's mangled names run to kilobytes)."""
    rows = []
    for line in disassembly.splitlines():
        found = re.match(r"\s*([0-9a-f]+):\s+(.*)", line)
        if found:
            offset = int(found.group(1), 16)
            text = re.sub(r"<[^>]*?(\+0x[0-9a-f]+)?>", lambda m: f"<{m.group(1) or ''}>", found.group(2))
            rows.append((offset, samples.get(offset, 0), text.strip()))
    return rows


def hottest(rows: list[tuple[int, int, str]], top: int, before: int = 4) -> list[str]:
    """The ``top`` instructions with the most samples, each after the ``before``
    instructions leading to it (a sample lands on the instruction after the one that
    waited, a load most often: read the lines above a hot one), hottest first."""
    total = sum(count for _, count, _ in rows) or 1
    order = sorted(range(len(rows)), key=lambda i: -rows[i][1])[:top]
    out = []
    for i in order:
        if rows[i][1] == 0:
            break
        out.append(f"-- {100 * rows[i][1] / total:.1f} % of the function's samples at +0x{rows[i][0]:x}")
        for j in range(max(0, i - before), i + 1):
            offset, count, text = rows[j]
            out.append(f"   {count:6d}  +0x{offset:<6x} {text}")
    return out


def annotate(data: str, objects: dict[str, tuple[bytes, int, int, int]], top: int, folder: str) -> None:
    """Print, for each function in ``objects`` (write_perf_map), its share of perf's samples
    in ``data`` and its hottest instructions; write its whole annotated listing to
    ``folder``/<name>.annotated.txt."""
    ips = [int(ip, 16) for ip in subprocess.run(["perf", "script", "-i", data, "-F", "ip"], capture_output=True,
                                                text=True).stdout.split()]
    for name, (blob, base, offset, size) in objects.items():
        samples: dict[int, int] = {}
        for ip in ips:
            if offset <= ip - base < offset + size:
                samples[ip - base] = samples.get(ip - base, 0) + 1
        with tempfile.NamedTemporaryFile(suffix=".o") as f:
            f.write(blob)
            f.flush()
            disassembly = subprocess.run(["objdump", "-d", "--no-show-raw-insn", f"--start-address={offset}",
                                          f"--stop-address={offset + size}", f.name], capture_output=True,
                                         text=True, check=True).stdout
        rows = annotated(disassembly, samples)
        path = os.path.join(folder, f"{name}.annotated.txt")
        with open(path, "w") as f:
            f.writelines(f"{count:6d}  +0x{off:<6x} {text}\n" for off, count, text in rows)
        print(f"\n{name}: {sum(samples.values())} of {len(ips)} samples "
              f"({100 * sum(samples.values()) / max(len(ips), 1):.1f} %); whole listing: {path}")
        print("\n".join(hottest(rows, top)))


def _runtime_rows() -> list[tuple[int, int, str]]:
    """numba's runtime functions (NRT_incref, NRT_decref, ...), compiled at start-up into a
    library of their own that no dispatcher owns: (address, size, name) rows, each sized up
    to the next one (the library's functions are laid out in order)."""
    from numba.core.runtime.nrt import rtsys

    library = getattr(rtsys, "_library", None)
    if library is None:
        return []
    names = ("nrt_atomic_add", "nrt_atomic_sub", "nrt_atomic_cas", "NRT_MemInfo_data_fast", "NRT_incref",
             "NRT_decref", "nrt_unresolved_abort")
    found = []
    for name in names:
        try:
            address = library.get_pointer_to_function(name)
        except Exception:  # a numba that builds its runtime differently: leave them unnamed
            continue
        if address:
            found.append((address, "numba." + name))
    found.sort()
    return [(address, (found[i + 1][0] - address) if i + 1 < len(found) else 16, name)
            for i, (address, name) in enumerate(found)]


def readable(symbol: str) -> str:
    """numba's mangled name -> module.function (other symbols as they are)."""
    if not symbol.startswith("_ZN"):
        return symbol
    parts, i = [], 3
    while i < len(symbol) and symbol[i].isdigit():
        j = i
        while symbol[j].isdigit():
            j += 1
        length = int(symbol[i:j])
        parts.append(symbol[j:j + length])
        i = j + length
    return ".".join(parts) or symbol


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--set", dest="overrides", action="append", default=[], help="a scene override, k=v")
    parser.add_argument("--skip", type=int, default=0, help="steps run before profiling starts")
    parser.add_argument("--steps", type=int, default=20, help="steps profiled")
    parser.add_argument("--frequency", type=int, default=999, help="perf samples per second")
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--annotate", default="", metavar="NAME,NAME",
                        help="also show where in these compiled functions the samples fell, instruction by "
                             "instruction (readable names as the report prints them, e.g. "
                             "physdbg.engine.timeline._repredict); needs objdump")
    parser.add_argument("--listings", default=".", metavar="FOLDER",
                        help="where --annotate writes each function's whole annotated listing (default: here)")
    args = parser.parse_args()
    wanted = tuple(name for name in args.annotate.split(",") if name)
    if wanted and not os.path.isdir(args.listings):
        _stop(f"--listings {args.listings}: no such folder (where --annotate writes each function's listing)")
    for tool in ("perf", "nm") + (("objdump",) if wanted else ()):
        if shutil.which(tool) is None:
            _stop(f"{tool} is not installed (Debian: apt-get install linux-perf binutils)")
    try:
        scene = load_scene(args.scene, args.overrides)
    except PhysdbgError as err:
        _stop(str(err))
    world = scene.build_world()
    print(f"compiling the kernels afresh (cache {os.environ['NUMBA_CACHE_DIR']}) ...", flush=True)
    print(f"compiled in {warm_up(world.broad_phase.name):.1f} s", flush=True)
    lengths = iter(scene.step_lengths(None))
    for _ in range(args.skip):
        world.step(next(lengths))
    data = os.path.join(os.environ["NUMBA_CACHE_DIR"], "perf.data")
    perf = subprocess.Popen(["perf", "record", "-q", "-F", str(args.frequency), "-p", str(os.getpid()), "-o", data],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)  # let perf attach
    started = time.perf_counter()
    done = 0
    for dt in lengths:
        if done == args.steps:
            break
        world.step(dt)
        done += 1
    seconds = time.perf_counter() - started
    perf.send_signal(signal.SIGINT)
    perf.wait()
    named, objects = write_perf_map(wanted)
    print(f"steps {args.skip + 1}-{args.skip + done}: {seconds:.2f} s; {named} compiled functions named")
    missing = [name for name in wanted if name not in objects]
    if missing:
        print(f"not compiled in this run (no object code to annotate): {', '.join(missing)}")
    report = subprocess.run(["perf", "report", "-i", data, "--no-children", "--sort", "symbol", "--stdio"],
                            capture_output=True, text=True).stdout
    shown = 0
    for line in report.splitlines():
        found = re.match(r"\s*([0-9.]+)%\s+\[[.k]\]\s+(\S+)", line)
        if found and shown < args.top:
            print(f"{found.group(1):>7}%  {readable(found.group(2))}")
            shown += 1
    if objects:
        annotate(data, objects, args.top, args.listings)


def _stop(message: str) -> None:
    """Say what is wrong in one line and exit 2."""
    print(f"perf_profile.py: {message}", file=sys.stderr)
    sys.exit(2)


if __name__ == "__main__":
    try:
        main()
    finally:  # the kernels compiled for the profile, and perf's data
        shutil.rmtree(os.environ["NUMBA_CACHE_DIR"], ignore_errors=True)
