"""The feature cache: Slime's block and tile features of an image reused by the next pairs, same matches."""

import dataclasses

import numpy as np
import pytest
from conftest import run_cli

from slime_match import Matcher, load_image, make_config
from slime_match.errors import ConfigError
from slime_match.slime import level_cache
from slime_match.slime.blocks import BlockConfig, make_blocks
from slime_match.slime.level_cache import FeatureLevels, LevelCache, feature_levels, nbytes, request_key
from slime_match.slime.levels import LevelRequest, ScaleLevel

WEIGHT_FREE_SMALL = {"shape": "baumberg", "orientation": "gradient", "descriptor": "rootsift", "scales": (1,)}


def _levels(nbytes_each: int) -> list[ScaleLevel]:
    """A stand-in level whose only array (the context) holds ``nbytes_each`` bytes."""
    return [ScaleLevel(1.0, (8, 8), np.zeros(nbytes_each, np.uint8), None, [0], [])]


def test_nbytes_counts_each_array_once():
    shared = np.zeros(100, np.uint8)
    levels = [ScaleLevel(1.0, (8, 8), shared, None, [0], [np.zeros(10, np.int64)]) for _ in range(2)]
    assert nbytes(levels) == 100 + 2 * 80
    assert nbytes({"a": [shared, (shared,)], "b": 3}) == 100


def test_get_put_eviction_and_the_same_immutable_levels():
    cache = LevelCache(budget_bytes=250)
    cache.put("a", _levels(100))
    cache.put("b", _levels(100))
    first = cache.get("a")  # "a" becomes the most recently used
    with pytest.raises(dataclasses.FrozenInstanceError):
        first[0].members = ["changed by a pair"]
    assert not hasattr(first[0], "fixed")  # no per-pair cache: FixedDescriptors holds a stage's descriptors
    again = cache.get("a")
    assert again is first and again[0] is first[0]  # each use gets the same levels back, unchanged
    cache.put("c", _levels(100))  # over budget: "b", the least recently used, goes
    assert cache.get("b") is None and cache.get("c") is not None and len(cache) == 2
    assert cache.size_bytes == 200 and (cache.hits, cache.misses) == (3, 1)
    cache.put("huge", _levels(300))  # larger than the whole budget: not kept, nothing evicted
    assert cache.get("huge") is None and len(cache) == 2
    with pytest.raises(ValueError, match=">= 0 bytes"):
        LevelCache(-1)


def test_image_count_counts_digests():
    cache = LevelCache(budget_bytes=1000)
    for key in (("digest0", "blocks"), ("digest0", "tiles"), ("digest1", "blocks")):  # request_key's layout
        cache.put(key, _levels(10))
    assert len(cache) == 3 and cache.image_count == 2


def test_request_key_follows_pixels_and_request():
    image = np.random.default_rng(0).random((300, 400, 3), dtype=np.float32)
    blocks = make_blocks(300, 400, BlockConfig())
    key = request_key(LevelRequest(image, blocks, detection="merged"))
    assert request_key(LevelRequest(image.copy(), blocks, detection="merged")) == key  # content, not identity
    changed = image.copy()
    changed[5, 5, 0] += 0.5
    assert request_key(LevelRequest(changed, blocks, detection="merged")) != key
    assert request_key(LevelRequest(image, blocks, detection="scale")) != key
    assert request_key(LevelRequest(image, blocks, regions_only=True, detection="merged")) != key
    assert request_key(LevelRequest(image, make_blocks(300, 400, BlockConfig(scales=(1,))), detection="merged")) != key


def test_cached_features_give_the_same_matches(pair):
    left, right = load_image(pair[0]), load_image(pair[1])
    config = make_config("slime", **WEIGHT_FREE_SMALL)
    cached, plain = Matcher(config), Matcher(config, feature_cache_mb=0)
    assert plain.level_cache is None
    for a, b in ((left, right), (right, left), (left, left[::-1].copy()), (left, right)):
        got, expected = cached(a, b), plain(a, b)
        assert len(expected.scores) > 0
        for key in ("keypoints0", "keypoints1", "scores"):
            np.testing.assert_array_equal(getattr(got, key), getattr(expected, key))
    # blocks and tiles of each image: 4 misses for the first pair, 2 for the flipped image, all else hits
    assert (cached.level_cache.misses, cached.level_cache.hits) == (6, 10)


def test_bad_cache_budgets(tmp_path, capsys, pair):
    with pytest.raises(ConfigError, match="feature_cache_mb"):
        Matcher(make_config("slime", **WEIGHT_FREE_SMALL), feature_cache_mb=-1)
    (tmp_path / "pairs.txt").write_text(f"{pair[0]} {pair[1]}\n")
    code, _, err = run_cli(capsys, "pairs", tmp_path / "pairs.txt", "-o", tmp_path / "run", "--feature-cache-mb",
                           "-5", "--method", "slime", "--scales", "1")
    assert code == 2 and "feature_cache_mb must be >= 0" in err and not (tmp_path / "run").exists()


def test_a_self_pair_counts_its_second_image_as_reused(pair):
    """Both images the same picture: its blocks and tiles are computed once and the other two requests are
    copies, so computed = feature_sets - cached_feature_sets holds as for any pair."""
    left, right = load_image(pair[0]), load_image(pair[1])
    matcher = Matcher(make_config("slime", **WEIGHT_FREE_SMALL))
    counts = [matcher(a, b).summary["counts"] for a, b in ((left, left), (left, right))]
    assert [(c["feature_sets"], c["cached_feature_sets"]) for c in counts] == [(4, 2), (4, 2)]
    assert (matcher.level_cache.misses, matcher.level_cache.hits) == (4, 2)


def test_feature_levels_counts():
    levels = [_levels(1), _levels(2), _levels(3)]
    assert FeatureLevels(levels, 2).counts == {"feature_sets": 3, "cached_feature_sets": 2}
    assert FeatureLevels([], 0).counts == {"feature_sets": 0, "cached_feature_sets": 0}


def test_feature_levels_computes_each_distinct_request_once(monkeypatch):
    """Requests the cache cannot answer are computed in one ``build_levels_many`` call, each distinct one once
    (a repeat in the same pair counts as reused); without a cache all are computed."""
    calls = []

    def fake_build(pipeline, requests, workers):
        calls.append([r.detection for r in requests])
        return [_levels(10 + k) for k, _ in enumerate(requests)]

    monkeypatch.setattr(level_cache, "build_levels_many", fake_build)
    g = np.random.default_rng(0)
    a, b = g.random((8, 8, 3), dtype=np.float32), g.random((8, 8, 3), dtype=np.float32)
    requests = [LevelRequest(a, [], detection="merged"), LevelRequest(a.copy(), [], detection="merged"),
                LevelRequest(a, [], detection="scale"), LevelRequest(b, [], detection="merged")]
    cache = LevelCache(budget_bytes=10_000)
    found = feature_levels(None, requests, 2, cache)
    assert calls == [["merged", "scale", "merged"]]  # the copy of a is the same request
    assert found.reused == 1 and found.counts == {"feature_sets": 4, "cached_feature_sets": 1}
    assert found.levels[0] is found.levels[1] and found.levels[2] is not found.levels[0]
    assert len(cache) == 3 and (cache.hits, cache.misses) == (0, 3)
    again = feature_levels(None, requests[2:][::-1], 2, cache)  # all cached
    assert calls == [["merged", "scale", "merged"]] and again.reused == 2
    assert again.levels[0] is found.levels[3] and again.levels[1] is found.levels[2]
    plain = feature_levels(None, requests, 2, None)
    assert calls[-1] == ["merged", "merged", "scale", "merged"]
    assert plain.reused == 0 and len(plain.levels) == 4
