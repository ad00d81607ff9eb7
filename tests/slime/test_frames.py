"""Slime's pixel frames: features moved between a level and a block's own crop."""

import torch

from slime_match.slime.frames import translate_features
from slime_match.types import Features


def test_translate_features_moves_centres_only():
    laf = torch.tensor([[[2.0, 0.5, 10.0], [0.0, 3.0, 20.0]]])
    f = Features(laf, torch.ones(1, 4), torch.ones(1), laf.clone())
    moved = translate_features(f, (-32.0, 5.0))
    assert torch.equal(moved.xy, torch.tensor([[-22.0, 25.0]]))
    assert torch.equal(moved.shape_laf[:, :, 2], torch.tensor([[-22.0, 25.0]]))
    assert torch.equal(moved.laf[:, :, :2], laf[:, :, :2]) and torch.equal(f.laf, laf)
