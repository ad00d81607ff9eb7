"""The order of a batch's pairs: next, the pair that reuses the most of a worker's cached image features.

A Matcher keeps the Slime features of the images it matched last (:class:`~slime_match.slime.level_cache.
LevelCache`), so a pair whose images it holds skips their feature stage. In file order an exhaustive list
(hloc's ``pairs_from_exhaustive``) meets each image again only after a whole row, when a small cache has long
dropped it: about one image in two is computed again. Chosen greedily, as here, a worker holding C images
brings in one new image for up to C - 1 pairs. The order changes no pair's matches, only when it is made.
"""

from __future__ import annotations

from collections import OrderedDict, defaultdict
from collections.abc import Hashable, Iterable, Sequence


class PairScheduler:
    """Hands out the pairs of a list one at a time, each once.

    :meth:`next` picks, among the pairs not handed out yet:
    1. one whose two images are both cached (the most recently used first);
    2. else one that brings in the uncached image shared with the most cached images by the remaining pairs
       (the pair with the most recently used of them);
    3. else the first in list order.
    Ties go to list order, so the order is deterministic.
    """

    def __init__(self, pairs: Sequence[tuple[Hashable, Hashable]]) -> None:
        """Args:
            pairs: (image0, image1) identities (paths, names) in list order.
        """
        self._pairs = list(pairs)
        self._taken = [False] * len(self._pairs)
        self._first = 0  # no pair before it is left
        self._left = len(self._pairs)
        # the remaining pairs of each image, in list order (a dict as an ordered set)
        self._by_image: dict[Hashable, dict[int, None]] = defaultdict(dict)
        for index, (image0, image1) in enumerate(self._pairs):
            self._by_image[image0][index] = None
            self._by_image[image1][index] = None

    def __len__(self) -> int:
        """The pairs not handed out yet."""
        return self._left

    def next(self, cached: Sequence[Hashable] = ()) -> int | None:
        """The list index of the next pair for a worker, now taken; None when every pair is taken.

        Args:
            cached: the images whose features the worker holds, the most recently used first.
        """
        if not self._left:
            return None
        index = self._both_cached(cached)
        if index is None:
            index = self._one_cached(cached)
        if index is None:
            while self._taken[self._first]:
                self._first += 1
            index = self._first
        self._take(index)
        return index

    def _both_cached(self, cached: Sequence[Hashable]) -> int | None:
        held = set(cached)
        for image in cached:
            for index in self._by_image.get(image, ()):
                image0, image1 = self._pairs[index]
                if image0 in held and image1 in held:
                    return index
        return None

    def _one_cached(self, cached: Sequence[Hashable]) -> int | None:
        held = set(cached)
        shared: dict[Hashable, int] = defaultdict(int)  # uncached image -> remaining pairs with cached ones
        first: dict[Hashable, int] = {}  # uncached image -> its pair with the most recently used cached image
        for image in cached:
            for index in self._by_image.get(image, ()):
                image0, image1 = self._pairs[index]
                other = image1 if image0 == image else image0
                if other not in held:
                    shared[other] += 1
                    first.setdefault(other, index)
        if not shared:
            return None
        most = max(shared.values())
        return min(first[image] for image, count in shared.items() if count == most)

    def _take(self, index: int) -> None:
        self._taken[index] = True
        self._left -= 1
        for image in self._pairs[index]:
            self._by_image[image].pop(index, None)


class RecentImages:
    """The images a worker matched, most recent first: the images its least-recently-used feature cache holds
    when that cache holds ``count`` images (:attr:`LevelCache.image_count`)."""

    def __init__(self) -> None:
        self._order: OrderedDict[Hashable, None] = OrderedDict()

    def touch(self, images: Iterable[Hashable]) -> None:
        """Record that the images of a pair were just used."""
        for image in images:
            self._order.pop(image, None)
            self._order[image] = None

    def held(self, count: int) -> list[Hashable]:
        """The ``count`` most recently used images, the most recent first."""
        recent = []
        for image in reversed(self._order):
            if len(recent) >= count:
                break
            recent.append(image)
        return recent
