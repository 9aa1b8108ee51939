"""How the engine's functions are compiled: ``kernel`` or ``borrowing`` (numba).

* ``kernel``: an ordinary compiled function (``njit(cache=True)``); it may allocate
  arrays, and numba's runtime (NRT) counts the references to every array it is handed.
* ``borrowing``: a compiled function that allocates nothing and only *borrows* the arrays
  it is given (its caller holds them for the whole call), compiled without NRT.

Why two: a compiled function increfs every array it takes on entry and decrefs it on
exit, each an atomic call into the runtime, and numba's pruning of such pairs removes
them only where the body does not branch. A helper taking the held-contact store (a
NamedTuple of 17 arrays) with one ``if`` pays 34 such calls: 200 ns a call, against
0.5 ns for the same helper compiled without NRT (``benchmarks/call_overhead.py``). In
rain-500's jammed steps they were 45 % of the time (perf, docs/benchmarks.md).

The rule: every function in the hot paths that does not allocate is ``borrowing``; what
allocates (a solve's scratch arrays) sits above them. A borrowing function can call
only functions that do not allocate: numba compiles its callees with its flags and
refuses an allocation in them at compile time, so a wrong mark cannot pass silently.
Mark the callees of a borrowing function ``borrowing`` too, or numba compiles them a
second time (once per set of flags).
"""

from __future__ import annotations

from numba import njit

kernel = njit(cache=True)
borrowing = njit(cache=True, _nrt=False)
