"""physdbg's version: a leaf module, so any layer can say which build wrote a file."""

__version__ = "0.1.0"
