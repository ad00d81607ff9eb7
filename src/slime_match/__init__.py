"""slime-match: image matching by bare homography (Slime) and its base pipelines (Hz+, RootSIFT).

Example:
    >>> import slime_match as sm
    >>> result = sm.match("a.jpg", "b.jpg")                  # Slime on Hz+
    >>> result.keypoints0, result.keypoints1, result.scores  # (K, 2), (K, 2), (K,)
"""

__version__ = "0.1.0"

from ._runtime import openmp  # noqa: I001, F401  (first: sets the OpenMP spin default before torch is loaded)
from ._runtime import compile_notice  # noqa: F401  (a notice while numba compiles the loops on a first run)
from .config import MatchConfig, make_config
from .errors import ConfigError, ImageError, SlimeMatchError, WeightsNotFoundError
from .io import load_image
from .matcher import Matcher, match
from .result import MatchResult

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
