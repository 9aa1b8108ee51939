"""Where numba keeps the engine's compiled kernels: a folder named by a hash of its sources.

numba's cache (``cache=True``) keeps each compiled function with the code of the
functions it calls, and reuses it after a callee changed: the old callee runs. That
happened while building physdbg (tests passed on stale kernels that a fresh clone did not
have; with a callee in another file, and with numba 0.68 for a callee in the same file).
A folder per version of the engine's sources makes a stale kernel impossible. A
NUMBA_CACHE_DIR set by the user is respected, and then nothing protects it: whoever sets
one while editing the engine must empty it.

The engine points numba there (``use``) when it is first imported, before any kernel is
defined; ``import physdbg`` alone does nothing of the kind. Standard library only: the
tiers (tier.py) read the folder without importing the engine.
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

_PACKAGE = Path(__file__).parent


@functools.lru_cache(maxsize=1)
def _sources_folder() -> Path:
    """~/.cache/physdbg/numba/<hash of engine/**/*.py and events.py> (XDG_CACHE_HOME honoured)."""
    engine = _PACKAGE / "engine"
    digest = hashlib.blake2b(digest_size=8)
    for source in sorted(engine.rglob("*.py")) + [_PACKAGE / "events.py"]:
        digest.update(str(source.relative_to(_PACKAGE)).encode() + source.read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "physdbg" / "numba" / digest.hexdigest()


def folder() -> Path:
    """The kernel cache folder: NUMBA_CACHE_DIR where set, else the engine's own (module doc)."""
    given = os.environ.get("NUMBA_CACHE_DIR")
    return Path(given) if given else _sources_folder()


def use() -> None:
    """Point numba at ``folder()`` (NUMBA_CACHE_DIR, inherited by the processes physdbg
    starts), unless the user set one; numba re-reads its configuration if it was loaded
    before (a kernel's cache is placed when the kernel is defined, after this)."""
    import sys

    if "NUMBA_CACHE_DIR" in os.environ:
        return
    os.environ["NUMBA_CACHE_DIR"] = str(_sources_folder())
    if "numba" in sys.modules:
        from numba.core import config

        config.reload_config()
