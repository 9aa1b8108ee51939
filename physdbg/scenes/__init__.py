"""Built-in scene files (TOML). Listing them imports nothing heavy."""

from __future__ import annotations

import tomllib
from importlib import resources


def builtin_names() -> list[str]:
    """Names of the scenes shipped inside the package."""
    return sorted(p.name[:-5] for p in resources.files(__name__).iterdir() if p.name.endswith(".toml"))


def builtin_text(name: str) -> str:
    """The TOML text of built-in scene ``name``."""
    return resources.files(__name__).joinpath(name + ".toml").read_text(encoding="utf-8")


def builtin_descriptions() -> list[tuple[str, str]]:
    """(name, one-line description) of each built-in scene."""
    return [(name, str(tomllib.loads(builtin_text(name)).get("description", ""))) for name in builtin_names()]
