"""Pairs files made from an image folder (``slime make-pairs``): every pair, or each image with its next few.

The file is what ``slime pairs`` reads (hloc's format): one ``name0 name1`` line per pair, names relative to
the image folder with ``/`` between sub-folders, and ``#`` comments.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from ..errors import ConfigError, ImageError, some_of
from ..io import IMAGE_EXTS, save_text

PAIRING_MODES = ("exhaustive", "sequential")


def list_images(folder: str | os.PathLike) -> list[str]:
    """Image files under ``folder`` and its sub-folders, by extension, sorted.

    Args:
        folder: the image folder.

    Returns:
        Names relative to ``folder`` with ``/`` between parts, sorted; hidden files and folders are skipped.

    Raises:
        ImageError: ``folder`` is not a folder.
        ConfigError: a name that a pairs file cannot hold (white space or ``#``).
    """
    root = Path(folder)
    if not root.is_dir():
        raise ImageError(f"image folder {root} not found")
    names = sorted(
        path.relative_to(root).as_posix()
        for path in root.rglob("*")
        if path.suffix.lower() in IMAGE_EXTS and path.is_file()
        and not any(part.startswith(".") for part in path.relative_to(root).parts)
    )
    unfit = [name for name in names if "#" in name or any(c.isspace() for c in name)]
    if unfit:
        raise ConfigError(f"{len(unfit)} image name(s) under {root} hold white space or '#', which a pairs file "
                          f"cannot: {some_of(unfit, 3)}; rename them")
    return names


def exhaustive_pairs(names: Sequence[str]) -> list[tuple[str, str]]:
    """Every unordered pair of ``names``, (names[i], names[j]) for i < j: N (N - 1) / 2 pairs."""
    return [(names[i], names[j]) for i in range(len(names)) for j in range(i + 1, len(names))]


def sequential_pairs(names: Sequence[str], window: int) -> list[tuple[str, str]]:
    """Each name with the ``window`` names after it (video frames in name order), (names[i], names[i + k])."""
    if window < 1:
        raise ConfigError(f"the sequential window must be at least 1 image, got {window}")
    return [(names[i], names[j]) for i in range(len(names)) for j in range(i + 1, min(i + 1 + window, len(names)))]


def make_pairs(folder: str | os.PathLike, mode: str = "exhaustive", window: int = 5) -> list[tuple[str, str]]:
    """The image pairs of a folder.

    Args:
        folder: the image folder (searched with its sub-folders).
        mode: "exhaustive" (every pair) or "sequential" (each image with the ``window`` after it in name order).
        window: images after each one in "sequential" mode.

    Returns:
        (name0, name1) pairs of names relative to ``folder``.

    Raises:
        ImageError: no folder. ConfigError: fewer than two images, a bad mode or window, unfit names.
    """
    if mode not in PAIRING_MODES:
        raise ConfigError(f"unknown pairing mode {mode!r}; choose one of {', '.join(PAIRING_MODES)}")
    names = list_images(folder)
    if len(names) < 2:
        raise ConfigError(f"{Path(folder)} has {len(names)} image(s) ({', '.join(IMAGE_EXTS)}); pairs need two")
    return exhaustive_pairs(names) if mode == "exhaustive" else sequential_pairs(names, window)


def write_pairs(path: str | os.PathLike, pairs: Sequence[tuple[str, str]], comment: str = "") -> None:
    """Write a pairs file atomically: ``comment`` lines first (as ``#`` comments), then one pair per line."""
    lines = [f"# {line}".rstrip() for line in comment.splitlines()] + [f"{a} {b}" for a, b in pairs]
    save_text(path, "\n".join(lines) + "\n")
