"""``--shard I/N``: the I-th of N parts of a pairs list, for N processes (a job array) sharing one run folder.

The split is deterministic (the same list gives every process the same parts), balanced (the parts' sizes
differ by one pair at most) and keeps the pairs that share images together: each image's features are then
computed in few parts. The pairs are ordered by the image graph: its connected components one after another,
each walked breadth-first from its first image, a pair placed at the later of its two images in that walk;
this order is cut into N runs of consecutive pairs. A component is thus split only where a cut falls, a
sequence of video frames into runs of frames, an exhaustive list into growing sets of images.
"""

from __future__ import annotations

from collections import defaultdict, deque
from collections.abc import Hashable, Sequence

from ..errors import ConfigError


def parse_shard(text: str) -> tuple[int, int]:
    """``"I/N"`` -> (I, N), with 1 <= I <= N.

    Raises:
        ConfigError: text that is not two integers I/N with 1 <= I <= N.
    """
    index, sep, count = str(text).partition("/")
    try:
        shard = (int(index), int(count))
    except ValueError:
        shard = None
    if not sep or shard is None:
        raise ConfigError(f"a shard is I/N (part I of N, e.g. 1/4), got {text!r}")
    check_shard(shard)
    return shard


def check_shard(shard: tuple[int, int]) -> None:
    """Raise ConfigError unless ``shard`` is (I, N) with 1 <= I <= N."""
    index, count = shard
    if count < 1 or not 1 <= index <= count:
        raise ConfigError(f"shard {index}/{count}: expected I/N with 1 <= I <= N (part I of N parts)")


def shard_positions(pairs: Sequence[tuple[Hashable, Hashable]], index: int, count: int) -> list[int]:
    """The list positions, in list order, of the pairs in part ``index`` (1 to ``count``) of ``count``.

    Args:
        pairs: (image0, image1) identities (paths, names) in list order.
        index, count: the part and the number of parts.
    """
    check_shard((index, count))
    by_image: dict[Hashable, list[Hashable]] = defaultdict(list)
    for image0, image1 in pairs:
        by_image[image0].append(image1)
        by_image[image1].append(image0)
    rank: dict[Hashable, int] = {}
    for first, _ in pairs:  # each component from its first pair's first image, breadth-first
        if first in rank:
            continue
        rank[first] = len(rank)
        queue = deque([first])
        while queue:
            for other in by_image[queue.popleft()]:
                if other not in rank:
                    rank[other] = len(rank)
                    queue.append(other)
    order = sorted(range(len(pairs)), key=lambda k: (max(rank[pairs[k][0]], rank[pairs[k][1]]),
                                                     min(rank[pairs[k][0]], rank[pairs[k][1]]), k))
    start, stop = (index - 1) * len(pairs) // count, index * len(pairs) // count
    return sorted(order[start:stop])
