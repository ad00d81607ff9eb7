"""slime-match: image matching by bare homography (Slime) and its base pipelines (Hz+, RootSIFT, Key.Net).

Example:
    >>> import slime_match as sm
    >>> result = sm.match("a.jpg", "b.jpg")                  # Slime on Hz+
    >>> result.keypoints0, result.keypoints1, result.scores  # (K, 2), (K, 2), (K,)

Importing the package changes nothing in the process and loads no heavy module: each name below is imported
on first use (torch with the matcher, the configuration and the result).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

_HOMES = {
    "ConfigError": "errors",
    "ImageError": "errors",
    "SlimeMatchError": "errors",
    "WeightsNotFoundError": "errors",
    "MatchConfig": "config",
    "make_config": "config",
    "MatchResult": "result",
    "Matcher": "matcher",
    "match": "matcher",
    "load_image": "io",
}

__all__ = [
    "ConfigError",
    "ImageError",
    "MatchConfig",
    "MatchResult",
    "Matcher",
    "SlimeMatchError",
    "WeightsNotFoundError",
    "__version__",
    "load_image",
    "make_config",
    "match",
]


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_HOMES[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_HOMES})


if TYPE_CHECKING:
    from .config import MatchConfig, make_config
    from .errors import ConfigError, ImageError, SlimeMatchError, WeightsNotFoundError
    from .io import load_image
    from .matcher import Matcher, match
    from .result import MatchResult
