"""Exceptions raised by slime_match; the CLI turns each into one line and a non-zero exit code."""


class SlimeMatchError(Exception):
    """Base class of every error this package raises on purpose."""


class ImageError(SlimeMatchError):
    """An input image is missing, unreadable, not an image, or unusable (e.g. smaller than 32 px)."""


class WeightsNotFoundError(SlimeMatchError):
    """Model weights are neither cached nor downloadable; the message names the alternatives."""


class ConfigError(SlimeMatchError, ValueError):
    """An unknown method/option name or an invalid parameter value."""


def some_of(names: list[str], shown: int) -> str:
    """The first ``shown`` names for an error message, then how many more: "a, b, c and 4 more"."""
    rest = len(names) - shown
    return ", ".join(names[:shown]) + (f" and {rest} more" if rest > 0 else "")


def caused_by_interrupt(error: BaseException) -> bool:
    """Whether a KeyboardInterrupt is among the causes of ``error``: numba re-raises a Ctrl-C that arrives
    inside compiled code as a SystemError whose context is the KeyboardInterrupt."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return True
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return False
