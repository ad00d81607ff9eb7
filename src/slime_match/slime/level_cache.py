"""The block and tile features of recently matched images, kept for the next pairs that share an image.

Slime's features stage (Secs. 3.1 and 3.8: every block scale and the tiles, detected and described) depends
on one image only, so in a batch of pairs (``slime pairs``, a loop over a Matcher) an image met again need
not be detected again. The cache keeps them per image content, least recently used first out, within a
byte budget. Levels are never changed once built, so a cached level serves any later pair: the matches are
the same as without the cache.
"""

from __future__ import annotations

import hashlib
import logging
from collections import OrderedDict
from dataclasses import dataclass, fields, is_dataclass
from typing import Any

import numpy as np
import torch

from ..pipelines import BasePipeline
from .levels import LevelRequest, ScaleLevel, build_levels_many

logger = logging.getLogger("slime_match")


def request_key(request: LevelRequest, digests: dict[int, str] | None = None) -> tuple:
    """What a request's levels depend on besides the configuration: the image's pixels and the request.

    Args:
        digests: digests of images already hashed, by ``id`` of the image array (filled here): an image's
            block and tile requests hash its pixels once.
    """
    image = request.image
    digests = {} if digests is None else digests
    if id(image) not in digests:
        digests[id(image)] = hashlib.blake2b(np.ascontiguousarray(image).view(np.uint8), digest_size=16).hexdigest()
    return (digests[id(image)], image.shape, str(image.dtype), repr(request.blocks), request.regions_only,
            request.detection)


def nbytes(obj: Any) -> int:
    """Bytes held by the tensors and arrays of ``obj`` (dataclasses, objects, lists, tuples, dicts), each once."""
    seen: set[int] = set()

    def walk(o: Any) -> int:
        if id(o) in seen:
            return 0
        seen.add(id(o))
        if isinstance(o, torch.Tensor):
            return o.numel() * o.element_size()
        if isinstance(o, np.ndarray):
            return o.nbytes
        if isinstance(o, (list, tuple)):
            return sum(walk(x) for x in o)
        if isinstance(o, dict):
            return sum(walk(x) for x in o.values())
        if is_dataclass(o):
            return sum(walk(getattr(o, f.name)) for f in fields(o))
        if hasattr(o, "__dict__"):
            return sum(walk(x) for x in vars(o).values())
        return 0

    return walk(obj)


class LevelCache:
    """Levels (``build_levels_many`` outputs) by request, least recently used evicted beyond ``budget_bytes``.

    Attributes:
        hits, misses: lookups answered from the cache, and not.
    """

    def __init__(self, budget_bytes: int) -> None:
        if budget_bytes < 0:
            raise ValueError(f"the feature cache budget must be >= 0 bytes, got {budget_bytes}")
        self.budget_bytes = budget_bytes
        self.hits = self.misses = 0
        self._entries: OrderedDict[tuple, tuple[list[ScaleLevel], int]] = OrderedDict()

    def __len__(self) -> int:
        return len(self._entries)

    @property
    def size_bytes(self) -> int:
        return sum(size for _, size in self._entries.values())

    @property
    def image_count(self) -> int:
        """The images (distinct pixel digests, :func:`request_key`'s first field) with levels held."""
        return len({key[0] for key in self._entries})

    def get(self, key: tuple) -> list[ScaleLevel] | None:
        """The levels stored under ``key``, or None."""
        entry = self._entries.get(key)
        if entry is None:
            self.misses += 1
            return None
        self.hits += 1
        self._entries.move_to_end(key)
        return entry[0]

    def put(self, key: tuple, levels: list[ScaleLevel]) -> None:
        """Store levels (evicting the least recently used beyond the budget; a set larger than it is not kept)."""
        size = nbytes(levels)
        self._entries.pop(key, None)
        if size > self.budget_bytes:
            return
        self._entries[key] = (levels, size)
        while self.size_bytes > self.budget_bytes:
            self._entries.popitem(last=False)


@dataclass
class FeatureLevels:
    """The features stage's output: per request, its levels (``build_levels_many``), and how many requests were
    not computed (answered by the cache, or a repeat of an earlier request of this pair)."""

    levels: list[list[ScaleLevel]]
    reused: int

    @property
    def counts(self) -> dict[str, int]:
        return {"feature_sets": len(self.levels), "cached_feature_sets": self.reused}


def feature_levels(pipeline: BasePipeline, requests: list[LevelRequest], workers: int, cache: LevelCache | None
                   ) -> FeatureLevels:
    """``build_levels_many`` on the requests that ``cache`` cannot answer (each distinct one once, so that
    computed = ``len(requests)`` minus the reused ones, a self-pair's second image included)."""
    if cache is None:
        return FeatureLevels(build_levels_many(pipeline, requests, workers), 0)
    digests: dict[int, str] = {}
    keys = [request_key(request, digests) for request in requests]
    first: dict[tuple, int] = {}  # each distinct request, at its first place, in request order
    for k, key in enumerate(keys):
        first.setdefault(key, k)
    found = {key: cache.get(key) for key in first}
    missing = [key for key, levels in found.items() if levels is None]
    fresh = build_levels_many(pipeline, [requests[first[key]] for key in missing], workers) if missing else []
    for key, levels in zip(missing, fresh):
        cache.put(key, levels)
        found[key] = levels
    reused = len(keys) - len(missing)
    logger.info("Slime features: %d of %d feature sets (the blocks, the tiles of each image) reused",
                reused, len(keys))
    return FeatureLevels([found[key] for key in keys], reused)
