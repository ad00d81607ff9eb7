"""The "auto" method: the best preset whose weights are available, and a note of what it took and passed over.

"auto" takes the first of :data:`AUTO_PRESETS` that can run: ``slime-aliked`` (Slime on ALIKED + LightGlue,
the best on the hard and non-planar sets, docs/choosing.md) when kornia's ALIKED and LightGlue weights are in
its torch-hub cache or can be downloaded there, else ``slime`` (Slime on Hz+, whose descriptor "auto" takes the
best network available, down to the weight-free RootSIFT). Options that only Hz+ reads (``descriptor``,
``shape``, ``orientation``, ``upright``...) or a named ``base`` make it take ``slime``: they say which base the
user wants. The note records the choice; a preset passed over for missing weights is also a warning.
"""

from __future__ import annotations

from .errors import WeightsNotFoundError

AUTO_PRESETS = ("slime-aliked", "slime")  # best first
_LEARNED_WEIGHTS = ("aliked-n16", "lightglue-aliked")  # what slime-aliked loads (features.learned_weights)
PASSED_OVER = "passed over"


def passed_over(note: str) -> bool:
    """Whether the note of :func:`resolve_auto` says a better preset was passed over for missing weights."""
    return PASSED_OVER in note


def resolve_auto(base_options: list[str]) -> tuple[str, str]:
    """The preset "auto" takes.

    Args:
        base_options: the options given with "auto" that name the base or set options the learned preset's
            base does not read (e.g. ``descriptor``); any makes "auto" take ``slime``.

    Returns:
        (preset name, a one-line note of the choice).
    """
    if base_options:
        return "slime", (f"method auto: slime (Slime on the base the options ask for), as given: "
                         f"{', '.join(sorted(base_options))}")
    missing = _missing_learned_weights()
    if missing is None:
        return "slime-aliked", "method auto: slime-aliked (Slime on ALIKED + LightGlue; weights available)"
    return "slime", (f"method auto: slime (Slime on Hz+); {PASSED_OVER} slime-aliked, whose weights are not "
                     f"available: {missing}")


def _missing_learned_weights() -> str | None:
    """None when ALIKED's and LightGlue's weights are cached or could be downloaded now (they are, into kornia's
    cache); else why not."""
    import torch

    from .features import learned_weights

    if all(learned_weights.cache_path(model).is_file() for model in _LEARNED_WEIGHTS):
        return None
    try:
        learned_weights.aliked("n16", 1, device=torch.device("cpu"))
        learned_weights.lightglue("aliked", torch.device("cpu"))
    except WeightsNotFoundError as error:
        return str(error)
    return None
