"""Configuration dataclasses from dicts and dotted option names, with clear errors for unknown names and values.

A configuration is a tree of dataclasses (``MatchConfig`` > ``SlimeConfig`` > ``TileConfig`` ...). Any of its
fields has a dotted path (``slime.tiles.t_xi``); :func:`set_option` sets one, parsing a command-line string by
the field's type, and :func:`config_from_dict` builds a tree back from the nested dicts of
``dataclasses.asdict`` (a run's ``summary.json``). Each dataclass checks its own values in ``__post_init__``,
which both run again.
"""

from __future__ import annotations

import dataclasses
import json
import numbers
import types
import typing
from dataclasses import fields, is_dataclass
from typing import Any, TypeVar

from ..errors import ConfigError

T = TypeVar("T")


def _hints(cls: type) -> dict[str, Any]:
    """The resolved type of each field of a dataclass."""
    return typing.get_type_hints(cls)


def _dataclass_type(annotation: Any) -> type | None:
    """The dataclass an annotation names (``X`` or ``X | None``), or None."""
    options = typing.get_args(annotation) if isinstance(annotation, types.UnionType) else (annotation,)
    found = [a for a in options if isinstance(a, type) and is_dataclass(a)]
    return found[0] if found else None


def _converted(value: Any, annotation: Any) -> Any:
    """``value`` read from JSON (lists, dicts) as ``annotation`` wants it: tuples and nested dataclasses."""
    nested = _dataclass_type(annotation)
    if nested is not None and isinstance(value, dict):
        return config_from_dict(nested, value)
    if isinstance(value, list) and tuple in {typing.get_origin(a) or a for a in _union_args(annotation)}:
        return tuple(value)
    return value


def _union_args(annotation: Any) -> tuple:
    return typing.get_args(annotation) if isinstance(annotation, types.UnionType) else (annotation,)


def config_from_dict(cls: type[T], options: dict[str, Any]) -> T:
    """``cls(**options)`` for a dataclass ``cls``, nested dicts becoming their fields' dataclasses and lists
    the tuples their fields ask for; unknown option names raise ConfigError listing the valid ones."""
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(options) - names)
    if unknown:
        raise ConfigError(f"unknown {cls.__name__} option(s) {unknown}; valid: {sorted(names)}")
    hints = _hints(cls)
    return cls(**{name: _converted(value, hints[name]) for name, value in options.items()})


def parse_value(text: str, annotation: Any) -> Any:
    """A command-line string as a value of the field type ``annotation``: numbers, booleans (true/false),
    ``none`` for optional fields, comma-separated tuples, or JSON (lists, objects)."""
    args = _union_args(annotation)
    lowered = text.strip().lower()
    if lowered in ("none", "null") and type(None) in args:
        return None
    for kind in args:
        origin = typing.get_origin(kind) or kind
        try:
            if kind is bool:
                if lowered in ("true", "yes", "1", "false", "no", "0"):
                    return lowered in ("true", "yes", "1")
            elif kind in (int, float):
                return kind(text)
            elif origin is tuple:
                item = (typing.get_args(kind) or (str,))[0]
                return tuple(parse_value(part, item) for part in text.split(",") if part.strip())
            elif kind is str:
                return text
            elif is_dataclass(kind):
                return config_from_dict(kind, json.loads(text))
        except (ValueError, json.JSONDecodeError):
            continue
    raise ConfigError(f"cannot read {text!r} as {_type_name(annotation)}")


def _type_name(annotation: Any) -> str:
    return " or ".join(getattr(a, "__name__", str(a)) for a in _union_args(annotation))


def field_type(config: Any, path: str) -> Any:
    """The type of the field at dotted ``path`` in a dataclass tree (ConfigError when there is none)."""
    obj, name = _parent(config, path)
    return _hints(type(obj))[name]


def _parent(config: Any, path: str) -> tuple[Any, str]:
    """The dataclass holding the last field of ``path``, and that field's name."""
    *parents, name = path.split(".")
    obj = config
    for depth, part in enumerate(parents):
        child = getattr(obj, part, None) if _has_field(obj, part) else None
        if child is None or not is_dataclass(child):
            raise ConfigError(f"unknown option {path!r}: {'.'.join(parents[:depth + 1])!r} is not a group of options")
        obj = child
    if not _has_field(obj, name):
        valid = ", ".join(f.name for f in fields(obj))
        raise ConfigError(f"unknown option {path!r}: {type(obj).__name__} has {valid}")
    return obj, name


def _has_field(obj: Any, name: str) -> bool:
    return is_dataclass(obj) and any(f.name == name for f in fields(obj))


def set_option(config: T, path: str, value: Any) -> T:
    """A copy of the dataclass tree ``config`` with the field at dotted ``path`` set to ``value`` (a string is
    parsed by the field's type, see :func:`parse_value`); every dataclass on the path is rebuilt, so each
    checks its values again in ``__post_init__``."""
    _parent(config, path)  # an unknown path fails here, named whole
    try:
        return _replaced(config, path.split("."), value)
    except ConfigError as error:
        raise ConfigError(f"option {path!r}: {error}") from None


def _replaced(config: T, parts: list[str], value: Any) -> T:
    head, *rest = parts
    if rest:
        return dataclasses.replace(config, **{head: _replaced(getattr(config, head), rest, value)})
    annotation = _hints(type(config))[head]
    if isinstance(value, str):
        value = parse_value(value, annotation)
    elif isinstance(value, (list, dict)):
        value = _converted(value, annotation)
    return dataclasses.replace(config, **{head: value})


def option_paths(config: Any, prefix: str = "") -> list[str]:
    """Every leaf option's dotted path in a dataclass tree, in field order."""
    out = []
    for f in fields(config):
        value = getattr(config, f.name)
        path = f"{prefix}{f.name}"
        out += option_paths(value, path + ".") if is_dataclass(value) else [path]
    return out


def check_choice(name: str, value: Any, choices: tuple) -> None:
    """ConfigError naming the choices when ``value`` is not one of them."""
    if value not in choices:
        raise ConfigError(f"invalid {name} {value!r}: choose one of {', '.join(map(str, choices))}")


def check_integer(name: str, value: Any, minimum: int, optional: bool = False) -> None:
    """ConfigError when ``value`` is not an integer of at least ``minimum`` (None allowed when ``optional``)."""
    if optional and value is None:
        return
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ConfigError(f"{name} must be an integer of at least {minimum}{' or None' if optional else ''}, "
                          f"got {value!r}")
