"""The options a page may give a match: ``choices.MATCH_OPTIONS``, the names and choices ``slime match`` takes
too, so that a new method or option reaches the page's menus at once; and the configuration they build,
refused (400) where this server cannot run it (CUDA absent, more workers than its CPUs)."""

from __future__ import annotations

from typing import Any

from ..choices import MATCH_OPTIONS
from .api_errors import ApiError


def server_cpus() -> int:
    """CPUs the server's worker may use (the most ``workers`` a match may ask for)."""
    from .._runtime.cpus import available_cpus

    return available_cpus()


def cuda_available() -> bool:
    import torch

    return bool(torch.cuda.is_available())


def match_choices() -> dict[str, Any]:
    """What ``/api/info`` tells the page about the options: their choices, the largest ``workers``, CUDA."""
    return {"choices": {key: list(values) for key, values in MATCH_OPTIONS.items() if values is not None},
            "options": list(MATCH_OPTIONS), "max_workers": server_cpus(), "cuda": cuda_available()}


def match_config(preset: Any, options: Any, settings: Any, save_stages: bool):
    """The MatchConfig of a preset and the page's options and dotted-path settings (ApiError, or ConfigError
    answered 400, for bad ones)."""
    from ..config import make_config

    if not isinstance(preset, str):
        raise ApiError("preset must be a preset name")
    if not isinstance(options, dict) or not isinstance(settings, dict):
        raise ApiError("options and settings must be JSON objects")
    unknown = sorted(set(options) - set(MATCH_OPTIONS))  # paths such as weights_dir stay the server's
    if unknown:
        raise ApiError(f"unknown or refused option(s) {', '.join(unknown)}: the page may set "
                       f"{', '.join(MATCH_OPTIONS)} and settings by dotted path")
    refused = [key for key in settings if not isinstance(key, str) or "weights_dir" in key]
    if refused:
        raise ApiError(f"setting(s) {', '.join(map(str, refused))} may not be set from the page")
    given = {key: value for key, value in {**options, **settings}.items() if value not in (None, "")}
    given = {key: (value if isinstance(value, (bool, int, float)) else str(value)) for key, value in given.items()}
    config = make_config(preset, **given)
    if config.device.startswith("cuda") and not cuda_available():
        raise ApiError("device cuda: this server has no CUDA device; choose auto or cpu")
    cpus = server_cpus()
    if config.slime.workers is not None and not 1 <= config.slime.workers <= cpus:
        raise ApiError(f"workers must be 1 to {cpus} (the CPUs of this server), got {config.slime.workers}")
    if save_stages and config.method == "slime":
        config.slime.keep_stages = True
    return config
