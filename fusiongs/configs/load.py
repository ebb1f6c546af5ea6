"""A small typed configuration system: dataclass trees loaded from YAML with ``key=value`` overrides.

Any tree of dataclasses works. Loading starts from the dataclasses' defaults, merges a YAML file,
then dotted ``key=value`` overrides (values parsed as YAML, e.g. ``train.steps=3000``,
``loss.kind=band``, ``model.size=[64,48]``). Unknown keys and values of the wrong type raise
:class:`fusiongs.errors.ConfigError` naming the file (or override) and the dotted key. Supported
field types: ``int``, ``float``, ``bool``, ``str``, ``pathlib.Path``, ``Literal[...]``,
``tuple[X, ...]``, ``tuple[X, Y]``, ``list[X]``, ``dict[str, X]``, ``X | None`` and nested
dataclasses. A float field also accepts an int, and a string spelling a number (PyYAML reads
``1e-3`` without a dot as a string).
"""

from __future__ import annotations

import dataclasses
import re
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar

import yaml

from fusiongs.atomic import write_text
from fusiongs.errors import ConfigError

T = TypeVar("T")
_FLOAT_RE = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _type_name(tp: Any) -> str:
    if isinstance(tp, type):
        return tp.__name__
    return str(tp).replace("typing.", "")


def _convert(tp: Any, value: Any, key: str, where: str, sources: Mapping[str, str]) -> Any:
    """Check ``value`` against type ``tp`` and build it (nested dataclasses, tuples)."""
    where = sources.get(key, where)

    def fail(expected: str) -> ConfigError:
        return ConfigError(where, key, expected, f"{value!r} ({type(value).__name__})")

    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        rest = [a for a in args if a is not type(None)]
        errors = []
        for a in rest:
            try:
                return _convert(a, value, key, where, sources)
            except ConfigError as e:
                errors.append(e)
        if len(rest) == 1:
            raise errors[0]
        raise fail(" or ".join(_type_name(a) for a in args))
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise fail(f"a mapping of {tp.__name__} keys")
        return _build(tp, value, key, where, sources)
    if origin is Literal:
        if value not in args or isinstance(value, bool) != any(isinstance(a, bool) for a in args):
            raise fail("one of " + ", ".join(repr(a) for a in args))
        return value
    if origin in (tuple, list):
        if not isinstance(value, list | tuple):
            raise fail(f"a list ({_type_name(tp)})")
        if origin is tuple and not (len(args) == 2 and args[1] is Ellipsis):
            if len(args) != len(value):
                raise fail(f"a list of {len(args)} items ({_type_name(tp)})")
            items = [
                _convert(a, v, f"{key}[{i}]", where, sources) for i, (a, v) in enumerate(zip(args, value))
            ]
        else:
            item_tp = args[0] if args else Any
            items = [_convert(item_tp, v, f"{key}[{i}]", where, sources) for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, Mapping):
            raise fail("a mapping")
        vt = args[1] if args else Any
        return {str(k): _convert(vt, v, f"{key}.{k}", where, sources) for k, v in value.items()}
    if tp is bool:
        if not isinstance(value, bool):
            raise fail("true or false")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise fail("an integer")
        return value
    if tp is float:
        if isinstance(value, str) and _FLOAT_RE.match(value.strip()):
            return float(value)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise fail("a number")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise fail("a string")
        return value
    if tp is Path:
        if not isinstance(value, str | Path):
            raise fail("a path string")
        return Path(value)
    raise ConfigError(where, key, f"a supported field type, not {_type_name(tp)}")


def _build(cls: type[T], data: Mapping[str, Any], prefix: str, where: str, sources: Mapping[str, str]) -> T:
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = _hints(cls)
    dotted = lambda name: f"{prefix}.{name}" if prefix else name
    for name in data:
        if name not in fields:
            raise ConfigError(sources.get(dotted(str(name)), where), dotted(str(name)),
                              "one of the keys " + ", ".join(fields), "an unknown key")
    kwargs = {}
    for name, f in fields.items():
        if name in data:
            kwargs[name] = _convert(hints[name], data[name], dotted(name), where, sources)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(where, dotted(name), f"a value ({_type_name(hints[name])})", "nothing")
    return cls(**kwargs)


def to_dict(cfg: Any) -> Any:
    """Plain YAML-ready data of a config: dataclasses -> dicts, tuples -> lists, paths -> str."""
    if dataclasses.is_dataclass(cfg) and not isinstance(cfg, type):
        return {f.name: to_dict(getattr(cfg, f.name)) for f in dataclasses.fields(cfg) if f.init}
    if isinstance(cfg, list | tuple):
        return [to_dict(v) for v in cfg]
    if isinstance(cfg, Mapping):
        return {str(k): to_dict(v) for k, v in cfg.items()}
    if isinstance(cfg, Path):
        return str(cfg)
    return cfg


def _schema_check(cls: type, path: list[str], override: str) -> None:
    """Reject an override whose dotted key is not a field (through nested dataclasses)."""
    tp: Any = cls
    for i, name in enumerate(path):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if not dataclasses.is_dataclass(tp) and len(args) == 1 and dataclasses.is_dataclass(args[0]):
            tp = args[0]  # Optional[Sub]
        if not dataclasses.is_dataclass(tp):
            return  # inside a dict or a list: checked when converting
        names = [f.name for f in dataclasses.fields(tp) if f.init]
        if name not in names:
            raise ConfigError(f"override {override!r}", ".".join(path[: i + 1]),
                              "one of the keys " + ", ".join(names), "an unknown key")
        tp = _hints(tp)[name]


def parse_override(text: str) -> tuple[list[str], Any]:
    """Split ``"a.b.c=value"`` into ``(["a", "b", "c"], value)``, the value parsed as YAML."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip() or any(not p for p in key.strip().split(".")):
        raise ConfigError(f"override {text!r}", key.strip() or "?", "the form dotted.key=value")
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as e:
        raise ConfigError(f"override {text!r}", key.strip(), "a YAML value", str(e).splitlines()[0]) from e
    return key.strip().split("."), value


def config_from_dict(
    cls: type[T], data: Mapping[str, Any], where: str = "config", overrides: Iterable[str] = ()
) -> T:
    """Build a config from plain data and overrides (see :func:`load_config`)."""
    if not isinstance(data, Mapping):
        raise ConfigError(where, "<top level>", "a mapping of keys", type(data).__name__)
    merged: dict[str, Any] = _deep_copy(data)
    sources: dict[str, str] = {}
    for text in overrides:
        path, value = parse_override(text)
        _schema_check(cls, path, text)
        node = merged
        for name in path[:-1]:
            child = node.get(name)
            node[name] = _deep_copy(child) if isinstance(child, Mapping) else {}
            node = node[name]
        node[path[-1]] = value
        sources[".".join(path)] = f"override {text!r}"
    return _build(cls, merged, "", where, sources)


def _deep_copy(data: Mapping[str, Any]) -> dict[str, Any]:
    return {k: _deep_copy(v) if isinstance(v, Mapping) else v for k, v in data.items()}


def load_config(cls: type[T], path: str | Path | None = None, overrides: Iterable[str] = ()) -> T:
    """Load a config dataclass from its defaults, an optional YAML file and ``key=value`` overrides.

    Args:
        cls: the root dataclass type.
        path: optional YAML file (a mapping; missing keys keep their defaults).
        overrides: dotted ``key=value`` strings applied after the file.

    Returns:
        An instance of ``cls``.

    Raises:
        ConfigError: unreadable file, unknown key, wrong type, missing required value.
    """
    data: Any = {}
    where = "config"
    if path is not None:
        where = str(path)
        try:
            text = Path(path).read_text()
        except OSError as e:
            raise ConfigError(where, "<file>", "a readable YAML file", e.strerror) from e
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as e:
            raise ConfigError(where, "<file>", "valid YAML", str(e).splitlines()[0]) from e
        data = {} if data is None else data
    return config_from_dict(cls, data, where, overrides)


def to_yaml(cfg: Any) -> str:
    """The config as YAML text (field order kept)."""
    return yaml.safe_dump(to_dict(cfg), sort_keys=False, default_flow_style=None)


def save_config(cfg: Any, path: str | Path) -> Path:
    """Write the resolved config as YAML atomically (temporary file, then rename).

    Returns:
        The written path.
    """
    path = Path(path)
    write_text(path, to_yaml(cfg))
    return path
