"""Fixed-orientation descriptors: described per (level, bin) on demand, only what was asked, in the crop's
frame, the same for any number of workers, and never stored in the (immutable) levels."""

import math

import numpy as np
import pytest
import torch

from slime_match._runtime.forking import fork_map
from slime_match.pipelines import BaseConfig, make_base_pipeline
from slime_match.slime.fixed_descriptors import FixedDescriptors
from slime_match.slime.levels import build_levels

from .helpers import WEIGHT_FREE, nearest, squares


class _Counting:
    """A pipeline stand-in that counts the regions ``describe_fixed`` is given, per angle."""

    def __init__(self, pipeline):
        self.pipeline, self.described = pipeline, {}

    def __getattr__(self, name):
        return getattr(self.pipeline, name)

    def describe_fixed(self, context, regions, angle):
        self.described.setdefault(round(angle, 9), []).append(len(regions))
        return self.pipeline.describe_fixed(context, regions, angle)


def test_fixed_orientation_descriptors_use_the_crop_context(levels):
    """Re-described per-block regions equal the shared ones: the crop-local frames sample the same pixels."""
    pipeline, _, _, shared, per_block = levels
    for k, lv in enumerate(per_block):
        own = shared[0].members[k]
        dist, j = nearest(lv.features.xy.numpy(), shared[0].features.xy.numpy()[own])
        same = np.nonzero(dist < 0.3)[0]
        assert len(same) > 0.8 * len(lv.features)
        fixed = FixedDescriptors(pipeline, 16)
        fixed.compute([(lv, {3: same}), (shared[0], {3: own[j[same]]})])
        ours = fixed.features(lv, same, 3).descriptors
        ref = fixed.features(shared[0], own[j[same]], 3).descriptors
        cosine = (ours * ref).sum(dim=1)
        assert cosine.median() > 0.99 and (cosine > 0.8).float().mean() > 0.9, cosine.median()
        # without the origin shift the same call samples other pixels: the check above can fail
        wrong = pipeline.describe_fixed(lv.context, lv.features.subset(torch.from_numpy(same)), 3 * 2 * np.pi / 16)
        assert (wrong.descriptors * ref).sum(dim=1).median() < 0.9


def test_fixed_features_of_a_block_without_keypoints_are_empty(levels):
    """A block or tile without keypoints asks for a bin that nothing else needs: ``FixedDescriptors.compute``
    has nothing to describe, and its fixed features are empty instead of an error for a bin never
    described."""
    pipeline, _, _, shared, _ = levels
    counting = _Counting(pipeline)
    nothing = np.zeros(0, np.int64)
    fixed = FixedDescriptors(counting, 16)
    fixed.compute([(shared[0], {11: nothing})])
    assert counting.described == {}  # nothing described for bin 11
    with pytest.raises(RuntimeError, match="before FixedDescriptors.compute"):
        fixed.features(shared[0], np.array([0]), 11)
    empty = fixed.features(shared[0], nothing, 11)
    assert len(empty) == 0 and empty.descriptors.shape[1] == shared[0].features.descriptors.shape[1]


def test_fork_map_and_forked_descriptors_equal_one_process(levels):
    assert fork_map(lambda k: k * k, 11, 2) == [k * k for k in range(11)]
    pipeline, _, _, shared, _ = levels
    out = []
    for workers in (1, 2):
        fixed = FixedDescriptors(pipeline, 16, workers)  # a fresh one: nothing described yet
        wanted = [(lv, {b: np.arange(0, len(lv.features), 1 + b) for b in (0, 3, 5)}) for lv in shared]
        fixed.compute(wanted)
        out.append([fixed.features(lv, index, b).descriptors
                    for lv, bins in wanted for b, index in bins.items()])
    assert all(torch.equal(a, b) for a, b in zip(*out, strict=True))


def test_features_asked_before_compute_raise(levels):
    """Features of a (level, bin) that ``compute`` did not describe are an error, not zeros; another
    FixedDescriptors on the same level describes its own (the level holds no cache)."""
    pipeline, _, _, shared, _ = levels
    level = shared[0]
    fixed = FixedDescriptors(pipeline, 16)
    with pytest.raises(RuntimeError, match="before FixedDescriptors.compute"):
        fixed.features(level, np.array([0, 1]), 3)
    fixed.compute([(level, {3: np.array([0, 1])})])
    assert len(fixed.features(level, np.array([1, 0]), 3)) == 2
    with pytest.raises(RuntimeError, match="before FixedDescriptors.compute"):
        fixed.features(level, np.array([0, 2]), 3)  # feature 2 was not asked for
    with pytest.raises(RuntimeError, match="before FixedDescriptors.compute"):
        fixed.features(level, np.array([0]), 4)  # nor was bin 4
    with pytest.raises(RuntimeError, match="before FixedDescriptors.compute"):
        FixedDescriptors(pipeline, 16).features(level, np.array([0]), 3)


def test_compute_describes_only_what_was_asked_and_not_yet_described(levels):
    """Each (level, bin) is described once for the asked features (duplicates once); asking again describes
    only the features not described before, and the descriptors and frames are those of one call."""
    pipeline, _, _, shared, _ = levels
    level = shared[0]
    counting = _Counting(pipeline)
    fixed = FixedDescriptors(counting, 16)
    fixed.compute([(level, {3: np.array([5, 0, 2, 5]), 6: np.array([1])})])
    assert counting.described == {round(3 * 2 * math.pi / 16, 9): [3], round(6 * 2 * math.pi / 16, 9): [1]}
    fixed.compute([(level, {3: np.array([2, 7, 0])})])
    assert counting.described[round(3 * 2 * math.pi / 16, 9)] == [3, 1]  # only feature 7 is new
    fixed.compute([(level, {3: np.array([7, 5])})])
    assert counting.described[round(3 * 2 * math.pi / 16, 9)] == [3, 1]  # nothing new
    index = np.array([0, 2, 5, 7])
    got = fixed.features(level, index, 3)
    angle = 3 * 2 * math.pi / 16
    whole = pipeline.describe_fixed(level.context, level.features.subset(torch.from_numpy(index)), angle)
    torch.testing.assert_close(got.descriptors, whole.descriptors)
    torch.testing.assert_close(got.laf, whole.laf)
    assert torch.equal(got.response, level.features.response[torch.from_numpy(index)])


def test_use_own_takes_the_levels_own_descriptors_as_bin_0(levels):
    """On an upright base the features' own descriptors are bin 0's: ``use_own`` takes them, nothing is
    described, and bin 0's features are the level's own bit for bit."""
    _, blocks, _, _, _ = levels
    upright = make_base_pipeline(BaseConfig(**{**WEIGHT_FREE, "orientation": "upright"}))
    level, = build_levels(upright, squares()[0], blocks)
    counting = _Counting(upright)
    fixed = FixedDescriptors(counting, 16)
    fixed.use_own([level])
    index = np.arange(0, len(level.features), 2)
    fixed.compute([(level, {0: index})])
    assert counting.described == {}
    got = fixed.features(level, index, 0)
    own = level.features.subset(torch.from_numpy(index))
    assert torch.equal(got.descriptors, own.descriptors) and torch.equal(got.laf, own.laf)
