"""Running the many small runs of a benchmark sweep: here, on local cores, or on Dask.

``run_jobs(call, jobs)`` runs ``call(*args)`` for every ``args`` in ``jobs`` and returns
the results in the order of ``jobs``:

* ``workers=1``: in this process, one after another;
* otherwise on local cores (``workers=None``: all of them) in a process pool: the
  kernels are compiled here first (by ``warm``: the caller's way, such as
  physdbg.precompile's two processes on a cold cache; the engine's own warm-up if none),
  then each worker loads them once before its first job (so no job's cost includes it,
  and no two workers compile the same kernels);
* ``dask="tcp://host:port"``: on an existing Dask cluster (the optional extra
  ``physdbg[dask]``), each worker warmed up the same way. No job system of physdbg's own.

Every job is deterministic, so where it ran changes nothing but the wall time it reports.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

from ..errors import DaskMissing





def warm_engine() -> None:
    """Compile (or load) the engine's kernels (the default ``warm`` of run_jobs)."""
    from ..engine.warm import warm_up

    warm_up()


def _call(call, args):
    return call(*args)


def run_jobs(call: Callable, jobs: Sequence[tuple], workers: int | None = None, dask: str | None = None,
             on_done: Callable[[object, int, int], None] | None = None,
             warm: Callable[[], None] = warm_engine) -> list:
    """The results of call(*args) for each args in jobs, in order (see module doc).
    on_done(result, done, total) after each, in the order they finish; warm: loads the
    kernels in each process (a module-level function, so a worker can be handed it)."""
    total = len(jobs)
    if dask:
        return _on_dask(call, jobs, dask, on_done, warm)
    workers = (os.cpu_count() or 1) if workers is None else workers
    if workers <= 1 or total <= 1:
        warm()
        out = []
        for done, args in enumerate(jobs, start=1):
            out.append(call(*args))
            if on_done is not None:
                on_done(out[-1], done, total)
        return out
    from concurrent.futures import ProcessPoolExecutor, as_completed

    warm()  # here first, so the workers load the kernels instead of each compiling them all
    results: list = [None] * total
    with ProcessPoolExecutor(max_workers=min(workers, total), initializer=warm) as pool:
        futures = {pool.submit(_call, call, args): k for k, args in enumerate(jobs)}
        for done, future in enumerate(as_completed(futures), start=1):
            results[futures[future]] = future.result()
            if on_done is not None:
                on_done(results[futures[future]], done, total)
    return results


def _on_dask(call, jobs, address: str, on_done, warm) -> list:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise DaskMissing("--dask needs dask.distributed: pip install 'physdbg[dask]'") from None
    try:
        client = Client(address, timeout="5s")
    except (OSError, TimeoutError, ValueError) as err:  # ValueError: not an address (no port, bad scheme)
        raise DaskMissing(f"cannot reach the Dask scheduler at {address} ({err})") from None
    try:
        client.run(warm)  # every worker loads the kernels before its first job
        futures = [client.submit(_call, call, args, pure=False) for args in jobs]
        index = {future.key: k for k, future in enumerate(futures)}
        results: list = [None] * len(jobs)
        for done, future in enumerate(as_completed(futures), start=1):
            results[index[future.key]] = future.result()
            if on_done is not None:
                on_done(results[index[future.key]], done, len(jobs))
        return results
    finally:
        client.close()
