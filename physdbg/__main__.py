"""``python -m physdbg``: the same command line as ``physdbg``."""

from .cli import console_main

if __name__ == "__main__":
    console_main()
