"""The block and tile features of recently matched images, kept for the next pairs that share an image.

Slime's features stage (Secs. 3.1 and 3.8: every block scale and the tiles, detected and described) depends
on one image only, so in a batch of pairs (``slime pairs``, a loop over a Matcher) an image met again need
not be detected again. The cache keeps them per image content, least recently used first out, within a
byte budget. Each use gets its own empty fixed-orientation cache (``ScaleLevel.fixed``), which a pair fills
as it goes: the matches are the same as without the cache.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import fields, is_dataclass, replace
from typing import Any

import numpy as np
import torch

from .block_matching import LevelRequest, ScaleLevel


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


def fresh_copy(levels: list[ScaleLevel]) -> list[ScaleLevel]:
    """The levels with empty fixed-orientation caches (the features and contexts are shared, never changed)."""
    return [replace(level, fixed={}) for level in levels]


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
        """The levels stored under ``key`` (with empty fixed-orientation caches), or None."""
        entry = self._entries.get(key)
        if entry is None:
            self.misses += 1
            return None
        self.hits += 1
        self._entries.move_to_end(key)
        return fresh_copy(entry[0])

    def put(self, key: tuple, levels: list[ScaleLevel]) -> None:
        """Store levels as they are now (call before a pair fills their fixed-orientation caches)."""
        size = nbytes(levels)
        self._entries.pop(key, None)
        if size > self.budget_bytes:
            return
        self._entries[key] = (fresh_copy(levels), size)
        while self.size_bytes > self.budget_bytes:
            self._entries.popitem(last=False)
