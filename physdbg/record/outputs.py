"""Output files claimed so that one process writes each: never two runs mixed in one file.

Checking that a file does not exist and then opening it are two steps, and two commands
started together both pass the first. So a file is *claimed* in one step before any work:

- without ``force``, it is created exclusively (``O_CREAT | O_EXCL``) at its own name; a
  second process asking for the same name is refused at once (exit 2), and the run writes
  in place, so a killed run leaves what it wrote readable under the name the user gave;
- with ``force``, it is written beside its name (``.NAME.PID.partial`` in the same folder)
  and renamed over it when the command ends (``os.replace``, atomic on one file system):
  the old file stays whole until the new one is, and of two forced runs the file is the
  whole output of the one that ended last. A killed forced run leaves its partial file
  (readable up to its last complete step) and the old file untouched.

``Claim.publish()`` puts each file in place; ``Claim.abandon()`` removes what the claim
created (a run that wrote nothing readable).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from ..errors import PhysdbgError


class Claim:
    """Output files held by this process. paths: where the caller writes (the final names,
    or the partial names under force), in the order given; None stays None."""

    def __init__(self, finals: Sequence[Path | None], force: bool):
        self.finals = list(finals)
        self.force = force
        self.paths: list[Path | None] = []
        self._created: list[Path] = []
        try:
            for final in self.finals:
                self.paths.append(None if final is None else self._claim(final))
        except BaseException:
            self.abandon()
            raise

    def _claim(self, final: Path) -> Path:
        if self.force:
            partial = final.parent / f".{final.name}.{os.getpid()}.partial"
            partial.unlink(missing_ok=True)  # left by a killed run of this pid's namesake
            self._created.append(partial)
            return partial
        try:
            fd = os.open(final, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            raise PhysdbgError(f"{final} already exists (another command may be writing it); "
                               f"pass --force to overwrite it") from None
        except OSError as err:
            raise PhysdbgError(f"{final}: cannot create the file ({err.strerror})") from None
        os.close(fd)
        self._created.append(final)
        return final

    def publish(self) -> None:
        """Put every partial file in place of its final name (force); nothing to do otherwise."""
        if not self.force:
            return
        for partial, final in zip(self.paths, self.finals):
            if partial is not None and partial.exists():
                os.replace(partial, final)
        self._created = []

    def abandon(self, path: Path | None = None) -> None:
        """Remove what this claim created (one file, or all): a run that wrote nothing readable."""
        for created in list(self._created):
            if path is None or created == path:
                created.unlink(missing_ok=True)
                self._created.remove(created)


def claim(finals: Sequence[Path | None], force: bool) -> Claim:
    """Claim output files (see the module docstring); PhysdbgError (exit 2) if one is taken."""
    return Claim(finals, force)


def write_claimed(final: Path, force: bool, write):
    """Claim one output file, write it with ``write(path)`` and put it in place; what the
    write returns is returned. A write that raises leaves no file of this claim behind."""
    outputs = claim([final], force)
    try:
        result = write(outputs.paths[0])
    except BaseException:
        outputs.abandon()
        raise
    outputs.publish()
    return result
