"""physdbg: a physics engine that shows its work."""
__version__ = "0.1.0"
