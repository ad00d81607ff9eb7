"""Base matching pipelines (Hz+, RootSIFT, Key.Net and the learned ones) behind one interface, registered by
name.

:mod:`.base` defines the interface (:class:`BasePipeline`: ``extract`` and ``match``, and Slime's hooks),
:mod:`.hzplus`, :mod:`.rootsift`, :mod:`.keynet` and :mod:`.learned` (ALIKED, DISK, XFeat with LightGlue or
mutual NN) the built-in pipelines, :mod:`.registry` the names.
"""

from .base import BaseConfig, BasePipeline, CandidateFilter, unimplemented
from .hzplus import HzPlusPipeline
from .keynet import KeyNetPipeline
from .registry import (
    BASE_NAMES,
    PIPELINES,
    base_names,
    make_base_pipeline,
    register_pipeline,
    resolve_auto_descriptor,
)
from .rootsift import RootSiftPipeline

__all__ = ["BASE_NAMES", "PIPELINES", "BaseConfig", "BasePipeline", "CandidateFilter", "HzPlusPipeline",
           "KeyNetPipeline", "RootSiftPipeline", "base_names", "make_base_pipeline", "register_pipeline",
           "resolve_auto_descriptor", "unimplemented"]
