"""The order of a batch's pairs: each next pair reuses the most of a worker's cached images."""

import itertools
from collections import OrderedDict

import pytest

from slime_match.runs.schedule import PairScheduler, RecentImages


def _lru_misses(pairs, order, capacity):
    """Images computed by a worker whose least-recently-used cache holds ``capacity`` images."""
    cache, misses = OrderedDict(), 0
    for index in order:
        for image in pairs[index]:
            if image in cache:
                cache.move_to_end(image)
            else:
                misses += 1
                cache[image] = None
                if len(cache) > capacity:
                    cache.popitem(last=False)
    return misses


def _scheduled(pairs, capacity):
    """The order a worker with such a cache is given, as ``slime pairs`` runs it."""
    scheduler, recent, order, seen = PairScheduler(pairs), RecentImages(), [], set()
    while (index := scheduler.next(recent.held(min(capacity, len(seen))))) is not None:
        order.append(index)
        recent.touch(pairs[index])
        seen.update(pairs[index])
    return order


def test_four_images_by_hand():
    pairs = list(itertools.combinations("ABCD", 2))  # AB AC AD BC BD CD
    # AB; then C, shared by both cached images (B most recent: BC); AC both cached; D (CD); AD; BD
    assert _scheduled(pairs, capacity=3) == [0, 3, 1, 5, 2, 4]
    assert _lru_misses(pairs, [0, 3, 1, 5, 2, 4], 3) == 5 < _lru_misses(pairs, range(6), 3) == 6


@pytest.mark.parametrize("images, capacity, expected", [(30, 16, 45), (30, 4, 183), (60, 8, 356)])
def test_exhaustive_lists_reuse_the_cache(images, capacity, expected):
    pairs = list(itertools.combinations(range(images), 2))
    order = _scheduled(pairs, capacity)
    assert sorted(order) == list(range(len(pairs)))  # every pair once
    in_file_order = _lru_misses(pairs, range(len(pairs)), capacity)
    assert _lru_misses(pairs, order, capacity) == expected
    assert in_file_order > 2 * expected  # about one image a pair in file order once the cache is too small


def test_sequential_and_retrieval_lists_are_never_worse():
    sequential = [(i, j) for i in range(40) for j in range(i + 1, min(40, i + 6))]
    retrieval = [(i, (7 * i + k * 11) % 50) for i in range(50) for k in (1, 2, 3, 5)]
    for pairs in (sequential, retrieval):
        for capacity in (2, 4, 8, 16):
            order = _scheduled(pairs, capacity)
            assert sorted(order) == list(range(len(pairs)))
            assert _lru_misses(pairs, order, capacity) <= _lru_misses(pairs, range(len(pairs)), capacity)


def test_no_cache_keeps_list_order_and_the_end_is_none():
    pairs = [("a", "b"), ("c", "d"), ("a", "a"), ("b", "c")]
    scheduler = PairScheduler(pairs)
    assert [scheduler.next() for _ in range(4)] == [0, 1, 2, 3]
    assert len(scheduler) == 0 and scheduler.next(["a"]) is None
    scheduler = PairScheduler(pairs)
    assert scheduler.next(["x"]) == 0  # images that no pair has are ignored
    assert scheduler.next(["a"]) == 2  # a pair of one image, held, comes first
    assert scheduler.next(["c"]) == 1 and len(scheduler) == 1  # ties between new images: list order


def test_recent_images():
    recent = RecentImages()
    recent.touch(["a", "b"])
    recent.touch(["c", "a"])
    assert recent.held(2) == ["a", "c"] and recent.held(10) == ["a", "c", "b"] and recent.held(0) == []
