"""Slime's pixel frames: features moved between a level (a block scale's scaled image) and a block's crop.

A block (or tile) crop's pixel (0, 0) is its box corner in the level, so a level point x is x - box[:2] in
the block's own frame; the level itself maps to original pixels by :meth:`.blocks.Block.to_original`.
"""

from __future__ import annotations

import torch

from ..types import Features
from .blocks import Block

__all__ = ["to_block_frame", "translate_features"]


def translate_features(features: Features, offset: tuple[float, float]) -> Features:
    """The same features moved by ``offset`` (x, y) px: LAF and shape-frame centres alike."""
    shift = torch.tensor(offset, dtype=features.laf.dtype, device=features.laf.device)
    laf = features.laf.clone()
    laf[:, :, 2] += shift
    shape_laf = None
    if features.shape_laf is not None:
        shape_laf = features.shape_laf.clone()
        shape_laf[:, :, 2] += shift
    return Features(laf, features.descriptors, features.response, shape_laf)


def to_block_frame(features: Features, block: Block) -> Features:
    """The same features in a block's own pixel frame (the block image's top-left pixel at (0, 0))."""
    return translate_features(features, (-block.box[0], -block.box[1]))
