"""The shipped YAML presets (``deblur``, ``deblur_fast``, ``deblur_quality``, ``event_only``).

They are package data (``fusiongs/configs/*.yaml``), so they resolve wherever fusiongs is installed;
``configs/`` at the repository root holds links to them for the paths the docs use.
"""

from __future__ import annotations

from pathlib import Path

from fusiongs.errors import InputError

SUFFIXES = (".yaml", ".yml")


def config_dir() -> Path:
    """Folder of the shipped presets (inside the installed package)."""
    here = Path(__file__).resolve().parent
    if not (here / "deblur.yaml").is_file():
        raise InputError(str(here), "configs", "the shipped deblur.yaml preset", "not found")
    return here


def preset_names() -> list[str]:
    """Names of the shipped presets, without suffix (``["deblur", "deblur_fast", ...]``)."""
    return sorted(p.stem for p in config_dir().glob("*.yaml"))


def config_file(name: str) -> Path:
    """Path of a shipped config such as ``deblur_fast.yaml``."""
    path = config_dir() / name
    if not path.is_file():
        names = ", ".join(sorted(p.name for p in config_dir().glob("*.yaml")))
        raise InputError(str(path), "config", f"one of {names}", name)
    return path


def resolve_config_path(name_or_path: str | Path, where: str = "--config") -> Path:
    """The YAML file meant by a ``--config`` value: an existing path, else a shipped preset.

    An existing file wins (``--config my.yaml``, ``--config runs/a/config.yaml``); a bare name with
    or without suffix (``deblur_fast``, ``deblur_fast.yaml``) names a preset of :func:`config_dir`.

    Args:
        name_or_path: the value as given.
        where: named in the error message.

    Returns:
        The path of the YAML file.

    Raises:
        InputError: neither an existing file nor a preset name, listing the presets.
    """
    path = Path(name_or_path)
    if path.is_file():
        return path
    text = str(name_or_path)
    if path.name == text and text:  # a bare name, no folder part
        stem = text[: -len(path.suffix)] if path.suffix in SUFFIXES else text
        preset = config_dir() / f"{stem}.yaml"
        if preset.is_file():
            return preset
    raise InputError(where, "config", f"an existing YAML file or a preset name "
                     f"({', '.join(preset_names())})", repr(text))
