"""Building a config dataclass from a dict of option names, with a clear error for unknown names."""

from __future__ import annotations

from dataclasses import fields
from typing import Any, TypeVar

from .errors import ConfigError

T = TypeVar("T")


def config_from_dict(cls: type[T], options: dict[str, Any]) -> T:
    """``cls(**options)`` for a dataclass ``cls``; unknown option names raise ConfigError listing the valid ones."""
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(options) - names)
    if unknown:
        raise ConfigError(f"unknown {cls.__name__} option(s) {unknown}; valid: {sorted(names)}")
    return cls(**options)
