"""``python -m physdbg``: the same command line as ``physdbg``."""

from .cli import app

if __name__ == "__main__":
    app(prog_name="physdbg")
