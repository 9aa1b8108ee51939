"""How the engine's functions are compiled: ``kernel`` or ``borrowing`` (numba).

Both compile in nopython mode, cache on disk, and compile *one version per argument
type*: a constant passed from compiled code does not get a version of its own (below).

* ``kernel``: an ordinary compiled function (``njit(cache=True)``); it may allocate
  arrays, and numba's runtime (NRT) counts the references to every array it is handed.
* ``borrowing``: a compiled function that allocates nothing and only *borrows* the arrays
  it is given (its caller holds them for the whole call), compiled without NRT.

Why two: a compiled function increfs every array it takes on entry and decrefs it on
exit, each an atomic call into the runtime, and numba's pruning of such pairs removes
them only where the body does not branch. A helper taking the held-contact store (a
NamedTuple of 17 arrays) with one ``if`` pays 34 such calls: 200 ns a call, against
0.5 ns for the same helper compiled without NRT (``benchmarks/experiments/call_overhead.py``). In
rain-500's jammed steps they were 45 % of the time (perf, docs/benchmarks.md).

The same goes for the *caller*: a ``kernel`` increfs every array it hands to a call it
does not inline, and decrefs it after. The time-ordered loop was a kernel calling the
re-prediction (~45 arrays) for every changed sphere: 13 % of box-rain 10k's time was
these atomic updates (perf: numba's ``NRT_incref`` and ``NRT_decref``, unnamed in
profiles before ``benchmarks/perf_profile.py`` named them). So a hot loop is itself
``borrowing``, and the kernel above it calls it once and takes over only for what must
allocate (timeline.run_time_order and _run_events).

The rule: every function in the hot paths that does not allocate is ``borrowing``; what
allocates (a solve's scratch arrays) sits above them. A borrowing function can call
only functions that do not allocate: numba compiles its callees with its flags and
refuses an allocation in them at compile time, so a wrong mark cannot pass silently.
Mark the callees of a borrowing function ``borrowing`` too, or numba compiles them a
second time (once per set of flags).

One version per type: numba's own dispatcher compiles a callee afresh for each constant a
compiled caller passes it (a literal ``True``, ``0``, a module constant), and each version
brings its whole call tree. Before this rule the cold compile built 159 versions, three of
``solve_contacts`` and nine of ``_give_up``, in 189 s; with it, 118 s
(docs/benchmarks.md). The flags such constants carry are branched on at run time instead:
the same arithmetic in the same order, so no result changes by a bit (the golden hashes).
"""

from __future__ import annotations

from numba.core import config, types
from numba.core.caching import CompileResultCacheImpl, UserProvidedCacheLocator
from numba.core.registry import CPUDispatcher

# the folder holding physdbg/, as the import system spells this file's path (so does numba
# for every function it caches: both come from the module's __file__)
_HERE = __file__.replace("\\", "/")
PACKAGE_ROOT = _HERE[: _HERE.rindex("/physdbg/engine/")]


class _CheckoutFreeLocator(UserProvidedCacheLocator):
    """numba's locator for a cache folder of the user's choice (physdbg/__init__.py names
    one per version of the engine's sources), for physdbg's own files only, filing each
    file's kernels by its folder inside the package (``physdbg_engine_resting``) instead
    of a hash of its absolute folder.

    Why: numba's own locator keys the files by where the checkout lives, so a second clone
    of the same version (a student's next assignment, a CI runner with a restored cache)
    found nothing to load and compiled every kernel again (40 s), though the folder was
    warm for its sources. The folder is already keyed by a hash of the sources, and numba
    checks each file's own source stamp (a hash of its contents) before it loads a
    kernel, so two clones of one version share kernels safely. (Paths as text: the core
    imports numpy and numba only.)"""

    @classmethod
    def from_function(cls, py_func, py_file):
        if not py_file.replace("\\", "/").startswith(PACKAGE_ROOT + "/physdbg/"):
            return None  # not physdbg's: numba's own locators decide
        return super().from_function(py_func, py_file)

    @classmethod
    def get_suitable_cache_subpath(cls, py_file):
        inside = py_file.replace("\\", "/")[len(PACKAGE_ROOT) + 1:]  # physdbg/engine/resting/store.py
        return inside.rsplit("/", 1)[0].replace("/", "_")


# numba asks each locator in turn; this one answers first, for physdbg's files alone
if _CheckoutFreeLocator not in CompileResultCacheImpl._locator_classes:
    CompileResultCacheImpl._locator_classes.insert(0, _CheckoutFreeLocator)


class _OneVersionPerType(CPUDispatcher):
    """numba's CPU dispatcher, compiling a call from compiled code for its argument *types*.

    numba types a constant argument in a compiled call (``solve(..., True)``, a module
    constant like ``KIND_PAIR``) as a literal, and by default compiles the callee afresh
    for every literal value: ``solve_contacts`` and the whole solve beneath it were
    compiled three times, ``_give_up`` nine. Dropping the literal before the callee is
    looked up leaves one version per argument type, compiled once; the branch on a flag
    is taken at run time instead, which costs nothing next to the work it selects and
    changes no result. Calls from Python are unliteral in numba already.
    """

    def get_call_template(self, args, kws):
        return super().get_call_template(tuple(types.unliteral(a) for a in args),
                                         {name: types.unliteral(t) for name, t in kws.items()})


def _compiled(**options):
    """A decorator compiling with numba in nopython mode, cached on disk, one version per
    type; the function itself, interpreted, when numba's JIT is off (NUMBA_DISABLE_JIT=1,
    as numba's own ``njit`` does)."""
    def decorate(function):
        if config.DISABLE_JIT:
            return function
        # nogil: a kernel called from Python lets other threads run, so a Ctrl-C can reach
        # World.request_stop within a second while a step is in compiled code (api.py)
        dispatcher = _OneVersionPerType(py_func=function, locals={},
                                        targetoptions={"nopython": True, "nogil": True, "boundscheck": None,
                                                       **options})
        dispatcher.enable_caching()
        return dispatcher
    return decorate


kernel = _compiled()
borrowing = _compiled(_nrt=False)


def records(array):
    """A structured array as the engine's functions index it: itself when they are compiled
    (numba reads a row's fields by name), a ``numpy.recarray`` view when they are
    interpreted (a plain row has no attributes in Python)."""
    if config.DISABLE_JIT:
        import numpy as np

        return array.view(np.recarray)
    return array
