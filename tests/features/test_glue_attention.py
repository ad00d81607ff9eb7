"""LightGlue's fused cross-attention: the same updates as kornia's block (random weights, several head counts,
a batch, unequal sides), kornia's forward for masked inputs, and with the real weights the same matches."""

import numpy as np
import pytest
import torch
from conftest import require_learned_weights, rotated_astronaut
from kornia.feature.lightglue import CrossBlock

from slime_match.config import make_config
from slime_match.features import learned_weights
from slime_match.features.glue_attention import FusedCrossBlock, fuse_cross_attention
from slime_match.pipelines import make_base_pipeline


def blocks(dim: int, heads: int) -> tuple[CrossBlock, FusedCrossBlock]:
    torch.manual_seed(0)
    reference = CrossBlock(dim, heads).eval()
    fused = CrossBlock(dim, heads).eval()
    fused.load_state_dict(reference.state_dict())
    return reference, fuse_cross_attention(torch.nn.Sequential(fused))[0]


@pytest.mark.parametrize(("dim", "heads", "m", "n"), [(64, 4, 300, 170), (96, 1, 50, 400), (128, 4, 1, 7)])
def test_fused_cross_attention_gives_kornias_updates(dim, heads, m, n):
    reference, fused = blocks(dim, heads)
    assert type(fused) is FusedCrossBlock
    x0, x1 = torch.randn(2, m, dim), torch.randn(2, n, dim)
    with torch.inference_mode():
        expected, found = reference(x0, x1), fused(x0, x1)
    for e, f in zip(expected, found):
        assert f.shape == e.shape
        torch.testing.assert_close(f, e, rtol=1e-4, atol=1e-4)


def test_masked_inputs_take_kornias_forward():
    reference, fused = blocks(64, 4)
    x0, x1 = torch.randn(1, 20, 64), torch.randn(1, 30, 64)
    mask = torch.ones(1, 1, 20, 30, dtype=torch.bool)
    mask[..., 25:] = False
    with torch.inference_mode():
        for e, f in zip(reference(x0, x1, mask), fused(x0, x1, mask)):
            torch.testing.assert_close(f, e, rtol=0, atol=0)


def test_lightglue_is_loaded_fused_and_matches_as_kornias():
    require_learned_weights("aliked-n16", "lightglue-aliked")
    for features in ("aliked", "disk", "xfeat"):
        if learned_weights.cache_path(f"lightglue-{features}").is_file():
            glue = learned_weights.lightglue(features)
            assert sum(type(b) is FusedCrossBlock for b in glue.modules()) == glue.conf.n_layers
            assert not any(type(b) is CrossBlock for b in glue.modules())

    pipeline = make_base_pipeline(make_config("aliked-lg").base, torch.device("cpu"))
    glue = pipeline.glue
    image0, image1, _ = rotated_astronaut(20, 0.8)
    features0, features1 = pipeline.extract(image0), pipeline.extract(image1)
    fused = pipeline.match(features0, features1, image0.shape[:2], image1.shape[:2])
    for block in glue.modules():
        if type(block) is FusedCrossBlock:
            block.__class__ = CrossBlock
    try:
        plain = pipeline.match(features0, features1, image0.shape[:2], image1.shape[:2])
    finally:
        fuse_cross_attention(glue)
    assert len(plain) > 100
    pairs = {tuple(p) for p in np.c_[plain.idx0, plain.idx1]}
    same = pairs & {tuple(p) for p in np.c_[fused.idx0, fused.idx1]}
    assert len(same) >= 0.99 * max(len(plain), len(fused))
