"""Error types raised on bad user input.

Every error a user can trigger with a file, a config key or a command-line value derives from
:class:`FusionGSError`; the command line prints its message as one line and exits with status 2.
"""

from __future__ import annotations

import math
from pathlib import Path


def is_finite_number(value: object) -> bool:
    """Whether ``value`` is a finite ``int`` or ``float`` and not a ``bool`` (JSON's ``true`` is no
    number): the test every option and file field that must hold a real number goes through."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


class FusionGSError(Exception):
    """Base class of every error fusiongs raises on purpose."""


class InputError(FusionGSError, ValueError):
    """Bad input data: names where (file), what (field or key) and what was expected.

    Args:
        where: the file, or another description of the source (``"scene.json"``, ``"config"``).
        field: the key, dataset, column or argument at fault (``"events/t"``, ``"camera.fx"``).
        expected: what a valid value looks like (``"int64 timestamps sorted ascending"``).
        got: optional description of what was found (``"decreasing at index 17"``).

    Example:
        >>> str(InputError("scene.json", "camera.fx", "a positive number", "-3"))
        'scene.json: camera.fx: expected a positive number, got -3'
    """

    def __init__(self, where: str | Path, field: str, expected: str, got: object | None = None):
        self.where = str(where)
        self.field = field
        self.expected = expected
        self.got = got
        msg = f"{self.where}: {field}: expected {expected}"
        if got is not None:
            msg += f", got {got}"
        super().__init__(msg)


class ConfigError(InputError):
    """A bad configuration key or value (YAML file or ``key=value`` override)."""


class MissingDependencyError(FusionGSError, ImportError):
    """An optional package is needed for the requested feature but is not installed."""

    def __init__(self, package: str, feature: str, extra: str | None = None):
        hint = f'pip install "fusiongs[{extra}]"' if extra else f"pip install {package}"
        super().__init__(f"{feature} needs the optional package '{package}': {hint}")
