"""Fixtures shared by the Slime stage tests."""

import pytest

from slime_match.pipelines import BaseConfig, make_base_pipeline
from slime_match.slime.blocks import make_blocks
from slime_match.slime.levels import build_levels

from .helpers import SIZE, WEIGHT_FREE, squares


@pytest.fixture(scope="package")
def levels():
    """A weight-free pipeline, the two blocks of ``squares`` at factor 0.8 (256 x 192), the squares' corners,
    and the blocks' levels with detection "scale" (one level) and "block" (one per block). Levels are never
    changed once built, so every test module of the package shares them."""
    image, corners = squares()
    pipeline = make_base_pipeline(BaseConfig(**WEIGHT_FREE))
    blocks = [b for b in make_blocks(*SIZE) if b.scale_index == 0]  # factor 0.8: 256 x 192, two blocks
    shared = build_levels(pipeline, image, blocks)
    per_block = build_levels(pipeline, image, blocks, detection="block")
    return pipeline, blocks, corners, shared, per_block
