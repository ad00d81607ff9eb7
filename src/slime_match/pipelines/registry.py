"""Base pipelines by name: the built-in Hz+, RootSIFT, Key.Net and learned ones, and those a user registers.

A registered pipeline is what ``BaseConfig.name`` (``make_config(base=...)``, ``--base``) selects:

    >>> class Mine(RootSiftPipeline):
    ...     name = "mine"
    >>> register_pipeline("mine", Mine)
    >>> matcher = Matcher(make_config("slime", base="mine"))
"""

from __future__ import annotations

import dataclasses

import torch

from ..choices import BUILTIN_BASES, LEARNED_BASES
from ..errors import ConfigError
from ..features.descriptors import AUTO_ORDER, resolve_descriptor
from .base import BaseConfig, BasePipeline, unimplemented
from .hzplus import HzPlusPipeline
from .keynet import KeyNetPipeline
from .learned import learned_pipeline_class
from .rootsift import RootSiftPipeline

PIPELINES: dict[str, type[BasePipeline]] = {}  # name -> class, in registration order


def register_pipeline(name: str, cls: type[BasePipeline], replace: bool = False) -> None:
    """Register the base pipeline class ``cls`` as ``name``; ``make_base_pipeline`` builds it as
    ``cls(config, device)``.

    Raises:
        ConfigError: ``name`` is not a non-empty string, or is taken and ``replace`` is False.
        TypeError: ``cls`` is not a :class:`BasePipeline` subclass, lacks a required method (see
            :func:`~.base.unimplemented`), or its ``options`` name fields that :class:`BaseConfig` lacks.
    """
    if not isinstance(name, str) or not name:
        raise ConfigError(f"a base pipeline's name must be a non-empty string, got {name!r}")
    if not (isinstance(cls, type) and issubclass(cls, BasePipeline)):
        raise TypeError(f"base pipeline {name!r}: {cls!r} is not a subclass of BasePipeline")
    missing = unimplemented(cls)
    if missing:
        raise TypeError(f"base pipeline {name!r}: {cls.__name__} must implement {'; '.join(missing)}")
    unknown = set(cls.options) - {f.name for f in dataclasses.fields(BaseConfig)}
    if unknown:
        raise TypeError(f"base pipeline {name!r}: {cls.__name__}.options names {', '.join(sorted(unknown))}, "
                        "which BaseConfig does not have")
    if name in PIPELINES and not replace:
        raise ConfigError(f"a base pipeline is already registered as {name!r} ({PIPELINES[name].__name__}): "
                          "pass replace=True to replace it")
    PIPELINES[name] = cls


def base_names() -> tuple[str, ...]:
    """The names of the registered base pipelines (what ``BaseConfig.name`` may be)."""
    return tuple(PIPELINES)


def make_base_pipeline(config: BaseConfig, device: torch.device | str = "cpu") -> BasePipeline:
    """Build the base pipeline named by ``config.name``."""
    if config.name not in PIPELINES:
        raise ConfigError(f"unknown base pipeline {config.name!r}: choose one of {', '.join(base_names())}")
    return PIPELINES[config.name](config, torch.device(device))


def resolve_auto_descriptor(config: BaseConfig) -> str | None:
    """Set ``config.descriptor`` "auto" of a pipeline that reads one to the best descriptor available (Key.Net's
    pipeline describes with networks only); the warning that names what it passed over, or None."""
    if "descriptor" not in PIPELINES[config.name].options or config.descriptor != "auto":
        return None
    candidates = AUTO_ORDER[:-1] if config.name == "keynet" else AUTO_ORDER
    config.descriptor, warning = resolve_descriptor("auto", weights_dir=config.weights_dir, candidates=candidates)
    return warning


for _name, _cls in zip(BUILTIN_BASES, (HzPlusPipeline, RootSiftPipeline, KeyNetPipeline), strict=True):
    register_pipeline(_name, _cls)
for _name in LEARNED_BASES:
    register_pipeline(_name, learned_pipeline_class(_name))

BASE_NAMES = base_names()  # the built-in pipelines, which are also methods that run one base alone
