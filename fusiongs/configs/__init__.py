"""The shipped YAML configs (``configs/`` at the repository root, also packaged in the wheel)."""

from __future__ import annotations

from pathlib import Path

from fusiongs.errors import InputError


def config_dir() -> Path:
    """Folder of the shipped configs: inside the installed package, else the repository's."""
    here = Path(__file__).resolve().parent
    for d in (here, here.parents[1] / "configs"):
        if (d / "deblur.yaml").is_file():
            return d
    raise InputError(str(here), "configs", "the shipped configs/deblur.yaml", "not found")


def config_file(name: str) -> Path:
    """Path of a shipped config such as ``deblur_fast.yaml``."""
    path = config_dir() / name
    if not path.is_file():
        names = ", ".join(sorted(p.name for p in config_dir().glob("*.yaml")))
        raise InputError(str(path), "config", f"one of {names}", name)
    return path
